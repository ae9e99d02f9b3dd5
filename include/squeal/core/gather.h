// A small distributed vector in full on every rank, as the dense back ends and the dense
// monodromy need it: one to-all scatter, reused.
#pragma once

#include "squeal/core/handle.h"

#include <petscmat.h>
#include <petscvec.h>

#include <Eigen/Dense>

#include <vector>

namespace squeal {

// One-off gather of a distributed vector: in full on every rank (to_all) or on rank 0 only
// (empty elsewhere). Collective. For repeated gathers of the same layout use AllGather.
PetscErrorCode GatherVector(Vec v, bool to_all, std::vector<PetscReal> &out);
// The other way: v's own rows from a whole vector that this rank holds (full[i] for each owned row
// i). Not collective.
PetscErrorCode SetOwnedRows(const PetscReal *full, Vec v);
// One-off gather of a distributed matrix (any type with MatCreateSubMatrices and MatGetRow: AIJ,
// dense): in full on rank 0 (empty elsewhere), or on every rank (to_all). Collective.
PetscErrorCode GatherMatrix(Mat A, bool to_all, Eigen::MatrixXd &out);
// A(rows, cols) as a dense matrix on this rank, each rank with index sets of its own (on
// PETSC_COMM_SELF, possibly empty). Collective.
PetscErrorCode GatherSubmatrix(Mat A, IS rows, IS cols, Eigen::MatrixXd &out);

class AllGather {
public:
  // Sets up the scatter for vectors laid out like `like` (collective).
  PetscErrorCode SetUp(Vec like);
  // out = x in full on every rank (collective); out must have the global size.
  PetscErrorCode operator()(Vec x, Eigen::Ref<Eigen::VectorXd> out);
  bool Ready() const { return static_cast<bool>(scatter_); }

private:
  Handle<VecScatter> scatter_;
  VecH               full_;
};

} // namespace squeal
