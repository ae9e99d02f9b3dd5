// The results file. One HDF5 file per run, one group per analysis (/equilibrium, /stability,
// /sweep, ...), opened through PetscViewerHDF5 (parallel HDF5, Open MPI flavour).
//
// PETSc objects (distributed Vecs) are written with VecView. Small dense arrays of any rank
// (eigenvalue tables, sweep grids) and attributes go through the HDF5 C API on the viewer's file
// id: PetscViewerHDF5 writes only Vec/Mat/IS shapes. Such arrays live on rank 0; every call is
// collective (metadata operations are collective in parallel HDF5), and only rank 0 writes data.
#pragma once

#include "squeal/core/handle.h"

#include <petscviewerhdf5.h>

#include <string>
#include <vector>

namespace squeal::io {

class H5Writer {
public:
  H5Writer() = default;
  ~H5Writer();
  PetscErrorCode Open(MPI_Comm comm, const char *path);
  PetscErrorCode Close();
  bool           IsOpen() const { return (bool)viewer_; }
  const std::string &Path() const { return path_; }

  // VecView into `group` under the Vec's name.
  PetscErrorCode WriteVec(const char *group, Vec v);
  // Dense row-major array of doubles (data read on rank 0 only), any rank of dims.
  PetscErrorCode WriteArray(const char *path, const std::vector<hsize_t> &dims, const PetscReal *data);
  PetscErrorCode WriteIntArray(const char *path, const std::vector<hsize_t> &dims, const PetscInt *data);
  // Attributes on a group or dataset (created as a group if missing). Values must agree on all ranks.
  PetscErrorCode WriteAttribute(const char *object, const char *name, PetscReal value);
  PetscErrorCode WriteAttribute(const char *object, const char *name, PetscInt value);
  PetscErrorCode WriteAttribute(const char *object, const char *name, const char *value);
  PetscErrorCode WriteAttribute(const char *object, const char *name, const std::vector<PetscReal> &values);

private:
  PetscErrorCode EnsureGroup(const std::string &path, hid_t *group);
  PetscErrorCode WriteTyped(const char *path, const std::vector<hsize_t> &dims, hid_t type, const void *data);
  PetscErrorCode WriteAttr(const char *object, const char *name, hid_t type, const std::vector<hsize_t> &dims,
                           const void *value);

  MPI_Comm    comm_ = MPI_COMM_NULL;
  ViewerH     viewer_;
  hid_t       file_ = -1;
  std::string path_;
};

} // namespace squeal::io
