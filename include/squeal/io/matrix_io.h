// Reading and writing sparse matrices: Matrix Market text (".mtx", for exchange with other tools)
// and PETSc binary (anything else, for speed). Every problem with a file is reported as a PETSc
// error whose one-line message names the file (and line) and what is wrong with it; all ranks
// raise it together, so a bad file never leaves some ranks waiting in a collective call.
#pragma once

#include <petscmat.h>
#include <petscviewer.h>

#include <vector>

namespace squeal::io {

// Reads "%%MatrixMarket matrix coordinate real|integer general|symmetric" or
// "%%MatrixMarket matrix array real|integer general" into a MATAIJ on comm (rows and columns
// split with PETSC_DECIDE; MatSetFromOptions is not called). Symmetric files hold the lower
// triangle and are expanded to both; duplicate coordinate entries are summed; zeros in array
// files are not stored. Every rank parses the file but keeps only the rows it owns.
PetscErrorCode MatLoadMatrixMarket(MPI_Comm comm, const char *path, Mat *A);

// Writes A as "coordinate real general", 1-based, values with %.17g so that reading the file
// back gives the same doubles. Rank 0 gathers the matrix and writes. Collective.
PetscErrorCode MatViewMatrixMarket(Mat A, const char *path);

// ".mtx" (any case) -> MatLoadMatrixMarket; anything else -> PETSc binary loaded as MATAIJ.
PetscErrorCode MatLoadFromFile(MPI_Comm comm, const char *path, Mat *A);

// ".mtx" (any case) -> MatViewMatrixMarket; anything else -> PETSc binary (no ".info" file).
PetscErrorCode MatSaveToFile(Mat A, const char *path);

// A load vector, by extension: ".h5" (dataset /F, N or N x 1), ".mtx" (Matrix Market array or
// coordinate, N x 1 or 1 x N), ".txt"/".dat"/".csv" (numbers separated by blanks, commas or
// newlines; '#' and '%' comments), anything else PETSc binary (size checked against the header:
// a truncated file is named, not read past its end). Every rank reads the file; the Vec is
// distributed with PETSC_DECIDE. Every failure names the file and the accepted formats.
PetscErrorCode VecLoadFromFile(MPI_Comm comm, const char *path, Vec *v);

// A Vec on comm (PETSC_DECIDE layout) holding x, which every rank passes whole.
PetscErrorCode VecCreateFromValues(MPI_Comm comm, const std::vector<PetscReal> &x, Vec *v);

// A PETSc binary viewer that neither writes nor reads the ".info" side file.
PetscErrorCode OpenBinaryViewer(MPI_Comm comm, const char *path, PetscFileMode mode, PetscViewer *viewer);

} // namespace squeal::io
