#include "squeal/io/h5.h"
#include "squeal/core/interrupt.h"

#include <cerrno>
#include <climits>
#include <cstdio>
#include <cstring>
#include <functional>
#include <fcntl.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/statvfs.h>
#include <unistd.h>

namespace squeal::io {

namespace {

// HDF5 prints its own error stack (15 lines for a missing directory); squeal reports one line.
void QuietHDF5() { H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr); }

std::string DirName(const std::string &p)
{
  const size_t s = p.find_last_of('/');
  if (s == std::string::npos) return ".";
  return s == 0 ? "/" : p.substr(0, s);
}

std::string BaseName(const std::string &p)
{
  const size_t s = p.find_last_of('/');
  return s == std::string::npos ? p : p.substr(s + 1);
}

} // namespace

H5Writer::~H5Writer()
{
  if (open_ && !keep_status_.empty()) {
    // An error raised by an interrupt inside a solver (InterruptPoint) is an interrupt, not a failure.
    const std::string status = InterruptSignal() ? std::string("interrupted (") + InterruptSignalName() +
                                                     ") inside an analysis; the groups written before it are complete"
                                                 : keep_status_;
    PetscCallVoid(SetStatus(status.c_str()));
    PetscCallVoid(Close());
    if (aside_)
      PetscCallVoid(PetscFPrintf(comm_, PETSC_STDERR,
                                 "squeal: results computed before the error written to %s (the complete results in %s are kept)\n",
                                 aside_path_.c_str(), path_.c_str()));
    else PetscCallVoid(PetscFPrintf(comm_, PETSC_STDERR, "squeal: results computed before the error written to %s\n", path_.c_str()));
  }
  PetscCallVoid(Close());
}

void H5Writer::Fail(const char *what)
{
  if (err_.empty()) err_ = std::string("HDF5 failed to ") + what + " in results file '" + path_ + "' (temporary '" + tmp_ + "')";
}

PetscErrorCode H5Writer::Sync()
{
  PetscMPIInt bad = err_.empty() ? 0 : 1;
  PetscFunctionBeginUser;
  PetscCallMPI(MPI_Bcast(&bad, 1, MPI_INT, 0, comm_));
  if (bad) {
    const std::string msg = err_.empty() ? std::string("results file error on rank 0") : err_;
    err_.clear();
    SETERRQ(comm_, PETSC_ERR_FILE_WRITE, "%s", msg.c_str());
  }
  PetscFunctionReturn(0);
}

PetscErrorCode H5Writer::CheckOpen()
{
  PetscFunctionBeginUser;
  PetscCheck(open_, comm_ == MPI_COMM_NULL ? PETSC_COMM_SELF : comm_, PETSC_ERR_ORDER, "results file is not open");
  // A write follows: the file on disk is no longer known to be consistent. Unless it was salvaged
  // after a signal (core/interrupt.h): then it is not touched again.
  if (!InterruptSalvageReady(false) && err_.empty())
    err_ = "the results written before the signal were moved to their name (said above); nothing more is written to them";
  PetscFunctionReturn(0);
}

namespace {

// The root string attribute `name` of the open file `f` if it has at most 63 characters, else "".
std::string RootStringAttribute(hid_t f, const char *name)
{
  char buf[64] = {0};
  if (H5Aexists(f, name) <= 0) return "";
  const hid_t a = H5Aopen(f, name, H5P_DEFAULT);
  const hid_t t = a >= 0 ? H5Aget_type(a) : -1;
  const bool  ok = t >= 0 && H5Tget_class(t) == H5T_STRING && H5Tget_size(t) < sizeof buf && H5Aread(a, t, buf) >= 0;
  if (t >= 0) H5Tclose(t);
  if (a >= 0) H5Aclose(a);
  return ok ? std::string(buf) : std::string();
}

// Whether the open file `f` has the object `path` (absolute): H5Lexists needs every parent to exist,
// so the path is walked from the root.
bool PathExists(hid_t f, const std::string &path)
{
  bool exists = true;
  for (size_t k = path.find('/', 1); exists; k = path.find('/', k + 1)) {
    exists = H5Lexists(f, path.substr(0, k).c_str(), H5P_DEFAULT) > 0;
    if (k == std::string::npos) break;
  }
  return exists;
}

} // namespace

