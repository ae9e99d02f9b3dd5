// The FE pad generator and its Craig-Bampton reduction. References: closed forms (mass of the
// meshed volume, rigid translations loading only the support springs) and the full model's own
// eigenvalues (the reduction error must fall as the cut-off grows, and be small well above the band).
#include "dense.h"
#include "reduction_helpers.h"
#include "squeal/core/gather.h"
#include "squeal/integration/theta.h"
#include "squeal/model/builders.h"
#include "squeal/model/pad.h"
#include "squeal/reduction/craig_bampton.h"
#include "squeal/stability/stability.h"

#include <Eigen/Dense>
#include <gtest/gtest.h>

#include <numeric>

#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <complex>
#include <string>

using namespace squeal;
using test::MaxRelError;
using test::SmallPad;
using test::Unstable;

namespace {

PetscErrorCode Reduce(const Model &full, PetscReal fmax, Model &red, ReductionInfo *info = nullptr)
{
  CraigBampton cb(full.comm());
  PetscFunctionBeginUser;
  PetscCall(cb.SetFMax(fmax));
  PetscCall(cb.Reduce(full, red));
  if (info) *info = cb.Info();
  PetscFunctionReturn(0);
}

double ColumnSum(Mat K, Vec x, Vec y)
{
  PetscScalar s;
  PetscCallAbort(PETSC_COMM_WORLD, MatMult(K, x, y));
  PetscCallAbort(PETSC_COMM_WORLD, VecSum(y, &s));
  return PetscRealPart(s);
}

} // namespace

TEST(Pad, MassIsDensityTimesMeshVolume)
{
  PadParams p = SmallPad();
  Model     model;
  ASSERT_EQ(BuildPad(PETSC_COMM_WORLD, p, model), 0);
  EXPECT_EQ(model.Size(), 3 * 4 * 13 * 3);
  EXPECT_EQ(model.contacts.Size(), 4 * 13);
  VecH d;
  ASSERT_EQ(MatCreateVecs(model.M, d.out(), nullptr), 0);
  ASSERT_EQ(MatGetDiagonal(model.M, d), 0);
  PetscScalar total;
  ASSERT_EQ(VecSum(d, &total), 0);
  const double mass = p.rho_fric * PadMeshVolume(p, false) + p.rho_steel * PadMeshVolume(p, true);
  EXPECT_NEAR(PetscRealPart(total) / 3, mass, 1e-12 * mass); // each node's mass on its 3 DOFs
  // The chord polygon is within 1 % of the exact annular sector for 12 sectors of 50 degrees.
  const double exact = 0.5 * p.angle * PETSC_PI / 180 * (p.r_out * p.r_out - p.r_in * p.r_in) *
                       (p.rho_fric * p.h_fric + p.rho_steel * p.h_steel);
  EXPECT_NEAR(mass, exact, 1e-3 * exact);
}

TEST(Pad, RigidTranslationLoadsOnlyTheSupportSprings)
{
  PadParams p = SmallPad();
  Model     model;
  ASSERT_EQ(BuildPad(PETSC_COMM_WORLD, p, model), 0);
  VecH x, y;
  ASSERT_EQ(MatCreateVecs(model.K, x.out(), y.out()), 0);
  const double area = 0.5 * p.n_t * (p.r_out * p.r_out - p.r_in * p.r_in) * std::sin(p.angle * PETSC_PI / 180 / p.n_t);
  PetscInt     lo, hi;
  ASSERT_EQ(VecGetOwnershipRange(x, &lo, &hi), 0);
  const PetscInt nface = (p.n_r + 1) * (p.n_t + 1), ntop = nface * (p.n_fric + p.n_steel);
  PetscReal      knorm;
  ASSERT_EQ(MatNorm(model.K, NORM_INFINITY, &knorm), 0);
  for (int dir = 0; dir < 3; ++dir) {
    ASSERT_EQ(VecSet(x, 0.0), 0);
    for (PetscInt i = lo; i < hi; ++i)
      if (i % 3 == dir) {
        ASSERT_EQ(VecSetValue(x, i, 1.0, INSERT_VALUES), 0);
      }
    ASSERT_EQ(VecAssemblyBegin(x), 0);
    ASSERT_EQ(VecAssemblyEnd(x), 0);
    // The springs' total: foundation stiffness times the back face's area.
    const double k = dir == 2 ? p.k_n : p.k_t;
    EXPECT_NEAR(ColumnSum(model.K, x, y), k * area, 1e-9 * k * area);
    // Away from the back face, K times a rigid translation vanishes.
    const PetscScalar *a;
    double             worst = 0;
    ASSERT_EQ(VecGetArrayRead(y, &a), 0);
    for (PetscInt i = lo; i < hi; ++i)
      if (i / 3 < ntop) worst = std::max(worst, std::abs(PetscRealPart(a[i - lo])));
    ASSERT_EQ(VecRestoreArrayRead(y, &a), 0);
    EXPECT_LT(worst, 1e-12 * knorm) << "direction " << dir;
  }
  // Consistent pressure load: the total is pressure times the back face's area.
  PetscScalar f;
  ASSERT_EQ(VecSum(model.F, &f), 0);
  EXPECT_NEAR(PetscRealPart(f), -p.pressure * area, 1e-12 * p.pressure * area);
}

TEST(Reduction, UnstableEigenvaluesConvergeToTheFullModelsAsTheCutOffGrows)
{
  PetscMPIInt size;
  ASSERT_EQ(MPI_Comm_size(PETSC_COMM_WORLD, &size), 0);
  if (size > 1) GTEST_SKIP() << "serial numerics (8 stability solves); the distributed reduction is checked below";
  PadParams p = SmallPad();
  Model     full;
  ASSERT_EQ(BuildPad(PETSC_COMM_WORLD, p, full), 0);
  const auto ref = Unstable(full);
  ASSERT_FALSE(ref.empty());
  double fband = 0;
  for (auto r : ref) fband = std::max(fband, r.imag() / (2 * PETSC_PI));
  double prev = 1e300;
  for (double factor : {1.5, 3.0, 6.0}) {
    Model         red;
    ReductionInfo info;
    ASSERT_EQ(Reduce(full, factor * fband, red, &info), 0);
    EXPECT_EQ(info.n_interface, 3 * full.contacts.Size());
    EXPECT_EQ(red.Size(), info.n_interface + info.n_modes);
    for (PetscInt c = 0; c < red.contacts.Size(); ++c) EXPECT_EQ(red.contacts.points[c].nodes[0].dofs[0], 3 * c);
    const auto   got = Unstable(red);
    const double err = MaxRelError(ref, got);
    EXPECT_EQ(got.size(), ref.size()) << "cut-off " << factor << " x band";
    EXPECT_LE(err, prev * 1.0001) << "cut-off " << factor << " x band";
    prev = err;
  }
  EXPECT_LT(prev, 1e-3); // 6 x the band
}

