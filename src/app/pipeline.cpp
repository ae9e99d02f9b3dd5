#include "squeal/app/pipeline.h"
#include "squeal/core/interrupt.h"
#include "squeal/core/errors.h"
#include "squeal/core/gather.h"
#include "squeal/io/start_state.h"
#include "squeal/model/builders.h"
#include "squeal/reduction/craig_bampton.h"

#include <algorithm>
#include <map>
#include <memory>
#include <utility>

namespace squeal {

PetscErrorCode Request::Parse(MPI_Comm comm, char **names, PetscInt n, Request &req)
{
  PetscFunctionBeginUser;
  for (PetscInt i = 0; i < n; ++i) {
    const std::string a = names[i];
    if (a == "stability") req.stability = true;
    else if (a == "sweep") req.sweep = true;
    else if (a == "transient") req.transient = req.stability = true; // starts from a mode
    else if (a == "energy") req.energy = req.energy_named = req.stability = true;
    else if (a == "shooting") req.shooting = req.energy = req.stability = true; // starts from the estimate
    else if (a == "continuation") req.continuation = req.shooting = req.energy = req.stability = true; // from the cycle
    else if (a == "steady") req.steady = req.stability = true; // a transient from a mode
    else if (a == "auto") req.automatic = req.energy = req.stability = true; // the estimate starts the pre-periods
    else if (a == "torus") req.torus = req.stability = true; // a transient from a mode, then its stroboscopic map
    else {
      SETERRQ(comm, kErrInput,
              "unknown analysis '%s' in -analyses (available: stability, sweep, transient, energy, shooting, continuation, steady, auto, torus)",
              a.c_str());
    }
  }
  // auto is the choice between the two: asking for one of them as well leaves nothing to choose.
  PetscCheck(!(req.automatic && (req.shooting || req.steady)), comm, kErrInput,
             "-analyses: 'auto' chooses between shooting and the statistical steady state; give 'auto' alone, or 'shooting' or 'steady'");
  PetscFunctionReturn(0);
}

Pipeline::Pipeline(MPI_Comm comm)
  : model(comm), eqs(comm), stab(comm), sweep(comm), theta(comm), transient(comm), energy(comm), shooting(comm), continuation(comm),
    steady(comm), torus(comm), comm_(comm)
{
}

PetscErrorCode Pipeline::CheckOptions(const Request &req)
{
  PetscFunctionBeginUser;
  model.contacts.SetFriction(0, 1); // the sweep's default speed range; values read here are thrown away
  PetscCall(ModelCreateFromOptions(comm_, model, nullptr, true));
  bool reduce = false;
  PetscCall(CraigBampton(comm_).SetFromOptions(&reduce));
  PetscCall(SetFromOptions(req));
  PetscFunctionReturn(0);
}

PetscErrorCode Pipeline::BuildModel(std::string *export_dir)
{
  PetscFunctionBeginUser;
  PetscCall(ModelCreateFromOptions(comm_, model, export_dir));
  PetscFunctionReturn(0);
}

PetscErrorCode Pipeline::Reduce(bool *reduced)
{
  CraigBampton cb(comm_);
  bool         reduce = false;
  PetscBool    help   = PETSC_FALSE;
  PetscFunctionBeginUser;
  PetscCall(PetscOptionsHasHelp(nullptr, &help));
  PetscCall(cb.SetFromOptions(&reduce));
  reduce = reduce && !help;
  if (reduced) *reduced = reduce;
  if (!reduce) PetscFunctionReturn(0);
  const PetscInt expand = cb.ExpansionOption();
  PetscCall(cb.SetKeepExpansion(expand_results && (expand < 0 ? (bool)model.mesh : expand == 1)));
  Model red(comm_);
  PetscCall(cb.Reduce(model, red));
  reduction_top_hz = cb.Info().freq.empty() ? 0.0 : cb.Info().freq.back();
  PetscMPIInt wrank, rank;
  PetscCallMPI(MPI_Comm_rank(PETSC_COMM_WORLD, &wrank));
  PetscCallMPI(MPI_Comm_rank(comm_, &rank));
  // One report per run, also when every rank reduces its own copy (the sweep).
  if (wrank == 0 && rank == 0) PetscCall(cb.View(PETSC_VIEWER_STDOUT_SELF));
  model.M = std::move(red.M);
  model.C = std::move(red.C);
  model.K = std::move(red.K);
  model.F = std::move(red.F);
  // The mesh follows what stays physical: the contact nodes' DOFs (Craig-Bampton keeps them,
  // renumbered in contact order; with interface reduction the in-plane DOFs are modal, so none).
  // The kept expansion puts every node back on the mesh, in the full model's numbering (dof_full).
  const bool iface = red.contacts.HasExplicitColumns();
  if (model.mesh && (!iface || red.expansion)) {
    auto                         mesh = std::make_shared<io::FeMesh>(*model.mesh);
    std::map<PetscInt, PetscInt> to_red;
    if (!iface)
      for (size_t c = 0; c < model.contacts.points.size(); ++c)
        for (size_t j = 0; j < model.contacts.points[c].nodes.size(); ++j)
          for (int k = 0; k < 3; ++k) to_red[model.contacts.points[c].nodes[j].dofs[k]] = red.contacts.points[c].nodes[j].dofs[k];
    if (red.expansion) mesh->dof_full = model.mesh->dof;
    for (auto &d : mesh->dof)
      for (PetscInt &i : d) {
        auto it = to_red.find(i);
        i       = it == to_red.end() ? -1 : it->second;
      }
    PetscCall(MatGetSize(model.K, &mesh->full_size, nullptr)); // red.K was moved there above
    mesh->partial = true;
    model.mesh    = mesh;
  } else model.mesh.reset();
  model.contacts  = red.contacts;
  model.name      = red.name;
  model.expansion = red.expansion;
  PetscFunctionReturn(0);
}

PetscErrorCode Pipeline::SetFromOptions(const Request &req)
{
  PetscFunctionBeginUser;
  PetscCall(eqs.SetFromOptions());
  PetscCall(stab.SetFromOptions());
  PetscCall(sweep.SetFromOptions(model.contacts.V()));
  PetscCall(theta.SetFromOptions());
  PetscCall(transient.SetFromOptions());
  PetscCall(energy.SetFromOptions());
  energy.full_scan = req.energy_named;
  PetscCall(shooting.SetFromOptions());
  PetscCall(continuation.SetFromOptions());
  continuation.SetBranchStarter(SliceStarter());
  PetscCall(steady.SetFromOptions());
  PetscCall(torus.SetFromOptions());
  PetscFunctionReturn(0);
}

PetscErrorCode Pipeline::SetFriction(PetscReal mu, PetscReal V)
{
  PetscFunctionBeginUser;
  PetscCheck(mu >= 0 && std::isfinite(mu) && V > 0 && std::isfinite(V), comm_, kErrInput,
             "operating point mu = %g, V = %g m/s: expected mu >= 0 and V > 0, finite", (double)mu, (double)V);
  model.contacts.SetFriction(mu, V);
  PetscFunctionReturn(0);
}

PetscErrorCode Pipeline::SolveEquilibrium()
{
  PetscFunctionBeginUser;
  PetscCall(eqs.Solve(model, eq));
  PetscFunctionReturn(0);
}

PetscErrorCode Pipeline::SolveStability()
{
  PetscFunctionBeginUser;
  PetscCall(stab.Solve(model, eq, stability));
  PetscFunctionReturn(0);
}

PetscErrorCode Pipeline::EstimateEnergy()
{
  PetscFunctionBeginUser;
  PetscCall(energy.Estimate(model, eq, stability, estimate));
  PetscFunctionReturn(0);
}

PetscErrorCode Pipeline::Shoot()
{
  VecH U0, dU0;
  PetscFunctionBeginUser;
  PetscCheck(estimate.mode >= 0, comm_, PETSC_ERR_ARG_WRONGSTATE,
             "shooting: no unstable mode in the band at mu = %g, V = %g m/s, so no limit cycle to start from", (double)model.contacts.Mu(),
             (double)model.contacts.V());
  if (!shooting.start_file.empty()) {
    io::StartState z;
    PetscCall(io::ReadStartState(comm_, shooting.start_file, shooting.start_from, model.Size(), model.contacts.Size(), "-shoot_start", z));
    const PetscReal T = shooting.period > 0 ? shooting.period : (z.period > 0 ? z.period : estimate.T0);
    PetscCall(PetscPrintf(comm_, "shooting: start from %s, start period %.10g s (%s)\n", z.what.c_str(), (double)T,
                          shooting.period > 0 ? "-shoot_period" : z.period > 0 ? "the file's" : "the linear one: the file has none"));
    PetscCall(VecDuplicate(eq.U, U0.out()));
    PetscCall(VecDuplicate(eq.U, dU0.out()));
    PetscCall(SetOwnedRows(z.U.data(), U0));
    PetscCall(SetOwnedRows(z.dU.data(), dU0));
    PetscCall(shooting.Solve(model, eq, theta, U0, dU0, T, cycle));
    PetscFunctionReturn(0);
  }
  PetscCheck(estimate.found, comm_, PETSC_ERR_NOT_CONVERGED,
             "shooting: the energy estimate found no amplitude where damping and reaction powers balance up to %g q_sep; no initial guess "
             "(raise -energy_q_max_factor or -energy_extend)",
             (double)estimate.q_max_factor);
  // Z0 = U_e + s (U0 - U_e), s dU0: the estimate's orbit scaled by -shoot_q_scale.
  PetscCall(VecDuplicate(estimate.U0, U0.out()));
  PetscCall(VecDuplicate(estimate.dU0, dU0.out()));
  PetscCall(VecWAXPY(U0, -1.0, eq.U, estimate.U0));
  PetscCall(VecAYPX(U0, shooting.q_scale, eq.U));
  PetscCall(VecCopy(estimate.dU0, dU0));
  PetscCall(VecScale(dU0, shooting.q_scale));
  PetscCall(shooting.Solve(model, eq, theta, U0, dU0, shooting.period > 0 ? shooting.period : estimate.T0, cycle));
  PetscFunctionReturn(0);
}

namespace {

// All N values of a distributed vector on every rank.
PetscErrorCode ToAll(Vec v, std::vector<PetscReal> &out)
{
  VecScatter         sc;
  Vec                z;
  const PetscScalar *a;
  PetscInt           n;
  PetscFunctionBeginUser;
  PetscCall(VecScatterCreateToAll(v, &sc, &z));
  PetscCall(VecScatterBegin(sc, v, z, INSERT_VALUES, SCATTER_FORWARD));
  PetscCall(VecScatterEnd(sc, v, z, INSERT_VALUES, SCATTER_FORWARD));
  PetscCall(VecGetSize(z, &n));
  PetscCall(VecGetArrayRead(z, &a));
  out.resize(n);
  for (PetscInt i = 0; i < n; ++i) out[i] = PetscRealPart(a[i]);
  PetscCall(VecRestoreArrayRead(z, &a));
  PetscCall(VecDestroy(&z));
  PetscCall(VecScatterDestroy(&sc));
  PetscFunctionReturn(0);
}

} // namespace

PetscErrorCode Pipeline::ShootOrSettle(Route &route)
{
  char b[512];
  PetscFunctionBeginUser;
  route = Route{};
  PetscCheck(estimate.mode >= 0, comm_, PETSC_ERR_ARG_WRONGSTATE, "auto: no unstable mode in the band, nothing to choose");
  if (!estimate.found) {
    // No start for the pre-periods: the transient from the mode decides nothing about a cycle, but
    // its statistics are an answer where the estimate has none.
    std::snprintf(b, sizeof b,
                  "statistical steady state: the energy estimate found no amplitude where the powers balance (up to %g q_sep), so no start "
                  "for the pre-periods; the transient starts from the mode",
                  (double)estimate.q_max_factor);
    route.why = b;
    PetscCall(PetscPrintf(comm_, "route: %s\n", route.why.c_str()));
    PetscFunctionReturn(0);
  }
  // Not given: at least the model's own default (200 above 200 DOFs: the 562-DOF pad's flow needs
  // 22 periods to return within 0.02), so auto never calls a flow irregular that shooting's
  // defaults would have followed back to its cycle.
  const PetscInt given = shooting.pre_periods;
  PetscInt       model_default;
  PetscReal      model_tol;
  Shooting::DefaultPrePeriods(model.Size(), &model_default, &model_tol);
  route.pre_periods    = given > 0 ? given : std::max(Route::kAutoPrePeriods, model_default);
  shooting.pre_periods = route.pre_periods;
  // The most unstable mode above the band, when it grows faster than the one shooting starts from.
  const PetscReal sigma_b = stability.modes[estimate.mode].sigma, f_b = stability.modes[estimate.mode].Frequency();
  route.faster_above_band = (PetscInt)std::count_if(above_band_sigma.begin(), above_band_sigma.end(), [&](PetscReal s) { return s > sigma_b; });
  const PetscInt n_faster = stab.GuardRoute() ? route.faster_above_band : 0;
  const PetscInt given_stagnation = shooting.pre_stagnation;
  if (given_stagnation == PETSC_DECIDE) shooting.pre_stagnation = Route::kAutoStagnation;
  shooting.after_pre_periods = [&](const Shooting::PrePeriodsOutcome &o, Vec U, Vec dU, bool *newton) -> PetscErrorCode {
    PetscFunctionBeginUser;
    route.pre = o;
    PetscCall(ToAll(U, route.U));
    PetscCall(ToAll(dU, route.dU));
    route.shooting = route.newton_ran = *newton = o.returned;
    const std::string limit = "-shoot_pre_periods " + std::to_string(route.pre_periods) + (given > 0 ? "" : " (auto's default)");
    if (o.returned)
      std::snprintf(b, sizeof b, "shooting: the flow returns, return distance %.2e < -shoot_pre_tol %g after %" PetscInt_FMT " pre-period(s) of %s, period %.7g s",
                    (double)o.distance, (double)shooting.pre_tol, o.periods, limit.c_str(), (double)o.period);
    else if (o.stagnated)
      std::snprintf(b, sizeof b,
                    "statistical steady state: the flow does not return, its return distance stagnates (best %.2e in the last %" PetscInt_FMT
                    " pre-periods, %.2e before; -shoot_pre_stagnation %" PetscInt_FMT "), %.2e >= -shoot_pre_tol %g after %" PetscInt_FMT
                    " pre-period(s) of %s",
                    (double)o.best_recent, shooting.pre_stagnation, (double)o.best_before, shooting.pre_stagnation, (double)o.distance,
                    (double)shooting.pre_tol, o.periods, limit.c_str());
    else
      std::snprintf(b, sizeof b,
                    "statistical steady state: the flow does not return, return distance %.2e %s -shoot_pre_tol %g after %" PetscInt_FMT
                    " pre-period(s) (%s)%s",
                    (double)o.distance, o.distance < shooting.pre_tol ? "<" : ">=", (double)shooting.pre_tol, o.periods, limit.c_str(),
                    o.measured_period > 0 ? "" : ", no period measured at the Poincare section");
    route.why = b;
    if (o.returned && n_faster > 0) {
      // The band's cycle would have to hold down a faster-growing mode: on the brakes measured
      // (docs/fe-workflow.md) such flows "returned" only by a fluctuation, and Newton ran 37 min
      // for nothing on the size-2 brake.
      *newton = false, route.shooting = route.newton_ran = false;
      std::snprintf(b, sizeof b,
                    "statistical steady state: the flow returned (return distance %.2e after %" PetscInt_FMT " pre-period(s)), but %" PetscInt_FMT " mode(s) "
                    "above the band grow faster than the band's %.1f Hz (%.1f Hz at %.4g 1/s against %.4g): no cycle of it to shoot "
                    "(-stab_guard_route 0 tries)",
                    (double)o.distance, o.periods, n_faster, (double)f_b, (double)above_band_f[0], (double)above_band_sigma[0], (double)sigma_b);
      route.why = b;
    }
    PetscCall(PetscPrintf(comm_, "route: %s\n", route.why.c_str()));
    PetscFunctionReturn(0);
  };
  struct Unhook {
    Pipeline &p;
    PetscInt  n, s;
    ~Unhook() { p.shooting.after_pre_periods = nullptr, p.shooting.pre_periods = n, p.shooting.pre_stagnation = s; }
  } unhook{*this, given, given_stagnation};
  // A Newton that does not converge from a returned flow is a route, not an error.
  PetscCall(PetscPushErrorHandler(PetscReturnErrorHandler, nullptr));
  PetscErrorCode err = Shoot();
  PetscCall(PetscPopErrorHandler());
  // The handler above kept the interrupt's own message from the screen: say it here.
  PetscCheck(err != PETSC_ERR_SIG, comm_, PETSC_ERR_SIG, "interrupted by %s during the shooting of -analyses auto", InterruptSignalName());
  if (err && err != PETSC_ERR_NOT_CONVERGED) SETERRQ(comm_, err, "auto: shooting failed: %s", cycle.reason.empty() ? "(no reason recorded)" : cycle.reason.c_str());
  if (route.shooting && (err || !cycle.converged)) {
    route.shooting = false, route.newton_failed = true;
    std::snprintf(b, sizeof b, "statistical steady state after all: shooting did not converge from the returned flow (%s)", cycle.reason.c_str());
    route.why += std::string("; ") + b;
    PetscCall(PetscPrintf(comm_, "route: %s\n", b));
  }
  PetscFunctionReturn(0);
}

PetscErrorCode Pipeline::Settle(const std::vector<PetscReal> &U, const std::vector<PetscReal> &dU, const std::string &start)
{
  PetscFunctionBeginUser;
  PetscCall(steady.Run(model, eq, stability, theta, transient, U, dU, start, settled));
  PetscFunctionReturn(0);
}

PetscErrorCode Pipeline::Continue(ContinuationResult &res)
{
  PetscFunctionBeginUser;
  PetscCall(continuation.Run(model, eqs, stab, theta, shooting, cycle, res));
  PetscFunctionReturn(0);
}

PetscErrorCode Pipeline::RunTransient(TransientResult &res)
{
  PetscFunctionBeginUser;
  PetscCall(transient.Run(model, eq, stability, theta, res));
  PetscFunctionReturn(0);
}

PetscErrorCode Pipeline::Sweep(SweepResult &res)
{
  // Each rank's points on a model of its own: the points need no messages, and this pipeline's
  // model keeps its operating point for the analyses after. The model is built and reduced once:
  // on one rank the points' model shares this one's matrices, on several each rank gets a copy of
  // the whole (a reduced model is small; before, each rank built and reduced its own).
  PetscMPIInt size;
  PetscFunctionBeginUser;
  PetscCallMPI(MPI_Comm_size(comm_, &size));
  const bool built = (bool)model.M;
  Pipeline   point(size == 1 && built ? comm_ : PETSC_COMM_SELF);
  if (!built) {
    PetscCall(point.BuildModel());
    PetscCall(point.Reduce());
  } else if (size == 1) PetscCall(ModelShare(model, point.model));
  else PetscCall(ModelReplicate(model, point.model));
  PetscCall(point.eqs.SetFromOptions());
  PetscCall(point.stab.SetComputeModes(false));
  PetscCall(point.stab.SetFromOptions());
  PetscCall(point.stab.SetComputeModes(false));
  auto solve = [&point](PetscReal mu, PetscReal V, StabilityResult &sr, bool *ok) -> PetscErrorCode {
    PetscFunctionBeginUser;
    PetscCall(point.SetFriction(mu, V));
    // A point without steady sliding is a result (failed), not an error.
    PetscCall(PetscPushErrorHandler(PetscReturnErrorHandler, nullptr));
    PetscErrorCode ierr = point.SolveEquilibrium();
    if (!ierr) ierr = point.stab.Solve(point.model, point.eq, sr);
    PetscCall(PetscPopErrorHandler());
    *ok = !ierr;
    PetscFunctionReturn(0);
  };
  PetscCall(sweep.Solve(solve, res));
  PetscFunctionReturn(0);
}

BranchStarter Pipeline::SliceStarter()
{
  return [](MPI_Comm comm, const std::string &param, PetscReal value, const std::function<PetscErrorCode(BranchStart &)> &use) -> PetscErrorCode {
    Pipeline p(comm);
    PetscFunctionBeginUser;
    PetscCall(p.BuildModel());
    PetscCall(p.Reduce());
    PetscCall(p.SetFromOptions());
    const ContactSet &cs = p.model.contacts;
    PetscCall(p.SetFriction(param == "mu" ? value : cs.Mu(), param == "mu" ? cs.V() : value));
    p.shooting.interruptible = false; // the slice polls between its points
    PetscCall(p.SolveEquilibrium());
    PetscCall(p.SolveStability());
    PetscCall(p.EstimateEnergy());
    PetscCall(PetscPushErrorHandler(PetscIgnoreErrorHandler, nullptr));
    PetscErrorCode err = p.Shoot();
    PetscCall(PetscPopErrorHandler());
    PetscCheck(!err && p.cycle.converged, comm, PETSC_ERR_NOT_CONVERGED,
               "continuation slice at %s = %g: shooting from the energy estimate did not converge (%s); change -cont_slices", param.c_str(),
               (double)value, err && p.cycle.reason.empty() ? "no start" : p.cycle.reason.c_str());
    BranchStart st{p.model, p.eqs, p.stab, p.theta, p.shooting, p.cycle};
    PetscCall(use(st));
    PetscFunctionReturn(0);
  };
}

} // namespace squeal
