// Cost of one theta-method step (docs/method.md §5).
//   ThreeDof/Library/case:k: the 3-DOF reference case k through the library (ThetaIntegrator::Step,
//     dense back end); case 1: separation/slip at V = 3, case 2: stick/slip at V = 0.75.
//   ThreeDof/MinimalLoop/case:k: the same equations written out by hand with fixed-size Eigen
//     types (H = I, no PETSc, no dynamic sizes); the yardstick for the library's overhead.
//   Chain/N/nc/dense: the synthetic multi-contact chain, per-step cost against N and n_c, with the
//     dense (1) and the sparse KSP (0) back end.
// Counters: fp_passes = mean fixed-point passes per step. After the runs, one line per case prints
// library / hand-written time per step (fastest repetition of each).
// Instruction counts: `squeal_bench --instr CASE VARIANT STEPS [WARM]` (VARIANT library or minimal)
// runs STEPS steps inside CountedSteps only, after WARM others (default 50000), for callgrind's
// --toggle-collect (benchmarks/step_instructions.sh, benchmarks/transient_instructions.sh).
#include "squeal/integration/theta.h"
#include "squeal/model/builders.h"
#include "squeal/stability/stability.h"

#include <benchmark/benchmark.h>
#include <slepcsys.h>

#include <Eigen/Dense>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <map>
#include <string>

#include <sys/resource.h>

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
  for (PetscInt c = 0; c < nc; ++c) p.r[3 * c + kT] = p.model.contacts.Mu() * p.eq.N[c], p.r[3 * c + kN] = p.eq.N[c];
  StepInfo info;
  for (PetscInt i = 0; i < warm; ++i) PetscCallAbort(PETSC_COMM_WORLD, p.ti.Step(p.U, p.dU, p.r, &info));
}

// The two 3-DOF reference cases (docs/method.md §7): 1 = separation/slip, 2 = stick/slip.
ThreeDofParams CaseParams(int which)
{
  ThreeDofParams prm;
  prm.V = which == 2 ? 0.75 : 3.0;
  return prm;
}

// warm: steps before the timed ones (50 periods: on the cycle); the run starts as `-analyses
// transient` does (h = T / 1000, amplitude 1e-5), so steps warm + 1 ... are that run's.
void PrepareThreeDof(Prepared &p, int which, PetscInt warm = 50000)
{
  PetscCallAbort(PETSC_COMM_WORLD, BuildThreeDof(PETSC_COMM_WORLD, CaseParams(which), p.model));
  Prepare(p, warm, 2000);
}

// The same step with fixed-size types: no PETSc, no dynamic sizes, H = I, g0 = 0; same h, theta,
// rho, tolerance (1e-12, R_ref = 1) and pass limit (500) as the library's defaults.
struct Minimal {
  using M3 = Eigen::Matrix3d;
  using V3 = Eigen::Vector3d;
  M3     P1_, P2_, Y_, hW_;
  V3     p3_, U_, dU_, r_;
  double th_ = 0.5, h_ = 0, mu_ = 0, V_ = 0, rho_n_ = 0, rho_t_ = 0, passes = 0;

