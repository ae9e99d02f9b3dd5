// The results file. One HDF5 file per run, one group per analysis (/equilibrium, /stability,
// /sweep, ...); the datasets are listed in docs/user-guide.md ("Results file").
//
// Results are never lost or mixed:
//  - Open() refuses to replace an existing file that is not a squeal results file (an HDF5 file
//    whose root carries creator = "squeal...", or an older one with a /model group), and writes
//    into a temporary file beside the target (".NAME.part-PID"); Close() renames it onto the
//    target. rename(2) is atomic, so two runs writing the same target leave one complete file
//    (the last to finish), never a mixture; a reader never sees a half-written file.
//  - Flush() after each analysis puts what is complete on disk (in the temporary file).
//  - The root attribute "status" says "complete", "interrupted (SIGINT)" or "failed: ...".
//  - A run that did not complete never replaces a complete results file: its file goes beside
//    the target as NAME.failed.h5 (NAME.h5 the target), and Path() then names that file.
//
// Only rank 0 touches the file, through HDF5's default (serial, POSIX) driver: every array squeal
// writes is small or already gathered to rank 0, and the MPI-IO driver overflows a buffer on
// paths of ~245 characters or more (file locking). Calls are collective: a failure on rank 0 is
// raised on every rank, with a one-line message naming the file.
#pragma once

#include <petscvec.h>

#include <hdf5.h>

#include <string>
#include <vector>

namespace squeal::io {

class H5Writer {
public:
  H5Writer() = default;
  ~H5Writer();
  H5Writer(const H5Writer &)            = delete;
  H5Writer &operator=(const H5Writer &) = delete;

  // Checks the target (not a directory, not a foreign file, directory writable) and creates the
  // temporary file. Collective.
  PetscErrorCode Open(MPI_Comm comm, const char *path);
  // Closes the temporary file and renames it onto the target (or, if the status is not
  // "complete" and the target is a complete results file, onto NAME.failed.h5 beside it).
  // Collective; no-op if not open.
  PetscErrorCode Close();
  // Writes buffered data to disk. Collective.
  PetscErrorCode Flush();
  bool               IsOpen() const { return open_; }
  MPI_Comm           Comm() const { return comm_; }
  // The file the results went to: the target, or its .failed.h5 sibling (see Close).
  const std::string &Path() const { return aside_ ? aside_path_ : path_; }
  const std::string &TemporaryPath() const { return tmp_; }

  // Root attribute "status" ("complete", "interrupted (SIGINT) ...", "failed: ...").
  PetscErrorCode SetStatus(const char *status);
  // If the writer is destroyed while open (an error unwound the caller), set this status, keep
  // the file (rename it onto the target) and say so on stderr.
  void KeepOnError(const char *status) { keep_status_ = status; }
  // The gathered Vec as a 1-D dataset `group`/<name of the Vec>.
  PetscErrorCode WriteVec(const char *group, Vec v);
  // Dense row-major array of doubles (data read on rank 0 only), any rank of dims.
  PetscErrorCode WriteArray(const char *path, const std::vector<hsize_t> &dims, const PetscReal *data);
  PetscErrorCode WriteIntArray(const char *path, const std::vector<hsize_t> &dims, const PetscInt *data);
  // Removes the group or dataset `path` if the file has it (a result written again: the second
  // attempt's datasets only, none of the first's). Collective.
  PetscErrorCode Remove(const char *path);
  // Attributes on a group or dataset (created as a group if missing). Values are taken from rank 0.
  PetscErrorCode WriteAttribute(const char *object, const char *name, PetscReal value);
  PetscErrorCode WriteAttribute(const char *object, const char *name, PetscInt value);
  PetscErrorCode WriteAttribute(const char *object, const char *name, const char *value);
  PetscErrorCode WriteAttribute(const char *object, const char *name, const std::vector<PetscReal> &values);

  // True if `path` is an HDF5 file written by squeal (rank-local, no MPI).
  static bool IsResultsFile(const char *path);
  // True if `path` is a squeal results file whose status is "complete" (rank-local, no MPI).
  static bool IsCompleteResultsFile(const char *path);
  // NAME.failed.h5 for NAME.h5 (or NAME.hdf5, or NAME with another ending: NAME.failed.h5).
  static std::string FailedSibling(const std::string &path);

private:
  // Rank-0 parts: record the first failure in err_ instead of raising.
  void           EnsureGroup(const std::string &path);
  void           WriteTyped(const char *path, const std::vector<hsize_t> &dims, hid_t type, const void *data);
  // Empty if `bytes` more fit on the temporary file's file system and under the process's file
  // size limit; else the message that says why not.
  std::string    RoomFor(const std::string &name, double bytes) const;
  void           WriteAttr(const char *object, const char *name, hid_t type, const std::vector<hsize_t> &dims,
                           const void *value);
  void           Fail(const char *what);
  // Raises err_ (from rank 0) on every rank of comm_.
  PetscErrorCode Sync();
  PetscErrorCode CheckOpen();

  MPI_Comm    comm_ = MPI_COMM_NULL;
  PetscMPIInt rank_ = 0;
  bool        open_ = false;
  hid_t       file_ = -1;
  std::string path_, tmp_, err_, keep_status_, status_, aside_path_;
  bool        aside_ = false; // the file went to aside_path_ (see Close)
};

// Reading back a squeal results file (a transient's start, -transient_start). Rank 0 reads through
// HDF5's serial driver and every rank gets the values; calls are collective, and a failure (no such
// file, not a results file, a dataset of another type) is one message naming the file and `what`
// (the option that named it).
class H5Reader {
public:
  H5Reader() = default;
  ~H5Reader();
  H5Reader(const H5Reader &)            = delete;
  H5Reader &operator=(const H5Reader &) = delete;

  PetscErrorCode     Open(MPI_Comm comm, const char *path, const char *what);
  const std::string &Path() const { return path_; }
  // The dimensions of dataset `name` (absolute path); empty if the file has none of that name.
  PetscErrorCode Dims(const char *name, std::vector<hsize_t> &dims);
  // Dataset `name` as doubles, row-major: the whole of it, or only its row `row` along the first
  // dimension (a record of a transient's /transient/U without reading the others).
  PetscErrorCode Read(const char *name, std::vector<PetscReal> &data, hsize_t row = (hsize_t)-1);
  // A real scalar: the dataset `name` holding one value, or with `attr` the attribute `attr` of the
  // object `name`; *found false (and *v 0) if absent.
  PetscErrorCode ReadScalar(const char *name, const char *attr, PetscReal *v, bool *found);
  // The root attribute "status" ("complete", "interrupted (SIGINT) ...", "failed: ...").
  const std::string &Status() const { return status_; }

private:
  PetscErrorCode Sync(); // raises err_ (from rank 0) on every rank
  MPI_Comm       comm_ = MPI_COMM_NULL;
  PetscMPIInt    rank_ = 0;
  hid_t          file_ = -1;
  std::string    path_, what_, err_, status_;
};

} // namespace squeal::io
