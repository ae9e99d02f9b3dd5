// The results of a reduced model on the full model's DOFs: the group /expanded of the results
// file, from Model::expansion (u_full = E u; -reduce_expand). Each writer does nothing for a model
// without an expansion. Collective on the writer's communicator; the vectors are read on rank 0.
//
//   /expanded/modes/re, im     [full DOF][k]  the unstable modes (/stability/unstable, in its order)
//   /expanded/modes/index      [k]            their columns of /stability/modes
//   /expanded/orbit/t, U       [sample], [sample][full DOF]  the limit cycle's period
//   /expanded/transient/t, U   the transient's last records (-reduce_expand_records)
//
// /mesh/dof_full maps the mesh nodes' x, y, z to these rows (docs/fe-workflow.md).
#pragma once

#include "squeal/integration/transient.h"
#include "squeal/io/h5.h"
#include "squeal/model/model.h"
#include "squeal/shooting/shooting.h"
#include "squeal/stability/stability.h"

namespace squeal {

PetscErrorCode WriteExpandedModes(const Model &model, const StabilityResult &res, io::H5Writer &out);
PetscErrorCode WriteExpandedOrbit(const Model &model, const ShootingResult &res, io::H5Writer &out);
PetscErrorCode WriteExpandedRecords(const Model &model, const TransientResult &res, io::H5Writer &out);
// A reduced end state (U, dU; all n values on every rank) on the full model's DOFs, /expanded/Z_end:
// the full model's transient goes on from the reduced steady state with -transient_start.
PetscErrorCode WriteExpandedEnd(const Model &model, const std::vector<PetscReal> &U, const std::vector<PetscReal> &dU, io::H5Writer &out);

} // namespace squeal
