#include "squeal/contact/contact_set.h"
#include "squeal/core/errors.h"
#include "squeal/core/sparse.h"

#include <cmath>
#include <algorithm>
#include <map>

namespace squeal {

const char *FrictionLawName(FrictionLaw law) { return law == FrictionLaw::Planar ? "planar" : "rectilinear"; }

bool ContactSet::HasExplicitColumns() const
{
  for (const ContactPoint &p : points)
    for (const ColumnEntries &col : p.cols)
      if (!col.empty()) return true;
  return false;
}

PetscErrorCode ContactSet::Validate(MPI_Comm comm, PetscInt N)
{
  std::map<PetscInt, PetscInt> owner; // DOF -> point using it
  PetscFunctionBeginUser;
  PetscCheck(!PetscIsInfOrNanReal(mu_) && mu_ >= 0, comm, kErrInput, "friction coefficient mu = %g: expected >= 0", (double)mu_);
  PetscCheck(!PetscIsInfOrNanReal(V_) && V_ > 0, comm, kErrInput, "sliding speed V = %g: expected > 0", (double)V_);
  for (PetscInt c = 0; c < Size(); ++c) {
    ContactPoint &p = points[c];
    PetscCheck(!p.nodes.empty() || !p.cols[kN].empty(), comm, kErrInput, "contact %" PetscInt_FMT " has no node and no normal column", c);
    for (const ContactNode &nd : p.nodes) {
      PetscCheck(!PetscIsInfOrNanReal(nd.weight) && nd.weight != 0, comm, kErrInput,
                 "contact %" PetscInt_FMT ": node weight %g must be finite and non-zero", c, (double)nd.weight);
      for (PetscInt d : nd.dofs) {
        PetscCheck(d >= 0 && d < N, comm, kErrInput,
                   "contact %" PetscInt_FMT ": DOF index %" PetscInt_FMT " out of range [0, %" PetscInt_FMT ")", c, d, N);
        auto it = owner.find(d);
        // One DOF twice in a row would make the x, y, z directions of the node dependent.
        PetscCheck(it == owner.end() || it->second != c, comm, kErrInput,
                   "contact %" PetscInt_FMT " uses DOF %" PetscInt_FMT " twice (the x y z DOFs of a contact row must be distinct)",
                   c, d);
        PetscCheck(it == owner.end(), comm, kErrInput,
                   "contacts %" PetscInt_FMT " and %" PetscInt_FMT " share DOF %" PetscInt_FMT
                   " (each DOF may belong to one contact point)", it == owner.end() ? c : it->second, c, d);
        owner[d] = c;
      }
    }
    for (int dir = 0; dir < 3; ++dir) {
      std::vector<PetscInt> seen;
      for (const auto &en : p.cols[dir]) {
        PetscCheck(en.first >= 0 && en.first < N, comm, kErrInput,
                   "contact %" PetscInt_FMT ": column %c entry at DOF %" PetscInt_FMT " out of range [0, %" PetscInt_FMT ")", c,
                   "tbn"[dir], en.first, N);
        PetscCheck(!PetscIsInfOrNanReal(en.second), comm, kErrInput,
                   "contact %" PetscInt_FMT ": column %c entry at DOF %" PetscInt_FMT " is not finite", c, "tbn"[dir], en.first);
        // The pivot choice and the energy estimate read raw entries: one entry per DOF and column.
        auto it = owner.find(en.first);
        PetscCheck(it == owner.end() || it->second != c, comm, kErrInput,
                   "contact %" PetscInt_FMT ": column %c has an explicit entry at DOF %" PetscInt_FMT
                   ", which its nodes already use; give the column either nodes or explicit entries there",
                   c, "tbn"[dir], en.first);
        seen.push_back(en.first);
      }
      std::sort(seen.begin(), seen.end());
      const auto twice = std::adjacent_find(seen.begin(), seen.end());
      PetscCheck(twice == seen.end(), comm, kErrInput,
                 "contact %" PetscInt_FMT ": column %c lists DOF %" PetscInt_FMT " twice; give each DOF one entry", c, "tbn"[dir],
                 twice == seen.end() ? -1 : *twice);
    }
    PetscCheck(p.t.allFinite() && p.n.allFinite(), comm, kErrInput, "contact %" PetscInt_FMT ": frame is not finite", c);
    // Accept frames written with a few digits; reject ones that are plainly wrong.
    PetscCheck(std::abs(p.t.norm() - 1) < 1e-6 && std::abs(p.n.norm() - 1) < 1e-6, comm, kErrInput,
               "contact %" PetscInt_FMT ": t and n must be unit vectors (|t| = %g, |n| = %g)", c, p.t.norm(), p.n.norm());
    PetscCheck(std::abs(p.t.dot(p.n)) < 1e-6, comm, kErrInput,
               "contact %" PetscInt_FMT ": t and n must be orthogonal (t.n = %g)", c, p.t.dot(p.n));
    p.t.normalize();
    p.n = (p.n - p.n.dot(p.t) * p.t).normalized();
    p.b = p.n.cross(p.t);
    PetscCheck(!PetscIsInfOrNanReal(p.speed_factor) && p.speed_factor > 0, comm, kErrInput,
               "contact %" PetscInt_FMT ": speed factor %g: expected > 0", c, (double)p.speed_factor);
    PetscCheck(!PetscIsInfOrNanReal(p.g0), comm, kErrInput, "contact %" PetscInt_FMT ": initial gap is not finite", c);
  }
  if (HasExplicitColumns()) {
    // Nodal points satisfy these by the checks above (distinct DOFs, orthogonal frames); with
    // explicit entries they are checked: the pivot elimination (Q, L of docs/method.md §4) and the
    // energy estimate's psi (§7) rely on them.
    std::map<PetscInt, std::pair<PetscInt, PetscReal>> normal; // DOF -> (point, value of its h_n there)
    std::vector<PetscReal>                             nn(Size(), 0.0);
    for (PetscInt c = 0; c < Size(); ++c) {
      std::map<PetscInt, PetscReal> col;
      ForEachEntry(c, kN, [&](PetscInt d, PetscReal v) { col[d] += v; });
      for (const auto &e : col) {
        if (e.second == 0) continue;
        auto it = normal.find(e.first);
        PetscCheck(it == normal.end() || it->second.first == c, comm, kErrInput,
                   "contacts %" PetscInt_FMT " and %" PetscInt_FMT " both have DOF %" PetscInt_FMT
                   " in their normal column h_n: the normal constraints must act on distinct DOFs",
                   it == normal.end() ? c : it->second.first, c, e.first);
        normal[e.first] = {c, e.second};
        nn[c] += e.second * e.second;
      }
      PetscCheck(nn[c] > 0, comm, kErrInput, "contact %" PetscInt_FMT ": the normal column h_n is zero", c);
    }
    for (PetscInt c = 0; c < Size(); ++c)
      for (int dir : {kT, kB}) {
        std::map<PetscInt, PetscReal> dots; // point of h_n -> h_n^T h_{dir,c}
        PetscReal                     hh = 0;
        std::map<PetscInt, PetscReal> col;
        ForEachEntry(c, dir, [&](PetscInt d, PetscReal v) { col[d] += v; });
        for (const auto &e : col) {
          hh += e.second * e.second;
          auto it = normal.find(e.first);
          if (it != normal.end()) dots[it->second.first] += it->second.second * e.second;
        }
        // A zero h_t (or h_b with planar friction) gives W_tt = 0 and an infinite rho in the local solver.
        PetscCheck(hh > 0 || (dir == kB && law == FrictionLaw::Rectilinear), comm, kErrInput,
                   "contact %" PetscInt_FMT ": the %s column h_%c is zero; friction needs it (give its entries)", c,
                   dir == kT ? "tangential" : "binormal", "tbn"[dir]);
        for (const auto &d : dots)
          PetscCheck(std::abs(d.second) <= 1e-10 * std::sqrt(nn[d.first] * hh), comm, kErrInput,
                     "contact %" PetscInt_FMT ": column %c is not orthogonal to the normal column of contact %" PetscInt_FMT
                     " (h_n^T h = %g); the linearisation needs H_n^T H_t = H_n^T H_b = 0",
                     c, "tbn"[dir], d.first, (double)d.second);
      }
  }
  PetscFunctionReturn(0);
}

PetscInt ContactSet::PivotDof(PetscInt c) const
{
  PetscInt  best = -1;
  PetscReal big  = -1;
  ForEachEntry(c, kN, [&](PetscInt d, PetscReal v) {
    if (std::abs(v) > big) big = std::abs(v), best = d;
  });
  return best;
}

PetscErrorCode ContactSet::AssembleColumns(Vec like, int dir, const std::vector<PetscInt> &which, Mat *H) const
{
  PetscInt rstart, rend, nloc, N;
  MPI_Comm comm;
  Triplets t;
  PetscFunctionBeginUser;
  PetscCall(PetscObjectGetComm((PetscObject)like, &comm));
  PetscCall(VecGetOwnershipRange(like, &rstart, &rend));
  PetscCall(VecGetLocalSize(like, &nloc));
  PetscCall(VecGetSize(like, &N));
  for (size_t j = 0; j < which.size(); ++j) {
    ForEachEntry(which[j], dir, [&](PetscInt d, PetscReal v) {
      if (d >= rstart && d < rend) t.Add(d, (PetscInt)j, v);
    });
  }
  PetscCall(MatCreateFromTriplets(comm, nloc, PETSC_DECIDE, N, (PetscInt)which.size(), t, H));
  PetscFunctionReturn(0);
}

PetscErrorCode ContactSet::LocalComponents(Vec x, std::vector<PetscReal> &out) const
{
  PetscInt           rstart, rend;
  const PetscScalar *a;
  MPI_Comm           comm;
  PetscFunctionBeginUser;
  PetscCall(PetscObjectGetComm((PetscObject)x, &comm));
  PetscCall(VecGetOwnershipRange(x, &rstart, &rend));
  PetscCall(VecGetArrayRead(x, &a));
  out.assign(3 * points.size(), 0.0);
  // Each rank adds the part of every dot product it owns; one reduction completes them.
  for (PetscInt c = 0; c < Size(); ++c)
    for (int dir = 0; dir < 3; ++dir)
      ForEachEntry(c, dir, [&](PetscInt d, PetscReal v) {
        if (d >= rstart && d < rend) out[3 * c + dir] += v * PetscRealPart(a[d - rstart]);
      });
  PetscCall(VecRestoreArrayRead(x, &a));
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, out.data(), (int)out.size(), MPIU_REAL, MPIU_SUM, comm));
  PetscFunctionReturn(0);
}

