// The results writer, read back with the HDF5 C API.
#include "squeal/io/h5.h"
#include "squeal/io/start_state.h"

#include <gtest/gtest.h>

#include <cstring>

using namespace squeal;

TEST(H5Writer, ArraysAttributesAndVecsReadBack)
{
  const std::string path = testing::TempDir() + "squeal_h5_test.h5";
  PetscMPIInt       rank, size;
  MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
  MPI_Comm_size(PETSC_COMM_WORLD, &size);
  {
    io::H5Writer out;
    ASSERT_EQ(out.Open(PETSC_COMM_WORLD, path.c_str()), 0);
    const double data[6] = {1.5, -2, 3, 4e-300, 5e300, 6};
    ASSERT_EQ(out.WriteArray("/a/b/table", {3, 2}, data), 0);
    ASSERT_EQ(out.WriteAttribute("/a/b/table", "units", "1/s"), 0);
    ASSERT_EQ(out.WriteAttribute("/a", "critical_mu", std::vector<PetscReal>{0.25, 0.5}), 0);
    ASSERT_EQ(out.WriteAttribute("/a", "count", (PetscInt)7), 0);
    Vec v;
    ASSERT_EQ(VecCreateMPI(PETSC_COMM_WORLD, PETSC_DECIDE, 5, &v), 0);
    ASSERT_EQ(PetscObjectSetName((PetscObject)v, "U"), 0);
    PetscInt lo, hi;
    ASSERT_EQ(VecGetOwnershipRange(v, &lo, &hi), 0);
    for (PetscInt i = lo; i < hi; ++i) ASSERT_EQ(VecSetValue(v, i, 10.0 * i, INSERT_VALUES), 0);
    ASSERT_EQ(VecAssemblyBegin(v), 0);
    ASSERT_EQ(VecAssemblyEnd(v), 0);
    ASSERT_EQ(out.WriteVec("/equilibrium", v), 0);
    ASSERT_EQ(VecDestroy(&v), 0);
  }
  MPI_Barrier(PETSC_COMM_WORLD);
  if (rank == 0) {
    const hid_t f = H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
    ASSERT_GE(f, 0);
    const hid_t d = H5Dopen2(f, "/a/b/table", H5P_DEFAULT);
    const hid_t s = H5Dget_space(d);
    hsize_t     dims[2];
    ASSERT_EQ(H5Sget_simple_extent_ndims(s), 2);
    H5Sget_simple_extent_dims(s, dims, nullptr);
    EXPECT_EQ(dims[0], 3u);
    EXPECT_EQ(dims[1], 2u);
    double back[6];
    ASSERT_GE(H5Dread(d, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, back), 0);
    EXPECT_EQ(back[0], 1.5);
    EXPECT_EQ(back[3], 4e-300);
    EXPECT_EQ(back[4], 5e300);
    const hid_t a = H5Aopen(d, "units", H5P_DEFAULT);
    const hid_t t = H5Aget_type(a);
    char        units[16] = {0};
    ASSERT_LT(H5Tget_size(t), sizeof(units));
    ASSERT_GE(H5Aread(a, t, units), 0);
    EXPECT_STREQ(units, "1/s");
    H5Tclose(t);
    H5Aclose(a);
    H5Sclose(s);
    H5Dclose(d);
    const hid_t g  = H5Oopen(f, "/a", H5P_DEFAULT);
    const hid_t ac = H5Aopen(g, "critical_mu", H5P_DEFAULT);
    double      mu[2];
    ASSERT_GE(H5Aread(ac, H5T_NATIVE_DOUBLE, mu), 0);
    EXPECT_EQ(mu[0], 0.25);
    EXPECT_EQ(mu[1], 0.5);
    H5Aclose(ac);
    H5Oclose(g);
    const hid_t du = H5Dopen2(f, "/equilibrium/U", H5P_DEFAULT);
    ASSERT_GE(du, 0);
    double u[5];
    ASSERT_GE(H5Dread(du, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, u), 0);
    for (int i = 0; i < 5; ++i) EXPECT_EQ(u[i], 10.0 * i);
    H5Dclose(du);
    H5Fclose(f);
  }
}

