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
// of job.dof.
PetscErrorCode MatLoadCalculix(MPI_Comm comm, const char *path, PetscInt N, Mat *A);

} // namespace squeal::io