namespace {

// A x for x = (1 + 0.01 i) on the first nB (interface) DOFs, 0 elsewhere, the first nB entries on
// every rank: the interface block of a reduced matrix, which depends on the constraint modes only.
std::vector<double> InterfaceBlockTimes(Mat A, PetscInt nB)
{
  Vec        x, y, all;
  VecScatter sc;
  PetscInt   lo, hi, n;
  PetscCallAbort(PETSC_COMM_WORLD, MatCreateVecs(A, &x, &y));
  PetscCallAbort(PETSC_COMM_WORLD, VecGetOwnershipRange(x, &lo, &hi));
  PetscCallAbort(PETSC_COMM_WORLD, VecSet(x, 0.0));
  for (PetscInt i = lo; i < PetscMin(hi, nB); ++i) PetscCallAbort(PETSC_COMM_WORLD, VecSetValue(x, i, 1.0 + 0.01 * i, INSERT_VALUES));
  PetscCallAbort(PETSC_COMM_WORLD, VecAssemblyBegin(x));
  PetscCallAbort(PETSC_COMM_WORLD, VecAssemblyEnd(x));
  PetscCallAbort(PETSC_COMM_WORLD, MatMult(A, x, y));
  PetscCallAbort(PETSC_COMM_WORLD, VecScatterCreateToAll(y, &sc, &all));
  PetscCallAbort(PETSC_COMM_WORLD, VecScatterBegin(sc, y, all, INSERT_VALUES, SCATTER_FORWARD));
  PetscCallAbort(PETSC_COMM_WORLD, VecScatterEnd(sc, y, all, INSERT_VALUES, SCATTER_FORWARD));
  PetscCallAbort(PETSC_COMM_WORLD, VecGetSize(all, &n));
  const PetscScalar *a;
  PetscCallAbort(PETSC_COMM_WORLD, VecGetArrayRead(all, &a));
  std::vector<double> out(a, a + PetscMin(n, nB));
  PetscCallAbort(PETSC_COMM_WORLD, VecRestoreArrayRead(all, &a));
  VecScatterDestroy(&sc), VecDestroy(&all), VecDestroy(&x), VecDestroy(&y);
  return out;
}

// The interface blocks of M, K and C of two reductions of one model agree to 1e-9 of the largest entry.
void ExpectSameInterfaceBlocks(const Model &x, const Model &y, PetscInt nB, const char *what)
{
  for (auto pair : {std::make_pair((Mat)x.M, (Mat)y.M), std::make_pair((Mat)x.K, (Mat)y.K), std::make_pair((Mat)x.C, (Mat)y.C)}) {
    const std::vector<double> a = InterfaceBlockTimes(pair.first, nB), b = InterfaceBlockTimes(pair.second, nB);
    ASSERT_EQ(a.size(), b.size());
    double scale = 0, diff = 0;
    for (size_t i = 0; i < a.size(); ++i) scale = std::max(scale, std::abs(b[i])), diff = std::max(diff, std::abs(a[i] - b[i]));
    EXPECT_LT(diff, 1e-9 * scale) << what;
  }
}

} // namespace

TEST(Reduction, DistributedReductionMatchesTheSerialOne)
{
  // On one rank both are serial; under mpiexec -n 2 the first is distributed. Compared through
  // the interface block A_BB x_B for a fixed x_B, for M, C and K (the modal blocks depend on the
  // basis chosen inside near-degenerate eigenspaces; the reduced eigenvalues agree to 1e-8).
  PadParams p = SmallPad();
  Model     full(PETSC_COMM_WORLD), full1(PETSC_COMM_SELF), red(PETSC_COMM_WORLD), red1(PETSC_COMM_SELF);
  ASSERT_EQ(BuildPad(PETSC_COMM_WORLD, p, full), 0);
  ASSERT_EQ(BuildPad(PETSC_COMM_SELF, p, full1), 0);
  ASSERT_EQ(Reduce(full, 30000, red), 0);
  ASSERT_EQ(Reduce(full1, 30000, red1), 0);
  ASSERT_EQ(red.Size(), red1.Size());
  const PetscInt nB = 3 * full.contacts.Size();
  ExpectSameInterfaceBlocks(red, red1, nB, "distributed against serial");
  PetscReal f, f1;
  ASSERT_EQ(VecNorm(red.F, NORM_2, &f), 0);
  ASSERT_EQ(VecNorm(red1.F, NORM_2, &f1), 0);
  EXPECT_NEAR(f, f1, 1e-12 * f1);
}