// A result written again (-analyses auto: shooting after the steady state, where Newton from the
// route's pre-periods had failed): the group removed first, the second write alone remains.
TEST(H5Writer, ARemovedGroupIsWrittenAgainAlone)
{
  const std::string path = testing::TempDir() + "squeal_h5_remove.h5";
  {
    io::H5Writer out;
    ASSERT_EQ(out.Open(PETSC_COMM_WORLD, path.c_str()), 0);
    const double a[2] = {1, 2}, b[3] = {3, 4, 5};
    ASSERT_EQ(out.WriteArray("/shooting/Z0", {2}, a), 0);
    ASSERT_EQ(out.WriteArray("/shooting/floquet", {2}, a), 0);
    ASSERT_EQ(out.Remove("/shooting"), 0);
    ASSERT_EQ(out.Remove("/absent/group"), 0); // nothing to remove: no error
    ASSERT_EQ(out.WriteArray("/shooting/Z0", {3}, b), 0);
    ASSERT_EQ(out.Close(), 0);
  }
  io::H5Reader in;
  ASSERT_EQ(in.Open(PETSC_COMM_WORLD, path.c_str(), "-test"), 0);
  std::vector<hsize_t> dims;
  ASSERT_EQ(in.Dims("/shooting/floquet", dims), 0);
  EXPECT_TRUE(dims.empty());
  std::vector<PetscReal> z;
  ASSERT_EQ(in.Read("/shooting/Z0", z), 0);
  EXPECT_EQ(z, (std::vector<PetscReal>{3, 4, 5}));
}

// An empty list attribute (a steady state interrupted before its spectrum has bases) is written as a
// zero-length attribute, not an HDF5 error that loses the analysis' other results.
TEST(H5Writer, AnEmptyListAttributeIsZeroLength)
{
  const std::string path = testing::TempDir() + "squeal_h5_empty_attr.h5";
  PetscMPIInt       rank;
  MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
  {
    io::H5Writer out;
    ASSERT_EQ(out.Open(PETSC_COMM_WORLD, path.c_str()), 0);
    ASSERT_EQ(out.WriteAttribute("/steady_state", "bases", std::vector<PetscReal>{}), 0);
    ASSERT_EQ(out.WriteAttribute("/steady_state", "rms", 1.25), 0);
    ASSERT_EQ(out.Close(), 0);
  }
  MPI_Barrier(PETSC_COMM_WORLD);
  if (rank == 0) {
    const hid_t f = H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
    ASSERT_GE(f, 0);
    const hid_t g = H5Oopen(f, "/steady_state", H5P_DEFAULT);
    ASSERT_GE(g, 0);
    const hid_t a = H5Aopen(g, "bases", H5P_DEFAULT);
    ASSERT_GE(a, 0);
    const hid_t s = H5Aget_space(a);
    EXPECT_EQ(H5Sget_simple_extent_npoints(s), 0);
    H5Sclose(s);
    H5Aclose(a);
    double      rms = 0;
    const hid_t ar  = H5Aopen(g, "rms", H5P_DEFAULT);
    ASSERT_GE(H5Aread(ar, H5T_NATIVE_DOUBLE, &rms), 0);
    EXPECT_EQ(rms, 1.25);
    H5Aclose(ar);
    H5Oclose(g);
    H5Fclose(f);
  }
}

