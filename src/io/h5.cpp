#include "squeal/io/h5.h"

#include <cstring>

namespace squeal::io {

namespace {
// HDF5 returns negative ids/statuses on failure and prints its own stack; turn that into a
// PETSc error naming the operation.
#define SquealH5Call(expr, what)                                                                       \
  do {                                                                                                 \
    if ((expr) < 0) SETERRQ(PETSC_COMM_SELF, PETSC_ERR_LIB, "HDF5 failed to %s in '%s'", what, path_.c_str()); \
  } while (0)
} // namespace

H5Writer::~H5Writer() { PetscCallVoid(Close()); }

PetscErrorCode H5Writer::Open(MPI_Comm comm, const char *path)
{
  PetscFunctionBeginUser;
  PetscCall(Close());
  comm_ = comm;
  path_ = path;
  PetscCall(PetscViewerHDF5Open(comm, path, FILE_MODE_WRITE, viewer_.out()));
  PetscCall(PetscViewerHDF5GetFileId(viewer_, &file_));
  PetscFunctionReturn(0);
}

PetscErrorCode H5Writer::Close()
{
  PetscFunctionBeginUser;
  viewer_.reset();
  file_ = -1;
  PetscFunctionReturn(0);
}

PetscErrorCode H5Writer::EnsureGroup(const std::string &path, hid_t *group)
{
  PetscFunctionBeginUser;
  std::string sofar;
  size_t      pos = 1;
  while (pos <= path.size()) {
    size_t next = path.find('/', pos);
    if (next == std::string::npos) next = path.size();
    sofar = path.substr(0, next);
    if (!sofar.empty() && sofar != "/") {
      const htri_t exists = H5Lexists(file_, sofar.c_str(), H5P_DEFAULT);
      SquealH5Call(exists, "look up a group");
      if (!exists) {
        const hid_t g = H5Gcreate2(file_, sofar.c_str(), H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
        SquealH5Call(g, "create a group");
        SquealH5Call(H5Gclose(g), "close a group");
      }
    }
    pos = next + 1;
  }
  if (group) {
    *group = H5Oopen(file_, path.empty() ? "/" : path.c_str(), H5P_DEFAULT);
    SquealH5Call(*group, "open an object");
  }
  PetscFunctionReturn(0);
}

PetscErrorCode H5Writer::WriteVec(const char *group, Vec v)
{
  PetscFunctionBeginUser;
  PetscCheck(IsOpen(), comm_, PETSC_ERR_ORDER, "results file is not open");
  PetscCall(EnsureGroup(group, nullptr));
  PetscCall(PetscViewerHDF5PushGroup(viewer_, group));
  PetscCall(VecView(v, viewer_));
  PetscCall(PetscViewerHDF5PopGroup(viewer_));
  PetscFunctionReturn(0);
}

PetscErrorCode H5Writer::WriteTyped(const char *path, const std::vector<hsize_t> &dims, hid_t type, const void *data)
{
  PetscMPIInt rank;
  PetscFunctionBeginUser;
  PetscCheck(IsOpen(), comm_, PETSC_ERR_ORDER, "results file is not open");
  PetscCallMPI(MPI_Comm_rank(comm_, &rank));
  const std::string p(path);
  PetscCall(EnsureGroup(p.substr(0, p.find_last_of('/')), nullptr));
  hsize_t total = 1;
  for (hsize_t d : dims) total *= d;
  const hid_t space = dims.empty() ? H5Screate(H5S_SCALAR) : H5Screate_simple((int)dims.size(), dims.data(), nullptr);
  SquealH5Call(space, "create a dataspace");
  const hid_t dset = H5Dcreate2(file_, path, type, space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
  SquealH5Call(dset, "create a dataset");
  if (rank == 0 && total > 0) SquealH5Call(H5Dwrite(dset, type, H5S_ALL, H5S_ALL, H5P_DEFAULT, data), "write a dataset");
  SquealH5Call(H5Dclose(dset), "close a dataset");
  SquealH5Call(H5Sclose(space), "close a dataspace");
  PetscFunctionReturn(0);
}

PetscErrorCode H5Writer::WriteArray(const char *path, const std::vector<hsize_t> &dims, const PetscReal *data)
{
  PetscFunctionBeginUser;
  PetscCall(WriteTyped(path, dims, H5T_NATIVE_DOUBLE, data));
  PetscFunctionReturn(0);
}

PetscErrorCode H5Writer::WriteIntArray(const char *path, const std::vector<hsize_t> &dims, const PetscInt *data)
{
  PetscFunctionBeginUser;
  PetscCall(WriteTyped(path, dims, sizeof(PetscInt) == 8 ? H5T_NATIVE_INT64 : H5T_NATIVE_INT32, data));
  PetscFunctionReturn(0);
}

PetscErrorCode H5Writer::WriteAttr(const char *object, const char *name, hid_t type, const std::vector<hsize_t> &dims,
                                   const void *value)
{
  hid_t obj;
  PetscFunctionBeginUser;
  PetscCheck(IsOpen(), comm_, PETSC_ERR_ORDER, "results file is not open");
  const htri_t exists = H5Lexists(file_, object, H5P_DEFAULT);
  SquealH5Call(exists, "look up an object");
  if (exists > 0 || std::strcmp(object, "/") == 0) {
    obj = H5Oopen(file_, object, H5P_DEFAULT);
    SquealH5Call(obj, "open an object");
  } else {
    PetscCall(EnsureGroup(object, &obj));
  }
  if (H5Aexists(obj, name) > 0) SquealH5Call(H5Adelete(obj, name), "replace an attribute");
  const hid_t space = dims.empty() ? H5Screate(H5S_SCALAR) : H5Screate_simple((int)dims.size(), dims.data(), nullptr);
  SquealH5Call(space, "create a dataspace");
  const hid_t attr = H5Acreate2(obj, name, type, space, H5P_DEFAULT, H5P_DEFAULT);
  SquealH5Call(attr, "create an attribute");
  SquealH5Call(H5Awrite(attr, type, value), "write an attribute");
  SquealH5Call(H5Aclose(attr), "close an attribute");
  SquealH5Call(H5Sclose(space), "close a dataspace");
  SquealH5Call(H5Oclose(obj), "close an object");
  PetscFunctionReturn(0);
}

PetscErrorCode H5Writer::WriteAttribute(const char *object, const char *name, PetscReal value)
{
  PetscFunctionBeginUser;
  PetscCall(WriteAttr(object, name, H5T_NATIVE_DOUBLE, {}, &value));
  PetscFunctionReturn(0);
}

PetscErrorCode H5Writer::WriteAttribute(const char *object, const char *name, PetscInt value)
{
  PetscFunctionBeginUser;
  PetscCall(WriteAttr(object, name, sizeof(PetscInt) == 8 ? H5T_NATIVE_INT64 : H5T_NATIVE_INT32, {}, &value));
  PetscFunctionReturn(0);
}

PetscErrorCode H5Writer::WriteAttribute(const char *object, const char *name, const std::vector<PetscReal> &values)
{
  PetscFunctionBeginUser;
  PetscCall(WriteAttr(object, name, H5T_NATIVE_DOUBLE, {(hsize_t)values.size()}, values.data()));
  PetscFunctionReturn(0);
}

PetscErrorCode H5Writer::WriteAttribute(const char *object, const char *name, const char *value)
{
  PetscFunctionBeginUser;
  const hid_t type = H5Tcopy(H5T_C_S1);
  SquealH5Call(type, "create a string type");
  SquealH5Call(H5Tset_size(type, std::strlen(value) + 1), "size a string type");
  PetscCall(WriteAttr(object, name, type, {}, value));
  SquealH5Call(H5Tclose(type), "close a string type");
  PetscFunctionReturn(0);
}

} // namespace squeal::io
