// Contact points given by explicit columns of H, and the interface reduction of a Craig-Bampton
// model (craig_bampton.h). References: the full model's unstable eigenvalues (the error must fall
// as the in-plane basis grows), the plain Craig-Bampton model (k = 2 n_c is an exact change of
// basis), the same model written and read back, and hand-made contact sets that break one rule each.
#include "reduction_helpers.h"
#include "squeal/model/builders.h"
#include "squeal/model/fe_contact.h"
#include "squeal/model/pad.h"
#include "squeal/energy/energy.h"
#include "squeal/reduction/craig_bampton.h"
#include "squeal/shooting/shooting.h"
#include "squeal/stability/stability.h"

#include <gtest/gtest.h>

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <complex>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

using namespace squeal;
using test::MaxRelError;
using test::SmallPad;
using test::Unstable;

namespace {

PetscErrorCode Reduce(const Model &full, PetscReal fmax, PetscInt k, Model &red, ReductionInfo *info = nullptr, PetscInt statics = -1)
{
  CraigBampton cb(full.comm());
  PetscFunctionBeginUser;
  PetscCall(cb.SetFMax(fmax));
  PetscCall(cb.SetInterfaceModes(k));
  PetscCall(cb.SetInterfaceStatics(statics));
  PetscCall(cb.Reduce(full, red));
  if (info) *info = cb.Info();
  PetscFunctionReturn(0);
}

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

TEST(InterfaceReduction, WholeInPlaneBasisIsAnExactChangeOfBasis)
{
  // k = 2 n_c keeps every in-plane DOF: the reduced model is the plain CB model in rotated,
  // M-orthonormalised interface coordinates, so its eigenvalues are the same to round-off.
  PadParams p = SmallPad();
  Model     full, cb, ir;
  ASSERT_EQ(BuildPad(PETSC_COMM_WORLD, p, full), 0);
  const PetscInt nc = full.contacts.Size();
  ReductionInfo  info;
  ASSERT_EQ(Reduce(full, 30000, -1, cb), 0);
  ASSERT_EQ(Reduce(full, 30000, 2 * nc, ir, &info), 0);
  EXPECT_EQ(info.n_normal, nc);
  EXPECT_EQ(info.n_inplane_modes, 2 * nc);
  EXPECT_EQ(ir.Size(), cb.Size());
  EXPECT_TRUE(ir.contacts.HasExplicitColumns());
  EXPECT_NE(ir.name.find("IR("), std::string::npos);
  const auto a = Unstable(cb), b = Unstable(ir);
  ASSERT_FALSE(a.empty());
  EXPECT_EQ(a.size(), b.size());
  EXPECT_LT(MaxRelError(a, b), 1e-9);
  EXPECT_LT(MaxRelError(b, a), 1e-9);
}

TEST(InterfaceReduction, UnstableEigenvaluesConvergeToTheFullModelsAsTheInPlaneBasisGrows)
{
  PetscMPIInt size;
  ASSERT_EQ(MPI_Comm_size(PETSC_COMM_WORLD, &size), 0);
  if (size > 1) GTEST_SKIP() << "serial numerics (6 stability solves); the distributed reduction is checked by Reduction.*";
  PadParams p = SmallPad();
  Model     full;
  ASSERT_EQ(BuildPad(PETSC_COMM_WORLD, p, full), 0);
  const PetscInt nc = full.contacts.Size();
  // The band: the full model's unstable eigenvalues below 10 kHz (4 of its 12, 4.19-9.71 kHz).
  // Like the CB cut-off, the in-plane modes kept must reach well above it: k = n_c keeps them to
  // 14.5 kHz, k = 3 n_c / 2 to 17.1 kHz (the whole basis reaches 29 kHz).
  std::vector<std::complex<double>> ref;
  for (auto r : Unstable(full))
    if (r.imag() < 2 * PETSC_PI * 10000) ref.push_back(r);
  ASSERT_GE(ref.size(), 3u);
  Model cb;
  ASSERT_EQ(Reduce(full, 30000, -1, cb), 0);
  const double        cb_err = MaxRelError(ref, Unstable(cb));
  std::vector<double> errs;
  for (PetscInt k : {nc / 2, nc, 3 * nc / 2, 2 * nc}) {
    Model         red;
    ReductionInfo info;
    ASSERT_EQ(Reduce(full, 30000, k, red, &info), 0);
    EXPECT_EQ(red.Size(), cb.Size() - 2 * nc + k);
    errs.push_back(MaxRelError(ref, Unstable(red)));
    std::printf("interface modes k = %3d of %3d (to %7.1f Hz): reduced N = %3d, max rel. error of the %zu unstable eigenvalues "
                "below 10 kHz %.3e (CB alone %.3e)\n",
                (int)k, (int)(2 * nc), (double)info.inplane_freq.back(), (int)red.Size(), ref.size(), errs.back(), cb_err);
  }
  for (size_t i = 1; i < errs.size(); ++i) EXPECT_LT(errs[i], errs[i - 1]) << "k step " << i;
  EXPECT_LT(errs.back(), 1.001 * cb_err + 1e-9); // k = 2 n_c: CB's own error
  EXPECT_LT(errs[1], 1e-2);                      // k = n_c: half the in-plane DOFs
  EXPECT_LT(errs[2], 3e-3);                      // k = 3 n_c / 2
}

namespace {

// The committed CalculiX plate + pad (tests/data/calculix/tb.*, test_calculix.cpp): 171 DOFs,
// node-to-node pairs of a pad node (+1) and a plate node (-1), with Rayleigh damping here so
// that the eigenvalues are those of a damped brake.
CalculixModelSpec TwoBlocks()
{
  CalculixModelSpec s;
  s.job                = std::string(SQUEAL_SOURCE_DIR) + "/tests/data/calculix/tb";
  s.pressure           = 1e5;
  s.pairing.axis       = Eigen::Vector3d(0, 0, 1);
  s.pairing.axis_point = Eigen::Vector3d(-0.3, 0.02, 0);
  s.ray_b              = 1e-7;
  s.mu                 = 0.4;
  s.V                  = 5;
  return s;
}

// Eigenvalues sigma + i omega (omega > 0) of the linearisation below fmax Hz.
std::vector<std::complex<double>> Band(Model &model, double fmax)
{
  StabilityResult                   res;
  std::vector<std::complex<double>> out;
  if (!test::SolveStability(model, res, 24)) return out;
  for (const auto &m : res.modes)
    if (m.omega > 0 && m.omega < 2 * PETSC_PI * fmax) out.emplace_back(m.sigma, m.omega);
  return out;
}

} // namespace

TEST(InterfaceReduction, TwoBodyPairsKeepTheirRelativeNormalAndConvergeToTheFullModel)
{
  Model full;
  ASSERT_EQ(BuildCalculix(PETSC_COMM_WORLD, TwoBlocks(), full), 0);
  const PetscInt nc = full.contacts.Size();
  ASSERT_GT(nc, 0);
  ASSERT_EQ(full.contacts.points[0].nodes.size(), 2u);
  const PetscInt ns = 6 * nc - nc; // the interface DOFs besides one normal per pair
  // The band: the full model's eigenvalues below 6 kHz (its first 7 structural frequencies).
  const auto ref = Band(full, 6000);
  ASSERT_GE(ref.size(), 5u);
  Model cb;
  ASSERT_EQ(Reduce(full, 30000, -1, cb), 0);
  const double cb_err = MaxRelError(ref, Band(cb, 8000));
  // k = ns: an exact change of basis of the CB model, its eigenvalues to round-off.
  {
    Model         ir;
    ReductionInfo info;
    ASSERT_EQ(Reduce(full, 30000, ns, ir, &info), 0);
    EXPECT_EQ(info.n_normal, nc);
    EXPECT_EQ(info.n_inplane_modes, ns);
    EXPECT_EQ(ir.Size(), cb.Size());
    // h_n of pair c selects coordinate c with the pad node's weight: x_c is the relative normal displacement.
    for (PetscInt c = 0; c < nc; ++c) {
      const ContactPoint &p = ir.contacts.points[c];
      EXPECT_TRUE(p.nodes.empty());
      ASSERT_EQ(p.cols[kN].size(), 1u);
      EXPECT_EQ(p.cols[kN][0].first, c);
      EXPECT_EQ(p.cols[kN][0].second, full.contacts.points[c].nodes[0].weight);
      for (int d : {kT, kB})
        for (const auto &e : p.cols[d]) EXPECT_GE(e.first, nc) << "h_t, h_b on the modes only";
    }
    const auto a = Band(cb, 8000), b = Band(ir, 8000);
    ASSERT_EQ(a.size(), b.size());
    EXPECT_LT(MaxRelError(a, b), 1e-9);
    EXPECT_LT(MaxRelError(b, a), 1e-9);
  }
  // Fewer modes: the error against the full model falls to CB's own as k grows. By default the
  // statics of the n_c relative normals join the k modes (n_c more DOFs); without them (statics 0)
  // the basis is the k modes alone.
  std::vector<double> errs, errs_plain;
  for (PetscInt k : {ns / 4, ns / 2, 3 * ns / 4}) {
    Model         red, plain;
    ReductionInfo info, info_plain;
    ASSERT_EQ(Reduce(full, 30000, k, red, &info), 0);
    ASSERT_EQ(Reduce(full, 30000, k, plain, &info_plain, 0), 0);
    EXPECT_EQ(info.n_interface_statics, nc);
    EXPECT_EQ(info_plain.n_interface_statics, 0);
    EXPECT_EQ(red.Size(), cb.Size() - ns + k + nc);
    EXPECT_EQ(plain.Size(), cb.Size() - ns + k);
    errs.push_back(MaxRelError(ref, Band(red, 8000)));
    errs_plain.push_back(MaxRelError(ref, Band(plain, 8000)));
    int rank;
    MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
    if (rank == 0)
      std::printf("two-body interface modes k = %2d of %2d (to %7.1f Hz): reduced N = %3d, max rel. error of the %zu eigenvalues "
                "below 6 kHz %.3e with the %d statics, %.3e without (CB alone %.3e)\n",
                (int)k, (int)ns, (double)info_plain.inplane_freq.back(), (int)red.Size(), ref.size(), errs.back(), (int)nc,
                errs_plain.back(), cb_err);
  }
  // This plate + pad is nearly all interface (the pad is one cell thick): without the statics its
  // modes converge slowly with k (5440 Hz: 6717, 6413, 5640 Hz).
  EXPECT_LT(errs_plain[2], 0.5 * errs_plain[0]);
  EXPECT_LT(errs_plain[2], 0.05);
  // The statics are the interface's response to the contact's point loads, which the lowest modes
  // miss: with them 11 modes give CB's own error (8.5e-4 against 8.4e-4; 1.3e-1 without).
  for (size_t i = 0; i < errs.size(); ++i) EXPECT_LT(errs[i], 1.05 * cb_err) << "k step " << i;
}

TEST(InterfaceReduction, ExportedModelReadsBackIdentically)
{
  PadParams p = SmallPad();
  Model     full, red, back;
  ASSERT_EQ(BuildPad(PETSC_COMM_WORLD, p, full), 0);
  ASSERT_EQ(Reduce(full, 30000, full.contacts.Size(), red), 0);
  int pid = (int)getpid();
  MPI_Bcast(&pid, 1, MPI_INT, 0, PETSC_COMM_WORLD);
  const std::string dir = "test_interface_reduction_export_" + std::to_string(pid);
  ASSERT_EQ(red.Export(dir.c_str(), "bin"), 0);
  FileModelSpec s;
  s.mass = dir + "/M.bin", s.stiffness = dir + "/K.bin", s.damping = dir + "/C.bin", s.load = dir + "/F.bin";
  s.contacts = dir + "/contacts.txt", s.mu = p.mu, s.V = p.V;
  ASSERT_EQ(BuildFromFiles(PETSC_COMM_WORLD, s, back), 0);
  ASSERT_EQ(back.Size(), red.Size());
  ASSERT_EQ(back.contacts.Size(), red.contacts.Size());
  for (PetscInt c = 0; c < red.contacts.Size(); ++c)
    for (int d = 0; d < 3; ++d) {
      const ColumnEntries &x = red.contacts.points[c].cols[d], &y = back.contacts.points[c].cols[d];
      ASSERT_EQ(x.size(), y.size());
      for (size_t e = 0; e < x.size(); ++e) {
        EXPECT_EQ(x[e].first, y[e].first);
        EXPECT_EQ(x[e].second, y[e].second); // 17 digits
      }
    }
  const auto a = Unstable(red), b = Unstable(back);
  ASSERT_FALSE(a.empty());
  EXPECT_LT(MaxRelError(a, b), 1e-10);
  MPI_Barrier(PETSC_COMM_WORLD);
  int rank;
  MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
  if (rank == 0) std::filesystem::remove_all(dir);
}

TEST(InterfaceReduction, BadCountsAreRefused)
{
  PadParams p = SmallPad();
  Model     full;
  ASSERT_EQ(BuildPad(PETSC_COMM_WORLD, p, full), 0);
  const PetscInt nc = full.contacts.Size();
  for (PetscInt k : {(PetscInt)0, 2 * nc + 1}) {
    Model red;
    EXPECT_NE(Quietly([&] { return Reduce(full, 30000, k, red); }), 0) << "k = " << k;
  }
  {
    Model        red;
    CraigBampton cb(full.comm());
    ASSERT_EQ(cb.SetFMax(30000), 0);
    ASSERT_EQ(cb.SetInterfaceFMax(1.0), 0); // 1 Hz: below the lowest in-plane mode
    EXPECT_NE(Quietly([&] { return cb.Reduce(full, red); }), 0);
  }
  {
    // Reducing an interface-reduced model again: its points have no nodes.
    Model red, again;
    ASSERT_EQ(Reduce(full, 30000, nc, red), 0);
    EXPECT_NE(Quietly([&] { return Reduce(red, 30000, -1, again); }), 0);
  }
}

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
  q.cols[kT] = {{2, 1.0}}, q.cols[kB] = {{3, 1.0}};
  shared.points.push_back(q);
  EXPECT_TRUE(refused(shared, 4));
  ContactSet skew = ExplicitSet(); // point 0's h_t touches point 1's normal DOF
  ContactPoint r;
  r.cols[kN] = {{1, 1.0}};
  r.cols[kT] = {{2, 1.0}}, r.cols[kB] = {{3, 1.0}};
  skew.points.push_back(r);
  EXPECT_EQ(Quietly([&] { return skew.Validate(PETSC_COMM_WORLD, 4); }), 0);
  skew.points[0].cols[kT].push_back({1, 0.1});
  EXPECT_TRUE(refused(skew, 4));
  ContactSet no_t = ExplicitSet(); // W_tt = 0: an infinite rho in the local solver
  no_t.points[0].cols[kT].clear();
  EXPECT_TRUE(refused(no_t, 4));
  ContactSet no_b = ExplicitSet(); // needed by planar friction only
  no_b.points[0].cols[kB].clear();
  EXPECT_TRUE(refused(no_b, 4));
  no_b.law = FrictionLaw::Rectilinear;
  EXPECT_EQ(Quietly([&] { return no_b.Validate(PETSC_COMM_WORLD, 4); }), 0);
  ContactSet mixed = ExplicitSet(); // an explicit entry on a DOF the point's node already holds
  mixed.points[0].cols[kN].clear();
  mixed.points[0].nodes = {ContactNode{{0, 1, 4}, 1.0}};
  EXPECT_EQ(Quietly([&] { return mixed.Validate(PETSC_COMM_WORLD, 5); }), 0);
  mixed.points[0].cols[kN] = {{4, 0.5}};
  EXPECT_TRUE(refused(mixed, 5));
}

