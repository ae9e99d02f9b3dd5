// The contact set: n_c points, each with its nodal DOFs, local frame (t, b, n), counter-surface
// speed and initial gap, plus the friction law and coefficient shared by all points.
//
// Point c contributes the columns h_{t,c}, h_{b,c}, h_{n,c} of the contact operator
// H in R^{N x 3 n_c} (method.md §1.1): column h_{e,c} scatters weight * e_c onto the three
// translational DOFs of each node of the point (weight +1 for the structure node, -1 for an
// opposing deformable body). Local quantities: g_c = H_c^T U + g0_c, v_c = H_c^T dU, R = H r.
// The set is small (n_c << N) and replicated on every rank; H itself is distributed like U.
#pragma once

#include <petscmat.h>
#include <petscviewer.h>

#include <Eigen/Core>
#include <Eigen/Geometry> // cross()

#include <array>
#include <vector>

namespace squeal {

enum class FrictionLaw { Planar, Rectilinear };
const char *FrictionLawName(FrictionLaw law);

struct ContactNode {
  std::array<PetscInt, 3> dofs{};   // global indices of the node's translations
  PetscReal               weight = 1.0;
};

struct ContactPoint {
  std::vector<ContactNode> nodes;
  Eigen::Vector3d          t{1, 0, 0}, b{0, 1, 0}, n{0, 0, 1}; // in the nodal DOF basis
  PetscReal                speed_factor = 1.0;                  // V_c = speed_factor * V
  PetscReal                g0           = 0.0;                  // gap at U = 0
};

enum Direction : int { kT = 0, kB = 1, kN = 2 };

class ContactSet {
public:
  FrictionLaw               law = FrictionLaw::Planar;
  PetscReal                 mu  = 0.0; // Coulomb coefficient
  PetscReal                 V   = 1.0; // reference counter-surface speed (m/s)
  std::vector<ContactPoint> points;

  PetscInt  Size() const { return (PetscInt)points.size(); }
  PetscReal Speed(PetscInt c) const { return V * points[c].speed_factor; }
  const Eigen::Vector3d &Axis(PetscInt c, int dir) const
  {
    return dir == kT ? points[c].t : (dir == kB ? points[c].b : points[c].n);
  }

  // Completes b = n x t and checks everything a file or a builder may get wrong: DOF indices
  // in [0, N), unit and orthogonal t and n, positive speed factors, finite numbers, no DOF
  // shared by two points. Collective; every rank holds the same set.
  PetscErrorCode Validate(MPI_Comm comm, PetscInt N);

  // The DOF through which point c's normal constraint is eliminated in the linearisation:
  // the nodal DOF with the largest |weight * n| component.
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
};

} // namespace squeal