bool H5Writer::IsResultsFile(const char *path)
{
  QuietHDF5();
  if (H5Fis_hdf5(path) <= 0) return false;
  const hid_t f = H5Fopen(path, H5F_ACC_RDONLY, H5P_DEFAULT);
  if (f < 0) return false;
  bool ours;
  if (H5Aexists(f, "creator") > 0) ours = RootStringAttribute(f, "creator").rfind("squeal", 0) == 0;
  else ours = H5Lexists(f, "/model", H5P_DEFAULT) > 0; // written before the creator attribute existed
  H5Fclose(f);
  return ours;
}

bool H5Writer::IsCompleteResultsFile(const char *path)
{
  if (!IsResultsFile(path)) return false;
  const hid_t f = H5Fopen(path, H5F_ACC_RDONLY, H5P_DEFAULT);
  if (f < 0) return false;
  const bool complete = RootStringAttribute(f, "status") == "complete";
  H5Fclose(f);
  return complete;
}

std::string H5Writer::FailedSibling(const std::string &path)
{
  std::string stem = path;
  for (const char *ext : {".h5", ".hdf5"}) {
    const size_t n = std::strlen(ext);
    if (stem.size() > n && stem.compare(stem.size() - n, n, ext) == 0) {
      stem.resize(stem.size() - n);
      break;
    }
  }
  // Within NAME_MAX (255 bytes) for the file name: a long stem is cut.
  const size_t dir = stem.find_last_of('/') == std::string::npos ? 0 : stem.find_last_of('/') + 1;
  const size_t max = 255 - std::strlen(".failed.h5");
  if (stem.size() - dir > max) stem.resize(dir + max);
  return stem + ".failed.h5";
}

