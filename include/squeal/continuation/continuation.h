// Pseudo-arclength continuation of the periodic orbit (Z0, T) in one parameter, mu or V
// (issue 11), on top of the public interface of squeal::Shooting (docs/method.md §6).
//
// Unknowns y = (Z0, T, lambda). Corrector (options prefix "cont_"): Newton on
//     H = Z(Z0, T; lambda) - Z0,   p = G_a^T (Z0 - Z_a),   a = t . S (y - y_pred)
// with the shooting anchor (Z_a, G_a) reset to every iterate (Shooting::SetAnchor), t the unit
// secant of the last two points in the scaled norm S (U by ||U0 - U_e||, dU by ||dU0||, T by T,
// lambda by the range, all at the start point), y_pred = y_last + ds t. The bordered Jacobian is
// a MatShell: one finite-difference flow per product for (Z0, T), one extra flow per iteration for
// d/dlambda; GMRES without preconditioner (-cont_ksp_*). Folds are passed because lambda is an
// unknown. That GMRES converges only on small models: on FE models (the half brake, N = 782) it
// broke down at every step size, since the cycle's multipliers crowd 1. There (2N + 1 >
// -shoot_jacobian_dense_max) the products are exact tangents and GMRES is preconditioned by
// shooting's own preconditioner (Shooting::PreparePreconditioner) bordered by dH/dlambda and the
// arclength row (its Schur complement, a scalar). -cont_corrector parameter instead takes
// shooting's Newton at the predicted lambda from the predicted (Z0, T): no fold is passed (the leg
// stops there with the reason); auto takes it where shooting has no preconditioner (the sparse
// back end). A converged corrector is polished by Shooting::Solve at its lambda (one correction),
// which also gives the Floquet multipliers (phase-averaged route) and the orbit summary, so every
// point IS a stand-alone shooting solution. A failed step halves ds (and says so); below
// -cont_ds_min the leg stops and what was computed is kept.
// The branch is run from the start point in both directions (towards -cont_min and -cont_max); a
// leg ends at the range ends (a last point exactly on the bound), after -cont_max_steps points, or
// when the cycle shrinks onto the sliding equilibrium (the Hopf point: amplitude below
// -cont_min_amplitude times the start's).
// Events between consecutive points: regime changes (lift-off, stick, and their ends; located by
// bisection in lambda to -cont_locate_tol), folds (lambda turns back), cycle stability changes
// classified by the multiplier that crosses (+1: cyclic fold / branch point, -1: period doubling,
// complex pair: Neimark-Sacker), monodromy jumps (a non-trivial multiplier modulus changes by more
// than -cont_jump_tol between neighbours), equilibrium stability changes (Hopf point, mu_c) and the
// coexistence of a stable cycle and a stable equilibrium (hysteresis).
// SIGINT/SIGTERM (core/interrupt.h) are polled before every point and every corrector iteration:
// the run stops there, keeps the points so far (res.interrupted), and the caller writes them.
#pragma once

#include "squeal/core/inf.h"
#include "squeal/io/h5.h"
#include "squeal/shooting/shooting.h"
#include "squeal/stability/equilibrium.h"
#include "squeal/stability/stability.h"

#include <complex>
#include <functional>
#include <string>
#include <vector>

