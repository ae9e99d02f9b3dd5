#include "squeal/io/matrix_io.h"

#include <gtest/gtest.h>
#include <petscsys.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <numeric>
#include <string>
#include <vector>

namespace {

using Dense = std::vector<std::vector<double>>;

int Rank()
{
  int rank;
  MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
  return rank;
}

// A file in the test temp dir with the same name on every rank (rank 0 writes it, all ranks read it)
// but distinct between concurrent test runs; removed when the test ends, even after a failed ASSERT.
struct TempFile {
  std::string path;
  explicit TempFile(const std::string &name, const char *text = nullptr)
  {
    static const std::string prefix = [] {
      long pid = (long)getpid();
      MPI_Bcast(&pid, 1, MPI_LONG, 0, PETSC_COMM_WORLD);
      return testing::TempDir() + "squeal_matrix_io_" + std::to_string(pid) + "_";
    }();
    path = prefix + name;
    if (text && Rank() == 0) std::ofstream(path) << text;
    MPI_Barrier(PETSC_COMM_WORLD);
  }
  ~TempFile()
  {
    MPI_Barrier(PETSC_COMM_WORLD); // nobody is still reading it
    if (Rank() == 0) std::remove(path.c_str());
  }
  const char *c_str() const { return path.c_str(); }
};

bool Exists(const std::string &path) { return std::ifstream(path).good(); }

// Like PetscReturnErrorHandler (prints nothing, passes the code up) but keeps the original message.
PetscErrorCode CaptureHandler(MPI_Comm, int, const char *, const char *, PetscErrorCode n, PetscErrorType p,
                              const char *mess, void *ctx)
{
  if (p == PETSC_ERROR_INITIAL) *static_cast<std::string *>(ctx) = mess ? mess : "";
  return n;
}

struct Failure {
  PetscErrorCode code;
  std::string    message;
};

template <class Call>
Failure RunCapturingError(Call call)
{
  Failure f{0, ""};
  PetscPushErrorHandler(CaptureHandler, &f.message);
  f.code = call();
  PetscPopErrorHandler();
  return f;
}

// Checks every entry of the locally owned rows, so the whole matrix is covered on any number of ranks.
void ExpectMatrix(Mat A, const Dense &dense, PetscInt expected_nonzeros)
{
  PetscInt M, N, rstart, rend;
  MatInfo  info;
  ASSERT_EQ(MatGetSize(A, &M, &N), 0);
  ASSERT_EQ(M, (PetscInt)dense.size());
  ASSERT_EQ(N, (PetscInt)dense[0].size());
  ASSERT_EQ(MatGetOwnershipRange(A, &rstart, &rend), 0);
  std::vector<PetscInt>    cols(N);
  std::vector<PetscScalar> row(N);
  std::iota(cols.begin(), cols.end(), 0);
  for (PetscInt i = rstart; i < rend; ++i) {
    ASSERT_EQ(MatGetValues(A, 1, &i, N, cols.data(), row.data()), 0);
    for (PetscInt j = 0; j < N; ++j) EXPECT_EQ(row[j], dense[i][j]) << "entry (" << i << ", " << j << ")";
  }
  // Exact preallocation: nothing allocated beyond the stored entries, and no mallocs during insertion.
  ASSERT_EQ(MatGetInfo(A, MAT_GLOBAL_SUM, &info), 0);
  EXPECT_EQ(info.nz_used, (double)expected_nonzeros);
  EXPECT_EQ(info.nz_unneeded, 0.0);
  EXPECT_EQ(info.mallocs, 0.0);
}

// A rectangular matrix with values that only survive a text round trip if printed with 17 digits.
PetscErrorCode BuildAwkwardMatrix(Mat *A)
{
  const PetscInt M = 7, N = 5;
  PetscInt       rstart, rend;
  PetscFunctionBeginUser;
  PetscCall(MatCreateAIJ(PETSC_COMM_WORLD, PETSC_DECIDE, PETSC_DECIDE, M, N, N, nullptr, N, nullptr, A));
  PetscCall(MatGetOwnershipRange(*A, &rstart, &rend));
  for (PetscInt i = rstart; i < rend; ++i)
    for (PetscInt j = 0; j < N; ++j) {
      if ((i + 2 * j) % 3 == 1) continue;
      const double v = (i % 2 ? -1.0 : 1.0) * std::ldexp((i + 1.0) / (j + 3.0), 40 * (int)(i - j));
      PetscCall(MatSetValue(*A, i, j, v, INSERT_VALUES));
    }
  if (rstart == 0) PetscCall(MatSetValue(*A, 0, 1, std::numeric_limits<double>::denorm_min(), INSERT_VALUES));
  PetscCall(MatAssemblyBegin(*A, MAT_FINAL_ASSEMBLY));
  PetscCall(MatAssemblyEnd(*A, MAT_FINAL_ASSEMBLY));
  PetscFunctionReturn(0);
}

void ExpectRoundTrip(const std::string &path)
{
  Mat       A = nullptr, B = nullptr;
  PetscBool equal = PETSC_FALSE;
  MatInfo   a, b;
  ASSERT_EQ(BuildAwkwardMatrix(&A), 0);
  ASSERT_EQ(squeal::io::MatSaveToFile(A, path.c_str()), 0);
  ASSERT_EQ(squeal::io::MatLoadFromFile(PETSC_COMM_WORLD, path.c_str(), &B), 0);
  ASSERT_EQ(MatEqual(A, B, &equal), 0);
  EXPECT_TRUE(equal);
  ASSERT_EQ(MatGetInfo(A, MAT_GLOBAL_SUM, &a), 0);
  ASSERT_EQ(MatGetInfo(B, MAT_GLOBAL_SUM, &b), 0);
  EXPECT_EQ(a.nz_used, b.nz_used);
  EXPECT_EQ(MatDestroy(&A), 0);
  EXPECT_EQ(MatDestroy(&B), 0);
}

struct BadFile {
  const char *name, *text, *message; // message as it continues after "matrix file '<path>'"
};

void ExpectRejected(const BadFile &c)
{
  SCOPED_TRACE(c.name);
  const TempFile file(c.name, c.text);
  Mat            A = nullptr;
  const Failure  f = RunCapturingError([&] { return squeal::io::MatLoadFromFile(PETSC_COMM_WORLD, file.c_str(), &A); });
  EXPECT_EQ(f.code, PETSC_ERR_FILE_UNEXPECTED);
  EXPECT_EQ(f.message, "matrix file '" + file.path + "'" + c.message);
  EXPECT_EQ(A, nullptr);
}

} // namespace