// Spectrum slicing (one part of [0, (2 pi fmax)^2] per rank, each with its own factorisations)
// against Krylov-Schur at the one shift 0 that shares the constraint modes' factor: the same
// fixed-interface frequencies and the same reduced eigenvalues. Under mpiexec -n 2, two parts.
TEST(Reduction, SpectrumSlicingGivesTheModesOfOneShift)
{
  PadParams p = SmallPad();
  Model     full(PETSC_COMM_WORLD);
  ASSERT_EQ(BuildPad(PETSC_COMM_WORLD, p, full), 0);
  Model         red[2] = {Model(PETSC_COMM_WORLD), Model(PETSC_COMM_WORLD)};
  ReductionInfo info[2];
  for (int s = 0; s < 2; ++s) {
    CraigBampton cb(PETSC_COMM_WORLD);
    ASSERT_EQ(cb.SetFMax(150000), 0);
    ASSERT_EQ(cb.SetSlice(s), 0);
    ASSERT_EQ(cb.SetLanczosBlock(0), 0); // SLEPc's routes, compared here
    ASSERT_EQ(cb.Reduce(full, red[s]), 0);
    info[s] = cb.Info();
  }
  PetscMPIInt size;
  MPI_Comm_size(PETSC_COMM_WORLD, &size);
  EXPECT_EQ(info[0].slice_parts, 0);
  ASSERT_GE(info[1].n_modes, 100); // enough for a part per rank (50 modes each at least)
  EXPECT_EQ(info[1].slice_parts, size);
  ASSERT_EQ(info[0].freq.size(), info[1].freq.size());
  for (size_t k = 0; k < info[0].freq.size(); ++k) EXPECT_NEAR(info[1].freq[k], info[0].freq[k], 1e-9 * info[0].freq[k]) << "mode " << k;
  ASSERT_EQ((PetscMPIInt)info[1].slice_counts.size(), size);
  EXPECT_EQ(std::accumulate(info[1].slice_counts.begin(), info[1].slice_counts.end(), (PetscInt)0), info[1].n_modes);
  StabilityResult a, b;
  ASSERT_TRUE(test::SolveStability(red[0], a, 12));
  ASSERT_TRUE(test::SolveStability(red[1], b, 12));
  ASSERT_EQ(a.modes.size(), b.modes.size());
  for (size_t k = 0; k < a.modes.size(); ++k) {
    const double mag = std::hypot(a.modes[k].sigma, a.modes[k].omega);
    EXPECT_NEAR(b.modes[k].sigma, a.modes[k].sigma, 1e-8 * mag) << "eigenvalue " << k;
    EXPECT_NEAR(b.modes[k].omega, a.modes[k].omega, 1e-8 * mag) << "eigenvalue " << k;
  }
}

// Block Lanczos (the default) against SLEPc's Krylov-Schur at one shift: the same fixed-interface
// modes, and the same reduced model's eigenvalues. Slices of 25 modes put shifts inside the
// interval, where the modes on both sides of the shift are found; on several ranks the slices are
// dealt out and their modes sent to all.
TEST(Reduction, BlockLanczosGivesTheModesOfSLEPc)
{
  PetscMPIInt size;
  MPI_Comm_size(PETSC_COMM_WORLD, &size);
  PadParams p = SmallPad();
  p.n_r = 6, p.n_t = 24, p.n_fric = 2, p.n_steel = 2; // room in the interior for the basis (8 x the modes)
  Model     full(PETSC_COMM_WORLD);
  ASSERT_EQ(BuildPad(PETSC_COMM_WORLD, p, full), 0);
  // The fourth: a basis bounded to 1 MB (31 columns) cannot hold them: SLEPc's modes instead.
  Model         red[4] = {Model(PETSC_COMM_WORLD), Model(PETSC_COMM_WORLD), Model(PETSC_COMM_WORLD), Model(PETSC_COMM_WORLD)};
  ReductionInfo info[4];
  const PetscInt  block[4] = {0, 8, 5, 8}, slice_modes[4] = {150, 150, 25, 150};
  const PetscReal max_mb[4] = {2048, 2048, 2048, 1};
  for (int s = 0; s < 4; ++s) {
    CraigBampton cb(PETSC_COMM_WORLD);
    ASSERT_EQ(cb.SetFMax(26000), 0);
    ASSERT_EQ(cb.SetSlice(0), 0);
    ASSERT_EQ(cb.SetLanczosBlock(block[s]), 0);
    ASSERT_EQ(cb.SetLanczosSliceModes(slice_modes[s]), 0);
    ASSERT_EQ(cb.SetLanczosMaxMB(max_mb[s]), 0);
    ASSERT_EQ(cb.Reduce(full, red[s]), 0);
    info[s] = cb.Info();
  }
  EXPECT_EQ(info[0].lanczos_block, 0);
  ASSERT_GE(info[0].n_modes, 20);
  EXPECT_EQ(info[1].lanczos_block, 8);
  EXPECT_EQ(info[1].lanczos_slices, size); // as many slices to every rank
  EXPECT_EQ(info[2].lanczos_block, 5);
  EXPECT_GE(info[2].lanczos_slices, 3);
  EXPECT_EQ(info[3].lanczos_block, 0);
  for (int s = 1; s < 4; ++s) {
    ASSERT_EQ(info[0].freq.size(), info[s].freq.size());
    for (size_t k = 0; k < info[0].freq.size(); ++k) EXPECT_NEAR(info[s].freq[k], info[0].freq[k], 1e-9 * info[0].freq[k]) << "mode " << k;
  }
  StabilityResult a;
  ASSERT_TRUE(test::SolveStability(red[0], a, 12));
  // Two eigensolves of the modes, each to 1e-10: the reduced eigenvalues agree to ~1e-8 (two SLEPc
  // runs on two ranks: 1.05e-8 on a mode damped at -829 1/s), far inside the reduction's own 1e-3.
  for (int s = 1; s < 4; ++s) {
    StabilityResult b;
    ASSERT_TRUE(test::SolveStability(red[s], b, 12));
    ASSERT_EQ(a.modes.size(), b.modes.size());
    for (size_t k = 0; k < a.modes.size(); ++k) {
      const double mag = std::hypot(a.modes[k].sigma, a.modes[k].omega);
      EXPECT_NEAR(b.modes[k].sigma, a.modes[k].sigma, 1e-7 * mag) << "eigenvalue " << k;
      EXPECT_NEAR(b.modes[k].omega, a.modes[k].omega, 1e-7 * mag) << "eigenvalue " << k;
    }
  }
}

