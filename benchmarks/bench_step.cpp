// Cost of one theta-method step (method.md §5).
//   ThreeDof/Library: the 3-DOF case 1 through the library (ThetaIntegrator::Step, dense back end).
//   ThreeDof/MinimalLoop: the same equations written out with fixed-size Eigen types, as a
//     hand-written loop would; the yardstick for the library's overhead.
//   Chain/N/nc/dense: the synthetic multi-contact chain, per-step cost against N and n_c, with the
//     dense (1) and the sparse KSP (0) back end.
// Counters: fp_passes = mean fixed-point passes per step.
#include "squeal/integration/theta.h"
#include "squeal/model/builders.h"
#include "squeal/stability/stability.h"

#include <benchmark/benchmark.h>
#include <slepcsys.h>

#include <Eigen/Dense>

#include <cmath>

using namespace squeal;

namespace {

struct Prepared {
  Model              model;
  SlidingEquilibrium eq;
  StabilityResult    stab;
  ThetaIntegrator    ti{PETSC_COMM_WORLD};
  Vec                U = nullptr, dU = nullptr;
  Eigen::VectorXd    r;
  ~Prepared()
  {
    VecDestroy(&U);
    VecDestroy(&dU);
  }
};

// Builds, starts from the unstable mode and runs `warm` steps so the timed steps are on the cycle.
void Prepare(Prepared &p, PetscInt warm, PetscInt dense_max)
{
  EquilibriumSolver eqs(PETSC_COMM_WORLD);
  StabilitySolver   stab(PETSC_COMM_WORLD);
  PetscCallAbort(PETSC_COMM_WORLD, eqs.Solve(p.model, p.eq));
  PetscCallAbort(PETSC_COMM_WORLD, stab.Solve(p.model, p.eq, p.stab));
  const Mode &m = p.stab.modes[p.stab.unstable.empty() ? 0 : p.stab.unstable[0]];
  PetscCallAbort(PETSC_COMM_WORLD, p.ti.SetFromOptions());
  PetscCallAbort(PETSC_COMM_WORLD, p.ti.SetDenseMax(dense_max));
  PetscCallAbort(PETSC_COMM_WORLD, p.ti.SetUp(p.model, m.Period() / 1000));
  PetscCallAbort(PETSC_COMM_WORLD, VecDuplicate(p.eq.U, &p.U));
  PetscCallAbort(PETSC_COMM_WORLD, VecDuplicate(p.eq.U, &p.dU));
  PetscCallAbort(PETSC_COMM_WORLD, VecWAXPY(p.U, 1e-5, m.phi_re, p.eq.U));
  PetscCallAbort(PETSC_COMM_WORLD, VecAXPBY(p.dU, -1e-5 * m.omega, 0.0, m.phi_im));
  const PetscInt nc = p.model.contacts.Size();
  p.r.setZero(3 * nc);
  for (PetscInt c = 0; c < nc; ++c) p.r[3 * c + kT] = p.model.contacts.mu * p.eq.N[c], p.r[3 * c + kN] = p.eq.N[c];
  StepInfo info;
  for (PetscInt i = 0; i < warm; ++i) PetscCallAbort(PETSC_COMM_WORLD, p.ti.Step(p.U, p.dU, p.r, &info));
}

void ThreeDofLibrary(benchmark::State &state)
{
  Prepared p;
  PetscCallAbort(PETSC_COMM_WORLD, BuildThreeDof(PETSC_COMM_WORLD, ThreeDofParams{}, p.model));
  Prepare(p, 50000, 2000);
  StepInfo info;
  double   passes = 0;
  for (auto _ : state) {
    PetscCallAbort(PETSC_COMM_WORLD, p.ti.Step(p.U, p.dU, p.r, &info));
    passes += info.contact.iterations;
  }
  state.counters["fp_passes"] = passes / state.iterations();
}

// The same step with fixed-size types: no PETSc, no dynamic sizes, H = I.
void ThreeDofMinimalLoop(benchmark::State &state)
{
  using M3 = Eigen::Matrix3d;
  using V3 = Eigen::Vector3d;
  ThreeDofParams prm;
  PetscReal      Kx[3][3], Kt[3][3];
  ThreeDofStiffness(prm, Kx, Kt);
  M3 K;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) K(i, j) = Kt[i][j];
  const M3     Mm = prm.m * M3::Identity(), C = prm.c * M3::Identity();
  const V3     F(0, 0, -prm.Fn);
  const double th = 0.5, h = 0.010905130684917356 / 1000, mu = prm.mu, V = prm.V;
  const M3     A = Mm + h * th * C + h * h * th * th * K, B = Mm - h * (1 - th) * C - h * h * th * (1 - th) * K;
  const Eigen::LLT<M3> llt(A);
  const M3     P1 = llt.solve(B), P2 = -h * llt.solve(K), Y = llt.solve(M3::Identity()), hW = h * Y;
  const V3     p3 = h * llt.solve(F);
  const double rho_n = 1 / (h * h * Y(2, 2)), rho_t = 1 / (h * Y(0, 0));
  // Same start and warm-up as the library run.
  Prepared p;
  PetscCallAbort(PETSC_COMM_WORLD, BuildThreeDof(PETSC_COMM_WORLD, prm, p.model));
  Prepare(p, 50000, 2000);
  V3 U, dU, r(p.r[0], p.r[1], p.r[2]);
  {
    const PetscScalar *a, *b;
    VecGetArrayRead(p.U, &a);
    VecGetArrayRead(p.dU, &b);
    U  = V3(a[0], a[1], a[2]);
    dU = V3(b[0], b[1], b[2]);
    VecRestoreArrayRead(p.U, &a);
    VecRestoreArrayRead(p.dU, &b);
  }
  double passes = 0;
  for (auto _ : state) {
    const V3     vf  = P1 * dU + P2 * U + p3;
    const double gn0 = U[2] + h * (1 - th) * dU[2];
    V3           v   = vf + hW * r;
    int          k   = 0;
    for (k = 1; k <= 500; ++k) {
      const double rn = std::max(0.0, r[2] - rho_n * (gn0 + h * v[2]));
      double       rt = r[0] - rho_t * (v[0] - V), rb = r[1] - rho_t * v[1];
      const double m = std::hypot(rt, rb), a = mu * rn;
      if (m > a) rt *= a / m, rb *= a / m;
      const V3 d(rt - r[0], rb - r[1], rn - r[2]);
      r += d;
      v += hW * d;
      if (d.lpNorm<1>() <= 1e-12 * (1 + rn)) break;
    }
    passes += k;
    const V3 dU0 = dU;
    dU           = vf + h * (Y * r);
    U += h * (th * dU + (1 - th) * dU0);
    benchmark::DoNotOptimize(U);
  }
  state.counters["fp_passes"] = passes / state.iterations();
}