  // Same model, step size and warmed-up start as the library run in p.
  explicit Minimal(const Prepared &p, const ThreeDofParams &prm)
  {
    PetscReal Kx[3][3], Kt[3][3];
    ThreeDofStiffness(prm, Kx, Kt);
    M3 K;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) K(i, j) = Kt[i][j];
    const M3 Mm = prm.m * M3::Identity(), C = prm.c * M3::Identity();
    const V3 F(0, 0, -prm.Fn);
    const double th = p.ti.Theta(), h = p.ti.StepSize();
    th_ = th, h_ = h, mu_ = prm.mu, V_ = prm.V;
    const M3             A = Mm + h * th * C + h * h * th * th * K, B = Mm - h * (1 - th) * C - h * h * th * (1 - th) * K;
    const Eigen::LLT<M3> llt(A);
    P1_ = llt.solve(B), P2_ = -h * llt.solve(K), Y_ = llt.solve(M3::Identity()), hW_ = h * Y_;
    p3_    = h * llt.solve(F);
    rho_n_ = 1 / (h * h * Y_(2, 2)), rho_t_ = 1 / (h * Y_(0, 0));
    r_     = V3(p.r[0], p.r[1], p.r[2]);
    const PetscScalar *a, *b;
    VecGetArrayRead(p.U, &a);
    VecGetArrayRead(p.dU, &b);
    U_  = V3(a[0], a[1], a[2]);
    dU_ = V3(b[0], b[1], b[2]);
    VecRestoreArrayRead(p.U, &a);
    VecRestoreArrayRead(p.dU, &b);
  }

  // Runs one step per element of `steps` with the state in locals, as a hand-written loop would.
  template <class Range>
  void Run(Range &&steps)
  {
    const M3     P1 = P1_, P2 = P2_, Y = Y_, hW = hW_;
    const V3     p3 = p3_;
    const double th = th_, h = h_, mu = mu_, V = V_, rho_n = rho_n_, rho_t = rho_t_;
    V3           U = U_, dU = dU_, r = r_;
    long         total = 0;
    for (auto &&step : steps) {
      (void)step;
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
      total += k;
      const V3 dU0 = dU;
      dU           = vf + h * (Y * r);
      U += h * (th * dU + (1 - th) * dU0);
      benchmark::DoNotOptimize(U);
    }
    U_ = U, dU_ = dU, r_ = r, passes += total;
  }
};

// 0, 1, ..., n - 1 for Minimal::Run outside Google Benchmark.
struct Steps {
  long n;
  struct It {
    long i;
    bool operator!=(const It &o) const { return i != o.i; }
    void operator++() { ++i; }
    long operator*() const { return i; }
  };
  It begin() const { return {0}; }
  It end() const { return {n}; }
};

void ThreeDofLibrary(benchmark::State &state)
{
  Prepared p;
  PrepareThreeDof(p, (int)state.range(0));
  StepInfo info;
  double   passes = 0;
  for (auto _ : state) {
    PetscCallAbort(PETSC_COMM_WORLD, p.ti.Step(p.U, p.dU, p.r, &info));
    passes += info.contact.iterations;
  }
  state.counters["fp_passes"] = passes / state.iterations();
}

void ThreeDofMinimalLoop(benchmark::State &state)
{
  Prepared p;
  PrepareThreeDof(p, (int)state.range(0));
  Minimal m(p, CaseParams((int)state.range(0)));
  m.Run(state);
  state.counters["fp_passes"] = m.passes / state.iterations();
}

// The only code callgrind counts in --instr mode (--toggle-collect=*CountedSteps*).
__attribute__((noinline)) void CountedStepsLibrary(Prepared &p, long steps, double *passes)
{
  StepInfo info;
  for (long i = 0; i < steps; ++i) {
    PetscCallAbort(PETSC_COMM_WORLD, p.ti.Step(p.U, p.dU, p.r, &info));
    *passes += info.contact.iterations;
  }
}

__attribute__((noinline)) void CountedStepsMinimal(Minimal &m, long steps) { m.Run(Steps{steps}); }