namespace squeal {

struct ContinuationPoint {
  PetscReal                            param = 0, period = 0, amplitude = 0; // amplitude: max peak-to-peak over DOFs
  PetscReal                            frac_separated = 0, frac_stuck = 0;
  std::vector<PetscReal>               peak_to_peak;
  std::vector<std::complex<PetscReal>> floquet; // by decreasing modulus
  PetscInt                             trivial = -1;
  bool                                 stable_cycle = false;
  PetscInt                             equilibrium_unstable = -1; // unstable modes of the sliding equilibrium (-1: not computed)
  PetscReal                            max_growth = 0;            // largest oscillatory growth rate there (1/s)
  PetscInt                             newton_iterations = 0, flow_evaluations = 0;
  PetscReal                            ds = 0, seconds = 0;
  PetscInt                             leg = 0; // -1 towards -cont_min, 0 start, +1 towards -cont_max
  PetscInt                             slice = 0; // -cont_slices: the parameter slice that computed it
  PetscReal   LargestNonTrivial() const;
  const char *Verdict() const { return floquet.empty() ? "not computed" : stable_cycle ? "stable" : "UNSTABLE"; } // -floquet_compute 0: none
};

struct ContinuationEvent {
  std::string type;     // lift-off, contact-closes, stick, stick-ends, fold, period-doubling, ...
  PetscInt    point;    // the event lies between points point-1 and point
  PetscReal   param;    // located value (bisection for regime changes, else interpolated)
  PetscReal   lo, hi;   // bracket
  std::string detail;
};

struct ContinuationResult {
  std::string                    param_name; // "mu" or "v"
  std::vector<ContinuationPoint> points;     // in branch order (from the -cont_min end to the -cont_max end)
  std::vector<ContinuationEvent> events;
  std::vector<std::string>       leg_end;    // why each leg stopped
  PetscInt                       halvings = 0, flow_evaluations = 0;
  PetscReal                      seconds = 0;
  bool                           interrupted = false; // SIGINT/SIGTERM stopped the run between points
  PetscReal                      range_lo = 0, range_hi = 0; // the range asked ([start, max] for one leg)

  // The branch reaches both ends of the range asked (to 1e-9 of its width).
  bool Covered() const;
};

// A slice's start on its own group of ranks: the model at one parameter value and the stages whose
// shooting run converged there.
struct BranchStart {
  Model             &model;
  EquilibriumSolver &eqs;
  StabilitySolver   &stab;
  ThetaIntegrator   &theta;
  Shooting          &shooting;
  ShootingResult    &cycle;
};
// Builds the whole chain on `comm` with the parameter `param` set to `value`, runs it up to a
// converged cycle, and calls `use` while it lives (the pipeline's: app/pipeline.h; the slices do not
// rebuild models themselves).
using BranchStarter = std::function<PetscErrorCode(MPI_Comm comm, const std::string &param, PetscReal value,
                                                   const std::function<PetscErrorCode(BranchStart &)> &use)>;

class Continuation {
public:
  explicit Continuation(MPI_Comm comm) : comm_(comm) {}
  // -cont_param mu|v, -cont_min, -cont_max, -cont_ds, -cont_ds_min, -cont_ds_max, -cont_max_steps,
  // -cont_max_it, -cont_min_amplitude, -cont_locate_tol, -cont_jump_tol, -cont_equilibrium, -cont_both, -cont_monitor,
  // -cont_ksp_*.
  PetscErrorCode SetFromOptions();
  // From the converged shooting solution `start` at the model's current parameter. The model's
  // parameter is changed during the run and restored at the end.
  PetscErrorCode Run(Model &model, EquilibriumSolver &eqs, StabilitySolver &stab, ThetaIntegrator &ti, Shooting &shoot,
                     const ShootingResult &start, ContinuationResult &res);
  PetscErrorCode View(const ContinuationResult &res, PetscViewer viewer) const;
  PetscErrorCode Write(const ContinuationResult &res, io::H5Writer &out) const;
  // Where -cont_slices > 1 gets each slice's start.
  void SetBranchStarter(BranchStarter starter) { starter_ = std::move(starter); }

  // Settings, public for tests. The corrector stops on the shooting rule (6.3) with
  // -shoot_eps1/-shoot_eps2, plus |dlambda| / range < eps2.
  std::string param = "mu";
  PetscReal   lmin = -kInf, lmax = kInf; // defaults: mu [0, 0.6], v [0.1, 10]
  PetscReal   ds = 0.02, ds_min = 1e-4, ds_max = 0.1, locate_tol = 1e-4, jump_tol = 0.2, min_amplitude = 0.02;
  PetscInt    max_steps = 200, max_it = 12;
  std::string corrector = "auto"; // -cont_corrector arclength|parameter|auto
  // -cont_slices k: [min, max] cut into k equal slices, each continued downwards from a shooting
  // solution (energy estimate) at its upper end by a group of ranks (MPI_Comm_split, size / k each;
  // a group computes several slices in turn when k > size); the points gathered into one branch.
  PetscInt    slices = 1;
  PetscBool   monitor = PETSC_FALSE, equilibrium = PETSC_TRUE, both = PETSC_TRUE;
  // Test hook: the corrector of this step number (counted over the run, from 1) is declared failed
  // once, so that the halving of the step can be checked; -1: never.
  PetscInt fail_step = -1;