// The reader of -transient_start and -shoot_start: what the writer wrote comes back whole or by
// rows, scalars from one-value datasets and attributes, absent names as absent; the start states
// are chosen by source and size, with the reactions and the period of each kind.
TEST(H5Reader, ReadsBackWhatTheWriterWrote)
{
  const std::string path = testing::TempDir() + "squeal_h5_reader.h5";
  {
    io::H5Writer out;
    ASSERT_EQ(out.Open(PETSC_COMM_WORLD, path.c_str()), 0);
    const double table[6] = {1, 2, 3, 4, 5, 6}, one = 0.125;
    ASSERT_EQ(out.WriteArray("/g/table", {3, 2}, table), 0);
    ASSERT_EQ(out.WriteArray("/g/one", {}, &one), 0);
    ASSERT_EQ(out.WriteAttribute("/g", "count", (PetscInt)7), 0);
    ASSERT_EQ(out.WriteAttribute("/g", "pair", std::vector<PetscReal>{0.25, 0.5}), 0);
    ASSERT_EQ(out.WriteAttribute("/g", "single", std::vector<PetscReal>{2.5}), 0);
    ASSERT_EQ(out.SetStatus("complete"), 0);
    ASSERT_EQ(out.Close(), 0);
  }
  io::H5Reader in;
  ASSERT_EQ(in.Open(PETSC_COMM_WORLD, path.c_str(), "-test_start"), 0);
  EXPECT_EQ(in.Status(), "complete");
  std::vector<hsize_t> dims;
  ASSERT_EQ(in.Dims("/g/table", dims), 0);
  ASSERT_EQ(dims, (std::vector<hsize_t>{3, 2}));
  ASSERT_EQ(in.Dims("/g/none", dims), 0);
  EXPECT_TRUE(dims.empty());
  ASSERT_EQ(in.Dims("/nogroup/none", dims), 0);
  EXPECT_TRUE(dims.empty());
  std::vector<PetscReal> x;
  ASSERT_EQ(in.Read("/g/table", x), 0);
  EXPECT_EQ(x, (std::vector<PetscReal>{1, 2, 3, 4, 5, 6}));
  ASSERT_EQ(in.Read("/g/table", x, 2), 0);
  EXPECT_EQ(x, (std::vector<PetscReal>{5, 6}));
  PetscReal v;
  bool      found;
  ASSERT_EQ(in.ReadScalar("/g/one", nullptr, &v, &found), 0);
  EXPECT_TRUE(found);
  EXPECT_EQ(v, 0.125);
  ASSERT_EQ(in.ReadScalar("/g", "count", &v, &found), 0);
  EXPECT_TRUE(found);
  EXPECT_EQ(v, 7);
  ASSERT_EQ(in.ReadScalar("/g", "single", &v, &found), 0);
  EXPECT_TRUE(found);
  EXPECT_EQ(v, 2.5);
  ASSERT_EQ(in.ReadScalar("/g", "pair", &v, &found), 0); // two values: not a scalar
  EXPECT_FALSE(found);
  ASSERT_EQ(in.ReadScalar("/g", "none", &v, &found), 0);
  EXPECT_FALSE(found);
  ASSERT_EQ(in.ReadScalar("/none/one", nullptr, &v, &found), 0);
  EXPECT_FALSE(found);
  PetscPushErrorHandler(PetscReturnErrorHandler, nullptr);
  EXPECT_NE(in.Read("/g/none", x), 0);
  EXPECT_NE(in.Read("/g/table", x, 3), 0); // past the last row
  io::H5Reader bad;
  EXPECT_NE(bad.Open(PETSC_COMM_WORLD, (testing::TempDir() + "squeal_no_such_file.h5").c_str(), "-test_start"), 0);
  PetscPopErrorHandler();
}

