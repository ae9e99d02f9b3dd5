// The structural model  M U'' + C U' + K U = R + F  with its contact set (docs/method.md §1).
//
// One representation for every model: M, C, K are distributed PETSc AIJ matrices, F a Vec, and
// the contact set is replicated. The built-in 3-DOF system, reduced FE models read from files
// and the synthetic multi-contact chain all arrive here through the builders in builders.h.
#pragma once

#include "squeal/contact/contact_set.h"
#include "squeal/core/handle.h"
#include "squeal/io/fe_mesh.h"
#include "squeal/model/expansion.h"

#include <functional>
#include <memory>
#include <string>

namespace squeal {

class Model {
public:
  explicit Model(MPI_Comm comm = PETSC_COMM_WORLD) : comm_(comm) {}

  MPI_Comm comm() const { return comm_; }
  PetscInt Size() const;
  bool     HasDamping() const { return (bool)C; }

  std::string name = "model";
  MatH        M, C, K; // C may be empty: no viscous damping
  VecH        F;
  // C = damping_a M + damping_b K + damping_extra, when its builder knows (damping_a >= 0); the
  // extra holds entries on a few rows only (parts damped on their own). A reduction then projects
  // the extra alone and takes the rest from M's and K's projections. damping_a < 0: unknown.
  PetscReal   damping_a = -1, damping_b = 0;
  MatH        damping_extra;
  ContactSet  contacts;

  // The FE mesh the model was read from, if any (its dof map indexes the full model's DOFs).
  std::shared_ptr<const io::FeMesh> mesh;
  // For a reduced model: u_full = E u back to the full model's DOFs (on rank 0), when the
  // reduction was asked to keep it (-reduce_expand). Empty for a full model, where u itself is
  // on the mesh.
  std::shared_ptr<const Expansion> expansion;

  // Checks what the physics needs: matching sizes, finite entries, symmetric M, C, K, positive
  // mass diagonal, non-negative stiffness and damping diagonals, a valid contact set. Every
  // failure names the matrix, the entry and the value. Collective.
  PetscErrorCode Validate();
  PetscErrorCode View(PetscViewer viewer) const;

  // Writes M, C, K (PETSc binary, or Matrix Market if format is "mtx"), F (PETSc binary) and
  // the contact table (text) into directory `dir`, in the form the file builder reads back.
  PetscErrorCode Export(const char *dir, const char *format) const;

private:
  MPI_Comm comm_;
};

// Fills dst, a model on PETSC_COMM_SELF, on rank 0 of src's communicator with the whole of src
// (M, C, K sequential, F, the contact set, the name); dst is left empty on the other ranks.
// Collective on src's communicator.
PetscErrorCode ModelGatherToRankZero(const Model &src, Model &dst);

// The same on every rank: dst, on PETSC_COMM_SELF, holds the whole of src (no mesh or expansion).
// For the sweep on several ranks, whose points each rank solves alone. Collective on src's communicator.
PetscErrorCode ModelReplicate(const Model &src, Model &dst);

// dst shares src's matrices and load (references, no copy) and gets its own copy of the contact
// set, so that dst's operating point (ContactSet::SetFriction) can move while src's stays; no mesh
// or expansion. dst must be on src's communicator. For the sweep on one rank, which used to build
// and reduce the model a second time (254 s and 3.8 GB more on a 126 861-DOF brake).
PetscErrorCode ModelShare(const Model &src, Model &dst);

} // namespace squeal