  struct State {
    VecH      U, dU;
    PetscReal T = 0, lambda = 0;
  };

private:
  friend struct ContinuationCallbacks;
  PetscErrorCode SetParam(Model &model, PetscReal v) const;
  PetscReal      GetParam(const Model &model) const;
  PetscErrorCode RunSlices(ContinuationResult &res);
  bool           down_only_ = false; // a slice: from its upper end towards -cont_min only
  bool           by_parameter_ = false; // the corrector is shooting at the predicted parameter (Run decides)
  // The arclength corrector on exact tangent products with shooting's preconditioner (FE models),
  // else on difference products without one (small models). Run decides.
  bool           precond_ = false;
  PetscReal      cz_ = 0, row_l_ = 0; // t-row applied to P^-1 dH/dlambda, and the row's lambda entry
  PetscReal      ksp_rtol_ = 1e-6, ksp_atol_ = 0; // -cont_ksp_rtol, -cont_ksp_atol as set
  PetscErrorCode RowDot(Vec vx, PetscReal *a) const; // the arclength row on a shooting-layout vector
  PetscErrorCode Corrector(const State &last, const State &pred, const State &tangent, State &y, PetscInt *its, std::string &why);
  PetscErrorCode CorrectorIterations(const State &last, const State &pred, const State &tangent, State &y, PetscInt *its,
                                     std::string &why);
  // Shooting::Solve at y.lambda from y, with the equilibrium (and its stability) there; the Floquet
  // multipliers only if `multipliers` (and -floquet_compute).
  PetscErrorCode Polish(const State &y, ContinuationPoint &pt, State *sol, bool *ok, std::string &why, bool multipliers = true);
  PetscErrorCode Leg(int dir, const State &start, std::vector<ContinuationPoint> &pts, std::vector<State> &sts, std::string &end);
  PetscErrorCode FromRank0(const std::vector<PetscReal> &Z0, State &s) const;
  PetscErrorCode FillPoint(const ShootingResult &sr, ContinuationPoint &pt) const;
  PetscErrorCode ToExt(Vec x, PetscReal last, Vec e) const;
  PetscErrorCode FromExt(Vec e, Vec x, PetscReal *last) const;
  PetscErrorCode Locate(ContinuationResult &res, ContinuationEvent &ev);
  PetscErrorCode Detect(ContinuationResult &res);
  PetscErrorCode Dot(const State &a, const State &b, PetscReal *d) const; // in the scaled norm
  PetscErrorCode Axpby(State &y, PetscReal a, const State &x, PetscReal b) const; // y = a x + b y
  PetscErrorCode Create(State &s) const;
  PetscErrorCode Copy(const State &x, State &y) const;

  MPI_Comm           comm_;
  BranchStarter      starter_;
  Model             *model_ = nullptr;
  EquilibriumSolver *eqs_   = nullptr;
  StabilitySolver   *stab_  = nullptr;
  ThetaIntegrator   *ti_    = nullptr;
  Shooting          *shoot_ = nullptr;
  PetscReal          su_ = 1, sdu_ = 1, sT_ = 1, sl_ = 1; // scales of the arclength norm
  PetscReal          radius_ = 1; // the last polished cycle's size about its equilibrium, in that norm
  PetscInt           step_count_ = 0, halvings_ = 0, flows_ = 0;
  bool               interrupted_ = false;
  std::vector<State> states_; // per point of the branch, for the secants and the bisections
  // Corrector work space.
  VecH     x_, f_, fl_, xp_, fp_, vx_, rhs_, dy_;
  MatH     J_;
  KSPH     ksp_;
  VecH     wU_, wdU_, pz_, wx_; // pz_ = P^-1 dH/dlambda of this corrector iteration (precond_)
  const State *tan_ = nullptr;
};

} // namespace squeal
