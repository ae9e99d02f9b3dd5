// Internal to src/io: the pieces of the text readers (Matrix Market, CalculiX) that every reader
// needs: collective existence checks, strict number tokens, and assembling the rows a rank owns.
#pragma once

#include <petscmat.h>

#include <cctype>
#include <cerrno>
#include <cstdlib>
#include <type_traits>
#include <vector>

namespace squeal::io::detail {

struct Entry {
  PetscInt    row, col;
  PetscScalar val;
};

// Consumes one whitespace-separated token; false unless all of it is a T ("3x", "1.5" are not
// indices). strtod, unlike operator>>, reads "nan" and "inf", so they are reported as such.
template <class T>
inline bool ReadNumber(const char *&p, T *v)
{
  char *end;
  errno = 0;
  if constexpr (std::is_integral_v<T>) *v = std::strtoll(p, &end, 10);
  else *v = std::strtod(p, &end);
  const bool ok = end != p && (*end == '\0' || std::isspace((unsigned char)*end)) && (!std::is_integral_v<T> || !errno);
  p             = end;
  return ok;
}

inline bool AtEnd(const char *p)
{
  while (std::isspace((unsigned char)*p)) ++p;
  return *p == '\0';
}

// A file visible to some ranks only (node-local disk) must still fail on all ranks at once; the
// message names the file as "<what> '<path>'".
PetscErrorCode CheckReadable(MPI_Comm comm, const char *path, const char *what);

// The rows [start, end) of an N-row PETSC_DECIDE layout on comm that this rank owns.
PetscErrorCode OwnedRange(MPI_Comm comm, PetscInt N, PetscInt *start, PetscInt *end);

// A MATAIJ M x N on comm (PETSC_DECIDE layout) from the entries of the rows this rank owns;
// entries at the same position are summed; the vector is sorted in place.
PetscErrorCode AssembleOwnedEntries(MPI_Comm comm, PetscInt M, PetscInt N, std::vector<Entry> &owned, Mat *A);

} // namespace squeal::io::detail