PetscErrorCode H5Writer::Open(MPI_Comm comm, const char *path)
{
  PetscFunctionBeginUser;
  PetscCall(Close());
  comm_ = comm;
  PetscCallMPI(MPI_Comm_rank(comm, &rank_));
  path_ = path ? path : "";
  tmp_  = DirName(path_) + "/." + BaseName(path_) + ".part-" + std::to_string((long long)getpid());
  // A name near NAME_MAX (255 bytes) leaves no room for the temporary's dot and suffix: a short
  // temporary name then, still beside the target (rename(2) must stay within one file system).
  if (BaseName(tmp_).size() > 255) {
    char h[32];
    std::snprintf(h, sizeof h, "%016zx", std::hash<std::string>{}(BaseName(path_)));
    tmp_ = DirName(path_) + "/.squeal-" + h + ".part-" + std::to_string((long long)getpid());
  }
  err_.clear();
  status_.clear();
  aside_path_.clear();
  aside_ = false;
  PetscCheck(!path_.empty() && path_.back() != '/', comm, PETSC_ERR_USER_INPUT, "-output '%s': expected a file name", path_.c_str());
  if (rank_ == 0) {
    QuietHDF5();
    struct stat st;
    if (stat(path_.c_str(), &st) == 0) {
      if (S_ISDIR(st.st_mode)) err_ = "-output '" + path_ + "' is a directory: expected a results file name (.h5)";
      else if (!IsResultsFile(path_.c_str()))
        err_ = "refusing to overwrite '" + path_ + "': it exists and is not a squeal results file; choose another -output (.h5)";
    }
    if (err_.empty()) {
      // open(2) first: it says why (no such directory, permission), HDF5 does not.
      const int fd = ::open(tmp_.c_str(), O_CREAT | O_EXCL | O_WRONLY, 0644);
      if (fd < 0) err_ = "cannot write results file '" + path_ + "': " + std::strerror(errno) + " (-output)";
      else ::close(fd);
    }
    if (err_.empty()) {
      file_ = H5Fcreate(tmp_.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
      if (file_ < 0) {
        Fail("create the file");
        std::remove(tmp_.c_str());
      } else InterruptSalvage(tmp_.c_str(), (IsCompleteResultsFile(path_.c_str()) ? FailedSibling(path_) : path_).c_str());
    }
  }
  {
    PetscMPIInt bad = err_.empty() ? 0 : 1;
    PetscCallMPI(MPI_Bcast(&bad, 1, MPI_INT, 0, comm_));
    if (bad) {
      const std::string msg = err_;
      err_.clear();
      SETERRQ(comm, PETSC_ERR_FILE_OPEN, "%s", msg.c_str());
    }
  }
  open_ = true;
  PetscCall(WriteAttribute("/", "creator", "squeal results file (see docs/user-guide.md, Results file)"));
  PetscCall(SetStatus("running"));
  PetscFunctionReturn(0);
}

PetscErrorCode H5Writer::Close()
{
  PetscFunctionBeginUser;
  if (!open_) PetscFunctionReturn(0);
  open_ = false;
  InterruptSalvage(nullptr, nullptr);
  PetscMPIInt aside = 0;
  if (rank_ == 0 && InterruptSalvaged()) {
    // Renamed already, and it may be killed any moment: closing would write to it again.
    file_ = -1;
    if (err_.empty()) err_ = "the results written before the signal were moved to their name (said above)";
  } else if (rank_ == 0) {
    if (H5Fclose(file_) < 0) Fail("close the file");
    file_ = -1;
    std::string target = path_;
    if (status_ != "complete" && IsCompleteResultsFile(path_.c_str())) {
      aside  = 1;
      target = FailedSibling(path_);
    }
    if (err_.empty() && std::rename(tmp_.c_str(), target.c_str()) != 0)
      err_ = "cannot rename '" + tmp_ + "' to '" + target + "': " + std::strerror(errno);
  }
  PetscCallMPI(MPI_Bcast(&aside, 1, MPI_INT, 0, comm_));
  aside_      = aside != 0;
  aside_path_ = aside_ ? FailedSibling(path_) : std::string();
  PetscCall(Sync());
  PetscFunctionReturn(0);
}

PetscErrorCode H5Writer::Flush()
{
  PetscFunctionBeginUser;
  PetscCall(CheckOpen());
  if (rank_ == 0 && err_.empty() && H5Fflush(file_, H5F_SCOPE_LOCAL) < 0) Fail("flush");
  if (rank_ == 0 && err_.empty()) InterruptSalvageReady(true);
  PetscCall(Sync());
  PetscFunctionReturn(0);
}

PetscErrorCode H5Writer::SetStatus(const char *status)
{
  PetscFunctionBeginUser;
  PetscCall(WriteAttribute("/", "status", status));
  status_ = status;
  PetscFunctionReturn(0);
}

void H5Writer::EnsureGroup(const std::string &path)
{
  size_t pos = 1;
  while (err_.empty() && pos <= path.size()) {
    size_t next = path.find('/', pos);
    if (next == std::string::npos) next = path.size();
    const std::string sofar = path.substr(0, next);
    if (!sofar.empty() && sofar != "/") {
      const htri_t exists = H5Lexists(file_, sofar.c_str(), H5P_DEFAULT);
      if (exists < 0) Fail("look up a group");
      else if (!exists) {
        const hid_t g = H5Gcreate2(file_, sofar.c_str(), H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
        if (g < 0 || H5Gclose(g) < 0) Fail(("create group " + sofar).c_str());
      }
    }
    pos = next + 1;
  }
}

// A write that runs out of room (a full disk, the process's file size limit) cannot be undone:
// HDF5 keeps the new dataset's metadata to write at the close, the close fails too, and the
// library's own clean-up at MPI_Finalize then crashed (Debian's HDF5 1.10: a segmentation fault,
// the results left in the hidden temporary file). So a dataset is checked against the room left
// before it is created; refused, the file still closes with what was written before it.
std::string H5Writer::RoomFor(const std::string &name, double bytes) const
{
  // The dataset's header, the file's metadata and the closing status attribute: well under this.
  constexpr double  kSlack = 1048576.0;
  const double      need   = bytes + kSlack;
  const std::string dir    = DirName(tmp_);
  char              b[2 * PATH_MAX + 512]; // two paths (-output takes 300-character ones) and the numbers
  struct statvfs    fs;
  // A file system that reports no size (some FUSE mounts: f_blocks 0) is not judged.
  if (statvfs(dir.c_str(), &fs) == 0 && fs.f_blocks > 0) {
    const double avail = (double)fs.f_bavail * (double)fs.f_frsize;
    if (need > avail) {
      std::snprintf(b, sizeof b,
                    "no room for dataset %s (%.1f MiB) in results file '%s': %.1f MiB left on the file system of '%s'; free some, or "
                    "give -output on another file system",
                    name.c_str(), bytes / 1048576.0, path_.c_str(), avail / 1048576.0, dir.c_str());
      return b;
    }
  }
  struct rlimit lim;
  struct stat   st;
  if (getrlimit(RLIMIT_FSIZE, &lim) == 0 && lim.rlim_cur != RLIM_INFINITY && stat(tmp_.c_str(), &st) == 0 &&
      (double)st.st_size + need > (double)lim.rlim_cur) {
    std::snprintf(b, sizeof b,
                  "no room for dataset %s (%.1f MiB) in results file '%s': the process's file size limit is %.1f MiB (ulimit -f) and the "
                  "file holds %.1f MiB",
                  name.c_str(), bytes / 1048576.0, path_.c_str(), (double)lim.rlim_cur / 1048576.0, (double)st.st_size / 1048576.0);
    return b;
  }
  return "";
}

void H5Writer::WriteTyped(const char *path, const std::vector<hsize_t> &dims, hid_t type, const void *data)
{
  const std::string p(path);
  EnsureGroup(p.substr(0, p.find_last_of('/')));
  if (!err_.empty()) return;
  hsize_t total = 1;
  for (hsize_t d : dims) total *= d;
  {
    const std::string room = RoomFor(p, (double)total * (double)H5Tget_size(type));
    if (!room.empty()) {
      // The group stays without this dataset; its attribute says so to whoever reads the file (in
      // the slack RoomFor keeps).
      const std::string group = p.substr(0, p.find_last_of('/'));
      const hid_t       st    = H5Tcopy(H5T_C_S1);
      if (st >= 0 && H5Tset_size(st, room.size() + 1) >= 0) WriteAttr(group.empty() ? "/" : group.c_str(), "incomplete", st, {}, room.c_str());
      if (st >= 0) H5Tclose(st);
      err_ = room;
      return;
    }
  }
  const hid_t space = dims.empty() ? H5Screate(H5S_SCALAR) : H5Screate_simple((int)dims.size(), dims.data(), nullptr);
  if (space < 0) return Fail("create a dataspace");
  const hid_t dset = H5Dcreate2(file_, path, type, space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
  if (dset < 0) Fail(("create dataset " + p).c_str());
  else {
    if (total > 0 && H5Dwrite(dset, type, H5S_ALL, H5S_ALL, H5P_DEFAULT, data) < 0) Fail(("write dataset " + p).c_str());
    H5Dclose(dset);
  }
  H5Sclose(space);
}

PetscErrorCode H5Writer::WriteVec(const char *group, Vec v)
{
  VecScatter         sc;
  Vec                all;
  const char        *name;
  const PetscScalar *a;
  PetscInt           n;
  PetscFunctionBeginUser;
  PetscCall(CheckOpen());
  PetscCall(PetscObjectGetName((PetscObject)v, &name));
  PetscCall(VecScatterCreateToZero(v, &sc, &all));
  PetscCall(VecScatterBegin(sc, v, all, INSERT_VALUES, SCATTER_FORWARD));
  PetscCall(VecScatterEnd(sc, v, all, INSERT_VALUES, SCATTER_FORWARD));
  PetscCall(VecGetLocalSize(all, &n));
  if (rank_ == 0) {
    std::vector<PetscReal> x(n);
    PetscCall(VecGetArrayRead(all, &a));
    for (PetscInt i = 0; i < n; ++i) x[i] = PetscRealPart(a[i]);
    PetscCall(VecRestoreArrayRead(all, &a));
    WriteTyped((std::string(group) + "/" + name).c_str(), {(hsize_t)n}, H5T_NATIVE_DOUBLE, x.data());
  }
  PetscCall(VecScatterDestroy(&sc));
  PetscCall(VecDestroy(&all));
  PetscCall(Sync());
  PetscFunctionReturn(0);
}

PetscErrorCode H5Writer::Remove(const char *path)
{
  PetscFunctionBeginUser;
  PetscCall(CheckOpen());
  if (rank_ == 0 && err_.empty() && PathExists(file_, path) && H5Ldelete(file_, path, H5P_DEFAULT) < 0)
    Fail((std::string("remove ") + path).c_str());
  PetscCall(Sync());
  PetscFunctionReturn(0);
}

PetscErrorCode H5Writer::WriteArray(const char *path, const std::vector<hsize_t> &dims, const PetscReal *data)
{
  PetscFunctionBeginUser;
  PetscCall(CheckOpen());
  if (rank_ == 0) WriteTyped(path, dims, H5T_NATIVE_DOUBLE, data);
  PetscCall(Sync());
  PetscFunctionReturn(0);
}

PetscErrorCode H5Writer::WriteIntArray(const char *path, const std::vector<hsize_t> &dims, const PetscInt *data)
{
  PetscFunctionBeginUser;
  PetscCall(CheckOpen());
  if (rank_ == 0) WriteTyped(path, dims, sizeof(PetscInt) == 8 ? H5T_NATIVE_INT64 : H5T_NATIVE_INT32, data);
  PetscCall(Sync());
  PetscFunctionReturn(0);
}

void H5Writer::WriteAttr(const char *object, const char *name, hid_t type, const std::vector<hsize_t> &dims,
                         const void *value)
{
  hid_t obj;
  if (!err_.empty()) return;
  const bool   root   = std::strcmp(object, "/") == 0;
  const htri_t exists = root ? 1 : H5Lexists(file_, object, H5P_DEFAULT);
  if (exists < 0) return Fail("look up an object");
  if (!exists) EnsureGroup(object);
  if (!err_.empty()) return;
  obj = H5Oopen(file_, object, H5P_DEFAULT);
  if (obj < 0) return Fail(("open " + std::string(object)).c_str());
  if (H5Aexists(obj, name) > 0 && H5Adelete(obj, name) < 0) Fail("replace an attribute");
  const hid_t space = dims.empty() ? H5Screate(H5S_SCALAR) : H5Screate_simple((int)dims.size(), dims.data(), nullptr);
  const hid_t attr  = err_.empty() && space >= 0 ? H5Acreate2(obj, name, type, space, H5P_DEFAULT, H5P_DEFAULT) : -1;
  if (attr < 0 || H5Awrite(attr, type, value) < 0) Fail(("write attribute " + std::string(object) + ":" + name).c_str());
  if (attr >= 0) H5Aclose(attr);
  if (space >= 0) H5Sclose(space);
  H5Oclose(obj);
}

PetscErrorCode H5Writer::WriteAttribute(const char *object, const char *name, PetscReal value)
{
  PetscFunctionBeginUser;
  PetscCall(CheckOpen());
  if (rank_ == 0) WriteAttr(object, name, H5T_NATIVE_DOUBLE, {}, &value);
  PetscCall(Sync());
  PetscFunctionReturn(0);
}

PetscErrorCode H5Writer::WriteAttribute(const char *object, const char *name, PetscInt value)
{
  PetscFunctionBeginUser;
  PetscCall(CheckOpen());
  if (rank_ == 0) WriteAttr(object, name, sizeof(PetscInt) == 8 ? H5T_NATIVE_INT64 : H5T_NATIVE_INT32, {}, &value);
  PetscCall(Sync());
  PetscFunctionReturn(0);
}

PetscErrorCode H5Writer::WriteAttribute(const char *object, const char *name, const std::vector<PetscReal> &values)
{
  PetscFunctionBeginUser;
  PetscCall(CheckOpen());
  // An empty list (no spectral bases yet in a steady state stopped early) is a zero-length
  // attribute: H5Awrite refuses the null pointer an empty vector's data() may be.
  static const PetscReal none = 0;
  if (rank_ == 0) WriteAttr(object, name, H5T_NATIVE_DOUBLE, {(hsize_t)values.size()}, values.empty() ? &none : values.data());
  PetscCall(Sync());
  PetscFunctionReturn(0);
}

PetscErrorCode H5Writer::WriteAttribute(const char *object, const char *name, const char *value)
{
  PetscFunctionBeginUser;
  PetscCall(CheckOpen());
  if (rank_ == 0) {
    const hid_t type = H5Tcopy(H5T_C_S1);
    if (type < 0 || H5Tset_size(type, std::strlen(value) + 1) < 0) Fail("create a string type");
    else WriteAttr(object, name, type, {}, value);
    if (type >= 0) H5Tclose(type);
  }
  PetscCall(Sync());
  PetscFunctionReturn(0);
}

H5Reader::~H5Reader()
{
  if (file_ >= 0) H5Fclose(file_);
}

PetscErrorCode H5Reader::Sync()
{
  PetscMPIInt bad = err_.empty() ? 0 : 1;
  PetscFunctionBeginUser;
  PetscCallMPI(MPI_Bcast(&bad, 1, MPI_INT, 0, comm_));
  if (bad) {
    const std::string msg = err_.empty() ? std::string("reading '") + path_ + "' (" + what_ + ") failed on rank 0" : err_;
    err_.clear();
    SETERRQ(comm_, PETSC_ERR_FILE_READ, "%s", msg.c_str());
  }
  PetscFunctionReturn(0);
}

PetscErrorCode H5Reader::Open(MPI_Comm comm, const char *path, const char *what)
{
  PetscFunctionBeginUser;
  if (file_ >= 0) H5Fclose(file_), file_ = -1;
  comm_ = comm;
  path_ = path ? path : "";
  what_ = what ? what : "";
  PetscCallMPI(MPI_Comm_rank(comm, &rank_));
  if (rank_ == 0) {
    QuietHDF5();
    struct stat st;
    if (stat(path_.c_str(), &st) != 0) err_ = what_ + " '" + path_ + "': " + std::strerror(errno);
    else if (S_ISDIR(st.st_mode)) err_ = what_ + " '" + path_ + "' is a directory: expected a squeal results file (.h5)";
    else if (!H5Writer::IsResultsFile(path_.c_str())) err_ = what_ + " '" + path_ + "' is not a squeal results file (HDF5 written by squeal -output)";
    else if ((file_ = H5Fopen(path_.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT)) < 0) err_ = what_ + " '" + path_ + "': HDF5 cannot open it";
    else status_ = RootStringAttribute(file_, "status");
  }
  PetscCall(Sync());
  {
    // Every rank knows the status (a caller may warn that the file is not complete).
    int n = (int)status_.size();
    PetscCallMPI(MPI_Bcast(&n, 1, MPI_INT, 0, comm_));
    status_.resize((size_t)n);
    if (n) PetscCallMPI(MPI_Bcast(status_.data(), n, MPI_CHAR, 0, comm_));
  }
  PetscFunctionReturn(0);
}

PetscErrorCode H5Reader::Dims(const char *name, std::vector<hsize_t> &dims)
{
  int nd = 0;
  PetscFunctionBeginUser;
  dims.clear();
  if (rank_ == 0 && file_ >= 0) {
    const std::string p(name);
    if (PathExists(file_, p) && H5Oexists_by_name(file_, name, H5P_DEFAULT) > 0) {
      const hid_t d = H5Dopen2(file_, name, H5P_DEFAULT);
      const hid_t s = d >= 0 ? H5Dget_space(d) : -1;
      nd            = s >= 0 ? H5Sget_simple_extent_ndims(s) : -1;
      if (nd > 0) {
        dims.resize((size_t)nd);
        H5Sget_simple_extent_dims(s, dims.data(), nullptr);
      } else if (nd < 0) err_ = what_ + " '" + path_ + "': " + p + " is not a dataset";
      if (s >= 0) H5Sclose(s);
      if (d >= 0) H5Dclose(d);
      nd = (int)dims.size();
    }
  }
  PetscCall(Sync());
  PetscCallMPI(MPI_Bcast(&nd, 1, MPI_INT, 0, comm_));
  dims.resize((size_t)nd);
  if (nd) PetscCallMPI(MPI_Bcast(dims.data(), nd, MPI_UNSIGNED_LONG_LONG, 0, comm_));
  PetscFunctionReturn(0);
}

PetscErrorCode H5Reader::Read(const char *name, std::vector<PetscReal> &data, hsize_t row)
{
  std::vector<hsize_t> dims;
  PetscFunctionBeginUser;
  PetscCall(Dims(name, dims));
  PetscCheck(!dims.empty(), comm_, PETSC_ERR_FILE_UNEXPECTED, "%s '%s' has no dataset %s", what_.c_str(), path_.c_str(), name);
  const bool one = row != (hsize_t)-1;
  PetscCheck(!one || row < dims[0], comm_, PETSC_ERR_FILE_UNEXPECTED, "%s '%s': %s has %llu rows, not row %llu", what_.c_str(),
             path_.c_str(), name, (unsigned long long)dims[0], (unsigned long long)row);
  size_t count = 1;
  for (size_t i = one ? 1 : 0; i < dims.size(); ++i) count *= (size_t)dims[i];
  data.assign(count, 0.0);
  if (rank_ == 0) {
    const hid_t d = H5Dopen2(file_, name, H5P_DEFAULT);
    const hid_t t = d >= 0 ? H5Dget_type(d) : -1;
    if (t < 0 || H5Tget_class(t) != H5T_FLOAT) err_ = what_ + " '" + path_ + "': " + name + " is not an array of reals";
    else {
      hid_t fs = H5S_ALL, ms = H5S_ALL;
      if (one) {
        std::vector<hsize_t> start(dims.size(), 0), cnt(dims);
        start[0] = row, cnt[0] = 1;
        fs       = H5Dget_space(d);
        H5Sselect_hyperslab(fs, H5S_SELECT_SET, start.data(), nullptr, cnt.data(), nullptr);
        const hsize_t n = count;
        ms              = H5Screate_simple(1, &n, nullptr);
      }
      if (count && H5Dread(d, H5T_NATIVE_DOUBLE, ms, fs, H5P_DEFAULT, data.data()) < 0)
        err_ = what_ + " '" + path_ + "': HDF5 failed to read " + name;
      if (one) H5Sclose(fs), H5Sclose(ms);
    }
    if (t >= 0) H5Tclose(t);
    if (d >= 0) H5Dclose(d);
  }
  PetscCall(Sync());
  if (count) PetscCallMPI(MPI_Bcast(data.data(), (int)count, MPIU_REAL, 0, comm_));
  PetscFunctionReturn(0);
}

PetscErrorCode H5Reader::ReadScalar(const char *name, const char *attr, PetscReal *v, bool *found)
{
  PetscReal x[2] = {0, 0}; // value, found
  PetscFunctionBeginUser;
  if (rank_ == 0 && file_ >= 0 && PathExists(file_, name)) {
    double val = 0;
    if (attr) {
      if (H5Aexists_by_name(file_, name, attr, H5P_DEFAULT) > 0) {
        const hid_t a = H5Aopen_by_name(file_, name, attr, H5P_DEFAULT, H5P_DEFAULT);
        const hid_t s = a >= 0 ? H5Aget_space(a) : -1;
        const hid_t t = a >= 0 ? H5Aget_type(a) : -1;
        const H5T_class_t c = t >= 0 ? H5Tget_class(t) : H5T_NO_CLASS;
        if (s >= 0 && H5Sget_simple_extent_npoints(s) == 1 && (c == H5T_FLOAT || c == H5T_INTEGER) && H5Aread(a, H5T_NATIVE_DOUBLE, &val) >= 0)
          x[0] = val, x[1] = 1;
        if (t >= 0) H5Tclose(t);
        if (s >= 0) H5Sclose(s);
        if (a >= 0) H5Aclose(a);
      }
    } else if (H5Oexists_by_name(file_, name, H5P_DEFAULT) > 0) {
      const hid_t d = H5Dopen2(file_, name, H5P_DEFAULT);
      const hid_t s = d >= 0 ? H5Dget_space(d) : -1;
      const hid_t t = d >= 0 ? H5Dget_type(d) : -1;
      const H5T_class_t c = t >= 0 ? H5Tget_class(t) : H5T_NO_CLASS;
      if (s >= 0 && H5Sget_simple_extent_npoints(s) == 1 && (c == H5T_FLOAT || c == H5T_INTEGER) &&
          H5Dread(d, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, &val) >= 0)
        x[0] = val, x[1] = 1;
      if (t >= 0) H5Tclose(t);
      if (s >= 0) H5Sclose(s);
      if (d >= 0) H5Dclose(d);
    }
  }
  PetscCallMPI(MPI_Bcast(x, 2, MPIU_REAL, 0, comm_));
  *v     = x[0];
  *found = x[1] != 0;
  PetscFunctionReturn(0);
}

} // namespace squeal::io
