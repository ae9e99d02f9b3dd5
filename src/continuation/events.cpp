// Events between neighbouring points of a branch (regime changes, folds, cycle and equilibrium
// stability changes, monodromy jumps), and the location of regime changes by bisection.
#include "squeal/continuation/continuation.h"
#include "squeal/core/interrupt.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

namespace squeal {

namespace {
bool Separates(const ContinuationPoint &p) { return p.frac_separated > 0; }
bool Sticks(const ContinuationPoint &p) { return p.frac_stuck > 0; }
} // namespace

PetscErrorCode Continuation::Locate(ContinuationResult &res, ContinuationEvent &ev)
{
  const size_t i = (size_t)ev.point;
  PetscFunctionBeginUser;
  if (!(locate_tol > 0) || interrupted_) PetscFunctionReturn(0);
  const bool sep = ev.type == "lift-off" || ev.type == "separation-ends";
  auto       flag = [&](const ContinuationPoint &p) { return sep ? Separates(p) : Sticks(p); };
  const bool flo  = flag(res.points[i - 1]);
  PetscReal  lo = res.points[i - 1].param, hi = res.points[i].param;
  State      g, t, y, sol, slo, shi; // slo, shi: the solutions at the bracket ends
  PetscCall(Copy(states_[i - 1], g));
  PetscCall(Copy(states_[i - 1], t));
  PetscCall(Copy(states_[i - 1], slo));
  PetscCall(Copy(states_[i], shi));
  PetscCall(Create(y));
  PetscCall(VecZeroEntries(t.U));
  PetscCall(VecZeroEntries(t.dU));
  t.T = 0, t.lambda = sl_; // unit pure-parameter tangent: the corrector at fixed lambda
  for (int it = 0; it < 40 && std::abs(hi - lo) > locate_tol; ++it) {
    const PetscReal   mid = 0.5 * (lo + hi);
    ContinuationPoint pt;
    bool              ok;
    std::string       why;
    PetscCall(InterruptRequested(comm_, &interrupted_));
    if (interrupted_) break;
    // Shooting at the fixed parameter from the solution at the lower bracket end (exact tangents:
    // a few corrections, the parameter moving by half the bracket). Where it fails, the bordered
    // corrector from the straight line between the two bracket solutions.
    PetscCall(Copy(slo, g));
    g.lambda = mid;
    PetscCall(Polish(g, pt, &sol, &ok, why, false)); // only the contact's regime is looked at
    if (!ok) {
      why = "shooting from the lower end: " + why;
      std::string why2;
      PetscInt    its;
      PetscCall(Copy(slo, g));
      PetscCall(Axpby(g, 0.5, shi, 0.5));
      g.lambda = mid;
      PetscCall(Corrector(slo, g, t, y, &its, why2));
      if (interrupted_) {
        ev.detail += "; bisection stopped: " + why2;
        break;
      }
      ok = why2.empty();
      if (ok) PetscCall(Polish(y, pt, &sol, &ok, why2, false));
      if (!ok) why += "; corrector: " + why2;
    }
    if (!ok) {
      ev.detail += "; bisection stopped: " + why;
      break;
    }
    sol.lambda = mid;
    if (flag(pt) == flo) {
      lo = mid;
      PetscCall(Copy(sol, slo));
    } else {
      hi = mid;
      PetscCall(Copy(sol, shi));
    }
  }
  ev.lo = std::min(lo, hi), ev.hi = std::max(lo, hi), ev.param = 0.5 * (lo + hi);
  PetscFunctionReturn(0);
}

PetscErrorCode Continuation::Detect(ContinuationResult &res)
{
  auto &P = res.points;
  PetscFunctionBeginUser;
  res.events.clear();
  auto add = [&](const char *type, size_t i, PetscReal at, const std::string &detail) {
    res.events.push_back({type, (PetscInt)i, at, std::min(P[i - 1].param, P[i].param), std::max(P[i - 1].param, P[i].param), detail});
  };
  for (size_t i = 1; i < P.size(); ++i) {
    const auto &p = P[i - 1], &q = P[i];
    // Along the branch order (from the -cont_min end): appearing or vanishing separation / stick.
    if (Separates(p) != Separates(q)) add(Separates(q) ? "lift-off" : "separation-ends", i, 0.5 * (p.param + q.param), "");
    if (Sticks(p) != Sticks(q)) add(Sticks(q) ? "stick" : "stick-ends", i, 0.5 * (p.param + q.param), "");
    if (p.stable_cycle != q.stable_cycle) {
      const auto &u = p.stable_cycle ? q : p; // the unstable side names the crossing multiplier
      std::complex<PetscReal> m = 0;
      for (size_t k = 0; k < u.floquet.size(); ++k)
        if ((PetscInt)k != u.trivial && std::abs(u.floquet[k]) > std::abs(m)) m = u.floquet[k];
      const char *type = std::abs(m.imag()) > 1e-6 * std::abs(m) ? "neimark-sacker" : (m.real() < 0 ? "period-doubling" : "cyclic-fold");
      const PetscReal a = p.LargestNonTrivial() - 1, b = q.LargestNonTrivial() - 1;
      char            d[160];
      std::snprintf(d, sizeof d, "multiplier %.4f%+.4fi on the unstable side", m.real(), m.imag());
      add(type, i, a != b ? p.param + (q.param - p.param) * a / (a - b) : q.param, d);
    }
    if (p.floquet.size() == q.floquet.size() && p.trivial >= 0 && q.trivial >= 0) {
      std::vector<PetscReal> mp, mq;
      for (size_t k = 0; k < p.floquet.size(); ++k)
        if ((PetscInt)k != p.trivial) mp.push_back(std::abs(p.floquet[k]));
      for (size_t k = 0; k < q.floquet.size(); ++k)
        if ((PetscInt)k != q.trivial) mq.push_back(std::abs(q.floquet[k]));
      PetscReal jmp = 0;
      for (size_t k = 0; k < mp.size() && k < mq.size(); ++k) jmp = std::max(jmp, std::abs(mp[k] - mq[k]));
      if (jmp > jump_tol) {
        char d[96];
        std::snprintf(d, sizeof d, "a non-trivial |multiplier| changes by %.3f", (double)jmp);
        add("monodromy-jump", i, 0.5 * (p.param + q.param), d);
      }
    }
    if (p.equilibrium_unstable >= 0 && q.equilibrium_unstable >= 0 && (p.equilibrium_unstable == 0) != (q.equilibrium_unstable == 0)) {
      const PetscReal a = p.max_growth, b = q.max_growth;
      add("hopf", i, std::isfinite(a) && std::isfinite(b) && a != b ? p.param + (q.param - p.param) * a / (a - b) : q.param,
          "the sliding equilibrium changes stability (zero crossing of the growth rate)");
    }
  }
  for (size_t i = 1; i + 1 < P.size(); ++i)
    if ((P[i].param - P[i - 1].param) * (P[i + 1].param - P[i].param) < 0) {
      // Vertex of the parabola through the three points, in the point index.
      const PetscReal a = P[i - 1].param, b = P[i].param, c = P[i + 1].param, den = a - 2 * b + c;
      const PetscReal x = den != 0 ? 0.5 * (a - c) / den : 0;
      add("fold", i, b - 0.25 * (a - c) * x, P[i].param > P[i - 1].param ? "the parameter turns back (maximum)" : "the parameter turns back (minimum)");
    }
  // Coexistence of a stable cycle with a stable equilibrium: hysteresis.
  PetscReal clo = kInf, chi = -kInf;
  size_t    cfirst = 0;
  for (size_t i = 0; i < P.size(); ++i)
    if (P[i].stable_cycle && P[i].equilibrium_unstable == 0) {
      if (clo == kInf) cfirst = i;
      clo = std::min(clo, P[i].param), chi = std::max(chi, P[i].param);
    }
  if (clo <= chi)
    res.events.push_back({"coexistence", (PetscInt)std::max<size_t>(cfirst, 1), 0.5 * (clo + chi), clo, chi,
                          "stable cycle and stable sliding equilibrium at the same parameter (hysteresis range)"});
  for (auto &ev : res.events)
    if (ev.type == "lift-off" || ev.type == "separation-ends" || ev.type == "stick" || ev.type == "stick-ends") {
      // No bisection across a fold: the bracket is not an interval of one branch piece.
      bool fold = false;
      for (auto &f : res.events) fold = fold || (f.type == "fold" && (f.point == ev.point || f.point == ev.point - 1));
      if (!fold) PetscCall(Locate(res, ev));
    }
  PetscFunctionReturn(0);
}

} // namespace squeal