TEST(ExplicitColumns, MalformedColumnRowsAreRefused)
{
  // Each row alone in a table: truncated, counts that do not match the pairs, a count too large to
  // sum (2^63), a count that is not an integer, a NaN, a negative or non-integer DOF index.
  const char *rows[] = {
    "cols 1 0 0 0 0 1 1 0 1 0 1 2 0.5",
    "cols 1 0 0 0 0 1 1 0 1 0 1 2 0.5 0 1 5 1",
    "cols 1 0 0 0 0 1 1 0 9223372036854775808 0 0",
    "cols 1 0 0 0 0 1 1 0 1.5 0 1 2 0.5 0 1",
    "cols 1 0 0 0 0 1 1 0 inf 0 1 2 0.5 0 1",
    "cols 1 0 0 0 0 1 1 0 1 0 1 2 nan 0 1",
    "cols 1 0 0 0 0 1 1 0 1 0 1 -2 0.5 0 1",
    "cols 1 0 0 0 0 1 1 0 1 0 1 2.5 0.5 0 1",
  };
  int pid = (int)getpid();
  MPI_Bcast(&pid, 1, MPI_INT, 0, PETSC_COMM_WORLD);
  int rank;
  MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
  const std::string path = "test_malformed_columns_" + std::to_string(pid) + ".txt";
  for (const char *row : rows) {
    if (rank == 0) {
      std::FILE *f = std::fopen(path.c_str(), "w");
      ASSERT_NE(f, nullptr);
      std::fprintf(f, "%s\n", row);
      std::fclose(f);
    }
    MPI_Barrier(PETSC_COMM_WORLD);
    ContactSet cs;
    // A row that reads must still fail validation (a NaN value); none may be accepted.
    const PetscErrorCode ierr = Quietly([&]() -> PetscErrorCode {
      PetscFunctionBeginUser;
      PetscCall(ReadContactTable(PETSC_COMM_WORLD, path.c_str(), cs));
      PetscCall(cs.Validate(PETSC_COMM_WORLD, 8));
      PetscFunctionReturn(0);
    });
    EXPECT_NE(ierr, 0) << row;
    MPI_Barrier(PETSC_COMM_WORLD);
  }
  if (rank == 0) std::remove(path.c_str());
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

namespace {

// Every point of a model rewritten as explicit columns (the same H, entry by entry).
void ToColumnForm(Model &m)
{
  ContactSet &cs = m.contacts;
  for (PetscInt c = 0; c < cs.Size(); ++c) {
    std::array<ColumnEntries, 3> cols;
    for (int d = 0; d < 3; ++d) cs.ForEachEntry(c, d, [&](PetscInt j, PetscReal v) { cols[d].emplace_back(j, v); });
    cs.points[c].nodes.clear();
    cs.points[c].cols = cols;
  }
}

struct CycleRun {
  StabilityResult stab;
  ShootingResult  sr;
};

// Equilibrium, stability, energy estimate and shooting on the 3-DOF system in the springs' frame
// (H = R_gamma^T, three entries per column), nodal or in column form.
void RunThreeDof(bool column_form, CycleRun &out)
{
  ThreeDofParams p;
  p.V            = 0.75; // case 2: stick / slip, so the stick rows of the step tangent are used
  p.spring_frame = true;
  Model              model;
  SlidingEquilibrium eq;
  EnergyEstimate     est;
  EquilibriumSolver  eqs(PETSC_COMM_WORLD);
  StabilitySolver    ss(PETSC_COMM_WORLD);
  EnergyAnalysis     ea(PETSC_COMM_WORLD);
  ThetaIntegrator    ti(PETSC_COMM_WORLD);
  Shooting           sh(PETSC_COMM_WORLD);
  ASSERT_EQ(BuildThreeDof(PETSC_COMM_WORLD, p, model), 0);
  if (column_form) {
    ToColumnForm(model);
    ASSERT_EQ(model.Validate(), 0);
    ASSERT_TRUE(model.contacts.HasExplicitColumns());
  }
  ASSERT_EQ(eqs.Solve(model, eq), 0);
  ASSERT_EQ(ss.Solve(model, eq, out.stab), 0);
  ASSERT_EQ(ea.SetFromOptions(), 0);
  ASSERT_EQ(ea.Estimate(model, eq, out.stab, est), 0);
  ASSERT_TRUE(est.found);
  ASSERT_EQ(ti.SetFromOptions(), 0);
  ASSERT_EQ(sh.SetFromOptions(), 0);
  ASSERT_EQ(sh.Solve(model, eq, ti, est.U0, est.dU0, est.T0, out.sr), 0);
}

} // namespace

TEST(ExplicitColumns, ThreeDofInColumnFormGivesTheNodalEigenvaluesAndCycle)
{
  // The same H given as explicit entries instead of a node and its frame: every consumer reads it
  // through ContactSet::ForEachEntry, so the eigenvalues, the stick/slip cycle and its multipliers
  // agree with the nodal form to round-off.
  CycleRun a, b;
  RunThreeDof(false, a);
  RunThreeDof(true, b);
  ASSERT_EQ(a.stab.modes.size(), b.stab.modes.size());
  for (size_t i = 0; i < a.stab.modes.size(); ++i) {
    EXPECT_NEAR(a.stab.modes[i].sigma, b.stab.modes[i].sigma, 1e-10 * a.stab.modes[i].omega);
    EXPECT_NEAR(a.stab.modes[i].omega, b.stab.modes[i].omega, 1e-10 * a.stab.modes[i].omega);
  }
  ASSERT_TRUE(a.sr.converged);
  ASSERT_TRUE(b.sr.converged);
  PetscMPIInt rank;
  MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
  if (rank != 0) return; // the cycle's summary (regime fractions, multipliers) is formed on rank 0
  EXPECT_EQ(a.sr.iterations, b.sr.iterations);
  EXPECT_NEAR(b.sr.period, a.sr.period, 1e-9 * a.sr.period);
  EXPECT_GT(b.sr.frac_stuck, 0.01);
  EXPECT_NEAR(b.sr.frac_stuck, a.sr.frac_stuck, 1e-12);
  ASSERT_EQ(a.sr.floquet.size(), b.sr.floquet.size());
  for (size_t i = 0; i < a.sr.floquet.size(); ++i) EXPECT_LT(std::abs(a.sr.floquet[i] - b.sr.floquet[i]), 1e-6) << "multiplier " << i;
}

// A user who gives the band and not the cut-off (-reduce_type craig_bampton, -stab_fmax B): the
// fixed-interface modes go up to 6 B, and the eigenvalues in the band are within 1e-3 of the full
// model's (the accuracy target for a reduced brake), on a CalculiX model the default was
// not tuned on. A cut-off at the band itself is far off.
TEST(InterfaceReduction, DefaultCutOffFromTheBandMeetsTheAccuracyTarget)
{
  Model full;
  ASSERT_EQ(BuildCalculix(PETSC_COMM_WORLD, TwoBlocks(), full), 0);
  const auto ref = Band(full, 6000);
  ASSERT_GE(ref.size(), 5u);
  ASSERT_EQ(PetscOptionsSetValue(nullptr, "-stab_fmax", "6000"), 0);
  ASSERT_EQ(PetscOptionsSetValue(nullptr, "-reduce_type", "craig_bampton"), 0);
  CraigBampton cb(PETSC_COMM_WORLD);
  bool         enabled = false;
  const PetscErrorCode ierr = cb.SetFromOptions(&enabled);
  ASSERT_EQ(PetscOptionsClearValue(nullptr, "-stab_fmax"), 0); // before any assertion can leave them to later tests
  ASSERT_EQ(PetscOptionsClearValue(nullptr, "-reduce_type"), 0);
  ASSERT_EQ(ierr, 0);
  EXPECT_TRUE(enabled);
  Model red;
  ASSERT_EQ(cb.Reduce(full, red), 0);
  const ReductionInfo info = cb.Info();
  ASSERT_GT(info.n_modes, 0);
  EXPECT_LT(info.freq.back(), 36000.0); // the modes below 6 x 6 kHz
  const double err = MaxRelError(ref, Band(red, 8000));
  Model        at_band;
  ASSERT_EQ(Reduce(full, 6000, -1, at_band), 0);
  const double err_band = MaxRelError(ref, Band(at_band, 8000));
  int          rank;
  MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
  if (rank == 0)
    std::printf("default cut-off (6 x 6 kHz): reduced N = %d, max rel. error of the %zu eigenvalues below 6 kHz %.3e "
                "(cut-off at the band: N = %d, %.3e)\n",
                (int)red.Size(), ref.size(), err, (int)at_band.Size(), err_band);
  EXPECT_LT(err, 1e-3);
  EXPECT_GT(err_band, 10 * err);
}
