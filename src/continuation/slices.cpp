// -cont_slices: the parameter range cut into slices, each continued by a group of ranks from
// its own start (Continuation::SetBranchStarter), the points merged into one branch.
#include "squeal/continuation/continuation.h"
#include "squeal/core/interrupt.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

namespace squeal {

namespace {
const char *const kEventTypes[] = {"lift-off", "separation-ends", "stick", "stick-ends", "fold", "period-doubling", "neimark-sacker",
                                   "cyclic-fold", "monodromy-jump", "hopf", "coexistence"};
constexpr int     kNEventTypes  = sizeof(kEventTypes) / sizeof(kEventTypes[0]);

void PackPoint(const ContinuationPoint &p, std::vector<PetscReal> &b)
{
  b.insert(b.end(), {p.param, p.period, p.amplitude, p.frac_separated, p.frac_stuck, (PetscReal)p.trivial, (PetscReal)p.stable_cycle,
                     (PetscReal)p.equilibrium_unstable, p.max_growth, (PetscReal)p.newton_iterations, (PetscReal)p.flow_evaluations, p.ds,
                     p.seconds, (PetscReal)p.leg, (PetscReal)p.slice, (PetscReal)p.peak_to_peak.size(), (PetscReal)p.floquet.size()});
  b.insert(b.end(), p.peak_to_peak.begin(), p.peak_to_peak.end());
  for (auto &z : p.floquet) b.insert(b.end(), {z.real(), z.imag()});
}

size_t UnpackPoint(const PetscReal *b, ContinuationPoint &p)
{
  size_t k = 0;
  p.param = b[k++], p.period = b[k++], p.amplitude = b[k++], p.frac_separated = b[k++], p.frac_stuck = b[k++];
  p.trivial = (PetscInt)b[k++], p.stable_cycle = b[k++] != 0, p.equilibrium_unstable = (PetscInt)b[k++], p.max_growth = b[k++];
  p.newton_iterations = (PetscInt)b[k++], p.flow_evaluations = (PetscInt)b[k++], p.ds = b[k++], p.seconds = b[k++];
  p.leg = (PetscInt)b[k++], p.slice = (PetscInt)b[k++];
  const size_t npp = (size_t)b[k++], nfl = (size_t)b[k++];
  p.peak_to_peak.assign(b + k, b + k + npp), k += npp;
  p.floquet.clear();
  for (size_t j = 0; j < nfl; ++j, k += 2) p.floquet.emplace_back(b[k], b[k + 1]);
  return k;
}
} // namespace

PetscErrorCode Continuation::RunSlices(ContinuationResult &res)
{
  PetscMPIInt rank, size, srank;
  MPI_Comm    sub;
  PetscFunctionBeginUser;
  PetscCheck(starter_, comm_, PETSC_ERR_ORDER, "continuation: -cont_slices %" PetscInt_FMT " needs a branch starter (SetBranchStarter; the pipeline sets one)",
             slices);
  PetscCallMPI(MPI_Comm_rank(comm_, &rank));
  PetscCallMPI(MPI_Comm_size(comm_, &size));
  const PetscInt groups = std::min<PetscInt>(slices, size), group = (PetscInt)rank * groups / size;
  PetscCallMPI(MPI_Comm_split(comm_, (int)group, rank, &sub));
  PetscCallMPI(MPI_Comm_rank(sub, &srank));
  // Numbers only cross ranks: every point, and the located events as (type, param, lo, hi).
  std::vector<PetscReal> buf;
  PetscInt               halv = 0, flows = 0, stopped = 0;
  std::string            ends;
  for (PetscInt s = group; s < slices; s += groups) {
    const PetscReal a = lmin + (lmax - lmin) * s / slices, b = s + 1 == slices ? lmax : lmin + (lmax - lmin) * (s + 1) / slices;
    ContinuationResult r;
    PetscCall(starter_(sub, param, b, [&](BranchStart &st) -> PetscErrorCode {
      PetscFunctionBeginUser;
      Continuation c(sub);
      PetscCall(c.SetFromOptions()); // the corrector's KSP (-cont_ksp_*); the settings are this object's
      c.param = param, c.lmin = a, c.lmax = b, c.ds = ds, c.ds_min = ds_min, c.ds_max = ds_max, c.locate_tol = locate_tol;
      c.jump_tol = jump_tol, c.min_amplitude = min_amplitude, c.max_steps = max_steps, c.max_it = max_it, c.monitor = monitor;
      c.equilibrium = equilibrium, c.both = PETSC_TRUE, c.down_only_ = true, c.slices = 1;
      PetscCall(c.Run(st.model, st.eqs, st.stab, st.theta, st.shooting, st.cycle, r));
      PetscFunctionReturn(0);
    }));
    if (srank == 0) {
      for (auto &p : r.points) {
        ContinuationPoint q = p;
        q.slice             = s;
        buf.push_back(1);
        PackPoint(q, buf);
      }
      for (auto &e : r.events) {
        const int t = (int)(std::find_if(kEventTypes, kEventTypes + kNEventTypes, [&](const char *x) { return e.type == x; }) - kEventTypes);
        if (t < kNEventTypes) buf.insert(buf.end(), {2, (PetscReal)t, e.param, e.lo, e.hi});
      }
      halv += r.halvings, flows += r.flow_evaluations, stopped |= r.interrupted;
      char line[64];
      std::snprintf(line, sizeof line, "slice %" PetscInt_FMT " [%g, %g]: ", s, (double)a, (double)b);
      for (auto &e : r.leg_end) ends += "; " + std::string(line) + e;
    }
    PetscCall(PetscPrintf(sub, "cont: slice %" PetscInt_FMT " [%g, %g] (rank group %" PetscInt_FMT "): %zu point(s)\n", s, (double)a, (double)b,
                          group, r.points.size()));
    PetscCall(InterruptRequested(sub, &interrupted_));
    if (interrupted_) break;
  }
  // Leg-end texts travel as characters after the numbers.
  for (char ch : ends) buf.insert(buf.end(), {3, (PetscReal)(unsigned char)ch});
  int n = (int)buf.size();
  std::vector<int> counts(size), displs(size, 0);
  PetscCallMPI(MPI_Allgather(&n, 1, MPI_INT, counts.data(), 1, MPI_INT, comm_));
  for (int r = 1; r < size; ++r) displs[r] = displs[r - 1] + counts[r - 1];
  std::vector<PetscReal> all(displs[size - 1] + counts[size - 1]);
  PetscCallMPI(MPI_Allgatherv(buf.data(), n, MPIU_REAL, all.data(), counts.data(), displs.data(), MPIU_REAL, comm_));
  PetscInt tot[3] = {halv, flows, stopped};
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, tot, 3, MPIU_INT, MPI_SUM, comm_));
  std::vector<ContinuationEvent> located;
  std::vector<std::string>       legs;
  std::string                    cur;
  for (size_t k = 0; k < all.size();) {
    const int tag = (int)all[k++];
    if (tag == 1) {
      ContinuationPoint p;
      k += UnpackPoint(&all[k], p);
      res.points.push_back(p);
    } else if (tag == 2) {
      located.push_back({kEventTypes[(int)all[k]], 0, all[k + 1], all[k + 2], all[k + 3], ""});
      k += 4;
    } else {
      cur += (char)(int)all[k++];
    }
  }
  res.leg_end.push_back(cur.size() > 2 ? cur.substr(2) : cur);
  // One branch ordered in the parameter; a slice's lower end and the next slice's start are two
  // shooting solutions at the same parameter: the upper slice's one is kept.
  std::stable_sort(res.points.begin(), res.points.end(), [](const ContinuationPoint &x, const ContinuationPoint &y) {
    return x.param < y.param || (x.param == y.param && x.slice > y.slice);
  });
  res.points.erase(std::unique(res.points.begin(), res.points.end(),
                               [](const ContinuationPoint &x, const ContinuationPoint &y) { return x.param == y.param; }),
                   res.points.end());
  // Events between neighbours of the merged branch, the slices' located ones put in their place.
  const PetscReal tol = locate_tol;
  locate_tol          = 0;
  states_.clear();
  PetscCall(Detect(res));
  locate_tol = tol;
  for (auto &e : res.events)
    for (auto &l : located)
      if (l.type == e.type && l.lo >= e.lo - 1e-12 && l.hi <= e.hi + 1e-12) e.param = l.param, e.lo = l.lo, e.hi = l.hi;
  res.param_name       = param;
  res.range_lo         = lmin;
  res.range_hi         = lmax;
  res.halvings         = tot[0];
  res.flow_evaluations = tot[1];
  res.interrupted      = tot[2] > 0;
  interrupted_         = res.interrupted;
  PetscCallMPI(MPI_Comm_free(&sub));
  PetscFunctionReturn(0);
}

} // namespace squeal