TEST(Reduction, SlicingPartsHoldAsManyModes)
{
  // On several ranks the parts' boundaries are put at equal mode counts (inertia counts seek the
  // median); SLEPc's equal widths of [0, (2 pi fmax)^2] give this pad 164 and 77 modes. Each part
  // within 10 % of the mean (counts stop within 5 % of the median), no worse balanced than equal
  // widths, and the same modes either way.
  PetscMPIInt size;
  MPI_Comm_size(PETSC_COMM_WORLD, &size);
  // (On more ranks only the median is counted, the other boundaries interpolated.)
  if (size != 2) GTEST_SKIP() << "two parts, two ranks";
  PadParams p = SmallPad();
  Model     full(PETSC_COMM_WORLD);
  ASSERT_EQ(BuildPad(PETSC_COMM_WORLD, p, full), 0);
  ReductionInfo info[2];
  double        spread[2];
  for (int balance = 0; balance < 2; ++balance) {
    CraigBampton cb(PETSC_COMM_WORLD);
    Model        red(PETSC_COMM_WORLD);
    ASSERT_EQ(cb.SetFMax(150000), 0);
    ASSERT_EQ(cb.SetSlice(1), 0);
    ASSERT_EQ(cb.SetLanczosBlock(0), 0);
    ASSERT_EQ(cb.SetSliceBalance(balance == 1), 0);
    ASSERT_EQ(cb.Reduce(full, red), 0);
    info[balance] = cb.Info();
    const auto &c = info[balance].slice_counts;
    ASSERT_EQ((PetscMPIInt)c.size(), size);
    const double mean = (double)info[balance].n_modes / size;
    spread[balance]   = 0;
    for (PetscInt n : c) spread[balance] = std::max(spread[balance], std::abs(n - mean) / mean);
  }
  EXPECT_LT(spread[1], 0.1) << "balanced parts " << info[1].slice_counts[0] << " + " << info[1].slice_counts[1] << ", equal widths " << info[0].slice_counts[0] << " + " << info[0].slice_counts[1];
  EXPECT_LE(spread[1], spread[0]) << "equal widths: " << spread[0];
  ASSERT_EQ(info[0].freq.size(), info[1].freq.size());
  for (size_t k = 0; k < info[0].freq.size(); ++k) EXPECT_NEAR(info[1].freq[k], info[0].freq[k], 1e-9 * info[0].freq[k]) << "mode " << k;
}

TEST(Reduction, SlicingUnderTheModeCapKeepsTheLowestModes)
{
  // More modes below the cut-off than -reduce_max_modes: slicing then solves below a lower
  // cut-off, found by counting, that holds 85-100 % of the cap, instead of dropping the rest
  // after solving them (or one shift for all of the cap). Its modes must be the lowest of the one
  // shift's (the reference: one shift asked for exactly the cap).
  PadParams p = SmallPad();
  Model     full(PETSC_COMM_WORLD);
  ASSERT_EQ(BuildPad(PETSC_COMM_WORLD, p, full), 0);
  PetscMPIInt size;
  MPI_Comm_size(PETSC_COMM_WORLD, &size);
  PetscInt      all = 0;
  ReductionInfo info[2];
  {
    Model        red(PETSC_COMM_WORLD);
    CraigBampton cb(PETSC_COMM_WORLD);
    ASSERT_EQ(cb.SetFMax(150000), 0);
    ASSERT_EQ(cb.SetSlice(0), 0);
    ASSERT_EQ(cb.SetLanczosBlock(0), 0);
    ASSERT_EQ(cb.Reduce(full, red), 0);
    all = cb.Info().n_modes;
  }
  const PetscInt cap = (PetscInt)(0.6 * all);
  ASSERT_GE(cap, 50 * size); // a part per rank
  for (int s = 0; s < 2; ++s) {
    Model        red(PETSC_COMM_WORLD);
    CraigBampton cb(PETSC_COMM_WORLD);
    ASSERT_EQ(cb.SetFMax(150000), 0);
    ASSERT_EQ(cb.SetMaxModes(cap), 0);
    ASSERT_EQ(cb.SetSlice(s), 0);
    ASSERT_EQ(cb.SetLanczosBlock(0), 0); // SLEPc's routes, compared here
    ASSERT_EQ(cb.Reduce(full, red), 0);
    info[s] = cb.Info();
  }
  EXPECT_EQ(info[0].n_modes, cap);
  EXPECT_EQ(info[1].slice_parts, size);
  EXPECT_LE(info[1].n_modes, cap);
  EXPECT_GE(info[1].n_modes, (PetscInt)(0.85 * cap));
  ASSERT_LE(info[1].freq.size(), info[0].freq.size());
  for (size_t k = 0; k < info[1].freq.size(); ++k) EXPECT_NEAR(info[1].freq[k], info[0].freq[k], 1e-9 * info[0].freq[k]) << "mode " << k;
}

TEST(Reduction, RedundantAndDistributedFactorsGiveTheSameReducedModel)
{
  // Under mpiexec -n 2 the default solves the constraint modes column share by column share on
  // whole copies of K_II (-reduce_redundant); the other path is one distributed MUMPS factor.
  // Both against the serial reduction: interface blocks of M, C and K to 1e-9, and the
  // fixed-interface frequencies (the eigensolver through the redundant factor) to 1e-9.
  PadParams p = SmallPad();
  Model     full(PETSC_COMM_WORLD), full1(PETSC_COMM_SELF), red1(PETSC_COMM_SELF);
  ASSERT_EQ(BuildPad(PETSC_COMM_WORLD, p, full), 0);
  ASSERT_EQ(BuildPad(PETSC_COMM_SELF, p, full1), 0);
  ReductionInfo info1;
  ASSERT_EQ(Reduce(full1, 30000, red1, &info1), 0);
  const PetscInt nB = 3 * full.contacts.Size();
  ASSERT_FALSE(info1.freq.empty());
  for (bool redundant : {true, false}) {
    Model        red(PETSC_COMM_WORLD);
    CraigBampton cb(full.comm());
    ASSERT_EQ(cb.SetFMax(30000), 0);
    ASSERT_EQ(cb.SetRedundantFactor(redundant), 0);
    ASSERT_EQ(cb.Reduce(full, red), 0);
    ASSERT_EQ(red.Size(), red1.Size());
    ExpectSameInterfaceBlocks(red, red1, nB, redundant ? "redundant" : "distributed");
    ASSERT_EQ(cb.Info().freq.size(), info1.freq.size());
    for (size_t k = 0; k < info1.freq.size(); ++k) EXPECT_NEAR(cb.Info().freq[k], info1.freq[k], 1e-9 * info1.freq[k]);
  }
}

