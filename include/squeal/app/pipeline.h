// The method's chain on one communicator (docs/method.md): the model from the options, its
// reduction (a step of its own), the sliding equilibrium, its stability, the energy estimate, and
// from it shooting (with the Floquet multipliers), the transient or the continuation.
//
// Everything that runs the chain goes through a Pipeline: the program (app.cpp), each rank's
// share of a stability sweep (a Pipeline on PETSC_COMM_SELF), each continuation slice (a Pipeline
// on its group of ranks). So the options are read one way, shooting starts from the estimate one
// way (-shoot_q_scale, the balance checked), and the operating point (mu, V) has one writer.
#pragma once

#include "squeal/continuation/continuation.h"
#include "squeal/energy/energy.h"
#include "squeal/integration/transient.h"
#include "squeal/model/model.h"
#include "squeal/shooting/shooting.h"
#include "squeal/stability/equilibrium.h"
#include "squeal/stability/stability.h"
#include "squeal/stability/sweep.h"
#include "squeal/steady/steady_state.h"
#include "squeal/torus/torus.h"

#include <string>

namespace squeal {

// The analyses a run asks for, each with what it starts from: a transient from a mode, shooting
// from the energy estimate, the continuation from a cycle.
struct Request {
  bool stability = false, sweep = false, transient = false, energy = false, shooting = false;
  bool continuation = false;
  bool energy_named = false; // the energy curve is asked for, not only shooting's start
  // steady: the statistical steady state of a transient from the mode; automatic ("auto"): after
  // the energy estimate and the pre-periods, shooting where the flow returns, the statistical
  // steady state where it does not (Pipeline::ShootOrSettle).
  bool steady = false, automatic = false;
  bool torus = false; // the invariant torus of the quasi-periodic motion after a transient from the mode

  // From the names of -analyses (stability, sweep, transient, energy, shooting, continuation, steady, auto, torus).
  static PetscErrorCode Parse(MPI_Comm comm, char **names, PetscInt n, Request &req);
};

class Pipeline {
public:
  explicit Pipeline(MPI_Comm comm);
  MPI_Comm Comm() const { return comm_; }

  // Reads and checks every option of the model, the reduction and each stage, and builds nothing:
  // a mistyped option fails in the first second, not after minutes of FE import and reduction.
  PetscErrorCode CheckOptions(const Request &req);
  // The model from -model_* and -contact_* (ModelCreateFromOptions), not reduced; the directory
  // of -model_export in *export_dir.
  PetscErrorCode BuildModel(std::string *export_dir = nullptr);
  // -reduce_type craig_bampton: the model replaced by its reduction (and its mesh by the DOFs
  // that stay physical). *reduced: whether it was. With expand_results, the reduction keeps the
  // expansion to the full model (-reduce_expand, by default when the model has a mesh).
  PetscErrorCode Reduce(bool *reduced = nullptr);
  // Set by the program, whose results file gets /expanded; the sweep's and the continuation
  // slices' pipelines write no vectors and keep no expansion.
  bool expand_results = false;
  // Every stage's options, once the model is there (the sweep's default V is the model's).
  PetscErrorCode SetFromOptions(const Request &req = Request());
  // The operating point: the one writer of mu and V (ContactSet::SetFriction); every stage reads
  // them from the model. Results computed before it are stale after it.
  PetscErrorCode SetFriction(PetscReal mu, PetscReal V);

  // The stages, in the method's order; each starts from the results of those before it.
  PetscErrorCode SolveEquilibrium();
  PetscErrorCode SolveStability();
  PetscErrorCode EstimateEnergy();
  // Shooting from the estimate's orbit scaled by -shoot_q_scale (or -shoot_period's start); fails
  // when the estimate found no balance. The best iterate is in `cycle` also when it fails.
  PetscErrorCode Shoot();
  // The choice of -analyses auto. The pre-periods (-shoot_pre_periods; when not given, the larger of
  // kAutoPrePeriods and the model's default, Shooting::DefaultPrePeriods) run from the estimate as
  // shooting's; when their return criterion holds (return distance below -shoot_pre_tol with a
  // measured period) Newton goes on from there as in Shoot, else the route is the statistical
  // steady state (Settle, from the pre-periods' end state unless -steady_from_mode). A returned flow whose Newton does
  // not converge goes there too. One line says which and why.
  struct Route {
    static constexpr PetscInt   kAutoPrePeriods = 20;
    // -shoot_pre_stagnation unless given: the 2625-DOF pad at mu = 0.3, V = 10 m/s ran its 200
    // pre-periods (74 s) to a return distance of 9.4e-2 before the statistics started.
    static constexpr PetscInt   kAutoStagnation = 20;
    bool                        shooting = false, newton_ran = false, newton_failed = false;
    Shooting::PrePeriodsOutcome pre;
    PetscInt                    pre_periods = 0;  // the limit they ran with
    std::vector<PetscReal>      U, dU;            // their end state, all N values on every rank (empty: none)
    std::string                 why;              // the line, without "route: "
    PetscInt                    faster_above_band = 0; // modes above the band (the guard's) growing faster than the mode shot
  };
  PetscErrorCode ShootOrSettle(Route &route);
  // The statistical steady state from (U, dU) (empty: the transient's start from the mode).
  PetscErrorCode Settle(const std::vector<PetscReal> &U, const std::vector<PetscReal> &dU, const std::string &start);
  PetscErrorCode Continue(ContinuationResult &res); // from the converged cycle
  PetscErrorCode RunTransient(TransientResult &res);
  PetscErrorCode Sweep(SweepResult &res); // collective; each rank solves its points on a Pipeline of its own

  // A continuation slice's start: a Pipeline on the slice's ranks, run up to a converged cycle.
  static BranchStarter SliceStarter();

  // The stages (the program views and writes them) and their results.
  Model              model;
  EquilibriumSolver  eqs;
  StabilitySolver    stab;
  SweepSolver        sweep;
  ThetaIntegrator    theta;
  TransientAnalysis  transient;
  EnergyAnalysis     energy;
  Shooting           shooting;
  Continuation       continuation;
  SteadyState        steady;
  TorusSolver        torus;
  SlidingEquilibrium eq;
  StabilityResult    stability;
  EnergyEstimate     estimate;
  ShootingResult     cycle;
  SteadyStateResult  settled;
  TorusResult        torus_result;
  PetscReal          reduction_top_hz = 0; // the highest fixed-interface mode a Reduce of this run kept (0: none)
  // The unstable modes above the band up to -stab_guard_fmax, most unstable first (the program's guard).
  std::vector<PetscReal> above_band_f, above_band_sigma;

private:
  MPI_Comm comm_;
};

} // namespace squeal