#define GENERAL "%%MatrixMarket matrix coordinate real general\n"

TEST(MatrixIO, ReadsGeneralCoordinate)
{
  const TempFile file("general.mtx", "%%MatrixMarket matrix coordinate real general\n"
                                     "% a comment, then a blank line\n"
                                     "\n"
                                     "5 4 7\n"
                                     "1 1 2.5\n"
                                     "5 4 -1e-3\r\n"
                                     "  3   2\t 7\n"
                                     "2 4 1.0E+2\n"
                                     "% comments may appear between entries\n"
                                     "4 1 -0.125\n"
                                     "1 3 3\n"
                                     "5 1 0\n");

  Mat A = nullptr;
  ASSERT_EQ(squeal::io::MatLoadMatrixMarket(PETSC_COMM_WORLD, file.c_str(), &A), 0);
  ExpectMatrix(A, {{2.5, 0, 3, 0}, {0, 0, 0, 100}, {0, 7, 0, 0}, {-0.125, 0, 0, 0}, {0, 0, 0, -1e-3}},
               7); // the explicit zero at (5, 1) is a structural entry
  EXPECT_EQ(MatDestroy(&A), 0);
}

TEST(MatrixIO, ExpandsSymmetricStorage)
{
  const TempFile file("symmetric.mtx", "%%MatrixMarket matrix coordinate real symmetric\n"
                                       "5 5 8\n"
                                       "1 1 4\n2 1 -1\n2 2 4\n3 2 -1\n3 3 4\n5 1 0.5\n4 4 4\n5 5 4\n");

  Mat       A         = nullptr;
  PetscBool symmetric = PETSC_FALSE;
  ASSERT_EQ(squeal::io::MatLoadFromFile(PETSC_COMM_WORLD, file.c_str(), &A), 0);
  ExpectMatrix(A, {{4, -1, 0, 0, 0.5}, {-1, 4, -1, 0, 0}, {0, -1, 4, 0, 0}, {0, 0, 0, 4, 0}, {0.5, 0, 0, 0, 4}}, 11);
  ASSERT_EQ(MatIsSymmetric(A, 0.0, &symmetric), 0);
  EXPECT_TRUE(symmetric);
  EXPECT_EQ(MatDestroy(&A), 0);
}