namespace {

using DenseMat = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic>;

// The whole of A on every rank.
DenseMat Gathered(Mat A)
{
  PetscInt n, m;
  IS       rows, cols;
  Mat     *sub;
  PetscCallAbort(PETSC_COMM_WORLD, MatGetSize(A, &n, &m));
  PetscCallAbort(PETSC_COMM_WORLD, ISCreateStride(PETSC_COMM_SELF, n, 0, 1, &rows));
  PetscCallAbort(PETSC_COMM_WORLD, ISCreateStride(PETSC_COMM_SELF, m, 0, 1, &cols));
  PetscCallAbort(PETSC_COMM_WORLD, MatCreateSubMatrices(A, 1, &rows, &cols, MAT_INITIAL_MATRIX, &sub));
  DenseMat out = DenseMat::Zero(n, m);
  for (PetscInt i = 0; i < n; ++i) {
    PetscInt           nc;
    const PetscInt    *c;
    const PetscScalar *v;
    PetscCallAbort(PETSC_COMM_WORLD, MatGetRow(sub[0], i, &nc, &c, &v));
    for (PetscInt k = 0; k < nc; ++k) out(i, c[k]) = PetscRealPart(v[k]);
    PetscCallAbort(PETSC_COMM_WORLD, MatRestoreRow(sub[0], i, &nc, &c, &v));
  }
  PetscCallAbort(PETSC_COMM_WORLD, MatDestroySubMatrices(1, &sub));
  PetscCallAbort(PETSC_COMM_WORLD, ISDestroy(&rows));
  PetscCallAbort(PETSC_COMM_WORLD, ISDestroy(&cols));
  return out;
}

double MaxAbs(const DenseMat &a) { return a.cwiseAbs().maxCoeff(); }

} // namespace

TEST(Reduction, ConstraintModesInBlocksEqualOneSolveAndTheStaticCondensation)
{
  // K_r's interface block is the Schur complement K_BB - K_BI K_II^{-1} K_IB (Psi^T (K_IB + K_II
  // Psi) = 0): checked against a dense Eigen solve of the full K for every block size. The
  // constraint modes solved in blocks of 7 and of 1 right-hand sides (-reduce_rhs_block; 156
  // interface DOFs: a short last block) against one solve of all 156: M, C, K and F agree to 1e-12
  // (on one rank the whole matrices; on several, MUMPS may rotate a near-degenerate pair of
  // fixed-interface modes between two reductions, so the blocks that depend on Psi alone: the
  // interface blocks and F_B). Both paths: sparse right-hand sides (default) and dense.
  PetscMPIInt size;
  ASSERT_EQ(MPI_Comm_size(PETSC_COMM_WORLD, &size), 0);
  PadParams p = SmallPad();
  Model     full;
  ASSERT_EQ(BuildPad(PETSC_COMM_WORLD, p, full), 0);
  const PetscInt nB = 3 * full.contacts.Size(), N = full.Size();
  // Static condensation of the full K (contact order first, as in the reduced model).
  std::vector<PetscInt> order, pos(N, -1);
  for (const ContactPoint &c : full.contacts.points)
    for (PetscInt d : c.nodes[0].dofs) pos[d] = (PetscInt)order.size(), order.push_back(d);
  for (PetscInt i = 0; i < N; ++i)
    if (pos[i] < 0) pos[i] = (PetscInt)order.size(), order.push_back(i);
  const DenseMat K = Gathered(full.K);
  DenseMat       Kp(N, N);
  for (PetscInt i = 0; i < N; ++i)
    for (PetscInt j = 0; j < N; ++j) Kp(pos[i], pos[j]) = K(i, j);
  const PetscInt nI = N - nB;
  const DenseMat schur = Kp.topLeftCorner(nB, nB) -
                         Kp.topRightCorner(nB, nI) * Kp.bottomRightCorner(nI, nI).ldlt().solve(Kp.bottomLeftCorner(nI, nB));

  for (bool sparse : {true, false}) {
    std::vector<DenseMat> ref; // M, K, C, F of the one solve
    for (PetscInt block : {0, 7, 1}) {
      Model        red(PETSC_COMM_WORLD);
      CraigBampton cb(full.comm());
      ASSERT_EQ(cb.SetFMax(30000), 0);
      ASSERT_EQ(cb.SetRHSBlock(block), 0);
      if (!sparse) {
        ASSERT_EQ(PetscOptionsSetValue(nullptr, "-reduce_sparse_rhs", "0"), 0);
      }
      ASSERT_EQ(cb.SetFromOptions(), 0);
      ASSERT_EQ(PetscOptionsClearValue(nullptr, "-reduce_sparse_rhs"), 0);
      ASSERT_EQ(cb.SetRHSBlock(block), 0); // SetFromOptions read the default
      ASSERT_EQ(cb.Reduce(full, red), 0);
      const std::string what = std::string(sparse ? "sparse" : "dense") + " right-hand sides, block " + std::to_string(block);
      std::vector<PetscReal> f;
      ASSERT_EQ(GatherVector(red.F, true, f), 0);
      std::vector<DenseMat> got = {Gathered(red.M), Gathered(red.K), Gathered(red.C),
                                   Eigen::Map<const DenseMat>(f.data(), (Eigen::Index)f.size(), 1)};
      EXPECT_LT(MaxAbs(got[1].topLeftCorner(nB, nB) - schur), 1e-9 * MaxAbs(schur)) << what;
      if (block == 0) {
        ref = got;
        continue;
      }
      for (size_t k = 0; k < got.size(); ++k) {
        ASSERT_EQ(got[k].rows(), ref[k].rows()) << what;
        ASSERT_EQ(got[k].cols(), ref[k].cols()) << what;
        const Eigen::Index c = size == 1 ? got[k].cols() : std::min<Eigen::Index>(nB, got[k].cols());
        const Eigen::Index r = size == 1 ? got[k].rows() : nB;
        EXPECT_LE(MaxAbs(got[k].topLeftCorner(r, c) - ref[k].topLeftCorner(r, c)), 1e-12 * MaxAbs(ref[k])) << what << ", matrix "
                                                                                                              << "MKCF"[k];
      }
    }
  }
}