TEST(H5Reader, StartStatesBySourceAndSize)
{
  const std::string path = testing::TempDir() + "squeal_h5_start.h5";
  const PetscInt    N = 2, nc = 1;
  {
    io::H5Writer out;
    ASSERT_EQ(out.Open(PETSC_COMM_WORLD, path.c_str()), 0);
    const double t[3] = {0, 0.1, 0.2}, U[6] = {1, 2, 3, 4, 5, 6}, V[6] = {-1, -2, -3, -4, -5, -6}, R[9] = {0, 0, 1, 0, 0, 2, 0.3, 0, 3};
    ASSERT_EQ(out.WriteArray("/transient/t", {3}, t), 0);
    ASSERT_EQ(out.WriteArray("/transient/U", {3, 2}, U), 0);
    ASSERT_EQ(out.WriteArray("/transient/V", {3, 2}, V), 0);
    ASSERT_EQ(out.WriteArray("/transient/R", {3, 1, 3}, R), 0);
    ASSERT_EQ(out.WriteAttribute("/transient", "settled", (PetscInt)1), 0);
    ASSERT_EQ(out.WriteAttribute("/transient", "period", 0.01), 0);
    const double Z[4] = {7, 8, 9, 10}, T = 0.02, Zf[6] = {1, 1, 1, 2, 2, 2};
    ASSERT_EQ(out.WriteArray("/shooting/Z0", {4}, Z), 0);
    ASSERT_EQ(out.WriteArray("/shooting/period", {}, &T), 0);
    ASSERT_EQ(out.WriteArray("/expanded/Z0", {6}, Zf), 0); // a full model of 3 DOFs
    ASSERT_EQ(out.WriteArray("/steady_state/Z_end", {4}, Zf), 0);
    ASSERT_EQ(out.WriteAttribute("/steady_state", "bases", std::vector<PetscReal>{50.0}), 0);
    ASSERT_EQ(out.SetStatus("complete"), 0);
    ASSERT_EQ(out.Close(), 0);
  }
  io::StartState s;
  ASSERT_EQ(io::ReadStartState(PETSC_COMM_WORLD, path, "auto", N, nc, "-test_start", s), 0);
  EXPECT_EQ(s.U, (std::vector<PetscReal>{5, 6})); // the last record
  EXPECT_EQ(s.dU, (std::vector<PetscReal>{-5, -6}));
  EXPECT_EQ(s.R, (std::vector<PetscReal>{0.3, 0, 3}));
  EXPECT_EQ(s.period, 0.01);
  EXPECT_NE(s.what.find("the last record of /transient (t = 0.2 s, record 2)"), std::string::npos);
  ASSERT_EQ(io::ReadStartState(PETSC_COMM_WORLD, path, "steady", N, nc, "-test_start", s), 0);
  EXPECT_EQ(s.U, (std::vector<PetscReal>{1, 1}));
  EXPECT_EQ(s.dU, (std::vector<PetscReal>{1, 2}));
  EXPECT_TRUE(s.R.empty());
  EXPECT_EQ(s.period, 1 / 50.0); // one base: 1 / f1
  ASSERT_EQ(io::ReadStartState(PETSC_COMM_WORLD, path, "shooting", N, nc, "-test_start", s), 0);
  EXPECT_EQ(s.U, (std::vector<PetscReal>{7, 8}));
  EXPECT_EQ(s.dU, (std::vector<PetscReal>{9, 10}));
  EXPECT_EQ(s.period, 0.02);
  // The full model of 3 DOFs: only /expanded/Z0 has its size, with the cycle's period.
  ASSERT_EQ(io::ReadStartState(PETSC_COMM_WORLD, path, "auto", 3, 5, "-test_start", s), 0);
  EXPECT_EQ(s.U, (std::vector<PetscReal>{1, 1, 1}));
  EXPECT_EQ(s.dU, (std::vector<PetscReal>{2, 2, 2}));
  EXPECT_EQ(s.period, 0.02);
  EXPECT_EQ(s.what, "/expanded/Z0 of " + path);
  PetscPushErrorHandler(PetscReturnErrorHandler, nullptr);
  EXPECT_NE(io::ReadStartState(PETSC_COMM_WORLD, path, "auto", 4, nc, "-test_start", s), 0); // no source of 4 DOFs
  EXPECT_NE(io::ReadStartState(PETSC_COMM_WORLD, path, "energy", N, nc, "-test_start", s), 0);
  PetscPopErrorHandler();
}