TEST(MatrixIO, SumsRepeatedIntegerEntries)
{
  const TempFile file("integer.mtx", "%%MATRIXMARKET Matrix Coordinate Integer General\n"
                                     "3 3 5\n"
                                     "1 1 1\n2 2 5\n3 1 -2\n2 2 -7\n1 1 10\n");

  Mat A = nullptr;
  ASSERT_EQ(squeal::io::MatLoadFromFile(PETSC_COMM_WORLD, file.c_str(), &A), 0);
  ExpectMatrix(A, {{11, 0, 0}, {0, -2, 0}, {-2, 0, 0}}, 3);
  EXPECT_EQ(MatDestroy(&A), 0);
}

TEST(MatrixIO, ReadsArrayColumnMajorWithoutZeros)
{
  const TempFile file("array.mtx", "%%MatrixMarket matrix array real general\n"
                                   "% column-major\n"
                                   "3 2\n"
                                   "1\n0\n3\n4\n5.5\n0\n");

  Mat A = nullptr;
  ASSERT_EQ(squeal::io::MatLoadFromFile(PETSC_COMM_WORLD, file.c_str(), &A), 0);
  ExpectMatrix(A, {{1, 4}, {0, 5.5}, {3, 0}}, 4);
  EXPECT_EQ(MatDestroy(&A), 0);
}

TEST(MatrixIO, MatrixMarketRoundTripIsExact)
{
  const TempFile file("roundtrip.mtx");
  ExpectRoundTrip(file.path);
}

TEST(MatrixIO, BinaryRoundTripIsExact)
{
  const TempFile file("roundtrip.bin");
  ExpectRoundTrip(file.path);
  EXPECT_FALSE(Exists(file.path + ".info")); // PETSc writes one unless told not to
}

TEST(MatrixIO, MissingFileIsReportedByName)
{
  for (const char *name : {"missing.mtx", "missing.bin"}) {
    const TempFile file(name); // never written
    Mat            A = nullptr;
    const Failure  f =
        RunCapturingError([&] { return squeal::io::MatLoadFromFile(PETSC_COMM_WORLD, file.c_str(), &A); });
    EXPECT_EQ(f.code, PETSC_ERR_FILE_OPEN);
    EXPECT_EQ(f.message, "matrix file '" + file.path + "' not found (or not a readable file)");
    EXPECT_EQ(A, nullptr);
  }
}

