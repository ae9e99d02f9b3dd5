// Contact points given by explicit columns of H. References: hand-made contact sets that break
// one rule each, and the same set written and read back.
#include "squeal/model/builders.h"
#include "squeal/model/pad.h"
#include "squeal/reduction/craig_bampton.h"
#include "squeal/stability/stability.h"

#include <gtest/gtest.h>

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <complex>
#include <filesystem>
#include <fstream>
#include <string>

using namespace squeal;

namespace {

// Runs f with PETSc errors returned instead of printed; the error code.
template <class F>
PetscErrorCode Quietly(F &&f)
{
  PetscPushErrorHandler(PetscReturnErrorHandler, nullptr);
  const PetscErrorCode ierr = f();
  PetscPopErrorHandler();
  return ierr;
}

} // namespace

namespace {

// A 4-DOF contact set in explicit-column form: point 0 on DOF 0 (normal) with h_t on DOFs 2, 3.
ContactSet ExplicitSet()
{
  ContactSet   cs;
  ContactPoint p;
  p.cols[kN] = {{0, 1.0}};
  p.cols[kT] = {{2, 0.5}, {3, -0.25}};
  p.cols[kB] = {{3, 1.0}};
  cs.points  = {p};
  return cs;
}

} // namespace

TEST(ExplicitColumns, ValidationNamesEachBrokenRule)
{
  ContactSet ok = ExplicitSet();
  EXPECT_EQ(ok.Validate(PETSC_COMM_WORLD, 4), 0);
  EXPECT_EQ(ok.PivotDof(0), 0);
  auto refused = [](ContactSet cs, PetscInt N) { return Quietly([&] { return cs.Validate(PETSC_COMM_WORLD, N); }) != 0; };
  ContactSet out = ExplicitSet();
  out.points[0].cols[kT].push_back({4, 1.0}); // DOF 4 of 4
  EXPECT_TRUE(refused(out, 4));
  ContactSet nan = ExplicitSet();
  nan.points[0].cols[kB][0].second = NAN;
  EXPECT_TRUE(refused(nan, 4));
  ContactSet zero = ExplicitSet();
  zero.points[0].cols[kN][0].second = 0;
  EXPECT_TRUE(refused(zero, 4));
  ContactSet twice = ExplicitSet();
  twice.points[0].cols[kT].push_back({2, 1.0});
  EXPECT_TRUE(refused(twice, 4));
  ContactSet shared = ExplicitSet(); // a second point whose h_n holds point 0's pivot
  ContactPoint q;
  q.cols[kN] = {{1, 1.0}, {0, 0.5}};
  shared.points.push_back(q);
  EXPECT_TRUE(refused(shared, 4));
  ContactSet skew = ExplicitSet(); // point 0's h_t touches point 1's normal DOF
  ContactPoint r;
  r.cols[kN] = {{1, 1.0}};
  skew.points.push_back(r);
  EXPECT_EQ(Quietly([&] { return skew.Validate(PETSC_COMM_WORLD, 4); }), 0);
  skew.points[0].cols[kT].push_back({1, 0.1});
  EXPECT_TRUE(refused(skew, 4));
}

TEST(ExplicitColumns, ContactTableRoundTripKeepsEveryColumn)
{
  // Three forms in one table: a plain node, a two-node point with weights (pad minus disc), and
  // explicit columns; written, read back, and compared column by column as dense vectors.
  const PetscInt N = 12;
  ContactSet     cs;
  ContactPoint   a, b, c;
  a.nodes    = {ContactNode{{0, 1, 2}, 1.0}};
  a.t        = {1, 0, 0}, a.n = {0, 0, 1};
  b.nodes    = {ContactNode{{3, 4, 5}, 1.0}, ContactNode{{6, 7, 8}, -1.0}};
  b.t        = {0, 1, 0}, b.n = {0, 0, 1};
  b.g0       = 1e-4, b.speed_factor = 1.5;
  c.cols[kN] = {{9, 1.0}};
  c.cols[kT] = {{10, 0.3}, {11, -0.7}};
  c.cols[kB] = {{11, 0.2}};
  cs.points  = {a, b, c};
  ASSERT_EQ(cs.Validate(PETSC_COMM_WORLD, N), 0);
  int pid = (int)getpid();
  MPI_Bcast(&pid, 1, MPI_INT, 0, PETSC_COMM_WORLD);
  const std::string path = "test_explicit_columns_" + std::to_string(pid) + ".txt";
  ASSERT_EQ(WriteContactTable(PETSC_COMM_WORLD, path.c_str(), cs), 0);
  ContactSet back;
  ASSERT_EQ(ReadContactTable(PETSC_COMM_WORLD, path.c_str(), back), 0);
  ASSERT_EQ(back.Validate(PETSC_COMM_WORLD, N), 0);
  ASSERT_EQ(back.Size(), cs.Size());
  EXPECT_FALSE(back.points[0].nodes.empty()); // the plain node keeps the old row form
  for (PetscInt p = 0; p < cs.Size(); ++p) {
    EXPECT_EQ(back.points[p].g0, cs.points[p].g0);
    EXPECT_EQ(back.points[p].speed_factor, cs.points[p].speed_factor);
    for (int d = 0; d < 3; ++d) {
      std::vector<double> x(N, 0.0), y(N, 0.0);
      cs.ForEachEntry(p, d, [&](PetscInt j, PetscReal v) { x[j] += v; });
      back.ForEachEntry(p, d, [&](PetscInt j, PetscReal v) { y[j] += v; });
      for (PetscInt j = 0; j < N; ++j) EXPECT_NEAR(x[j], y[j], 1e-15) << "point " << p << " direction " << d << " DOF " << j;
    }
  }
  MPI_Barrier(PETSC_COMM_WORLD);
  int rank;
  MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
  if (rank == 0) std::remove(path.c_str());
}