TEST(Reduction, RayleighShortcutEqualsTheProjectionOfC)
{
  // The pad's C = a M + b K. The general path projects C: T^T C T must equal a M_r + b K_r, which
  // is what the shortcut (default) returns. Compared within one reduction (one basis: on 2 ranks
  // MUMPS may rotate a near-degenerate pair of modes between two reductions).
  PadParams p = SmallPad();
  p.ray_a     = 30.0; // both terms, so the fit of a and b is exercised
  Model full;
  ASSERT_EQ(BuildPad(PETSC_COMM_WORLD, p, full), 0);
  auto reduce = [&](const Model &m, bool shortcut, Model &red, ReductionInfo &info) {
    CraigBampton cb(m.comm());
    ASSERT_EQ(cb.SetFMax(30000), 0);
    ASSERT_EQ(cb.SetRayleighShortcut(shortcut), 0);
    ASSERT_EQ(cb.Reduce(m, red), 0);
    info = cb.Info();
  };
  auto rayleigh_residual = [&](const Model &red) {
    MatH      D;
    PetscReal nd, nc;
    EXPECT_EQ(MatDuplicate(red.C, MAT_COPY_VALUES, D.out()), 0);
    EXPECT_EQ(MatAXPY(D, -p.ray_a, red.M, DIFFERENT_NONZERO_PATTERN), 0);
    EXPECT_EQ(MatAXPY(D, -p.ray_b, red.K, DIFFERENT_NONZERO_PATTERN), 0);
    EXPECT_EQ(MatNorm(D, NORM_FROBENIUS, &nd), 0);
    EXPECT_EQ(MatNorm(red.C, NORM_FROBENIUS, &nc), 0);
    return nd / nc;
  };
  Model         a, b;
  ReductionInfo ia, ib;
  reduce(full, false, b, ib);
  EXPECT_FALSE(ib.rayleigh);
  EXPECT_LT(rayleigh_residual(b), 1e-12); // the projection of C
  reduce(full, true, a, ia);
  EXPECT_TRUE(ia.rayleigh);
  EXPECT_LT(rayleigh_residual(a), 1e-12); // the shortcut (fitted a, b; entries below 1e-13 of the diagonal dropped)

  // C + a small extra dashpot on one DOF: no longer a M + b K, so the projection is used.
  Model    other;
  PetscInt lo, hi;
  ASSERT_EQ(BuildPad(PETSC_COMM_WORLD, p, other), 0);
  ASSERT_EQ(MatGetOwnershipRange(other.C, &lo, &hi), 0);
  if (lo == 0) {
    ASSERT_EQ(MatSetValue(other.C, 0, 0, 1e-3, ADD_VALUES), 0);
  }
  ASSERT_EQ(MatAssemblyBegin(other.C, MAT_FINAL_ASSEMBLY), 0);
  ASSERT_EQ(MatAssemblyEnd(other.C, MAT_FINAL_ASSEMBLY), 0);
  Model         c;
  ReductionInfo ic;
  reduce(other, true, c, ic);
  EXPECT_FALSE(ic.rayleigh);
}

TEST(Reduction, MassBlocksOfTheModesInClosedFormEqualTheDenseProjection)
{
  // M_r's blocks with a fixed-interface mode are formed in closed form (Phi^T M_II Phi = I,
  // Psi^T M_II Phi = -K_BI Phi Omega^-2); only Psi^T M_II Psi is a dense product. With C = M and
  // the Rayleigh shortcut off, C_r is the whole dense projection W^T M W of the same basis: the two
  // must agree to the eigensolver's tolerance (1e-10 relative residual). One shift and spectrum
  // slicing (one part a rank under mpiexec), 150 kHz: 100+ modes.
  PadParams p = SmallPad();
  p.ray_a = 1.0, p.ray_b = 0.0;
  Model full;
  ASSERT_EQ(BuildPad(PETSC_COMM_WORLD, p, full), 0);
  for (int slice = 0; slice < 2; ++slice) {
    CraigBampton cb(PETSC_COMM_WORLD);
    Model        red;
    ASSERT_EQ(cb.SetFMax(150000), 0);
    ASSERT_EQ(cb.SetSlice(slice), 0);
    ASSERT_EQ(cb.SetLanczosBlock(0), 0);
    ASSERT_EQ(cb.SetRayleighShortcut(false), 0);
    ASSERT_EQ(cb.Reduce(full, red), 0);
    ASSERT_GE(cb.Info().n_modes, 100);
    EXPECT_FALSE(cb.Info().rayleigh);
    // Block by block, each against its own size: the interface DOFs first (contact order), then
    // the modes. The closed forms are the mode-interface coupling and the modes' identity.
    const Eigen::MatrixXd Mr = test::ToDense(red.M), Cr = test::ToDense(red.C);
    const Eigen::Index    nB = 3 * full.contacts.Size(), m = Mr.rows() - nB;
    const char           *what = slice ? "spectrum slicing" : "one shift";
    auto rel = [](const Eigen::MatrixXd &got, const Eigen::MatrixXd &ref) { return (got - ref).norm() / ref.norm(); };
    EXPECT_LT(rel(Mr.topRightCorner(nB, m), Cr.topRightCorner(nB, m)), 1e-9) << what << ": coupling";
    EXPECT_LT(rel(Mr.bottomRightCorner(m, m), Cr.bottomRightCorner(m, m)), 1e-9) << what << ": modes";
    EXPECT_LT(rel(Mr.topLeftCorner(nB, nB), Cr.topLeftCorner(nB, nB)), 1e-12) << what << ": interface (the same dense product)";
    EXPECT_GT(rel(Mr.topRightCorner(nB, m), Cr.topRightCorner(nB, m)), 0.0) << "C_r and M_r formed the same way: the test compares nothing";
  }
}

TEST(Reduction, ExportedReducedModelReadsBackIdentically)
{
  PadParams p = SmallPad();
  Model     full, red, back;
  ASSERT_EQ(BuildPad(PETSC_COMM_WORLD, p, full), 0);
  ASSERT_EQ(Reduce(full, 30000, red), 0);
  // One folder per run: ctest runs this suite on 1 and 2 ranks at the same time in one directory.
  int pid = (int)getpid();
  MPI_Bcast(&pid, 1, MPI_INT, 0, PETSC_COMM_WORLD);
  const std::string dir = "test_reduction_export_" + std::to_string(pid);
  ASSERT_EQ(red.Export(dir.c_str(), "bin"), 0);
  FileModelSpec s;
  s.mass = dir + "/M.bin", s.stiffness = dir + "/K.bin", s.damping = dir + "/C.bin", s.load = dir + "/F.bin";
  s.contacts = dir + "/contacts.txt", s.mu = p.mu, s.V = p.V;
  ASSERT_EQ(BuildFromFiles(PETSC_COMM_WORLD, s, back), 0);
  ASSERT_EQ(back.Size(), red.Size());
  for (auto pair : {std::make_pair((Mat)red.M, (Mat)back.M), std::make_pair((Mat)red.K, (Mat)back.K),
                    std::make_pair((Mat)red.C, (Mat)back.C)}) {
    PetscBool eq;
    ASSERT_EQ(MatEqual(pair.first, pair.second, &eq), 0);
    EXPECT_TRUE(eq);
  }
  ASSERT_EQ(back.contacts.Size(), red.contacts.Size());
  for (PetscInt c = 0; c < red.contacts.Size(); ++c) {
    EXPECT_EQ(back.contacts.points[c].nodes[0].dofs, red.contacts.points[c].nodes[0].dofs);
    EXPECT_NEAR(back.contacts.points[c].speed_factor, red.contacts.points[c].speed_factor, 1e-15);
    EXPECT_LT((back.contacts.points[c].t - red.contacts.points[c].t).norm(), 1e-15);
  }
  const auto a = Unstable(red), b = Unstable(back);
  ASSERT_FALSE(a.empty());
  EXPECT_LT(MaxRelError(a, b), 1e-10);
  MPI_Barrier(PETSC_COMM_WORLD);
  int rank;
  MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
  if (rank == 0) std::filesystem::remove_all(dir);
}

