// The contact set: n_c points, each with its nodal DOFs, local frame (t, b, n), counter-surface
// speed and initial gap, plus the friction law and coefficient shared by all points.
//
// Point c contributes the columns h_{t,c}, h_{b,c}, h_{n,c} of the contact operator
// H in R^{N x 3 n_c} (docs/method.md §1.1): column h_{e,c} scatters weight * e_c onto the three
// translational DOFs of each node of the point (weight +1 for the structure node, -1 for an
// opposing deformable body), plus the point's explicit entries of that column, if any (a model
// whose DOFs are not all node translations: the in-plane interface modes of a reduced model,
// craig_bampton.h). Local quantities: g_c = H_c^T U + g0_c, v_c = H_c^T dU, R = H r.
// Every consumer reads H through ForEachEntry, so both forms take the same path.
// The set is small (n_c << N) and replicated on every rank; H itself is distributed like U.
#pragma once

#include <petscmat.h>
#include <petscviewer.h>

#include <Eigen/Core>
#include <Eigen/Geometry> // cross()

#include <array>
#include <utility>
#include <vector>

namespace squeal {

enum class FrictionLaw { Planar, Rectilinear };
const char *FrictionLawName(FrictionLaw law);

struct ContactNode {
  std::array<PetscInt, 3> dofs{};   // global indices of the node's translations
  PetscReal               weight = 1.0;
};

// Explicit entries (global DOF, value) of one column of H.
using ColumnEntries = std::vector<std::pair<PetscInt, PetscReal>>;

struct ContactPoint {
  std::vector<ContactNode> nodes;
  // Explicit entries of h_t, h_b, h_n (index kT, kB, kN), added to the nodes' part; the frame
  // then only names the directions (the nodes' columns use it).
  std::array<ColumnEntries, 3> cols;
  Eigen::Vector3d          t{1, 0, 0}, b{0, 1, 0}, n{0, 0, 1}; // in the nodal DOF basis
  PetscReal                speed_factor = 1.0;                  // V_c = speed_factor * V
  PetscReal                g0           = 0.0;                  // gap at U = 0
};

enum Direction : int { kT = 0, kB = 1, kN = 2 };

class ContactSet {
public:
  FrictionLaw               law = FrictionLaw::Planar;
  std::vector<ContactPoint> points;

  // The operating point (mu, V) has one writer: whoever caches something that depends on it (the
  // contact solver's sliding speeds) compares FrictionState() with the state it cached, so a
  // continuation in V or a sweep cannot flow with stale speeds.
  void SetFriction(PetscReal mu, PetscReal V)
  {
    mu_ = mu, V_ = V;
    ++friction_state_;
  }
  PetscReal Mu() const { return mu_; } // Coulomb coefficient
  PetscReal V() const { return V_; }   // reference counter-surface speed (m/s)
  unsigned long FrictionState() const { return friction_state_; }

  PetscInt  Size() const { return (PetscInt)points.size(); }
  PetscReal Speed(PetscInt c) const { return V_ * points[c].speed_factor; }
  const Eigen::Vector3d &Axis(PetscInt c, int dir) const
  {
    return dir == kT ? points[c].t : (dir == kB ? points[c].b : points[c].n);
  }

  // Visits every entry (dof, value) of column h_{dir,c}: the nodes' non-zero weight * e_k, then
  // the explicit entries. A DOF may come twice (two nodes, or a node and an explicit entry):
  // consumers add.
  template <class F>
  void ForEachEntry(PetscInt c, int dir, F &&f) const
  {
    const ContactPoint    &p = points[c];
    const Eigen::Vector3d &e = Axis(c, dir);
    for (const ContactNode &nd : p.nodes)
      for (int k = 0; k < 3; ++k) {
        const PetscReal v = nd.weight * e[k];
        if (v != 0) f(nd.dofs[k], v);
      }
    for (const auto &en : p.cols[dir]) f(en.first, en.second);
  }
  // True if some point carries explicit column entries.
  bool HasExplicitColumns() const;

  // Completes b = n x t and checks everything a file or a builder may get wrong: DOF indices
  // in [0, N), unit and orthogonal t and n, positive speed factors, finite numbers, no DOF
  // shared by two points' nodes, a non-zero h_n per point. With explicit entries also what the
  // linearisation and the energy estimate assume of nodal contact (docs/method.md §1.1, §4): the
  // h_n of distinct points act on distinct DOFs (so each point's pivot DOF is in no other h_n,
  // and H_n^T H_n is diagonal) and H_n^T H_t = H_n^T H_b = 0. Collective; every rank holds the same set.
  PetscErrorCode Validate(MPI_Comm comm, PetscInt N);

  // The DOF through which point c's normal constraint is eliminated in the linearisation:
  // the entry of h_n with the largest magnitude (the first one on a tie).
  PetscInt PivotDof(PetscInt c) const;

  // Assembles [h_{dir,c} for c in which] as an N x |which| AIJ matrix whose rows are laid out
  // like the vector `like`.
  PetscErrorCode AssembleColumns(Vec like, int dir, const std::vector<PetscInt> &which, Mat *H) const;

  // Local components e_c . (nodal values of x) for every point and direction, from a
  // distributed vector: out[3c + dir] = h_{dir,c}^T x. Collective (gathers the few nodal values).
  PetscErrorCode LocalComponents(Vec x, std::vector<PetscReal> &out) const;

  // R += H r for local reactions r (3 n_c: t, b, n per point), into the rows this rank owns.
  PetscErrorCode AddForce(const PetscReal *r, Vec R) const;

  PetscErrorCode View(PetscViewer viewer) const;

private:
  PetscReal     mu_ = 0.0, V_ = 1.0;
  unsigned long friction_state_ = 0;
};

} // namespace squeal
