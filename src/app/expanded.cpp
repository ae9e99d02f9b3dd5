#include "squeal/app/expanded.h"
#include "squeal/core/gather.h"

#include <algorithm>

namespace squeal {

namespace {
// The writers' sizes come from rank 0 (the only rank holding records and orbits), so that every
// rank creates the same datasets.
PetscErrorCode SizeFromRankZero(MPI_Comm comm, size_t local, hsize_t *n)
{
  PetscFunctionBeginUser;
  *n = local;
  PetscCallMPI(MPI_Bcast(n, 1, MPI_UNSIGNED_LONG_LONG, 0, comm));
  PetscFunctionReturn(0);
}
} // namespace

PetscErrorCode WriteExpandedModes(const Model &model, const StabilityResult &res, io::H5Writer &out)
{
  const Expansion *x = model.expansion.get();
  PetscFunctionBeginUser;
  if (!x || res.unstable.empty() || !res.modes[res.unstable[0]].phi_re) PetscFunctionReturn(0);
  const size_t           k = res.unstable.size(), n = (size_t)x->n;
  std::vector<PetscReal> re(n * k), im(n * k), col, ure, uim;
  for (size_t j = 0; j < k; ++j) {
    const Mode &m = res.modes[res.unstable[j]];
    PetscCall(GatherVector(m.phi_re, false, col));
    for (size_t i = 0; i < col.size(); ++i) re[i * k + j] = col[i];
    PetscCall(GatherVector(m.phi_im, false, col));
    for (size_t i = 0; i < col.size(); ++i) im[i * k + j] = col[i];
  }
  PetscCallCXX(x->ApplyColumns(re.data(), k, ure));
  PetscCallCXX(x->ApplyColumns(im.data(), k, uim));
  const hsize_t N = (hsize_t)x->full_size;
  PetscCall(out.WriteArray("/expanded/modes/re", {N, (hsize_t)k}, ure.data()));
  PetscCall(out.WriteArray("/expanded/modes/im", {N, (hsize_t)k}, uim.data()));
  PetscCall(out.WriteIntArray("/expanded/modes/index", {(hsize_t)k}, res.unstable.data()));
  PetscCall(out.WriteAttribute("/expanded/modes", "layout", "[full DOF][unstable mode], the columns /expanded/modes/index of /stability/modes"));
  PetscFunctionReturn(0);
}

namespace {
// `count` rows of n reduced values (rank 0) expanded and written as GROUP/t and GROUP/U, with the
// rows' meaning in GROUP's "layout"; every rank calls with the same count.
PetscErrorCode WriteExpandedRows(const Expansion &x, const char *group, const PetscReal *t, const PetscReal *Q, size_t have, hsize_t count,
                                 const char *layout, io::H5Writer &out)
{
  std::vector<PetscReal> U;
  const std::string      g = group;
  PetscFunctionBeginUser;
  if (have == count) PetscCallCXX(x.Apply(Q, count, U));
  else U.assign(count * (size_t)x.full_size, 0.0); // not rank 0: nothing is read there
  std::vector<PetscReal> tz;
  if (!t) tz.assign(count, 0.0), t = tz.data();
  PetscCall(out.WriteArray((g + "/t").c_str(), {count}, t));
  PetscCall(out.WriteArray((g + "/U").c_str(), {count, (hsize_t)x.full_size}, U.data()));
  PetscCall(out.WriteAttribute(group, "layout", layout));
  PetscFunctionReturn(0);
}
} // namespace

PetscErrorCode WriteExpandedOrbit(const Model &model, const ShootingResult &res, io::H5Writer &out)
{
  const Expansion *x = model.expansion.get();
  hsize_t          s;
  PetscFunctionBeginUser;
  if (!x) PetscFunctionReturn(0);
  PetscCall(SizeFromRankZero(out.Comm(), res.orbit_t.size(), &s));
  if (!s) PetscFunctionReturn(0);
  PetscCall(WriteExpandedRows(*x, "/expanded/orbit", res.orbit_t.data(), res.orbit_U.data(), res.orbit_U.size() / (size_t)x->n, s,
                              "[sample][full DOF], one period of /shooting/orbit", out));
  // The cycle's start (U, dU) on the full model, /shooting/Z0 expanded: the full model's transient
  // starts there with -transient_start (the check of a reduced cycle against the full model).
  std::vector<PetscReal> Z;
  if (res.Z0.size() == 2 * (size_t)x->n) PetscCallCXX(x->Apply(res.Z0.data(), 2, Z));
  else Z.assign(2 * (size_t)x->full_size, 0.0); // not rank 0: nothing is read there
  PetscCall(out.WriteArray("/expanded/Z0", {2 * (hsize_t)x->full_size}, Z.data()));
  PetscCall(out.WriteAttribute("/expanded/Z0", "layout", "(U, dU) on the full model's DOFs: /shooting/Z0 expanded"));
  PetscFunctionReturn(0);
}

PetscErrorCode WriteExpandedRecords(const Model &model, const TransientResult &res, io::H5Writer &out)
{
  const Expansion *x = model.expansion.get();
  hsize_t          s;
  PetscFunctionBeginUser;
  if (!x || x->records <= 0 || res.N != x->n) PetscFunctionReturn(0);
  // Streamed records keep the last state only (TransientResult::streamed).
  PetscCall(SizeFromRankZero(out.Comm(), res.N ? res.U.size() / (size_t)res.N : 0, &s));
  if (!s) PetscFunctionReturn(0);
  const hsize_t keep = std::min<hsize_t>(s, (hsize_t)x->records), first = s - keep;
  const size_t  have = res.U.size() / (size_t)x->n == s ? keep : 0;
  PetscCall(WriteExpandedRows(*x, "/expanded/transient", res.t.size() >= keep ? res.t.data() + (res.t.size() - keep) : nullptr,
                              have ? res.U.data() + first * (size_t)x->n : nullptr, have, keep,
                              "[record][full DOF], the last records of /transient/U (-reduce_expand_records)", out));
  PetscCall(out.WriteAttribute("/expanded/transient", "first_record", (PetscInt)first));
  PetscFunctionReturn(0);
}

PetscErrorCode WriteExpandedEnd(const Model &model, const std::vector<PetscReal> &U, const std::vector<PetscReal> &dU, io::H5Writer &out)
{
  const Expansion *x = model.expansion.get();
  PetscFunctionBeginUser;
  if (!x || U.size() != (size_t)x->n || dU.size() != U.size()) PetscFunctionReturn(0);
  std::vector<PetscReal> q(U), Z;
  PetscCallCXX(q.insert(q.end(), dU.begin(), dU.end()));
  if (!x->E.empty()) PetscCallCXX(x->Apply(q.data(), 2, Z));
  else Z.assign(2 * (size_t)x->full_size, 0.0); // not rank 0: nothing is read there
  PetscCall(out.WriteArray("/expanded/Z_end", {2 * (hsize_t)x->full_size}, Z.data()));
  PetscCall(out.WriteAttribute("/expanded/Z_end", "layout", "(U, dU) on the full model's DOFs: /steady_state/Z_end expanded"));
  PetscFunctionReturn(0);
}

} // namespace squeal