void Chain(benchmark::State &state)
{
  Prepared    p;
  ChainParams prm;
  prm.cells         = state.range(0) / 3;
  prm.contact_every = prm.cells / state.range(1);
  prm.gamma_step    = 360.0 / prm.cells;
  prm.speed_step    = 1.0 / prm.cells;
  PetscCallAbort(PETSC_COMM_WORLD, BuildChain(PETSC_COMM_WORLD, prm, p.model));
  PetscCallAbort(PETSC_COMM_WORLD, PetscOptionsSetValue(nullptr, "-stab_pep_nev", "4"));
  Prepare(p, 2000, state.range(2) ? 1000000 : 0);
  PetscCallAbort(PETSC_COMM_WORLD, PetscOptionsClearValue(nullptr, "-stab_pep_nev"));
  StepInfo info;
  double   passes = 0;
  for (auto _ : state) {
    PetscCallAbort(PETSC_COMM_WORLD, p.ti.Step(p.U, p.dU, p.r, &info));
    passes += info.contact.iterations;
  }
  state.counters["fp_passes"] = passes / state.iterations();
  state.counters["dense"]     = p.ti.Dense();
}

} // namespace

BENCHMARK(ThreeDofLibrary)->Name("ThreeDof/Library");
BENCHMARK(ThreeDofMinimalLoop)->Name("ThreeDof/MinimalLoop");
BENCHMARK(Chain)->Name("Chain")->ArgNames({"N", "nc", "dense"})->ArgsProduct({{30, 90, 300}, {10}, {0, 1}})
  ->ArgsProduct({{300, 1500, 3000}, {10, 100}, {0}})->Args({1500, 100, 1})->Unit(benchmark::kMicrosecond);

int main(int argc, char **argv)
{
  benchmark::Initialize(&argc, argv);
  PetscCall(SlepcInitialize(&argc, &argv, nullptr, nullptr));
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  PetscCall(SlepcFinalize());
  return 0;
}