TEST(Reduction, CutOffBelowTheBandIsRefused)
{
  CraigBampton cb(PETSC_COMM_WORLD);
  ASSERT_EQ(PetscOptionsSetValue(nullptr, "-reduce_type", "craig_bampton"), 0);
  ASSERT_EQ(PetscOptionsSetValue(nullptr, "-reduce_fmax", "2000"), 0);
  ASSERT_EQ(PetscOptionsSetValue(nullptr, "-reduce_fband", "9000"), 0);
  ASSERT_EQ(PetscPushErrorHandler(PetscReturnErrorHandler, nullptr), 0);
  bool                 on   = false;
  const PetscErrorCode ierr = cb.SetFromOptions(&on);
  ASSERT_EQ(PetscPopErrorHandler(), 0);
  for (const char *o : {"-reduce_type", "-reduce_fmax", "-reduce_fband"}) ASSERT_EQ(PetscOptionsClearValue(nullptr, o), 0);
  EXPECT_NE(ierr, 0);
}

// Issue 19 item 4: without -theta_dense_max the back end follows the model. The full small pad
// (468 DOFs, sparse) goes to the sparse back end; its Craig-Bampton reduction with 60 fixed-interface
// modes (216 DOFs, above the old fixed bound 200) has dense matrices and goes to the dense back end,
// which shooting's exact step tangents need; a given -theta_dense_max still decides. The density is
// counted here on the dense copies of K and M, independently of the integrator's MatGetInfo.
TEST(Reduction, ReducedModelTakesTheDenseThetaBackEndByDefault)
{
  Model full, red;
  ASSERT_EQ(BuildPad(PETSC_COMM_WORLD, SmallPad(), full), 0);
  CraigBampton cb(PETSC_COMM_WORLD);
  ASSERT_EQ(cb.SetFMax(0), 0);
  ASSERT_EQ(cb.SetNModes(60), 0);
  ASSERT_EQ(cb.Reduce(full, red), 0);
  ASSERT_EQ(full.Size(), 468);
  ASSERT_EQ(red.Size(), 216);
  auto density = [](const Model &m) {
    double d = 0;
    for (Mat A : {(Mat)m.K, (Mat)m.M}) {
      const Eigen::MatrixXd D = test::ToDense(A);
      d = std::max(d, (double)(D.array() != 0.0).count() / (double)D.size());
    }
    return d;
  };
  const double dfull = density(full), dred = density(red);
  EXPECT_LT(dfull, 0.125) << "full pad"; // 10.6 % on this coarse mesh (3 x 12 x 2 hexahedra), less on finer ones
  EXPECT_GT(dred, 0.5) << "reduced pad";
  EXPECT_FALSE(ThetaIntegrator::DefaultDense(full.Size(), dfull));
  EXPECT_TRUE(ThetaIntegrator::DefaultDense(red.Size(), dred));
  // The bounds: small models always dense (the 3-DOF cases), dense models up to 2000 DOFs.
  EXPECT_TRUE(ThetaIntegrator::DefaultDense(3, 1.0));
  EXPECT_TRUE(ThetaIntegrator::DefaultDense(200, 0.0));
  EXPECT_FALSE(ThetaIntegrator::DefaultDense(201, 0.2));
  EXPECT_TRUE(ThetaIntegrator::DefaultDense(2000, 0.25));
  EXPECT_FALSE(ThetaIntegrator::DefaultDense(2001, 1.0));
  // What the integrator does with them (the command line of unit_tests_np2_sparse aside).
  for (const Model *m : {&full, &red}) {
    ThetaIntegrator ti(PETSC_COMM_WORLD);
    ASSERT_EQ(ti.SetFromOptions(), 0);
    ASSERT_EQ(ti.SetDenseMax(PETSC_DECIDE), 0);
    ASSERT_EQ(ti.SetUp(*m, 1e-6), 0);
    EXPECT_EQ(ti.Dense(), m == &red) << m->Size() << " DOFs";
    ASSERT_EQ(ti.SetDenseMax(200), 0);
    ASSERT_EQ(ti.SetUp(*m, 1e-6), 0);
    EXPECT_FALSE(ti.Dense()) << m->Size() << " DOFs, -theta_dense_max 200";
  }
}

namespace {

// The model's full-DOF vector from the reduced q (all n entries on every rank) through the kept
// expansion, on rank 0 (empty elsewhere).
std::vector<PetscReal> Expanded(const Model &red, const std::vector<PetscReal> &q)
{
  std::vector<PetscReal> u;
  PetscMPIInt            rank;
  MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
  if (rank == 0) red.expansion->Apply(q.data(), 1, u);
  return u;
}

// The most unstable mode's shape, all N entries on every rank.
std::vector<std::complex<double>> MostUnstableShape(Model &model, double *freq)
{
  StabilityResult                   res;
  std::vector<std::complex<double>> phi;
  if (!test::SolveStability(model, res) || res.unstable.empty()) {
    ADD_FAILURE() << "no unstable mode";
    return phi;
  }
  const Mode            &m = res.modes[res.unstable[0]];
  std::vector<PetscReal> re, im;
  EXPECT_EQ(GatherVector(m.phi_re, true, re), 0);
  EXPECT_EQ(GatherVector(m.phi_im, true, im), 0);
  for (size_t i = 0; i < re.size(); ++i) phi.emplace_back(re[i], im[i]);
  *freq = m.Frequency();
  return phi;
}

} // namespace

