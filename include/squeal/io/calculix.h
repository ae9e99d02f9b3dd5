// Reading a CalculiX model: the mesh of its input deck and the matrices that
// `*FREQUENCY, SOLVER=MATRIXSTORAGE` writes (docs/fe-workflow.md).
//
// ccx -i job with that step writes
//   job.sti, job.mas  the stiffness and mass matrices, one entry "row column value" per line,
//                     1-based, upper triangle only (row <= column);
//   job.dof           one line "node.direction" per row (direction 1, 2, 3 = x, y, z);
//                     constrained DOFs are absent.
// Every rank parses the files and keeps the rows it owns; each failure names the file, the
// line and what was expected, on all ranks together.
#pragma once

#include "squeal/io/fe_mesh.h"

#include <petscmat.h>

#include <vector>

namespace squeal::io {

// The mesh of an Abaqus-syntax deck (job.inp): *NODE, *ELEMENT (C3D4, C3D6, C3D8, C3D8R, C3D8I,
// C3D10, C3D15, C3D20, C3D20R as volume cells; spring, beam, shell and other elements are read
// past and counted in `skipped`), *NSET and *ELSET (number lists, set names, GENERATE),
// *INCLUDE (relative to the deck's folder). Keywords and set names are case-insensitive (set
// names are stored in upper case, as CalculiX does). Fills x, node_ids, blocks, node_sets;
// leaves dof and full_size alone.
PetscErrorCode ReadCalculixDeck(MPI_Comm comm, const char *path, FeMesh &mesh, PetscInt *skipped = nullptr);

// The DOF map job.dof: fills mesh.dof (every node of the mesh; -1 where absent) and
// mesh.full_size. A node of the file missing from the mesh is an error naming it.
PetscErrorCode ReadCalculixDofMap(MPI_Comm comm, const char *path, FeMesh &mesh);

// job.sti or job.mas as an N x N symmetric MATAIJ (both triangles stored), N the number of rows
// of job.dof. With `rows`, the file is a part's (its own .dof numbering, rows->size() DOFs) and
// row i of the file goes to row (*rows)[i] of the N x N matrix; rows mapped to -1 (DOFs the
// model constrains) are dropped.
PetscErrorCode MatLoadCalculix(MPI_Comm comm, const char *path, PetscInt N, Mat *A, const std::vector<PetscInt> *rows = nullptr);

// The .dof map of a part of the model (a job made of some of its elements, e.g. the lining
// alone, to damp it on its own): rows[i] is the model's row of the part's DOF i, or -1 where the
// model has none (a DOF the model constrains). A node missing from the model's mesh is an error.
PetscErrorCode ReadCalculixPartDofMap(MPI_Comm comm, const char *path, const FeMesh &mesh, std::vector<PetscInt> &rows);

} // namespace squeal::io
