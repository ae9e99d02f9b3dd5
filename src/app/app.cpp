#include "squeal/app/app.h"
#include "squeal/app/expanded.h"
#include "squeal/app/pipeline.h"
#include "squeal/core/errors.h"
#include "squeal/core/gather.h"
#include "squeal/core/interrupt.h"
#include "squeal/core/options.h"
#include "squeal/continuation/continuation.h"
#include "squeal/energy/energy.h"
#include "squeal/integration/transient.h"
#include "squeal/shooting/shooting.h"
#include "squeal/io/h5.h"
#include "squeal/model/builders.h"
#include "squeal/stability/equilibrium.h"
#include "squeal/stability/stability.h"
#include "squeal/stability/sweep.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

namespace squeal {

const char kHelp[] = "squeal: friction-induced self-excited vibration (brake squeal) on PETSc/SLEPc.\n"
                     "Usage: squeal -scene FILE.yaml [-analyses stability,sweep] [-output FILE.h5] [options]\n"
                     "Scene values are PETSc options (nested YAML keys joined by '_'); the command line overrides them.\n\n";

namespace {

std::string Num(PetscReal x)
{
  char b[32];
  std::snprintf(b, sizeof b, "%g", (double)x);
  return b;
}

PetscErrorCode ReadScene(int argc, char **argv)
{
  char      scene[PETSC_MAX_PATH_LEN];
  PetscBool set, exists;
  PetscFunctionBeginUser;
  PetscCall(PetscOptionsGetString(nullptr, nullptr, "-scene", scene, sizeof(scene), &set));
  if (!set) PetscFunctionReturn(0);
  PetscCall(PetscTestFile(scene, 'r', &exists));
  PetscCheck(exists, PETSC_COMM_WORLD, PETSC_ERR_FILE_OPEN, "scene file '%s' not found", scene);
  PetscCall(CheckYAMLFile(PETSC_COMM_WORLD, scene));
  PetscCall(PetscOptionsInsertFileYAML(PETSC_COMM_WORLD, nullptr, scene, PETSC_TRUE));
  // The scene must not override the command line: insert the arguments again on top.
  PetscCall(PetscOptionsInsertArgs(nullptr, argc - 1, argv + 1));
  PetscFunctionReturn(0);
}

std::string DefaultOutput()
{
  char      scene[PETSC_MAX_PATH_LEN];
  PetscBool set = PETSC_FALSE;
  PetscCallAbort(PETSC_COMM_WORLD, PetscOptionsGetString(nullptr, nullptr, "-scene", scene, sizeof(scene), &set));
  if (!set) return "squeal.h5";
  std::string s(scene);
  s = s.substr(s.find_last_of('/') + 1);
  return s.substr(0, s.find_last_of('.')) + ".h5";
}

// /mesh: what scripts/squeal_xdmf.py needs to put the results' vectors on the FE mesh.
PetscErrorCode WriteMesh(const io::FeMesh &mesh, io::H5Writer &out)
{
  const hsize_t          n = mesh.x.size();
  std::vector<PetscReal> x(3 * n);
  std::vector<PetscInt>  dof(3 * n), ids(n);
  PetscFunctionBeginUser;
  for (hsize_t i = 0; i < n; ++i) {
    ids[i] = (PetscInt)mesh.node_ids[i];
    for (int k = 0; k < 3; ++k) x[3 * i + k] = mesh.x[i][k], dof[3 * i + k] = mesh.dof.empty() ? -1 : mesh.dof[i][k];
  }
  PetscCall(out.WriteArray("/mesh/x", {n, 3}, x.data()));
  PetscCall(out.WriteIntArray("/mesh/dof", {n, 3}, dof.data()));
  PetscCall(out.WriteIntArray("/mesh/node_ids", {n}, ids.data()));
  for (const io::FeMesh::Block &b : mesh.blocks) {
    std::vector<PetscInt> conn(b.conn.begin(), b.conn.end());
    const std::string     path = "/mesh/cells/" + b.type;
    PetscCall(out.WriteIntArray(path.c_str(), {conn.size() / b.nodes_per_cell, (hsize_t)b.nodes_per_cell}, conn.data()));
  }
  PetscCall(out.WriteAttribute("/mesh", "dof_meaning",
                               "row of the model's vectors holding each node's x, y, z translation; -1: none (constrained, "
                               "or not kept physical by a reduction)"));
  PetscCall(out.WriteAttribute("/mesh", "partial", (PetscInt)mesh.partial));
  if (!mesh.dof_full.empty()) {
    for (hsize_t i = 0; i < n; ++i)
      for (int k = 0; k < 3; ++k) dof[3 * i + k] = mesh.dof_full[i][k];
    PetscCall(out.WriteIntArray("/mesh/dof_full", {n, 3}, dof.data()));
    PetscCall(out.WriteAttribute("/mesh/dof_full", "meaning",
                                 "row of each node's x, y, z in the full model's vectors (/expanded); -1: constrained"));
  }
  PetscFunctionReturn(0);
}

PetscErrorCode WriteModelInfo(const Model &model, io::H5Writer &out)
{
  PetscFunctionBeginUser;
  PetscCall(out.WriteAttribute("/model", "name", model.name.c_str()));
  PetscCall(out.WriteAttribute("/model", "dofs", model.Size()));
  PetscCall(out.WriteAttribute("/model", "contact_points", model.contacts.Size()));
  PetscCall(out.WriteAttribute("/model", "mu", model.contacts.Mu()));
  PetscCall(out.WriteAttribute("/model", "V", model.contacts.V()));
  PetscCall(out.WriteAttribute("/model", "friction", FrictionLawName(model.contacts.law)));
  if (model.mesh) PetscCall(WriteMesh(*model.mesh, out));
  PetscFunctionReturn(0);
}

// After each analysis: what is complete goes to disk; on SIGINT/SIGTERM the run stops here with
// the file closed (status "interrupted ...") and a non-zero exit.
PetscErrorCode Checkpoint(MPI_Comm comm, io::H5Writer &out, const char *done)
{
  bool stop;
  PetscFunctionBeginUser;
  // What a second signal leaves (core/interrupt.h) then says how far it got.
  PetscCall(out.SetStatus((std::string("running (complete up to ") + done + ")").c_str()));
  PetscCall(out.Flush());
  PetscCall(InterruptRequested(comm, &stop));
  if (!stop) PetscFunctionReturn(0);
  const std::string status = std::string("interrupted (") + InterruptSignalName() + ") after " + done;
  PetscCall(out.SetStatus(status.c_str()));
  PetscCall(out.Close());
  SETERRQ(comm, PETSC_ERR_SIG, "interrupted by %s after %s; results so far written to %s", InterruptSignalName(), done,
          out.Path().c_str());
}

struct Stages {
  PetscLogStage eq, stab, sweep, transient, energy, shooting, steady;
};

// The verdict of the stability analysis, in words; energy, shooting and continuation need it decided.
PetscErrorCode ReportStability(MPI_Comm comm, const StabilityResult &res, const Request &req)
{
  PetscFunctionBeginUser;
  // A stable verdict holds only for the part of the spectrum that was computed completely.
  const StabilityResult::Verdict verdict = res.GetVerdict();
  std::string                    below, listed;
  if (const PetscInt nb = res.UnstableBelowBand()) {
    below  = "; " + std::to_string(nb) + " unstable mode(s) below -stab_fmin = " + Num(res.fmin) + " Hz are outside the band";
    listed = "unst<fmin";
  }
  if (const PetscInt na = res.UnstableAboveBand()) {
    below += "; " + std::to_string(na) + " unstable mode(s) above -stab_fmax = " + Num(res.fmax) + " Hz are outside the band";
    listed += std::string(listed.empty() ? "" : ", ") + "unst>fmax";
  }
  const std::string band = Num(res.fmin) + "-" + (res.fmax > 0 ? Num(res.fmax) : std::string("inf")) + " Hz";
  if (verdict == StabilityResult::Verdict::Stable && !below.empty())
    PetscCall(PetscPrintf(comm, "no unstable mode in the band %s (%s)%s (listed as %s, not reported)\n", band.c_str(),
                          res.all_eigenvalues ? "all eigenvalues computed" : ("every eigenvalue up to " + Num(res.CompleteUpTo()) + " Hz computed").c_str(),
                          below.c_str(), listed.c_str()));
  else if (verdict == StabilityResult::Verdict::Stable && res.all_eigenvalues)
    PetscCall(PetscPrintf(comm, "sliding equilibrium is stable (all eigenvalues computed): no self-excited vibration expected\n"));
  else if (verdict == StabilityResult::Verdict::Stable)
    PetscCall(PetscPrintf(comm, "sliding equilibrium is stable in the band %s (every eigenvalue up to %.6g Hz computed): no self-excited vibration expected in it\n",
                          band.c_str(), (double)res.CompleteUpTo()));
  else if (verdict == StabilityResult::Verdict::Undecided) {
    const std::string why = "stability undecided: " + std::to_string(res.converged) + " eigenvalue(s) computed, complete up to " +
                            Num(res.CompleteUpTo()) + " Hz, none unstable there" + below + "; " +
                            (res.fmax > 0 ? "raise -stab_nev_max to cover -stab_fmax = " + Num(res.fmax) + " Hz, or lower -stab_fmax"
                                          : "give the band with -stab_fmax");
    if (!(req.energy || req.shooting || req.continuation)) PetscCall(PetscPrintf(comm, "%s\n", why.c_str()));
    // Energy, shooting and continuation need an unstable mode: on an undecided verdict they
    // would report "no vibration" for modes nobody computed.
    PetscCheck(!(req.energy || req.shooting || req.continuation), comm, PETSC_ERR_NOT_CONVERGED,
               "%s (the energy estimate and shooting need the band decided)", why.c_str());
  }
  for (PetscInt i : res.unstable) {
    const Mode &m = res.modes[i];
    PetscCall(PetscPrintf(comm, "unstable mode %" PetscInt_FMT ": f = %.4f Hz, T = %.6f s, growth rate %.4f 1/s\n", i,
                          (double)m.Frequency(), (double)m.Period(), (double)m.sigma));
  }
  if (verdict == StabilityResult::Verdict::Unstable && res.UnstableAboveBand())
    PetscCall(PetscPrintf(comm, "  and %" PetscInt_FMT " unstable mode(s) above the band (-stab_fmax = %s Hz), listed as unst>fmax: not reported\n",
                          res.UnstableAboveBand(), Num(res.fmax).c_str()));
  PetscFunctionReturn(0);
}

// Energy, shooting and the transients integrate every mode of the model, not only the band's. An
// unstable mode above the band then drives the motion: on the size-2 brake reduced by CB 30 kHz + IR
// 60 kHz, 20 142.9 Hz with sigma = 30.2 1/s against the band's 13.3 (the unreduced model has no
// unstable mode there: the reduction made it), and Newton on the band's cycle could not converge.
// So before them the eigensolve is taken up to -stab_guard_fmax (by default the top of a reduction
// made in this run) and what is unstable above the band is said and written (/stability attributes
// guard_fmax, guard_complete_hz, unstable_above_band and their f, sigma).
PetscErrorCode GuardAboveBand(Pipeline &p, io::H5Writer &out)
{
  const MPI_Comm         comm = p.Comm();
  const StabilityResult &res  = p.stability;
  PetscFunctionBeginUser;
  PetscReal g = p.stab.GuardFMax();
  if (g < 0) g = p.reduction_top_hz;
  if (!(res.fmax > 0) || !(g > res.fmax)) PetscFunctionReturn(0);
  StabilityResult        wide;
  const StabilityResult *src = &res;
  if (!(res.all_eigenvalues || res.CompleteUpTo() >= g)) {
    PetscCall(p.stab.SolveUpTo(p.model, p.eq, g, wide));
    src = &wide;
  }
  const PetscReal        reached = src->all_eigenvalues ? kInf : std::min(src->CompleteUpTo(), g);
  std::vector<PetscReal> f, sigma;
  std::vector<size_t>    order;
  for (const Mode &m : src->modes)
    if (m.Unstable() && m.Oscillatory() && m.Frequency() > res.fmax && m.Frequency() <= g) f.push_back(m.Frequency()), sigma.push_back(m.sigma);
  for (size_t i = 0; i < f.size(); ++i) order.push_back(i);
  std::sort(order.begin(), order.end(), [&](size_t a, size_t b) { return sigma[a] > sigma[b]; });
  const std::string upto = std::isinf(reached) ? Num(g) + " Hz (all eigenvalues computed)"
                                               : Num(reached) + " Hz" + (reached < g ? " (of -stab_guard_fmax = " + Num(g) + " Hz; raise -stab_nev_max)" : "");
  if (f.empty()) PetscCall(PetscPrintf(comm, "no unstable mode above the band up to %s, the modes the time integration carries (-stab_guard_fmax)\n", upto.c_str()));
  else {
    std::string list;
    for (size_t k = 0; k < order.size() && k < 5; ++k) {
      char b[96];
      std::snprintf(b, sizeof b, "%s%.1f Hz (sigma %.4g 1/s)", k ? ", " : "", (double)f[order[k]], (double)sigma[order[k]]);
      list += b;
    }
    if (order.size() > 5) list += ", ...";
    const std::string band = res.unstable.empty() ? std::string("the band has none")
                                                  : "the band's most unstable grows at " + Num(res.modes[res.unstable[0]].sigma) + " 1/s";
    PetscCall(PetscPrintf(comm,
                          "WARNING: %zu unstable mode(s) above the band (-stab_fmax = %s Hz), up to %s, which the time integration "
                          "carries: %s; %s. The motion the nonlinear analyses compute is the whole model's: check these modes against "
                          "the unreduced model (a reduction can make them) or take them into the band (-stab_fmax)\n",
                          f.size(), Num(res.fmax).c_str(), upto.c_str(), list.c_str(), band.c_str()));
  }
  PetscCall(out.WriteAttribute("/stability", "guard_fmax", g));
  PetscCall(out.WriteAttribute("/stability", "guard_complete_hz", reached));
  PetscCall(out.WriteAttribute("/stability", "unstable_above_band", (PetscInt)f.size()));
  p.above_band_f.clear(), p.above_band_sigma.clear();
  for (size_t i : order) p.above_band_f.push_back(f[i]), p.above_band_sigma.push_back(sigma[i]);
  if (!f.empty()) {
    PetscCall(out.WriteAttribute("/stability", "unstable_above_band_f", p.above_band_f));
    PetscCall(out.WriteAttribute("/stability", "unstable_above_band_sigma", p.above_band_sigma));
  }
  PetscFunctionReturn(0);
}

// With several unstable modes, only with -energy_all_modes the others are estimated too (one line
// each; 57 modes of a 200-cell chain took > 300 s); shooting starts from the chosen one
// (-energy_mode, default the most unstable in the band).
PetscErrorCode EstimateOtherModes(Pipeline &p)
{
  const MPI_Comm         comm = p.Comm();
  const StabilityResult &res  = p.stability;
  EnergyAnalysis        &energy = p.energy;
  PetscFunctionBeginUser;
  if (res.unstable.size() > 1 && energy.all_modes) {
    const PetscInt chosen = energy.mode;
    for (PetscInt i : res.unstable) {
      if (i == p.estimate.mode) continue;
      EnergyEstimate other;
      energy.mode = i;
      PetscCall(energy.Estimate(p.model, p.eq, res, other));
      if (other.found)
        PetscCall(PetscPrintf(comm, "  other unstable mode %" PetscInt_FMT " (f = %.4f Hz): q0 = %.6e, T0 = %.7f s (-energy_mode %" PetscInt_FMT
                                    " to start from it)\n",
                              i, (double)(other.omega / (2 * PETSC_PI)), (double)other.q0, (double)other.T0, i));
      else
        PetscCall(PetscPrintf(comm, "  other unstable mode %" PetscInt_FMT " (f = %.4f Hz): no balance in the scanned range\n", i,
                              (double)(other.omega / (2 * PETSC_PI))));
    }
    energy.mode = chosen;
  } else if (res.unstable.size() > 1)
    PetscCall(PetscPrintf(comm, "  %zu other unstable mode(s) not estimated (-energy_all_modes to estimate each, -energy_mode to choose)\n",
                          res.unstable.size() - 1));
  PetscFunctionReturn(0);
}

// The statistical steady state (Pipeline::Settle), viewed, written and checkpointed.
PetscErrorCode Settle(Pipeline &p, const std::vector<PetscReal> &U, const std::vector<PetscReal> &dU, const std::string &start, io::H5Writer &out,
                      const Stages &st)
{
  const MPI_Comm comm = p.Comm();
  PetscFunctionBeginUser;
  PetscCall(PetscLogStagePush(st.steady));
  PetscErrorCode err = p.Settle(U, dU, start);
  PetscCall(PetscLogStagePop());
  PetscCall(err);
  PetscCall(p.steady.View(p.settled, PETSC_VIEWER_STDOUT_(comm)));
  PetscCall(p.steady.ViewFromOptions(p.settled));
  PetscCall(p.steady.Write(p.settled, out));
  PetscCall(WriteExpandedEnd(p.model, p.settled.U_end, p.settled.dU_end, out));
  PetscCall(Checkpoint(comm, out, p.settled.complete ? "the statistical steady state" : "the statistical steady state's chunks so far"));
  PetscFunctionReturn(0);
}

// The torus (p.torus, docs/torus.md)'s result viewed, written and checkpointed.
PetscErrorCode ReportTorus(Pipeline &p, io::H5Writer &out)
{
  const MPI_Comm comm = p.Comm();
  PetscFunctionBeginUser;
  PetscCall(p.torus.View(p.torus_result, PETSC_VIEWER_STDOUT_(comm)));
  PetscCall(p.torus.ViewFromOptions(p.torus_result));
  PetscCall(p.torus.Write(p.torus_result, out));
  PetscCall(Checkpoint(comm, out, "the torus"));
  PetscFunctionReturn(0);
}

// -analyses auto after the statistical steady state: a converged periodic verdict (one base, f1)
// goes on to shooting from the steady state's end state at T = 1 / f1 (-shoot_after_steady). The
// route's pre-periods start from the energy estimate at the unstable mode's period; the steady
// state's lines give the motion's own. The half brake at mu = 0.4, V = 5 m/s: the route's flow
// stagnated at 2.5e-2 over 56 periods at the 10.2 kHz mode's period; from the steady state's end at
// 1 / f1 = 1 / 9 226.86 Hz it returned within 1.6e-2 after 7 and Newton converged in 4 iterations,
// and its multipliers (a complex pair at 1.007) said the cycle is unstable (docs/fe-workflow.md).
// At most kAfterSteadyPrePeriods pre-periods and no Newton unless they return: the statistics stay
// the answer, said in the route line and /route (cycle = "..."), not an error.
PetscErrorCode CycleAfterSteady(Pipeline &p, io::H5Writer &out, const Stages &st)
{
  const MPI_Comm                comm = p.Comm();
  const steady::Classification &cls  = p.settled.signal.cls;
  char                          b[512];
  PetscFunctionBeginUser;
  // Broadcast: the statistics are rank 0's.
  PetscReal q[2] = {cls.verdict == "periodic" && cls.bases.size() == 1 ? cls.bases[0] : 0.0, p.settled.converged ? 1.0 : 0.0};
  PetscCallMPI(MPI_Bcast(q, 2, MPIU_REAL, 0, comm));
  const char *g = "/route";
  if (!(q[0] > 0) || !p.shooting.after_steady || p.settled.U_end.empty()) {
    PetscCall(out.WriteAttribute(g, "cycle", q[0] > 0 ? "off (-shoot_after_steady false)" : "not asked (verdict not periodic with one base)"));
    PetscFunctionReturn(0);
  }
  if (!(q[1] > 0)) {
    const char *why = "cycle: not attempted: the statistical steady state did not converge, its lines may still move (raise -steady_max_periods)";
    PetscCall(PetscPrintf(comm, "route: %s\n", why));
    PetscCall(out.WriteAttribute(g, "cycle", "not attempted (statistics not converged)"));
    PetscFunctionReturn(0);
  }
  Shooting &sh = p.shooting;
  struct Restore {
    Shooting &sh;
    PetscInt  n, w;
    ~Restore() { sh.pre_periods = n, sh.pre_stagnation = w, sh.after_pre_periods = nullptr; }
  } restore{sh, sh.pre_periods, sh.pre_stagnation};
  const PetscReal T = 1 / q[0];
  sh.pre_periods    = sh.pre_periods > 0 ? std::min(sh.pre_periods, Shooting::kAfterSteadyPrePeriods) : Shooting::kAfterSteadyPrePeriods;
  sh.pre_stagnation = PETSC_DECIDE;
  bool returned     = false;
  sh.after_pre_periods = [&](const Shooting::PrePeriodsOutcome &o, Vec, Vec, bool *newton) -> PetscErrorCode {
    returned = *newton = o.returned;
    return 0;
  };
  PetscCall(PetscPrintf(comm, "route: periodic, f1 = %.6g Hz: shooting from the steady state's end state at T = 1 / f1 = %.7g s (-shoot_after_steady)\n",
                        (double)q[0], (double)T));
  VecH U0, dU0;
  PetscCall(VecDuplicate(p.eq.U, U0.out()));
  PetscCall(VecDuplicate(p.eq.U, dU0.out()));
  PetscCall(SetOwnedRows(p.settled.U_end.data(), U0));
  PetscCall(SetOwnedRows(p.settled.dU_end.data(), dU0));
  PetscCall(PetscLogStagePush(st.shooting));
  PetscCall(PetscPushErrorHandler(PetscReturnErrorHandler, nullptr));
  PetscErrorCode err = sh.Solve(p.model, p.eq, p.theta, U0, dU0, T, p.cycle);
  PetscCall(PetscPopErrorHandler());
  PetscCall(PetscLogStagePop());
  PetscCheck(err != PETSC_ERR_SIG, comm, PETSC_ERR_SIG, "interrupted by %s during the shooting after the steady state", InterruptSignalName());
  if (err && err != PETSC_ERR_NOT_CONVERGED) SETERRQ(comm, err, "auto: shooting after the steady state failed: %s", p.cycle.reason.c_str());
  if (returned) { // Newton ran: its cycle or best iterate, in place of a failed Newton's from the route's pre-periods
    for (const char *g_old : {"/shooting", "/expanded/orbit", "/expanded/Z0"}) PetscCall(out.Remove(g_old));
    PetscCall(sh.Write(p.cycle, out));
    PetscCall(WriteExpandedOrbit(p.model, p.cycle, out));
  }
  if (p.cycle.converged) {
    PetscCall(sh.View(p.cycle, PETSC_VIEWER_STDOUT_(comm)));
    std::snprintf(b, sizeof b, "cycle: converged from the steady state's end, %.7g Hz, Floquet %s", (double)(1 / p.cycle.period),
                  p.cycle.floquet_verdict.empty() ? "not computed" : p.cycle.floquet_verdict.c_str());
  } else if (!returned)
    std::snprintf(b, sizeof b, "cycle: not converged: the flow from the steady state's end did not return within -shoot_pre_tol in %" PetscInt_FMT
                  " periods; the statistical steady state above stands", sh.pre_periods);
  else std::snprintf(b, sizeof b, "cycle: not converged (%s); the statistical steady state above stands", p.cycle.reason.c_str());
  PetscCall(PetscPrintf(comm, "route: %s\n", b));
  PetscCall(out.WriteAttribute(g, "cycle", p.cycle.converged ? "converged" : "not converged"));
  PetscCall(out.WriteAttribute(g, "cycle_reason", b));
  PetscCall(Checkpoint(comm, out, p.cycle.converged ? "the cycle after the steady state" : "the steady state and the attempt at its cycle"));
  PetscFunctionReturn(0);
}

// -analyses auto after the statistical steady state: a quasi-periodic verdict with two bases goes
// on to the torus (-torus_auto) from those two lines (as -torus_f1, -torus_f2) and the torus's own
// start-up from the mode (-torus_startup_periods). Not from the steady state's end state: on the
// small pad at V = 10 m/s, M = 9, Newton from there stalled at 3.6e-4 (15 iterations), from the
// start-up it converges (docs/torus.md: the start's phase on the torus decides). Newton not
// converging leaves the statistical result as the answer, said in the route line and /route
// (torus = "not converged"): a route, not an error.
PetscErrorCode TorusAfterSteady(Pipeline &p, io::H5Writer &out)
{
  const MPI_Comm                  comm = p.Comm();
  const steady::Classification   &cls  = p.settled.signal.cls;
  char                            b[512];
  PetscFunctionBeginUser;
  // Broadcast: the statistics are rank 0's.
  PetscReal q[3] = {cls.verdict == "quasi-periodic" && cls.bases.size() == 2 ? 1.0 : 0.0, 0, 0};
  if (q[0] > 0) q[1] = cls.bases[0], q[2] = cls.bases[1];
  PetscCallMPI(MPI_Bcast(q, 3, MPIU_REAL, 0, comm));
  const char *g = "/route";
  if (!(q[0] > 0) || !p.torus.in_auto) {
    PetscCall(out.WriteAttribute(g, "torus", q[0] > 0 ? "off (-torus_auto false)" : "not asked (verdict not quasi-periodic with two bases)"));
    PetscFunctionReturn(0);
  }
  // Lines of statistics that have not converged are not yet the motion's (the 807-DOF pad at
  // mu = 0.3, V = 10 m/s: its RMS still rising after 1000 periods); a torus from them costs more
  // than the statistics did.
  if (!p.settled.converged) {
    const char *why = "torus: not attempted: the statistical steady state did not converge, its lines may still move (raise -steady_max_periods)";
    PetscCall(PetscPrintf(comm, "route: %s\n", why));
    PetscCall(out.WriteAttribute(g, "torus", "not attempted (statistics not converged)"));
    PetscCall(out.WriteAttribute(g, "torus_reason", why));
    PetscFunctionReturn(0);
  }
  TorusSolver &t = p.torus;
  struct Restore {
    TorusSolver &t;
    PetscReal    f1, f2;
    ~Restore() { t.f1 = f1, t.f2 = f2; }
  } restore{t, t.f1, t.f2};
  // The stroboscopic period from the stronger base (bases[0] is the strongest line or a harmonic's base).
  t.f1 = q[1], t.f2 = q[2];
  PetscCall(PetscPrintf(comm, "route: quasi-periodic with two bases, f1 = %.6g Hz and f2 = %.6g Hz: on to the torus from them (-torus_auto)\n",
                        (double)q[1], (double)q[2]));
  PetscCall(PetscPushErrorHandler(PetscReturnErrorHandler, nullptr));
  PetscErrorCode err = t.Run(p.model, p.eq, p.stability, p.theta, p.transient, p.torus_result);
  PetscCall(PetscPopErrorHandler());
  if (err && err != PETSC_ERR_NOT_CONVERGED) SETERRQ(comm, err, "auto: the torus failed (error %d)", (int)err);
  const TorusResult &r = p.torus_result;
  if (!err) PetscCall(ReportTorus(p, out));
  if (!err && r.converged)
    std::snprintf(b, sizeof b, "torus: converged in %" PetscInt_FMT " Newton iteration(s), ||F||/||u|| %.2e: f1 = %.4f Hz, f2 = %.4f Hz (modulation %.4f Hz)",
                  r.iterations, (double)r.residual, (double)r.f1, (double)(r.f1 + std::min(r.rho, 1 - r.rho) / r.T),
                  (double)(std::min(r.rho, 1 - r.rho) / r.T));
  else
    std::snprintf(b, sizeof b, "torus: not converged (%s, ||F||/||u|| %.2e); the statistical steady state above stands",
                  err ? "the start-up stopped" : r.reason.c_str(), (double)r.residual);
  PetscCall(PetscPrintf(comm, "route: %s\n", b));
  PetscCall(out.WriteAttribute(g, "torus", !err && r.converged ? "converged" : "not converged"));
  PetscCall(out.WriteAttribute(g, "torus_reason", b));
  PetscFunctionReturn(0);
}

// -analyses auto: the pre-periods, then shooting or the statistical steady state; the route in
// /route (route, reason, return_distance, pre_periods).
PetscErrorCode ShootOrSettle(Pipeline &p, io::H5Writer &out, const Stages &st)
{
  const MPI_Comm  comm = p.Comm();
  Pipeline::Route route;
  PetscFunctionBeginUser;
  PetscCall(PetscLogStagePush(st.shooting));
  PetscErrorCode err = p.ShootOrSettle(route);
  PetscCall(PetscLogStagePop());
  if (route.newton_ran) { // also the best iterate of a failed Newton
    PetscCall(p.shooting.Write(p.cycle, out));
    PetscCall(WriteExpandedOrbit(p.model, p.cycle, out));
  }
  PetscCall(err);
  PetscCall(out.WriteAttribute("/route", "route", route.shooting ? "shooting" : "steady_state"));
  PetscCall(out.WriteAttribute("/route", "reason", route.why.c_str()));
  PetscCall(out.WriteAttribute("/route", "return_distance", route.pre.distance));
  PetscCall(out.WriteAttribute("/route", "pre_periods", route.pre.periods));
  PetscCall(out.WriteAttribute("/route", "pre_periods_limit", route.pre_periods));
  PetscCall(out.WriteAttribute("/route", "pre_tol", p.shooting.pre_tol));
  PetscCall(out.WriteAttribute("/route", "newton_failed", (PetscInt)route.newton_failed));
  PetscCall(out.WriteAttribute("/route", "faster_above_band", route.faster_above_band));
  if (route.shooting) {
    PetscCall(p.shooting.View(p.cycle, PETSC_VIEWER_STDOUT_(comm)));
    PetscCall(Checkpoint(comm, out, "shooting"));
    PetscFunctionReturn(0);
  }
  PetscCall(Checkpoint(comm, out, "the pre-periods"));
  const bool from_mode = route.U.empty() || p.steady.from_mode;
  if (from_mode) route.U.clear(), route.dU.clear();
  PetscCall(Settle(p, route.U, route.dU, from_mode ? "the mode" : "the pre-periods' end state", out, st));
  PetscCall(CycleAfterSteady(p, out, st));
  PetscCall(TorusAfterSteady(p, out));
  PetscFunctionReturn(0);
}

// The energy estimate, and from it shooting and the continuation when asked.
PetscErrorCode RunEnergyAndCycle(Pipeline &p, const Request &req, io::H5Writer &out, const Stages &st)
{
  const MPI_Comm comm = p.Comm();
  PetscFunctionBeginUser;
  PetscCall(PetscLogStagePush(st.energy));
  PetscCall(p.EstimateEnergy());
  PetscCall(PetscLogStagePop());
  PetscCall(p.energy.View(p.estimate, PETSC_VIEWER_STDOUT_(comm)));
  PetscCall(p.energy.Write(p.estimate, out));
  PetscCall(Checkpoint(comm, out, "the energy estimate"));
  PetscCall(EstimateOtherModes(p));
  const std::string at = "mu = " + Num(p.model.contacts.Mu()) + ", V = " + Num(p.model.contacts.V()) + " m/s";
  // No unstable mode in the band: no cycle to shoot for, and no branch to start from.
  if (req.shooting && p.estimate.mode < 0)
    PetscCall(PetscPrintf(comm, "shooting skipped: no unstable mode in the band at %s, so no limit cycle to compute\n", at.c_str()));
  PetscCheck(!(req.continuation && p.estimate.mode < 0), comm, kErrInput,
             "continuation: no limit cycle to start from: the sliding equilibrium has no unstable mode in the band at %s; start the scene "
             "at a mu (or V) where it is unstable (the sweep, -analyses sweep, gives the critical mu)",
             at.c_str());
  if (req.automatic && p.estimate.mode < 0)
    PetscCall(PetscPrintf(comm, "route: none: no unstable mode in the band at %s, so neither a cycle nor a self-excited steady state\n", at.c_str()));
  if (req.automatic && p.estimate.mode >= 0) PetscCall(ShootOrSettle(p, out, st));
  if (!req.shooting || p.estimate.mode < 0) PetscFunctionReturn(0);
  PetscCall(PetscLogStagePush(st.shooting));
  if (p.shooting.period > 0)
    PetscCall(PetscPrintf(comm, "shooting: start period %s s (-shoot_period) instead of the linear %s s\n", Num(p.shooting.period).c_str(),
                          Num(p.estimate.T0).c_str()));
  PetscErrorCode serr = p.Shoot();
  PetscCall(PetscLogStagePop());
  if (p.estimate.found || !p.shooting.start_file.empty()) { // also the best iterate of a failed run
    PetscCall(p.shooting.Write(p.cycle, out));
    PetscCall(WriteExpandedOrbit(p.model, p.cycle, out));
  }
  PetscCall(serr);
  PetscCall(p.shooting.View(p.cycle, PETSC_VIEWER_STDOUT_(comm)));
  PetscCall(Checkpoint(comm, out, "shooting"));
  if (!req.continuation) PetscFunctionReturn(0);
  ContinuationResult cres;
  PetscErrorCode     cerr = p.Continue(cres);
  PetscCall(p.continuation.Write(cres, out)); // the branch computed so far, also after an error
  PetscCall(cerr);
  PetscCall(p.continuation.View(cres, PETSC_VIEWER_STDOUT_(comm)));
  PetscCall(Checkpoint(comm, out, cres.interrupted ? "the continuation points so far" : "the continuation"));
  PetscFunctionReturn(0);
}

// The analyses the request names, in order, each written and flushed to `output` before the next.
PetscErrorCode RunAnalyses(Pipeline &p, const Request &req, const char *output, const Stages &st)
{
  const MPI_Comm comm = p.Comm();
  PetscFunctionBeginUser;
  io::H5Writer out;
  PetscCall(out.Open(comm, output));
  out.KeepOnError("failed: the run stopped with an error; the groups written before it are complete");
  PetscCall(WriteModelInfo(p.model, out));
  if (req.stability) {
    PetscCall(PetscLogStagePush(st.eq));
    PetscCall(p.SolveEquilibrium());
    PetscCall(PetscLogStagePop());
    PetscCall(p.eqs.View(p.model, p.eq, PETSC_VIEWER_STDOUT_(comm)));
    PetscCall(p.eqs.ViewFromOptions(p.model, p.eq));
    PetscCall(WriteEquilibrium(p.model, p.eq, out));

    PetscCall(PetscLogStagePush(st.stab));
    PetscCall(p.SolveStability());
    PetscCall(PetscLogStagePop());
    PetscCall(p.stab.View(p.stability, PETSC_VIEWER_STDOUT_(comm)));
    PetscCall(p.stab.ViewFromOptions(p.stability));
    PetscCall(WriteStability(p.stability, out));
    PetscCall(WriteExpandedModes(p.model, p.stability, out));
    PetscCall(Checkpoint(comm, out, "the stability analysis"));
    PetscCall(ReportStability(comm, p.stability, req));
    if (req.energy || req.shooting || req.transient || req.continuation || req.steady || req.automatic || req.torus) {
      PetscCall(PetscLogStagePush(st.stab));
      PetscCall(GuardAboveBand(p, out));
      PetscCall(PetscLogStagePop());
    }
  }
  if (req.sweep) {
    SweepResult sr;
    PetscCall(PetscLogStagePush(st.sweep));
    PetscCall(p.Sweep(sr));
    PetscCall(PetscLogStagePop());
    PetscCall(p.sweep.View(sr, PETSC_VIEWER_STDOUT_(comm)));
    PetscCall(p.sweep.Write(sr, out));
    // Stopped by a signal, the sweep keeps its computed points and says how many.
    const size_t      done = (size_t)std::count_if(sr.failed.begin(), sr.failed.end(), [](PetscInt f) { return f != 2; });
    const std::string what = sr.interrupted ? "the sweep's points so far (" + std::to_string(done) + " of " + std::to_string(sr.failed.size()) +
                                                ", the rest marked 2 in /sweep/failed)"
                                            : std::string("the sweep");
    PetscCall(Checkpoint(comm, out, what.c_str()));
  }
  if (req.energy) PetscCall(RunEnergyAndCycle(p, req, out, st));
  if (req.transient) {
    TransientResult tr;
    PetscCall(PetscLogStagePush(st.transient));
    PetscErrorCode terr = p.RunTransient(tr);
    PetscCall(PetscLogStagePop());
    // Whatever was recorded is written, also when the run stopped early.
    PetscCall(p.transient.Write(tr, out));
    PetscCall(WriteExpandedRecords(p.model, tr, out));
    PetscCall(terr);
    PetscCall(p.theta.View(PETSC_VIEWER_STDOUT_(comm)));
    PetscCall(p.transient.View(tr, PETSC_VIEWER_STDOUT_(comm)));
    PetscCall(Checkpoint(comm, out, tr.complete ? "the transient" : "the transient step in hand (the steps so far are written)"));
  }
  if (req.steady)
    PetscCall(Settle(p, {}, {}, p.transient.start_file.empty() ? "the mode" : "the state of -transient_start " + p.transient.start_file, out, st));
  if (req.torus) {
    PetscCall(p.torus.Run(p.model, p.eq, p.stability, p.theta, p.transient, p.torus_result));
    PetscCall(ReportTorus(p, out));
  }
  PetscCall(out.SetStatus("complete"));
  PetscCall(out.Close());
  PetscCall(PetscPrintf(comm, "results written to %s\n", output));
  PetscFunctionReturn(0);
}

} // namespace

PetscErrorCode RunApp(int argc, char **argv)
{
  const MPI_Comm comm = PETSC_COMM_WORLD;
  char           output[PETSC_MAX_PATH_LEN] = "";
  char          *names[16];
  PetscInt       nnames = 16;
  PetscBool      set, help = PETSC_FALSE, traceback = PETSC_FALSE, gather = PETSC_TRUE, gather_set = PETSC_FALSE;
  Request        req;
  Stages         st;
  PetscFunctionBeginUser;
  PetscCall(ReadScene(argc, argv));
  PetscCall(PetscOptionsHasHelp(nullptr, &help));
  PetscCall(PetscLogStageRegister("Equilibrium", &st.eq));
  PetscCall(PetscLogStageRegister("Stability", &st.stab));
  PetscCall(PetscLogStageRegister("Sweep", &st.sweep));
  PetscCall(PetscLogStageRegister("Transient", &st.transient));
  PetscCall(PetscLogStageRegister("Energy", &st.energy));
  PetscCall(PetscLogStageRegister("Shooting", &st.shooting));
  PetscCall(PetscLogStageRegister("SteadyState", &st.steady));

  const std::string default_output = DefaultOutput();
  PetscOptionsBegin(comm, nullptr, "squeal", "squeal");
  PetscCall(PetscOptionsString("-scene", "Scene file (YAML) filling the options database", "RunApp", "", output, sizeof(output), nullptr));
  PetscCall(PetscOptionsStringArray("-analyses", "Comma-separated analyses: stability, sweep, transient, energy, shooting, continuation, steady (the statistical steady state of a "
                                              "transient), auto (shooting where the flow returns after the pre-periods, else steady), torus (the invariant torus of a quasi-periodic motion)", "RunApp", names, &nnames, &set));
  std::snprintf(output, sizeof(output), "%s", default_output.c_str());
  PetscCall(PetscOptionsString("-output", "Results file (HDF5); default: the scene's name with .h5", "RunApp", output, output,
                               sizeof(output), nullptr));
  PetscCall(PetscOptionsBool("-reduce_gather",
                             "On several ranks, analyse a reduced (dense) model on rank 0 alone after the reduction (except sweep and "
                             "continuation, which spread their points over the ranks). Default: on, off when shooting is the only "
                             "time-domain analysis (its Floquet columns and preconditioner products are shared by the ranks)",
                             "RunApp", gather, &gather, &gather_set));
  PetscCall(PetscOptionsBool("-squeal_traceback", "Full PETSc tracebacks instead of one-line error messages", "PushErrorHandler",
                             traceback, &traceback, nullptr));
  PetscOptionsEnd();
  if (!set) {
    nnames   = 1;
    names[0] = nullptr;
    PetscCall(PetscStrallocpy("stability", &names[0]));
  }
  PetscErrorCode perr = Request::Parse(comm, names, nnames, req);
  for (PetscInt i = 0; i < nnames; ++i) PetscCall(PetscFree(names[i]));
  PetscCall(perr);
  // Shooting on every rank: rank 0 integrates the forward flows and one-column tangents for all
  // (Shooting::Flow), the blocks of tangent columns (Floquet) and the linear preconditioner's
  // products are split. A transient (also the steady state's and the torus's) would step the whole
  // model on every rank at once, which costs more than one rank alone: those keep the gather.
  if (!gather_set) gather = req.shooting && !req.transient && !req.steady && !req.automatic && !req.torus ? PETSC_FALSE : PETSC_TRUE;

  // Read every component's options up front (cheap) so that a typo is caught before hours of work:
  // first without building anything (a CalculiX import and its reduction take minutes), then for
  // real, with the PETSc objects' own options.
  if (!help) {
    Pipeline dry(comm);
    PetscCall(dry.CheckOptions(req));
    PetscCall(CheckUnknownSquealOptions(comm));
  }
  Pipeline    pl(comm);
  Model      &model = pl.model;
  pl.expand_results = true;
  std::string export_dir;
  bool        reduced = false;
  PetscCall(pl.BuildModel(&export_dir));
  PetscCall(pl.Reduce(&reduced));
  PetscCall(pl.SetFromOptions(req));
  if (help) PetscFunctionReturn(0);
  PetscCall(CheckUnusedOptions(comm, true));

  PetscCall(model.View(PETSC_VIEWER_STDOUT_(comm)));
  if (!export_dir.empty()) {
    PetscCall(model.Export(export_dir.c_str(), "bin"));
    PetscCall(PetscPrintf(comm, "model written to %s/ (M.bin, K.bin, C.bin, F.bin, contacts.txt)\n", export_dir.c_str()));
  }
  PetscMPIInt size, rank;
  PetscCallMPI(MPI_Comm_size(comm, &size));
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  // A reduced model is dense (every interface DOF couples to every other): a few thousand DOFs
  // whose distributed products, eigensolves and flows cost more in messages than they save (the
  // 542-DOF pad's pipeline: 72 s on one rank, 119 s on two). The reduction itself splits well, so
  // after it the model goes to rank 0 and the analyses run there; the other ranks wait. The sweep
  // and the continuation spread their points over the ranks themselves, so they keep every rank;
  // so does shooting alone (above).
  if (size > 1 && !gather && reduced && !req.sweep && !req.continuation)
    PetscCall(PetscPrintf(comm, "the reduced model (%" PetscInt_FMT " DOFs, dense) is analysed on all %d ranks (-reduce_gather 1 gathers it on rank 0)\n",
                          model.Size(), size));
  if (size > 1 && gather && reduced && !req.sweep && !req.continuation) {
    Pipeline p0(PETSC_COMM_SELF);
    PetscCall(ModelGatherToRankZero(model, p0.model));
    // What the reduction left for the analyses besides the model: without it the guard
    // (-stab_guard_fmax's default, the reduction's top mode) was silently off on several ranks.
    p0.reduction_top_hz = pl.reduction_top_hz;
    PetscCall(PetscPrintf(comm, "the reduced model (%" PetscInt_FMT " DOFs, dense) is analysed on rank 0 alone: split over %d ranks it costs more "
                                "than it saves (-reduce_gather 0 splits it)\n",
                          model.Size(), size));
    PetscErrorCode err = 0;
    if (rank == 0) {
      err = p0.SetFromOptions(req);
      if (!err) err = RunAnalyses(p0, req, output, st);
    }
    // Rank 0 has printed the error; the others only share the exit status.
    PetscCallMPI(MPI_Bcast(&err, 1, MPI_INT, 0, comm));
    if (err) PetscFunctionReturn(err);
  } else PetscCall(RunAnalyses(pl, req, output, st));
  PetscCall(CheckUnusedOptions(comm, false));
  PetscFunctionReturn(0);
}

} // namespace squeal