TEST(Reduction, KeptExpansionGivesTheFullStaticSolutionOfAnInterfaceLoad)
{
  // Craig-Bampton is exact for loads on the interface: u_full = K^{-1} F equals E K_r^{-1} T^T F
  // on every DOF, interior included, when F_I = 0. The reference is a dense Eigen solve of the
  // full K; the reduced side uses the reduced model's own K_r and F_r (not E). Interface reduction
  // with all 2 n_c in-plane modes is an exact change of basis: the same holds. On 2 ranks the
  // expansion gathers the interior rows of the other rank.
  PadParams p = SmallPad();
  Model     full;
  ASSERT_EQ(BuildPad(PETSC_COMM_WORLD, p, full), 0);
  const PetscInt N = full.Size(), nc = full.contacts.Size();
  // A load on the contact DOFs only, smooth in the contact index, all three directions.
  PetscInt lo, hi;
  ASSERT_EQ(VecGetOwnershipRange(full.F, &lo, &hi), 0);
  ASSERT_EQ(VecSet(full.F, 0.0), 0);
  Eigen::VectorXd F = Eigen::VectorXd::Zero(N);
  for (PetscInt c = 0; c < nc; ++c)
    for (int k = 0; k < 3; ++k) {
      const PetscInt d = full.contacts.points[c].nodes[0].dofs[k];
      F(d)             = (k == 2 ? -50.0 : 10.0) * (1 + std::sin(0.7 * c + k));
      if (d >= lo && d < hi) {
        ASSERT_EQ(VecSetValue(full.F, d, F(d), INSERT_VALUES), 0);
      }
    }
  ASSERT_EQ(VecAssemblyBegin(full.F), 0);
  ASSERT_EQ(VecAssemblyEnd(full.F), 0);
  const Eigen::VectorXd u = test::ToDense(full.K).ldlt().solve(F);
  PetscMPIInt           rank;
  ASSERT_EQ(MPI_Comm_rank(PETSC_COMM_WORLD, &rank), 0);
  for (PetscInt iface : {-1, 2 * nc}) {
    Model        red(PETSC_COMM_WORLD);
    CraigBampton cb(full.comm());
    ASSERT_EQ(cb.SetFMax(26000), 0);
    ASSERT_EQ(cb.SetInterfaceModes(iface), 0);
    ASSERT_EQ(cb.SetKeepExpansion(true), 0);
    ASSERT_EQ(cb.Reduce(full, red), 0);
    ASSERT_TRUE(red.expansion);
    EXPECT_EQ(red.expansion->full_size, N);
    EXPECT_EQ(red.expansion->n, red.Size());
    EXPECT_EQ(cb.Info().expansion_bytes, rank == 0 ? (size_t)N * red.Size() * sizeof(PetscReal) : 0u);
    const Eigen::VectorXd  Fr = test::ToDense(red.F);
    const Eigen::VectorXd  q  = test::ToDense(red.K).ldlt().solve(Fr);
    const std::vector<PetscReal> ue = Expanded(red, std::vector<PetscReal>(q.data(), q.data() + q.size()));
    if (rank != 0) continue;
    ASSERT_EQ((PetscInt)ue.size(), N);
    const double err = (Eigen::Map<const Eigen::VectorXd>(ue.data(), N) - u).cwiseAbs().maxCoeff();
    EXPECT_LT(err, 1e-10 * u.cwiseAbs().maxCoeff()) << (iface < 0 ? "Craig-Bampton" : "interface reduction, all in-plane modes");
  }
}

TEST(Reduction, ExpandedUnstableModeIsTheFullModelsMode)
{
  // The reduced model's most unstable mode, expanded to every DOF, against the full model's own
  // (an independent eigensolve of the unreduced pad): relative distance after the best complex
  // scaling, which the cut-off (4.6 x the mode's frequency) drives below 1e-3.
  PetscMPIInt size, rank;
  ASSERT_EQ(MPI_Comm_size(PETSC_COMM_WORLD, &size), 0);
  ASSERT_EQ(MPI_Comm_rank(PETSC_COMM_WORLD, &rank), 0);
  if (size > 1) GTEST_SKIP() << "serial numerics; the expansion's gather is checked on 2 ranks above";
  PadParams p = SmallPad();
  Model     full;
  ASSERT_EQ(BuildPad(PETSC_COMM_WORLD, p, full), 0);
  double     f_full = 0, f_red = 0;
  const auto ref = MostUnstableShape(full, &f_full);
  ASSERT_FALSE(ref.empty());
  Model        red(PETSC_COMM_WORLD);
  CraigBampton cb(full.comm());
  ASSERT_EQ(cb.SetFMax(40000), 0);
  ASSERT_EQ(cb.SetKeepExpansion(true), 0);
  ASSERT_EQ(cb.Reduce(full, red), 0);
  const auto phi = MostUnstableShape(red, &f_red);
  ASSERT_FALSE(phi.empty());
  EXPECT_NEAR(f_red, f_full, 1e-3 * f_full);
  std::vector<PetscReal> re(phi.size()), im(phi.size()), ure, uim;
  for (size_t i = 0; i < phi.size(); ++i) re[i] = phi[i].real(), im[i] = phi[i].imag();
  red.expansion->Apply(re.data(), 1, ure);
  red.expansion->Apply(im.data(), 1, uim);
  ASSERT_EQ(ure.size(), ref.size());
  std::complex<double> num = 0, den = 0;
  for (size_t i = 0; i < ref.size(); ++i) {
    const std::complex<double> e(ure[i], uim[i]);
    num += std::conj(e) * ref[i], den += std::conj(e) * e;
  }
  const std::complex<double> a = num / den;
  double                     d2 = 0, r2 = 0;
  for (size_t i = 0; i < ref.size(); ++i) d2 += std::norm(ref[i] - a * std::complex<double>(ure[i], uim[i])), r2 += std::norm(ref[i]);
  EXPECT_LT(std::sqrt(d2 / r2), 1e-3) << "most unstable mode, " << f_full << " Hz (full), " << f_red << " Hz (reduced)";
}