PetscErrorCode ContactSet::AddForce(const PetscReal *r, Vec R) const
{
  PetscInt     rstart, rend;
  PetscScalar *a;
  PetscFunctionBeginUser;
  PetscCall(VecGetOwnershipRange(R, &rstart, &rend));
  PetscCall(VecGetArray(R, &a));
  for (PetscInt c = 0; c < Size(); ++c)
    for (int dir = 0; dir < 3; ++dir) {
      const PetscReal rc = r[3 * c + dir];
      if (rc == 0) continue;
      ForEachEntry(c, dir, [&](PetscInt d, PetscReal v) {
        if (d >= rstart && d < rend) a[d - rstart] += v * rc;
      });
    }
  PetscCall(VecRestoreArray(R, &a));
  PetscFunctionReturn(0);
}

PetscErrorCode ContactSet::View(PetscViewer viewer) const
{
  PetscBool ascii;
  PetscFunctionBeginUser;
  PetscCall(PetscObjectTypeCompare((PetscObject)viewer, PETSCVIEWERASCII, &ascii));
  if (!ascii) PetscFunctionReturn(0);
  PetscCall(PetscViewerASCIIPrintf(viewer, "contact set: %" PetscInt_FMT " point(s), %s friction, mu = %g, V = %g m/s\n",
                                   Size(), FrictionLawName(law), (double)mu_, (double)V_));
  PetscCall(PetscViewerASCIIPushTab(viewer));
  const PetscInt shown = PetscMin(Size(), 8);
  for (PetscInt c = 0; c < shown; ++c) {
    const ContactPoint &p = points[c];
    if (p.nodes.empty()) {
      PetscCall(PetscViewerASCIIPrintf(viewer,
                                       "point %" PetscInt_FMT ": explicit columns (%zu, %zu, %zu entries in h_t, h_b, h_n), V_c = %g m/s\n", c,
                                       p.cols[kT].size(), p.cols[kB].size(), p.cols[kN].size(), (double)Speed(c)));
      continue;
    }
    PetscCall(PetscViewerASCIIPrintf(viewer,
                                     "point %" PetscInt_FMT ": DOFs (%" PetscInt_FMT ", %" PetscInt_FMT ", %" PetscInt_FMT
                                     ")%s t = (%.4g, %.4g, %.4g) n = (%.4g, %.4g, %.4g) V_c = %g m/s\n",
                                     c, p.nodes[0].dofs[0], p.nodes[0].dofs[1], p.nodes[0].dofs[2],
                                     p.nodes.size() > 1 ? " + opposing node," : "", p.t[0], p.t[1], p.t[2], p.n[0], p.n[1],
                                     p.n[2], (double)Speed(c)));
  }
  if (shown < Size()) PetscCall(PetscViewerASCIIPrintf(viewer, "... (%" PetscInt_FMT " more)\n", Size() - shown));
  PetscCall(PetscViewerASCIIPopTab(viewer));
  PetscFunctionReturn(0);
}

} // namespace squeal