int CountSteps(int which, const char *variant, long steps, long warm)
{
  Prepared p;
  PrepareThreeDof(p, which, warm);
  double passes = 0;
  if (!std::strcmp(variant, "library")) CountedStepsLibrary(p, steps, &passes);
  else {
    Minimal m(p, CaseParams(which));
    CountedStepsMinimal(m, steps);
    passes = m.passes;
  }
  std::printf("case %d %s: %ld steps, %.4f fixed-point passes per step\n", which, variant, steps, passes / steps);
  return 0;
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

// Many contacts at scale (issue 10): N DOFs, nc contacts, sparse back end, no eigenanalysis (h fixed at
// 1e-5 s, about 1/1000 of the cell's period); from the equilibrium with a velocity pattern that
// moves every point, 20 warm steps. W: 0 = dense Delassus matrix and stored Y = A^-1 H (the path of
// 3 n_c <= -theta_delassus_max), 1 = sparse W (drop 1e-15) and (S8) by one more solve, 2 = the default choice
// (by cost, or -theta_delassus_max; counter sparse_W says which). Counters: setup_s (ThetaIntegrator::SetUp), setup_MB (growth of
// the resident set over SetUp), rss_MB (peak resident set of the process so far), fp_passes.
void ChainScale(benchmark::State &state)
{
  Prepared    p;
  ChainParams prm;
  prm.cells         = state.range(0) / 3;
  prm.contact_every = prm.cells / state.range(1);
  prm.gamma_step    = 360.0 / prm.cells;
  prm.speed_step    = 1.0 / prm.cells;
  PetscCallAbort(PETSC_COMM_WORLD, BuildChain(PETSC_COMM_WORLD, prm, p.model));
  EquilibriumSolver eqs(PETSC_COMM_WORLD);
  PetscCallAbort(PETSC_COMM_WORLD, eqs.Solve(p.model, p.eq));
  PetscCallAbort(PETSC_COMM_WORLD, p.ti.SetFromOptions());
  PetscCallAbort(PETSC_COMM_WORLD, p.ti.SetDenseMax(0));
  if (state.range(2) < 2) PetscCallAbort(PETSC_COMM_WORLD, p.ti.SetDelassusMax(state.range(2) ? 0 : PETSC_MAX_INT, 1e-15));
  PetscLogDouble m0, m1, t0, t1;
  PetscCallAbort(PETSC_COMM_WORLD, PetscMemoryGetCurrentUsage(&m0));
  PetscCallAbort(PETSC_COMM_WORLD, PetscTime(&t0));
  PetscCallAbort(PETSC_COMM_WORLD, p.ti.SetUp(p.model, 1e-5));
  PetscCallAbort(PETSC_COMM_WORLD, PetscTime(&t1));
  PetscCallAbort(PETSC_COMM_WORLD, PetscMemoryGetCurrentUsage(&m1));
  PetscCallAbort(PETSC_COMM_WORLD, VecDuplicate(p.eq.U, &p.U));
  PetscCallAbort(PETSC_COMM_WORLD, VecDuplicate(p.eq.U, &p.dU));
  PetscCallAbort(PETSC_COMM_WORLD, VecCopy(p.eq.U, p.U));
  PetscInt lo, hi;
  PetscScalar *du;
  PetscCallAbort(PETSC_COMM_WORLD, VecGetOwnershipRange(p.dU, &lo, &hi));
  PetscCallAbort(PETSC_COMM_WORLD, VecGetArray(p.dU, &du));
  for (PetscInt i = lo; i < hi; ++i) du[i - lo] = 1e-2 * std::sin(0.7 * i);
  PetscCallAbort(PETSC_COMM_WORLD, VecRestoreArray(p.dU, &du));
  const PetscInt nc = p.model.contacts.Size();
  p.r.setZero(3 * nc);
  for (PetscInt c = 0; c < nc; ++c) p.r[3 * c + kT] = p.model.contacts.Mu() * p.eq.N[c], p.r[3 * c + kN] = p.eq.N[c];
  StepInfo info;
  for (PetscInt i = 0; i < 20; ++i) PetscCallAbort(PETSC_COMM_WORLD, p.ti.Step(p.U, p.dU, p.r, &info));
  double passes = 0;
  for (auto _ : state) {
    PetscCallAbort(PETSC_COMM_WORLD, p.ti.Step(p.U, p.dU, p.r, &info));
    passes += info.contact.iterations;
  }
  struct rusage ru;
  getrusage(RUSAGE_SELF, &ru);
  state.counters["fp_passes"] = passes / state.iterations();
  state.counters["setup_s"]   = t1 - t0;
  state.counters["setup_MB"]  = (m1 - m0) / 1048576.0;
  state.counters["rss_MB"]    = ru.ru_maxrss / 1024.0; // kB on Linux
  state.counters["sparse_W"]  = p.ti.SparseDelassus();
  state.counters["W_nnz"]     = p.ti.SparseDelassus() ? (double)p.ti.DelassusSparse().nonZeros() : 9.0 * nc * nc;
}

// Console output plus, at the end, library / hand-written time per step for each 3-DOF case
// (fastest repetition of each, the least disturbed by other load on the machine).
class RatioReporter : public benchmark::ConsoleReporter {
public:
  void ReportRuns(const std::vector<Run> &runs) override
  {
    ConsoleReporter::ReportRuns(runs);
    for (const Run &r : runs) {
      if (r.run_type != Run::RT_Iteration || r.error_occurred) continue;
      const std::string name = r.run_name.str();
      const double      ns   = r.GetAdjustedRealTime() * (r.time_unit == benchmark::kMicrosecond ? 1e3 : 1.0);
      if (!best_.count(name) || ns < best_[name]) best_[name] = ns;
    }
  }
  void Finalize() override
  {
    for (int c : {1, 2}) {
      const std::string suffix = "/case:" + std::to_string(c), lib = "ThreeDof/Library" + suffix, min = "ThreeDof/MinimalLoop" + suffix;
      if (best_.count(lib) && best_.count(min))
        std::printf("3-DOF case %d: library %.1f ns/step, hand-written %.1f ns/step, ratio %.2f (%s)\n", c, best_[lib], best_[min],
                    best_[lib] / best_[min], best_[lib] <= 1.5 * best_[min] ? "meets <= 1.5" : "above 1.5: issue 10 target missed");
    }
    ConsoleReporter::Finalize();
  }

private:
  std::map<std::string, double> best_;
};

} // namespace

