// A reduced model's way back to the DOFs of the full model it came from, so that its results can
// be shown on the FE mesh (docs/fe-workflow.md, "Results on the mesh").
//
//   u_full = E u,   E (full_size x n) dense,
//
// for Craig-Bampton E = P [I 0; Psi Phi] T: the interface rows are unit rows (rows of the interface
// reduction T, if any), the interior rows those of [Psi Phi] T (src/reduction/craig_bampton.cpp).
// E is held on rank 0 only, where the results file is written: 8 full_size n bytes, the size of
// the reduction's own basis. Linear, so modes, orbits and records expand alike; nonlinear
// statistics (RMS, spectra) do not, and are not expanded.
#pragma once

#include <petscsys.h>

#include <cstddef>
#include <vector>

namespace squeal {

struct Expansion {
  PetscInt               full_size = 0, n = 0;
  std::vector<PetscReal> E; // column-major full_size x n, on rank 0; empty elsewhere
  PetscInt               records = 200; // a transient's last records expanded in the results file (-reduce_expand_records)

  // U = Q E^T: `count` reduced vectors (rows of Q, count x n, row-major) to full ones (rows of U,
  // count x full_size, row-major). Rank 0 only. U is resized.
  void   Apply(const PetscReal *Q, size_t count, std::vector<PetscReal> &U) const;
  // Column-wise: a reduced vector of n entries every `stride` entries (a [dof][column] layout with
  // `stride` columns) to full ones, same layout with full_size rows.
  void   ApplyColumns(const PetscReal *Q, size_t columns, std::vector<PetscReal> &U) const;
  size_t Bytes() const { return E.size() * sizeof(PetscReal); }
};

} // namespace squeal