TEST(MatrixIO, MalformedEntriesAreReportedByLine)
{
  const BadFile cases[] = {
      {"range.mtx", GENERAL "% c\n10 10 2\n1 1 1.0\n12 3 2.0\n", ", line 5: row index 12 out of range [1, 10]"},
      {"column.mtx", GENERAL "10 10 1\n1 0 1.0\n", ", line 3: column index 0 out of range [1, 10]"},
      {"nan.mtx", GENERAL "2 2 2\n1 1 1.0\n2 2 nan\n", ", line 4: value is NaN or infinite"},
      {"inf.mtx", GENERAL "2 2 1\n1 1 -Inf\n", ", line 3: value is NaN or infinite"},
      {"overflow.mtx", GENERAL "2 2 1\n1 1 1e400\n", ", line 3: value is NaN or infinite"},
      {"few.mtx", GENERAL "10 10 9\n1 1 1\n2 2 1\n3 3 1\n4 4 1\n5 5 1\n6 6 1\n7 7 1\n",
       ": header promises 9 entries, found 7"},
      {"many.mtx", GENERAL "2 2 1\n1 1 1\n2 2 1\n", ": header promises 1 entries, found 2"},
      {"garbage.mtx", GENERAL "2 2 1\n1 x 1.0\n", ", line 3: expected 'row column value'"},
      {"index.mtx", GENERAL "2 2 1\n1.5 1 1.0\n", ", line 3: expected 'row column value'"},
      {"value.mtx", GENERAL "2 2 1\n1 1 one\n", ", line 3: cannot read a real value"},
      {"intvalue.mtx", "%%MatrixMarket matrix coordinate integer general\n2 2 1\n1 1 1.5\n",
       ", line 3: cannot read an integer value"},
      {"extra.mtx", GENERAL "2 2 1\n1 1 1.0 0.5\n", ", line 3: unexpected text after the value"},
      {"size.mtx", GENERAL "2 2\n1 1 1.0\n", ", line 2: expected size line 'rows columns entries'"},
      {"nosize.mtx", GENERAL "% only a comment\n", ": size line missing after the header"},
      {"upper.mtx", "%%MatrixMarket matrix coordinate real symmetric\n3 3 2\n1 1 1\n1 3 2\n",
       ", line 4: entry (1, 3) lies above the diagonal of a symmetric matrix"},
      {"square.mtx", "%%MatrixMarket matrix coordinate real symmetric\n3 2 0\n",
       ", line 2: symmetric matrix must be square, not 3 x 2"},
  };
  for (const BadFile &c : cases) ExpectRejected(c);
}

TEST(MatrixIO, UnsupportedFormatsAreReported)
{
  const BadFile cases[] = {
      {"complex.mtx", "%%MatrixMarket matrix coordinate complex general\n1 1 1\n1 1 1 0\n",
       ": unsupported Matrix Market type 'complex' (expected real, integer)"},
      {"pattern.mtx", "%%MatrixMarket matrix coordinate pattern general\n1 1 1\n1 1\n",
       ": unsupported Matrix Market type 'pattern' (expected real, integer)"},
      {"skew.mtx", "%%MatrixMarket matrix coordinate real skew-symmetric\n2 2 1\n2 1 1\n",
       ": unsupported Matrix Market symmetry 'skew-symmetric' for coordinate format (expected general, symmetric)"},
      {"arraysym.mtx", "%%MatrixMarket matrix array real symmetric\n1 1\n1\n",
       ": unsupported Matrix Market symmetry 'symmetric' for array format (expected general)"},
      {"vector.mtx", "%%MatrixMarket vector coordinate real general\n1 1 1\n1 1 1\n",
       ": unsupported Matrix Market object 'vector' (expected matrix)"},
      {"noheader.mtx", "1 1 1\n1 1 1.0\n", ": first line is not a '%%MatrixMarket' header"},
      {"empty.mtx", "", ": first line is not a '%%MatrixMarket' header"},
      {"text.bin", GENERAL "1 1 1\n1 1 1\n", ": not a PETSc binary matrix (accepted: PETSc binary, or Matrix Market with extension .mtx)"},
  };
  for (const BadFile &c : cases) ExpectRejected(c);
}

TEST(MatrixIO, UnwritablePathIsReported)
{
  Mat A = nullptr;
  ASSERT_EQ(BuildAwkwardMatrix(&A), 0);
  for (const char *path : {"/nonexistent-squeal-dir/k.mtx", "/nonexistent-squeal-dir/k.bin"}) {
    const Failure f = RunCapturingError([&] { return squeal::io::MatSaveToFile(A, path); });
    EXPECT_EQ(f.code, PETSC_ERR_FILE_OPEN);
    EXPECT_EQ(f.message, std::string("matrix file '") + path + "' cannot be written: No such file or directory");
  }
  EXPECT_EQ(MatDestroy(&A), 0);
}
