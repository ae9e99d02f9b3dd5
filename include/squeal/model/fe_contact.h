// Contact points and preload of an FE brake from its geometry (docs/fe-workflow.md): the pad's
// friction face against the face of a disc that rotates about an axis.
//
// For each node p of the pad face, the disc point it touches: a disc-face node at the same place
// (node-to-node, conforming meshes) or, where there is none, the projection of p on a disc-face
// facet with the facet's interpolation weights w_k (node-to-surface). The point's columns of H
// are then pad minus disc: node p with weight +1 and the disc nodes with weight -w_k (-1 for a
// node-to-node pair), so g = g0 + h_n^T U is the normal gap between the two bodies.
// Its frame at the disc point x_d, with e the unit axis and a a point of it:
//   n  the disc face's outward normal (it must point at the pad: checked),
//   t  the disc's velocity direction there, e x (x_d - a) projected on the face and normalised
//      (the counter-surface drags the pad along +t, docs/method.md §1.1), b = n x t;
//   speed factor |e x (x_d - a)| / r_ref, so V_c = V r / r_ref for -contact_v V at r_ref;
//   g0 = (x_p - x_d) . n.
#pragma once

#include "squeal/contact/contact_set.h"
#include "squeal/io/fe_mesh.h"

#include <string>
#include <vector>

namespace squeal {

struct FacePairing {
  enum class Mode { Node, Surface, Auto };
  std::string     pad_set = "PAD_FACE", disc_set = "DISC_FACE";
  Eigen::Vector3d axis{0, 0, 1}, axis_point{0, 0, 0};
  PetscReal       r_ref = 0;    // <= 0: the mean radius of the pad face
  PetscReal       tol   = 1e-6; // m: largest pad-to-disc distance of a pair
  Mode            mode  = Mode::Auto;
};

// A boundary facet of the cells whose corner nodes all lie in a node set: its corners (mesh
// nodes, ordered around the facet), unit normal pointing out of its cell, and area.
struct Facet {
  std::vector<long> corners;
  Eigen::Vector3d   normal;
  PetscReal         area = 0;
};
std::vector<Facet> SetFacets(const io::FeMesh &mesh, const std::vector<long> &set);

// Interpolation weights of the point of `f` nearest to x (bilinear on quadrilaterals, linear on
// triangles), in corner order; false if that point lies outside the facet by more than `slack`
// (relative to the facet's size). dist: the distance from x to that point.
bool FacetWeights(const io::FeMesh &mesh, const Facet &f, const Eigen::Vector3d &x, PetscReal slack, std::vector<PetscReal> &w,
                  PetscReal *dist);

// What the pairing found, for the model's view.
struct PairingReport {
  PetscInt  node_pairs = 0, surface_pairs = 0;
  PetscReal max_distance = 0, r_ref = 0;
};

// Fills set.points (law, mu, V untouched) from the mesh's node sets. Every DOF of a paired node
// must be in the mesh's DOF map. Errors name the set, the node and what to change: a set missing
// or empty, the two sets sharing nodes or cells, no disc point within the tolerance (the first
// ones, with their distance), a disc normal pointing away from the pad, a node on the axis, a
// constrained contact node, two pad nodes on one disc node. Collective (every rank computes the
// same set).
PetscErrorCode PairContactFaces(MPI_Comm comm, const io::FeMesh &mesh, const FacePairing &spec, ContactSet &set,
                                PairingReport *report = nullptr);

// Nodal forces of a uniform pressure P (Pa) on the facets of node set `name`, pushing into the
// body (-P n_out area, shared equally by the facet's corners), added into F (full DOF numbering;
// constrained DOFs dropped). Returns the total force vector in `total`.
PetscErrorCode AddPressureLoad(MPI_Comm comm, const io::FeMesh &mesh, const std::string &name, PetscReal P,
                               std::vector<PetscReal> &F, Eigen::Vector3d *total = nullptr);

} // namespace squeal