BENCHMARK(ThreeDofLibrary)->Name("ThreeDof/Library")->ArgName("case")->Arg(1)->Arg(2);
BENCHMARK(ThreeDofMinimalLoop)->Name("ThreeDof/MinimalLoop")->ArgName("case")->Arg(1)->Arg(2);
BENCHMARK(Chain)->Name("Chain")->ArgNames({"N", "nc", "dense"})->ArgsProduct({{30, 90, 300}, {10}, {0, 1}})
  ->ArgsProduct({{300, 1500, 3000}, {10, 100}, {0}})->Args({1500, 100, 1})->Unit(benchmark::kMicrosecond);
// No dense-W runs of 1000 points: at N = 30000 they took 0.9 GB, 22 s of set-up and 0.3 s per step.
BENCHMARK(ChainScale)->Name("ChainScale")->ArgNames({"N", "nc", "W"})->ArgsProduct({{3000, 30000}, {10, 100}, {0, 1, 2}})
  ->ArgsProduct({{3000, 30000}, {1000}, {1}})->Iterations(20)->Unit(benchmark::kMicrosecond);

int main(int argc, char **argv)
{
  // --instr CASE VARIANT STEPS [WARM]: no Google Benchmark run, only the counted steps after WARM
  // (default 50000) uncounted ones (for callgrind).
  if ((argc == 5 || argc == 6) && !std::strcmp(argv[1], "--instr")) {
    int one = 1;
    PetscCall(SlepcInitialize(&one, &argv, nullptr, nullptr));
    const int rc = CountSteps(std::atoi(argv[2]), argv[3], std::atol(argv[4]), argc == 6 ? std::atol(argv[5]) : 50000);
    PetscCall(SlepcFinalize());
    return rc;
  }
  benchmark::Initialize(&argc, argv);
  PetscCall(SlepcInitialize(&argc, &argv, nullptr, nullptr));
  RatioReporter reporter;
  benchmark::RunSpecifiedBenchmarks(&reporter);
  benchmark::Shutdown();
  PetscCall(SlepcFinalize());
  return 0;
}
