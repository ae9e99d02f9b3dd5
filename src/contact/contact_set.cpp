#include "squeal/contact/contact_set.h"
#include "squeal/core/errors.h"
#include "squeal/core/sparse.h"

#include <cmath>
#include <map>

namespace squeal {

const char *FrictionLawName(FrictionLaw law) { return law == FrictionLaw::Planar ? "planar" : "rectilinear"; }

PetscErrorCode ContactSet::Validate(MPI_Comm comm, PetscInt N)
{
  std::map<PetscInt, PetscInt> owner; // DOF -> point using it
  PetscFunctionBeginUser;
  PetscCheck(!PetscIsInfOrNanReal(mu) && mu >= 0, comm, kErrInput, "friction coefficient mu = %g: expected >= 0", (double)mu);
  PetscCheck(!PetscIsInfOrNanReal(V) && V > 0, comm, kErrInput, "sliding speed V = %g: expected > 0", (double)V);
  for (PetscInt c = 0; c < Size(); ++c) {
    ContactPoint &p = points[c];
    PetscCheck(!p.nodes.empty(), comm, kErrInput, "contact %" PetscInt_FMT " has no node", c);
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
  PetscFunctionReturn(0);
}

PetscInt ContactSet::PivotDof(PetscInt c) const
{
  PetscInt  best = -1;
  PetscReal big  = -1;
  for (const ContactNode &nd : points[c].nodes)
    for (int k = 0; k < 3; ++k) {
      const PetscReal a = std::abs(nd.weight * points[c].n[k]);
      if (a > big) big = a, best = nd.dofs[k];
    }
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
    const ContactPoint    &p = points[which[j]];
    const Eigen::Vector3d &e = Axis(which[j], dir);
    for (const ContactNode &nd : p.nodes)
      for (int k = 0; k < 3; ++k)
        if (e[k] != 0 && nd.dofs[k] >= rstart && nd.dofs[k] < rend) t.Add(nd.dofs[k], (PetscInt)j, nd.weight * e[k]);
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
  for (size_t c = 0; c < points.size(); ++c)
    for (const ContactNode &nd : points[c].nodes)
      for (int k = 0; k < 3; ++k)
        if (nd.dofs[k] >= rstart && nd.dofs[k] < rend) {
          const PetscReal xv = nd.weight * PetscRealPart(a[nd.dofs[k] - rstart]);
          out[3 * c + kT] += points[c].t[k] * xv;
          out[3 * c + kB] += points[c].b[k] * xv;
          out[3 * c + kN] += points[c].n[k] * xv;
        }
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
  for (size_t c = 0; c < points.size(); ++c) {
    const Eigen::Vector3d f = r[3 * c + kT] * points[c].t + r[3 * c + kB] * points[c].b + r[3 * c + kN] * points[c].n;
    for (const ContactNode &nd : points[c].nodes)
      for (int k = 0; k < 3; ++k)
        if (nd.dofs[k] >= rstart && nd.dofs[k] < rend) a[nd.dofs[k] - rstart] += nd.weight * f[k];
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
                                   Size(), FrictionLawName(law), (double)mu, (double)V));
  PetscCall(PetscViewerASCIIPushTab(viewer));
  const PetscInt shown = PetscMin(Size(), 8);
  for (PetscInt c = 0; c < shown; ++c) {
    const ContactPoint &p = points[c];
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
