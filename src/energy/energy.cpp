#include "squeal/energy/energy.h"
#include "squeal/core/inf.h"
#include "squeal/core/interrupt.h"
#include "squeal/core/errors.h"
#include "squeal/core/options.h"

#include <cmath>

namespace squeal {

PetscErrorCode EnergyAnalysis::SetFromOptions()
{
  OptionChecks checks;
  PetscFunctionBeginUser;
  PetscOptionsBegin(comm_, "energy_", "Energy estimate of the limit-cycle amplitude", "EnergyAnalysis");
  PetscCall(PetscOptionsInt("-mode", "Mode to estimate (index in the eigenvalue table; -1: most unstable)", "EnergyAnalysis",
                            mode, &mode, nullptr));
  PetscCall(PetscOptionsInt("-n_scan", "Points of the amplitude scan", "EnergyAnalysis", n_scan, &n_scan, nullptr));
  PetscCall(PetscOptionsInt("-samples", "Time samples per period for the mean powers", "EnergyAnalysis", samples, &samples, nullptr));
  PetscCall(PetscOptionsInt("-bisections", "Bisection halvings after the scan", "EnergyAnalysis", bisections, &bisections, nullptr));
  SquealOptionsReal("-q_max_factor", "Scan up to this multiple of the first lift-off amplitude", "EnergyAnalysis", &q_max_factor,
                    Range::Positive(), checks);
  PetscCall(PetscOptionsInt("-extend", "Doublings of the scan range when it holds no balance", "EnergyAnalysis", extend, &extend,
                            nullptr));
  PetscCall(PetscOptionsBool("-all_modes", "Estimate every unstable mode (one line each), not only the chosen one",
                             "EnergyAnalysis", all_modes, &all_modes, nullptr));
  PetscOptionsEnd();
  PetscCall(checks.Run(comm_));
  // -7 ran as -1 (the most unstable mode) without a word.
  PetscCheck(mode >= -1, comm_, kErrInput, "option -energy_mode = %" PetscInt_FMT ": expected a mode index >= 0, or -1 for the most unstable mode",
             mode);
  PetscCheck(n_scan >= 2 && samples >= 8 && bisections >= 0 && extend >= 0, comm_, kErrInput,
             "energy: need -energy_n_scan >= 2, -energy_samples >= 8, -energy_bisections >= 0, -energy_extend >= 0");
  PetscFunctionReturn(0);
}

PetscReal EnergyAnalysis::Reactions(PetscReal q) const
{
  const ContactSet &cs          = *cs_;
  const bool        rectilinear = cs.law == FrictionLaw::Rectilinear;
  const size_t      ns          = cos_.size();
  PetscReal         sum         = 0;
  // Points outside, samples inside: the point's coefficients stay in registers and the inner loop
  // is plain arithmetic (sqrt, not hypot: the velocities are far from overflow). The scan calls
  // this n_scan + bisections times, samples x points each: 4e8 evaluations for 52 points.
  for (size_t p = 0; p < N_.size(); ++p) {
    const PetscReal pr = q * psi_[p].real(), pi = q * psi_[p].imag(), Np = N_[p], V = speed_[p];
    const PetscReal tr = -q * omega_ * phit_[p].real(), ti = -q * omega_ * phit_[p].imag();
    const PetscReal br = -q * omega_ * phib_[p].real(), bi = -q * omega_ * phib_[p].imag();
    PetscReal       acc = 0;
    for (size_t k = 0; k < ns; ++k) {
      // Re(z e^{i w t}) = Re z cos - Im z sin; velocity Re(i w z e^{i w t}) = -w (Re z sin + Im z cos).
      const PetscReal c = cos_[k], s = sin_[k];
      const PetscReal rn = Np + (pr * c - pi * s);
      if (rn <= 0) continue;
      const PetscReal ut = tr * s + ti * c, ub = br * s + bi * c;
      const PetscReal st = V - ut; // surface velocity relative to the structure
      if (rectilinear) acc += rn * (st > 0 ? 1.0 : (st < 0 ? -1.0 : 0.0)) * ut;
      else {
        const PetscReal m2 = st * st + ub * ub;
        if (m2 > 0) acc += rn * (st * ut - ub * ub) / std::sqrt(m2);
      }
    }
    sum += acc;
  }
  return cs.Mu() * sum / ns;
}

PetscErrorCode EnergyAnalysis::Scan(PetscReal factor, EnergyEstimate &est, bool *found) const
{
  PetscFunctionBeginUser;
  *found = false;
  const PetscReal q_max = factor * est.q_sep;
  // A signal is seen every ~1e7 contact evaluations (0.1 s or less): a fine scan of the reduced
  // small pad (-energy_n_scan 40000) ran 83 s deaf. Counted, not timed, so every rank polls at
  // the same point.
  const PetscInt poll_every = PetscMax((PetscInt)1, (PetscInt)(1e7 / PetscMax((double)(cos_.size() * N_.size()), 1.0)));
  est.q.resize(n_scan);
  est.P_damping.resize(n_scan);
  est.P_reactions.resize(n_scan);
  PetscInt crossing = -1;
  for (PetscInt k = 0; k < n_scan; ++k) {
    if (k % poll_every == 0) PetscCall(InterruptPoint(comm_, "the energy scan"));
    const PetscReal q  = (k + 1) * q_max / n_scan;
    est.q[k]           = q;
    est.P_damping[k]   = 0.5 * q * q * omega_ * omega_ * cphi_;
    est.P_reactions[k] = Reactions(q);
    if (crossing < 0 && k > 0 && est.P_reactions[k - 1] - est.P_damping[k - 1] > 0 && est.P_reactions[k] - est.P_damping[k] <= 0)
      crossing = k - 1;
    if (crossing >= 0 && !full_scan) {
      est.q.resize(k + 1), est.P_damping.resize(k + 1), est.P_reactions.resize(k + 1);
      break;
    }
  }
  // Already saturated at the first scan point (a fine structure of f below q_max / n_scan): the
  // balance lies in (0, q_1]; f > 0 near 0 for an unstable mode, so bisect there.
  PetscReal lo = 0, hi = 0;
  if (crossing >= 0) lo = est.q[crossing], hi = est.q[crossing + 1];
  else if (est.P_reactions[0] - est.P_damping[0] <= 0 && PowerBalance(1e-6 * est.q[0]) > 0) {
    lo = 1e-6 * est.q[0], hi = est.q[0];
    crossing = 0;
  }
  if (crossing < 0) PetscFunctionReturn(0);
  for (PetscInt i = 0; i < bisections; ++i) {
    const PetscReal mid = 0.5 * (lo + hi);
    (PowerBalance(mid) > 0 ? lo : hi) = mid;
  }
  est.q0 = 0.5 * (lo + hi);
  *found = true;
  PetscFunctionReturn(0);
}

PetscReal EnergyAnalysis::PowerBalance(PetscReal q) const { return Reactions(q) - 0.5 * q * q * omega_ * omega_ * cphi_; }

PetscErrorCode EnergyAnalysis::Estimate(const Model &model, const SlidingEquilibrium &eq, const StabilityResult &stab,
                                        EnergyEstimate &est)
{
  const ContactSet &cs = model.contacts;
  PetscFunctionBeginUser;
  est       = EnergyEstimate{};
  est.mode  = mode >= 0 ? mode : (stab.unstable.empty() ? -1 : stab.unstable[0]);
  if (est.mode < 0) PetscFunctionReturn(0);
  PetscCheck(est.mode < (PetscInt)stab.modes.size() && stab.modes[est.mode].Oscillatory(), comm_, kErrInput,
             "energy: mode %" PetscInt_FMT " is not an oscillatory mode of the eigenvalue table", est.mode);
  const Mode &m = stab.modes[est.mode];
  PetscCheck(m.phi_re, comm_, kErrInput, "energy: mode shapes are needed (-stab_modes)");
  est.omega = omega_ = m.omega;
  est.sigma          = m.sigma;
  est.T0             = 2 * PETSC_PI / m.omega;
  cs_                = &cs;

  // phi^H C phi and (-omega^2 M + i omega C + K) phi, split in real and imaginary parts.
  VecH a, b, t1;
  PetscCall(VecDuplicate(m.phi_re, a.out()));
  PetscCall(VecDuplicate(m.phi_re, b.out()));
  PetscCall(VecDuplicate(m.phi_re, t1.out()));
  cphi_ = 0;
  PetscCall(MatMult(model.K, m.phi_re, a));
  PetscCall(MatMult(model.M, m.phi_re, t1));
  PetscCall(VecAXPY(a, -m.omega * m.omega, t1));
  PetscCall(MatMult(model.K, m.phi_im, b));
  PetscCall(MatMult(model.M, m.phi_im, t1));
  PetscCall(VecAXPY(b, -m.omega * m.omega, t1));
  if (model.HasDamping()) {
    PetscScalar d1, d2;
    PetscCall(MatMult(model.C, m.phi_im, t1));
    PetscCall(VecDot(m.phi_im, t1, &d2));
    PetscCall(VecAXPY(a, -m.omega, t1));
    PetscCall(MatMult(model.C, m.phi_re, t1));
    PetscCall(VecDot(m.phi_re, t1, &d1));
    PetscCall(VecAXPY(b, m.omega, t1));
    cphi_ = PetscRealPart(d1 + d2);
  }
  std::vector<PetscReal> la, lb, pr, pi;
  PetscCall(cs.LocalComponents(a, la));
  PetscCall(cs.LocalComponents(b, lb));
  PetscCall(cs.LocalComponents(m.phi_re, pr));
  PetscCall(cs.LocalComponents(m.phi_im, pi));
  N_.clear();
  psi_.clear();
  phit_.clear();
  phib_.clear();
  speed_.clear();
  est.q_sep = kInf;
  for (PetscInt c : eq.active) {
    PetscReal D = 0; // h_n^T h_n (H_n^T H_n is diagonal: ContactSet::Validate)
    cs.ForEachEntry(c, kN, [&](PetscInt, PetscReal v) { D += v * v; });
    N_.push_back(eq.N[c]);
    psi_.emplace_back(la[3 * c + kN] / D, lb[3 * c + kN] / D);
    phit_.emplace_back(pr[3 * c + kT], pi[3 * c + kT]);
    phib_.emplace_back(pr[3 * c + kB], pi[3 * c + kB]);
    speed_.push_back(cs.Speed(c));
    if (std::abs(psi_.back()) > 0) est.q_sep = std::min(est.q_sep, eq.N[c] / std::abs(psi_.back()));
  }
  // Without normal reaction fluctuations lift-off never bounds the scan: use the amplitude at
  // which the tangential velocity reaches the surface speed (the stick side saturation).
  if (!std::isfinite(est.q_sep)) {
    PetscReal best = kInf;
    for (size_t p = 0; p < phit_.size(); ++p)
      if (std::abs(phit_[p]) > 0) best = std::min(best, cs.Speed(eq.active[p]) / (m.omega * std::abs(phit_[p])));
    est.q_sep = std::isfinite(best) ? best : 1.0;
  }
  cos_.resize(samples);
  sin_.resize(samples);
  for (PetscInt k = 0; k < samples; ++k) {
    cos_[k] = std::cos(2 * PETSC_PI * k / samples);
    sin_[k] = std::sin(2 * PETSC_PI * k / samples);
  }

  est.found = false;
  for (est.extensions = 0; est.extensions <= extend; ++est.extensions) {
    est.q_max_factor = q_max_factor * std::ldexp(1.0, (int)est.extensions);
    PetscCall(Scan(est.q_max_factor, est, &est.found));
    if (est.found) break;
  }
  if (!est.found) est.extensions = extend;
  if (est.found) {
    // (7.5): the phase puts the normalising component at its maximum, on the surface (phi_n = 0).
    PetscCall(VecDuplicate(eq.U, est.U0.out()));
    PetscCall(VecWAXPY(est.U0, est.q0, m.phi_re, eq.U));
    PetscCall(VecDuplicate(eq.U, est.dU0.out()));
    PetscCall(VecCopy(m.phi_im, est.dU0));
    PetscCall(VecScale(est.dU0, -est.q0 * m.omega));
  }
  PetscFunctionReturn(0);
}

PetscErrorCode EnergyAnalysis::View(const EnergyEstimate &est, PetscViewer viewer) const
{
  PetscBool ascii;
  PetscFunctionBeginUser;
  PetscCall(PetscObjectTypeCompare((PetscObject)viewer, PETSCVIEWERASCII, &ascii));
  if (!ascii) PetscFunctionReturn(0);
  if (est.mode < 0) {
    PetscCall(PetscViewerASCIIPrintf(viewer, "energy estimate: no unstable mode in the band: nothing to estimate\n"));
    PetscFunctionReturn(0);
  }
  PetscCall(PetscViewerASCIIPrintf(viewer, "energy estimate for mode %" PetscInt_FMT " (f = %.4f Hz, sigma = %.4f 1/s):\n", est.mode,
                                   (double)(est.omega / (2 * PETSC_PI)), (double)est.sigma));
  PetscCall(PetscViewerASCIIPushTab(viewer));
  PetscCall(PetscViewerASCIIPrintf(viewer, "first lift-off amplitude q_sep = %.6e, scan up to %.4g q_sep\n", (double)est.q_sep,
                                   (double)est.q_max_factor));
  if (est.extensions > 0 && est.found)
    PetscCall(PetscViewerASCIIPrintf(viewer, "no balance up to %.4g q_sep (-energy_q_max_factor): range doubled %" PetscInt_FMT " time(s)\n",
                                     (double)q_max_factor, est.extensions));
  if (est.found)
    PetscCall(PetscViewerASCIIPrintf(viewer, "power balance at q0 = %.6e (%.3f q_sep); shooting guess T0 = %.7f s\n", (double)est.q0,
                                     (double)(est.q0 / est.q_sep), (double)est.T0));
  else
    PetscCall(PetscViewerASCIIPrintf(viewer,
                                     "no balance up to %.4g q_sep (%" PetscInt_FMT " doubling(s) of -energy_q_max_factor %g): reaction power "
                                     "never falls below damping power; raise -energy_q_max_factor above %.4g or -energy_extend\n",
                                     (double)est.q_max_factor, est.extensions, (double)q_max_factor, (double)est.q_max_factor));
  PetscCall(PetscViewerASCIIPopTab(viewer));
  PetscFunctionReturn(0);
}

PetscErrorCode EnergyAnalysis::Write(const EnergyEstimate &est, io::H5Writer &out) const
{
  PetscFunctionBeginUser;
  if (est.mode < 0) {
    PetscCall(out.WriteAttribute("/energy", "stable", (PetscInt)1));
    PetscFunctionReturn(0);
  }
  const hsize_t n = est.q.size();
  PetscCall(out.WriteArray("/energy/q", {n}, est.q.data()));
  PetscCall(out.WriteArray("/energy/P_damping", {n}, est.P_damping.data()));
  PetscCall(out.WriteArray("/energy/P_reactions", {n}, est.P_reactions.data()));
  PetscCall(out.WriteAttribute("/energy/P_damping", "units", "W"));
  PetscCall(out.WriteAttribute("/energy/P_reactions", "units", "W"));
  PetscCall(out.WriteAttribute("/energy/q", "units", "m (modal amplitude, largest tangential contact component of phi = 1)"));
  PetscCall(out.WriteAttribute("/energy", "mode", est.mode));
  PetscCall(out.WriteAttribute("/energy", "q_sep", est.q_sep));
  PetscCall(out.WriteAttribute("/energy", "T0", est.T0));
  PetscCall(out.WriteAttribute("/energy", "found", (PetscInt)est.found));
  PetscCall(out.WriteAttribute("/energy", "q_max_factor", est.q_max_factor));
  PetscCall(out.WriteAttribute("/energy", "extensions", est.extensions));
  if (est.found) {
    PetscCall(out.WriteAttribute("/energy", "q0", est.q0));
    Vec  parts[2] = {est.U0, est.dU0};
    PetscInt n0;
    PetscCall(VecGetSize(est.U0, &n0));
    // Z0 = (U0, dU0) as one 2N dataset, gathered like the other arrays.
    std::vector<PetscReal> z;
    for (Vec v : parts) {
      VecScatter         sc;
      Vec                all;
      const PetscScalar *a;
      PetscCall(VecScatterCreateToZero(v, &sc, &all));
      PetscCall(VecScatterBegin(sc, v, all, INSERT_VALUES, SCATTER_FORWARD));
      PetscCall(VecScatterEnd(sc, v, all, INSERT_VALUES, SCATTER_FORWARD));
      PetscInt nl;
      PetscCall(VecGetLocalSize(all, &nl));
      PetscCall(VecGetArrayRead(all, &a));
      for (PetscInt i = 0; i < nl; ++i) z.push_back(PetscRealPart(a[i]));
      PetscCall(VecRestoreArrayRead(all, &a));
      PetscCall(VecDestroy(&all));
      PetscCall(VecScatterDestroy(&sc));
    }
    PetscCall(out.WriteArray("/energy/Z0", {(hsize_t)(2 * n0)}, z.data()));
    PetscCall(out.WriteAttribute("/energy/Z0", "layout", "(U, dU)"));
  }
  PetscFunctionReturn(0);
}

} // namespace squeal
