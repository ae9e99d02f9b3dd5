#include "squeal/io/matrix_io.h"
#include "text_io.h"

#include <petscviewer.h>

#include <hdf5.h>

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

using namespace detail;

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

// The first k PetscInts of a PETSc binary file (big-endian); false if the file is shorter.
bool ReadBinaryInts(const char *path, int k, long long *v, long long *bytes)
{
  std::ifstream in(path, std::ios::binary | std::ios::ate);
  if (!in) return false;
  *bytes = (long long)in.tellg();
  in.seekg(0);
  for (int i = 0; i < k; ++i) {
    unsigned char      buf[sizeof(PetscInt)] = {};
    unsigned long long x                     = 0;
    if (!in.read(reinterpret_cast<char *>(buf), sizeof buf)) return false;
    for (unsigned char b : buf) x = (x << 8) | b;
    v[i] = sizeof(PetscInt) == 4 ? (long long)(int32_t)(uint32_t)x : (long long)x;
  }
  return true;
}

// MatLoad would only say "Not a matrix object in file" or "Read past end of file", without
// naming the file (and leaves its viewer behind).
PetscErrorCode CheckBinaryHeader(MPI_Comm comm, const char *path)
{
  long long h[4] = {0, 0, 0, 0}, bytes = 0;
  PetscFunctionBeginUser;
  const bool got = ReadBinaryInts(path, 4, h, &bytes);
  PetscCheck(got && h[0] == MAT_FILE_CLASSID, comm, PETSC_ERR_FILE_UNEXPECTED,
             "matrix file '%s': not a PETSc binary matrix (accepted: PETSc binary, or Matrix Market with extension .mtx)", path);
  PetscCheck(h[1] >= 0 && h[2] >= 0 && h[3] >= 0, comm, PETSC_ERR_FILE_UNEXPECTED,
             "matrix file '%s': corrupt PETSc binary header (%lld x %lld, %lld nonzeros)", path, h[1], h[2], h[3]);
  const long long need = (4 + h[1] + h[3]) * (long long)sizeof(PetscInt) + h[3] * (long long)sizeof(PetscScalar);
  PetscCheck(bytes >= need, comm, PETSC_ERR_FILE_UNEXPECTED,
             "matrix file '%s' is truncated: %lld bytes, but its header (%lld x %lld, %lld nonzeros) needs %lld", path, bytes,
             h[1], h[2], h[3], need);
  PetscFunctionReturn(0);
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
  Mat                   B;
  PetscFunctionBeginUser;
  PetscCall(CheckReadable(comm, path, "matrix file"));
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

  PetscCall(detail::AssembleOwnedEntries(comm, h.M, h.N, owned, &B));
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
  PetscCall(CheckReadable(comm, path, "matrix file"));
  PetscCall(CheckBinaryHeader(comm, path));
  PetscCall(OpenBinaryViewer(comm, path, FILE_MODE_READ, &viewer));
  PetscCall(MatCreate(comm, &B));
  PetscCall(MatSetType(B, MATAIJ));
  const PetscErrorCode ierr = MatLoad(B, viewer);
  PetscCall(PetscViewerDestroy(&viewer)); // also when MatLoad failed
  if (ierr) PetscCall(MatDestroy(&B));
  PetscCall(ierr);
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

namespace {

bool HasExtension(const char *path, const char *ext)
{
  const size_t n = std::strlen(path), e = std::strlen(ext);
  auto         same = [](char a, char b) { return std::tolower((unsigned char)a) == b; };
  return n >= e && std::equal(path + n - e, path + n, ext, same);
}

const char kVecFormats[] = "accepted: PETSc binary, HDF5 .h5 with dataset /F, Matrix Market .mtx (array or coordinate, "
                           "N x 1), text .txt/.dat/.csv (one number per line)";

// Whitespace- or comma-separated numbers; '#' and '%' start comments.
PetscErrorCode ReadTextColumn(MPI_Comm comm, const char *path, std::vector<PetscReal> &x)
{
  std::ifstream in;
  std::string   line;
  long long     lineno = 0;
  PetscFunctionBeginUser;
  PetscCallCXX(in.open(path));
  while (true) {
    bool more = false;
    PetscCallCXX(more = (bool)std::getline(in, line));
    if (!more) break;
    ++lineno;
    const size_t c = line.find_first_of("#%");
    if (c != std::string::npos) line.erase(c);
    std::replace(line.begin(), line.end(), ',', ' ');
    const char *p = line.c_str();
    while (!AtEnd(p)) {
      double v;
      PetscCheck(ReadNumber(p, &v) && std::isfinite(v), comm, PETSC_ERR_FILE_UNEXPECTED,
                 "load vector file '%s', line %lld: not a finite number (%s)", path, lineno, kVecFormats);
      PetscCallCXX(x.push_back(v));
    }
  }
  PetscCheck(!x.empty(), comm, PETSC_ERR_FILE_UNEXPECTED, "load vector file '%s' holds no number (%s)", path, kVecFormats);
  PetscFunctionReturn(0);
}

PetscErrorCode ReadMatrixMarketVector(MPI_Comm comm, const char *path, std::vector<PetscReal> &x)
{
  std::ifstream in;
  std::string   line;
  long long     lineno = 0, found = 0;
  Header        h;
  PetscFunctionBeginUser;
  PetscCallCXX(in.open(path));
  PetscCall(ReadHeader(comm, path, in, lineno, &h));
  PetscCheck(h.M == 1 || h.N == 1, comm, PETSC_ERR_FILE_UNEXPECTED,
             "load vector file '%s': a %" PetscInt_FMT " x %" PetscInt_FMT " matrix, expected N x 1 (%s)", path, h.M, h.N, kVecFormats);
  PetscCallCXX(x.assign(std::max(h.M, h.N), 0.0));
  while (true) {
    bool more = false;
    PetscCallCXX(more = NextDataLine(in, line, lineno));
    if (!more) break;
    PetscCheck(++found <= h.entries, comm, PETSC_ERR_FILE_UNEXPECTED, "load vector file '%s', line %lld: more entries than the header's %lld",
               path, lineno, h.entries);
    const char *p = line.c_str();
    long long   i = found, j = 1;
    double      v;
    if (h.coordinate)
      PetscCheck(ReadNumber(p, &i) && ReadNumber(p, &j) && i >= 1 && j >= 1 && i <= h.M && j <= h.N, comm, PETSC_ERR_FILE_UNEXPECTED,
                 "load vector file '%s', line %lld: expected 'row column value' within %" PetscInt_FMT " x %" PetscInt_FMT, path, lineno,
                 h.M, h.N);
    PetscCheck(ReadNumber(p, &v) && AtEnd(p) && std::isfinite(v), comm, PETSC_ERR_FILE_UNEXPECTED,
               "load vector file '%s', line %lld: expected one finite value", path, lineno);
    x[h.M == 1 ? j - 1 : i - 1] += v;
  }
  PetscCheck(found == h.entries, comm, PETSC_ERR_FILE_UNEXPECTED, "load vector file '%s': header promises %lld entries, found %lld", path,
             h.entries, found);
  PetscFunctionReturn(0);
}

PetscErrorCode ReadBinaryVector(MPI_Comm comm, const char *path, std::vector<PetscReal> &x)
{
  long long h[2] = {0, 0}, bytes = 0;
  PetscFunctionBeginUser;
  const bool got = ReadBinaryInts(path, 2, h, &bytes);
  PetscCheck(got && h[0] == VEC_FILE_CLASSID, comm, PETSC_ERR_FILE_UNEXPECTED, "load vector file '%s': not a PETSc binary vector (%s)",
             path, kVecFormats);
  const long long need = 2 * (long long)sizeof(PetscInt) + h[1] * (long long)sizeof(PetscScalar);
  PetscCheck(h[1] >= 0 && bytes >= need, comm, PETSC_ERR_FILE_UNEXPECTED,
             "load vector file '%s' is truncated: %lld bytes, but its header (%lld entries) needs %lld", path, bytes, h[1], need);
  std::ifstream in;
  PetscCallCXX(in.open(path, std::ios::binary); in.seekg(2 * sizeof(PetscInt)); x.resize(h[1]));
  for (long long i = 0; i < h[1]; ++i) {
    unsigned char      b[8];
    unsigned long long u = 0;
    PetscCallCXX(in.read(reinterpret_cast<char *>(b), 8));
    for (unsigned char c : b) u = (u << 8) | c;
    double v;
    std::memcpy(&v, &u, 8);
    x[i] = v;
  }
  PetscCheck((bool)in, comm, PETSC_ERR_FILE_READ, "load vector file '%s': read error", path);
  PetscFunctionReturn(0);
}

PetscErrorCode ReadHDF5Vector(MPI_Comm comm, const char *path, const char *dataset, std::vector<PetscReal> &x)
{
  PetscFunctionBeginUser;
  // Every rank reads (serial driver, read-only): the vector is small, and no MPI-IO is involved.
  H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
  std::string err;
  const hid_t f = H5Fopen(path, H5F_ACC_RDONLY, H5P_DEFAULT);
  if (f < 0) err = "not an HDF5 file";
  else if (H5Lexists(f, dataset, H5P_DEFAULT) <= 0) err = std::string("no dataset ") + dataset;
  else {
    const hid_t d = H5Dopen2(f, dataset, H5P_DEFAULT);
    const hid_t sp = d >= 0 ? H5Dget_space(d) : -1;
    hsize_t     dims[2] = {0, 1};
    const int   nd      = sp >= 0 ? H5Sget_simple_extent_ndims(sp) : -1;
    if (nd < 1 || nd > 2 || H5Sget_simple_extent_dims(sp, dims, nullptr) < 0 || (nd == 2 && dims[0] != 1 && dims[1] != 1))
      err = std::string("dataset ") + dataset + " is not a vector (N or N x 1)";
    else {
      x.resize(dims[0] * (nd == 2 ? dims[1] : 1));
      if (H5Dread(d, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, x.data()) < 0) err = std::string("cannot read ") + dataset;
    }
    if (sp >= 0) H5Sclose(sp);
    if (d >= 0) H5Dclose(d);
  }
  if (f >= 0) H5Fclose(f);
  PetscCheck(err.empty(), comm, PETSC_ERR_FILE_UNEXPECTED, "load vector file '%s': %s (%s)", path, err.c_str(), kVecFormats);
  PetscFunctionReturn(0);
}

} // namespace

PetscErrorCode VecLoadFromFile(MPI_Comm comm, const char *path, Vec *v)
{
  std::vector<PetscReal> x;
  PetscFunctionBeginUser;
  PetscCall(detail::CheckReadable(comm, path, "load vector file"));
  if (HasExtension(path, ".h5") || HasExtension(path, ".hdf5")) PetscCall(ReadHDF5Vector(comm, path, "/F", x));
  else if (HasExtension(path, ".mtx")) PetscCall(ReadMatrixMarketVector(comm, path, x));
  else if (HasExtension(path, ".txt") || HasExtension(path, ".dat") || HasExtension(path, ".csv")) PetscCall(ReadTextColumn(comm, path, x));
  else PetscCall(ReadBinaryVector(comm, path, x));
  for (size_t i = 0; i < x.size(); ++i)
    PetscCheck(std::isfinite(x[i]), comm, PETSC_ERR_FILE_UNEXPECTED, "load vector file '%s': entry %zu is NaN or infinite", path, i);
  PetscCall(VecCreateFromValues(comm, x, v));
  PetscFunctionReturn(0);
}

PetscErrorCode VecCreateFromValues(MPI_Comm comm, const std::vector<PetscReal> &x, Vec *v)
{
  PetscInt rstart, rend;
  PetscFunctionBeginUser;
  PetscCall(VecCreateMPI(comm, PETSC_DECIDE, (PetscInt)x.size(), v));
  PetscCall(VecGetOwnershipRange(*v, &rstart, &rend));
  for (PetscInt i = rstart; i < rend; ++i) PetscCall(VecSetValue(*v, i, x[i], INSERT_VALUES));
  PetscCall(VecAssemblyBegin(*v));
  PetscCall(VecAssemblyEnd(*v));
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

namespace detail {

// A file visible to some ranks only (node-local disk) must still fail on all ranks at once.
PetscErrorCode CheckReadable(MPI_Comm comm, const char *path, const char *what)
{
  PetscBool   found;
  PetscMPIInt here, everywhere;
  PetscFunctionBeginUser;
  PetscCall(PetscTestFile(path, 'r', &found));
  here = found ? 1 : 0;
  PetscCallMPI(MPI_Allreduce(&here, &everywhere, 1, MPI_INT, MPI_MIN, comm));
  PetscCheck(everywhere, comm, PETSC_ERR_FILE_OPEN, "%s '%s' not found (or not a readable file)", what, path);
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

// Repeated coordinates are summed, as scipy's and MATLAB's mmread do.
PetscErrorCode AssembleOwnedEntries(MPI_Comm comm, PetscInt M, PetscInt N, std::vector<Entry> &owned, Mat *A)
{
  PetscInt              rstart, rend, cstart, cend;
  std::vector<PetscInt> dnz, onz;
  Mat                   B;
  PetscFunctionBeginUser;
  PetscCall(OwnedRange(comm, M, &rstart, &rend));
  PetscCall(OwnedRange(comm, N, &cstart, &cend));
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
  PetscCall(MatSetSizes(B, rend - rstart, cend - cstart, M, N));
  PetscCall(MatSetType(B, MATAIJ));
  PetscCall(MatXAIJSetPreallocation(B, 1, dnz.data(), onz.data(), nullptr, nullptr));
  PetscCall(MatSetOption(B, MAT_NEW_NONZERO_ALLOCATION_ERR, PETSC_TRUE));
  for (const Entry &e : owned) PetscCall(MatSetValue(B, e.row, e.col, e.val, INSERT_VALUES));
  PetscCall(MatAssemblyBegin(B, MAT_FINAL_ASSEMBLY));
  PetscCall(MatAssemblyEnd(B, MAT_FINAL_ASSEMBLY));
  *A = B;
  PetscFunctionReturn(0);
}

} // namespace detail

} // namespace squeal::io
