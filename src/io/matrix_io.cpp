#include "squeal/io/matrix_io.h"

#include <petscviewer.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <sstream>
#include <string>
#include <type_traits>
#include <vector>

#if defined(PETSC_USE_COMPLEX)
  #error "squeal's matrix I/O reads and writes real matrices only"
#endif

namespace squeal::io {

namespace {

struct Entry {
  PetscInt    row, col;
  PetscScalar val;
};

struct Header {
  bool      coordinate = false, symmetric = false, integer = false;
  PetscInt  M = 0, N = 0;
  long long entries = 0; // data lines the header promises
};

bool HasMtxExtension(const char *path)
{
  const size_t n    = std::strlen(path);
  auto         same = [](char a, char b) { return std::tolower((unsigned char)a) == b; };
  return n >= 4 && std::equal(path + n - 4, path + n, ".mtx", same);
}

// A file visible to some ranks only (node-local disk) must still fail on all ranks at once.
PetscErrorCode CheckReadable(MPI_Comm comm, const char *path)
{
  PetscBool   found;
  PetscMPIInt here, everywhere;
  PetscFunctionBeginUser;
  PetscCall(PetscTestFile(path, 'r', &found));
  here = found ? 1 : 0;
  PetscCallMPI(MPI_Allreduce(&here, &everywhere, 1, MPI_INT, MPI_MIN, comm));
  PetscCheck(everywhere, comm, PETSC_ERR_FILE_OPEN, "matrix file '%s' not found (or not a readable file)", path);
  PetscFunctionReturn(0);
}

// Only rank 0 writes, but a bad path must fail on every rank: PETSc's binary viewer fails on rank 0
// alone and leaves the others waiting.
PetscErrorCode OpenForWriting(MPI_Comm comm, const char *path, FILE **fp)
{
  PetscMPIInt rank, err = 0;
  PetscFunctionBeginUser;
  *fp = nullptr;
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  if (rank == 0 && !(*fp = std::fopen(path, "w"))) err = errno ? errno : EIO;
  PetscCallMPI(MPI_Bcast(&err, 1, MPI_INT, 0, comm));
  PetscCheck(!err, comm, PETSC_ERR_FILE_OPEN, "matrix file '%s' cannot be written: %s", path, std::strerror(err));
  PetscFunctionReturn(0);
}

// MatLoad would only say "Not a matrix object in file", without naming the file.
PetscErrorCode CheckBinaryHeader(MPI_Comm comm, const char *path)
{
  unsigned char      buf[sizeof(PetscInt)] = {};
  unsigned long long classid               = 0;
  std::ifstream      in;
  PetscFunctionBeginUser;
  PetscCallCXX(in.open(path, std::ios::binary); in.read(reinterpret_cast<char *>(buf), sizeof buf));
  for (unsigned char b : buf) classid = (classid << 8) | b; // PETSc binary files are big-endian
  PetscCheck(in && classid == MAT_FILE_CLASSID, comm, PETSC_ERR_FILE_UNEXPECTED,
             "matrix file '%s': not a PETSc binary matrix (Matrix Market files must end in .mtx)", path);
  PetscFunctionReturn(0);
}

// Consumes one whitespace-separated token; false unless all of it is a T ("3x", "1.5" are not
// indices). strtod, unlike operator>>, reads "nan" and "inf", so they are reported as such.
template <class T>
bool ReadNumber(const char *&p, T *v)
{
  char *end;
  errno = 0;
  if constexpr (std::is_integral_v<T>) *v = std::strtoll(p, &end, 10);
  else *v = std::strtod(p, &end);
  const bool ok = end != p && (*end == '\0' || std::isspace((unsigned char)*end)) && (!std::is_integral_v<T> || !errno);
  p             = end;
  return ok;
}

bool AtEnd(const char *p)
{
  while (std::isspace((unsigned char)*p)) ++p;
  return *p == '\0';
}

bool NextDataLine(std::istream &in, std::string &line, long long &lineno)
{
  while (std::getline(in, line)) {
    ++lineno;
    const size_t first = line.find_first_not_of(" \t\r");
    if (first != std::string::npos && line[first] != '%') return true;
  }
  return false;
}

PetscErrorCode ReadHeader(MPI_Comm comm, const char *path, std::istream &in, long long &lineno, Header *h)
{
  std::string line, banner, object, format, field, symmetry;
  bool        more = false;
  long long   M = -1, N = -1, nnz = -1;
  PetscFunctionBeginUser;
  PetscCallCXX({
    std::getline(in, line);
    ++lineno;
    std::transform(line.begin(), line.end(), line.begin(), [](unsigned char c) { return (char)std::tolower(c); });
    std::istringstream(line) >> banner >> object >> format >> field >> symmetry;
  });
  h->coordinate = format == "coordinate";
  h->integer    = field == "integer";
  h->symmetric  = symmetry == "symmetric";
  PetscCheck(banner == "%%matrixmarket", comm, PETSC_ERR_FILE_UNEXPECTED,
             "matrix file '%s': first line is not a '%%%%MatrixMarket' header", path);
  PetscCheck(object == "matrix", comm, PETSC_ERR_FILE_UNEXPECTED,
             "matrix file '%s': unsupported Matrix Market object '%s' (expected matrix)", path, object.c_str());
  PetscCheck(h->coordinate || format == "array", comm, PETSC_ERR_FILE_UNEXPECTED,
             "matrix file '%s': unsupported Matrix Market format '%s' (expected coordinate, array)", path, format.c_str());
  PetscCheck(h->integer || field == "real", comm, PETSC_ERR_FILE_UNEXPECTED,
             "matrix file '%s': unsupported Matrix Market type '%s' (expected real, integer)", path, field.c_str());
  PetscCheck(symmetry == "general" || (h->symmetric && h->coordinate), comm, PETSC_ERR_FILE_UNEXPECTED,
             "matrix file '%s': unsupported Matrix Market symmetry '%s' for %s format (expected %s)", path,
             symmetry.c_str(), format.c_str(), h->coordinate ? "general, symmetric" : "general");

  PetscCallCXX(more = NextDataLine(in, line, lineno));
  PetscCheck(more, comm, PETSC_ERR_FILE_UNEXPECTED, "matrix file '%s': size line missing after the header", path);
  const char *p = line.c_str();
  PetscCheck(ReadNumber(p, &M) && ReadNumber(p, &N) && (!h->coordinate || ReadNumber(p, &nnz)) && AtEnd(p) &&
               M >= 0 && N >= 0 && (!h->coordinate || nnz >= 0),
             comm, PETSC_ERR_FILE_UNEXPECTED, "matrix file '%s', line %lld: expected size line '%s'", path, lineno,
             h->coordinate ? "rows columns entries" : "rows columns");
  PetscCheck(M <= PETSC_MAX_INT && N <= PETSC_MAX_INT, comm, PETSC_ERR_FILE_UNEXPECTED,
             "matrix file '%s', line %lld: %lld x %lld is too large for PetscInt", path, lineno, M, N);
  PetscCheck(!h->symmetric || M == N, comm, PETSC_ERR_FILE_UNEXPECTED,
             "matrix file '%s', line %lld: symmetric matrix must be square, not %lld x %lld", path, lineno, M, N);
  h->M       = (PetscInt)M;
  h->N       = (PetscInt)N;
  h->entries = h->coordinate ? nnz : M * N;
  PetscFunctionReturn(0);
}

PetscErrorCode OwnedRange(MPI_Comm comm, PetscInt N, PetscInt *start, PetscInt *end)
{
  PetscLayout map;
  PetscFunctionBeginUser;
  PetscCall(PetscLayoutCreateFromSizes(comm, PETSC_DECIDE, N, 1, &map));
  PetscCall(PetscLayoutGetRange(map, start, end));
  PetscCall(PetscLayoutDestroy(&map));
  PetscFunctionReturn(0);
}

} // namespace

PetscErrorCode MatLoadMatrixMarket(MPI_Comm comm, const char *path, Mat *A)
{
  std::ifstream         in;
  std::string           line;
  long long             lineno = 0, found = 0;
  bool                  more   = false;
  Header                h;
  PetscInt              rstart, rend, cstart, cend;
  std::vector<Entry>    owned;
  std::vector<PetscInt> dnz, onz;
  Mat                   B;
  PetscFunctionBeginUser;
  PetscCall(CheckReadable(comm, path));
  PetscCallCXX(in.open(path));
  PetscCheck(in.is_open(), comm, PETSC_ERR_FILE_OPEN, "matrix file '%s' cannot be opened", path);
  PetscCall(ReadHeader(comm, path, in, lineno, &h));
  PetscCall(OwnedRange(comm, h.M, &rstart, &rend));
  PetscCall(OwnedRange(comm, h.N, &cstart, &cend));

  // Every rank checks every line, so a bad line fails on all ranks together, and before any PETSc
  // object exists that could leak.
  while (true) {
    PetscCallCXX(more = NextDataLine(in, line, lineno));
    if (!more) break;
    if (++found > h.entries) continue; // reported below, with the count
    const char *p = line.c_str();
    long long   i, j, iv = 0;
    double      v = 0;
    if (h.coordinate) {
      PetscCheck(ReadNumber(p, &i) && ReadNumber(p, &j), comm, PETSC_ERR_FILE_UNEXPECTED,
                 "matrix file '%s', line %lld: expected 'row column value'", path, lineno);
    } else { // column-major
      i = (found - 1) % h.M + 1;
      j = (found - 1) / h.M + 1;
    }
    PetscCheck(h.integer ? ReadNumber(p, &iv) : ReadNumber(p, &v), comm, PETSC_ERR_FILE_UNEXPECTED,
               "matrix file '%s', line %lld: cannot read %s value", path, lineno, h.integer ? "an integer" : "a real");
    if (h.integer) v = (double)iv;
    PetscCheck(AtEnd(p), comm, PETSC_ERR_FILE_UNEXPECTED, "matrix file '%s', line %lld: unexpected text after the value",
               path, lineno);
    PetscCheck(std::isfinite(v), comm, PETSC_ERR_FILE_UNEXPECTED, "matrix file '%s', line %lld: value is NaN or infinite",
               path, lineno);
    PetscCheck(i >= 1 && i <= h.M, comm, PETSC_ERR_FILE_UNEXPECTED,
               "matrix file '%s', line %lld: row index %lld out of range [1, %" PetscInt_FMT "]", path, lineno, i, h.M);
    PetscCheck(j >= 1 && j <= h.N, comm, PETSC_ERR_FILE_UNEXPECTED,
               "matrix file '%s', line %lld: column index %lld out of range [1, %" PetscInt_FMT "]", path, lineno, j, h.N);
    // Mirroring would count an entry listed in both triangles twice.
    PetscCheck(!h.symmetric || j <= i, comm, PETSC_ERR_FILE_UNEXPECTED,
               "matrix file '%s', line %lld: entry (%lld, %lld) lies above the diagonal of a symmetric matrix", path, lineno,
               i, j);
    if (!h.coordinate && v == 0.0) continue; // a dense listing says nothing about structure
    const PetscInt r = (PetscInt)(i - 1), c = (PetscInt)(j - 1);
    if (r >= rstart && r < rend) PetscCallCXX(owned.push_back({r, c, v}));
    if (h.symmetric && r != c && c >= rstart && c < rend) PetscCallCXX(owned.push_back({c, r, v}));
  }
  PetscCheck(!in.bad(), comm, PETSC_ERR_FILE_READ, "matrix file '%s': read error after line %lld", path, lineno);
  PetscCheck(found == h.entries, comm, PETSC_ERR_FILE_UNEXPECTED, "matrix file '%s': header promises %lld entries, found %lld",
             path, h.entries, found);

  // Repeated coordinates are summed, as scipy's and MATLAB's mmread do.
  PetscCallCXX(std::sort(owned.begin(), owned.end(),
                         [](const Entry &a, const Entry &b) { return a.row != b.row ? a.row < b.row : a.col < b.col; }));
  size_t n = 0;
  for (const Entry &e : owned) {
    if (n > 0 && owned[n - 1].row == e.row && owned[n - 1].col == e.col) owned[n - 1].val += e.val;
    else owned[n++] = e;
  }
  owned.resize(n);
  PetscCallCXX(dnz.assign(rend - rstart, 0); onz.assign(rend - rstart, 0));
  for (const Entry &e : owned) (e.col >= cstart && e.col < cend ? dnz : onz)[e.row - rstart]++;

  PetscCall(MatCreate(comm, &B));
  PetscCall(MatSetSizes(B, rend - rstart, cend - cstart, h.M, h.N));
  PetscCall(MatSetType(B, MATAIJ));
  PetscCall(MatXAIJSetPreallocation(B, 1, dnz.data(), onz.data(), nullptr, nullptr));
  PetscCall(MatSetOption(B, MAT_NEW_NONZERO_ALLOCATION_ERR, PETSC_TRUE));
  for (const Entry &e : owned) PetscCall(MatSetValue(B, e.row, e.col, e.val, INSERT_VALUES));
  PetscCall(MatAssemblyBegin(B, MAT_FINAL_ASSEMBLY));
  PetscCall(MatAssemblyEnd(B, MAT_FINAL_ASSEMBLY));
  *A = B;
  PetscFunctionReturn(0);
}

PetscErrorCode MatViewMatrixMarket(Mat A, const char *path)
{
  MPI_Comm           comm;
  PetscMPIInt        rank, failed = 0;
  PetscInt           M, N, nsub, ncols;
  MatInfo            info;
  const PetscInt    *cols;
  const PetscScalar *vals;
  IS                 all_rows, all_cols;
  Mat               *sub;
  FILE              *fp;
  PetscFunctionBeginUser;
  PetscCall(PetscObjectGetComm((PetscObject)A, &comm));
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  PetscCall(MatGetSize(A, &M, &N));
  PetscCall(OpenForWriting(comm, path, &fp));
  // Rank 0 asks for the whole matrix as one sequential submatrix; the other ranks ask for none.
  nsub = rank == 0 ? 1 : 0;
  PetscCall(ISCreateStride(PETSC_COMM_SELF, nsub * M, 0, 1, &all_rows));
  PetscCall(ISCreateStride(PETSC_COMM_SELF, nsub * N, 0, 1, &all_cols));
  PetscCall(MatCreateSubMatrices(A, nsub, &all_rows, &all_cols, MAT_INITIAL_MATRIX, &sub));
  if (rank == 0) {
    PetscCall(MatGetInfo(sub[0], MAT_LOCAL, &info));
    std::fprintf(fp, "%%%%MatrixMarket matrix coordinate real general\n");
    std::fprintf(fp, "%" PetscInt_FMT " %" PetscInt_FMT " %" PetscInt_FMT "\n", M, N, (PetscInt)info.nz_used);
    for (PetscInt i = 0; i < M; ++i) {
      PetscCall(MatGetRow(sub[0], i, &ncols, &cols, &vals));
      for (PetscInt k = 0; k < ncols; ++k)
        std::fprintf(fp, "%" PetscInt_FMT " %" PetscInt_FMT " %.17g\n", i + 1, cols[k] + 1, (double)vals[k]);
      PetscCall(MatRestoreRow(sub[0], i, &ncols, &cols, &vals));
    }
    failed = std::ferror(fp);
    failed = std::fclose(fp) != 0 || failed;
  }
  PetscCall(MatDestroySubMatrices(nsub, &sub));
  PetscCall(ISDestroy(&all_rows));
  PetscCall(ISDestroy(&all_cols));
  PetscCallMPI(MPI_Bcast(&failed, 1, MPI_INT, 0, comm));
  PetscCheck(!failed, comm, PETSC_ERR_FILE_WRITE, "matrix file '%s': write failed (disk full?)", path);
  PetscFunctionReturn(0);
}

PetscErrorCode MatLoadFromFile(MPI_Comm comm, const char *path, Mat *A)
{
  PetscViewer viewer;
  Mat         B;
  PetscFunctionBeginUser;
  if (HasMtxExtension(path)) {
    PetscCall(MatLoadMatrixMarket(comm, path, A));
    PetscFunctionReturn(0);
  }
  PetscCall(CheckReadable(comm, path));
  PetscCall(CheckBinaryHeader(comm, path));
  PetscCall(OpenBinaryViewer(comm, path, FILE_MODE_READ, &viewer));
  PetscCall(MatCreate(comm, &B));
  PetscCall(MatSetType(B, MATAIJ));
  PetscCall(MatLoad(B, viewer));
  PetscCall(PetscViewerDestroy(&viewer));
  *A = B;
  PetscFunctionReturn(0);
}

PetscErrorCode MatSaveToFile(Mat A, const char *path)
{
  MPI_Comm    comm;
  FILE       *fp;
  PetscViewer viewer;
  PetscFunctionBeginUser;
  if (HasMtxExtension(path)) {
    PetscCall(MatViewMatrixMarket(A, path));
    PetscFunctionReturn(0);
  }
  PetscCall(PetscObjectGetComm((PetscObject)A, &comm));
  PetscCall(OpenForWriting(comm, path, &fp));
  if (fp) std::fclose(fp);
  PetscCall(OpenBinaryViewer(comm, path, FILE_MODE_WRITE, &viewer));
  PetscCall(MatView(A, viewer));
  PetscCall(PetscViewerDestroy(&viewer));
  PetscFunctionReturn(0);
}

// Without SkipInfo PETSc writes a ".info" file next to the data, and reads options from a stale one.
PetscErrorCode OpenBinaryViewer(MPI_Comm comm, const char *path, PetscFileMode mode, PetscViewer *viewer)
{
  PetscFunctionBeginUser;
  PetscCall(PetscViewerCreate(comm, viewer));
  PetscCall(PetscViewerSetType(*viewer, PETSCVIEWERBINARY));
  PetscCall(PetscViewerFileSetMode(*viewer, mode));
  PetscCall(PetscViewerBinarySetSkipInfo(*viewer, PETSC_TRUE));
  PetscCall(PetscViewerFileSetName(*viewer, path));
  PetscFunctionReturn(0);
}

} // namespace squeal::io
