// Interface reduction of a Craig-Bampton model: the normal DOFs of the contact nodes stay
// physical, the in-plane ones are replaced by the lowest characteristic constraint modes
// (include/squeal/reduction/craig_bampton.h; src/reduction/internal.h).
#include "internal.h"

#include "squeal/core/errors.h"
#include "squeal/core/options.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

namespace squeal::cb {

namespace {

// Interface reduction of a Craig-Bampton model (matrices in contact order: point c's x, y, z at
// 3c .. 3c+2, then the m modes). With E_c = [t_c b_c] (3 x 2), the in-plane interface block
//   K_pp(2c+a, 2d+b) = E_c(:, a)^T K_r(3c.., 3d..) E_d(:, b)   (normals and modes held at 0), M_pp alike,
// gives the characteristic constraint modes K_pp Psi = M_pp Psi Lambda, Psi^T M_pp Psi = I; the
// k lowest replace the 2 n_c in-plane DOFs. T (n2 x n_c + k + m) maps the new coordinates
// [u_n (one per point), xi (k), eta (m)] to the CB ones: u_xyz(c) = n_c u_n,c + E_c Psi(2c.., :) xi.
// lam receives all 2 n_c eigenvalues (ascending), so the caller chooses k.
PetscErrorCode InPlaneModes(MPI_Comm comm, const ContactSet &cs, const Dense &Mp, const Dense &Kp, Dense &Psi,
                            std::vector<PetscReal> &lam)
{
  const PetscInt nc = cs.Size();
  PetscFunctionBeginUser;
  Dense Kpp(2 * nc, 2 * nc), Mpp(2 * nc, 2 * nc);
  for (PetscInt c = 0; c < nc; ++c) {
    Eigen::Matrix<PetscReal, 3, 2> Ec;
    Ec << cs.points[c].t, cs.points[c].b;
    for (PetscInt d = 0; d < nc; ++d) {
      Eigen::Matrix<PetscReal, 3, 2> Ed;
      Ed << cs.points[d].t, cs.points[d].b;
      Kpp.block<2, 2>(2 * c, 2 * d) = Ec.transpose() * Kp.block<3, 3>(3 * c, 3 * d) * Ed;
      Mpp.block<2, 2>(2 * c, 2 * d) = Ec.transpose() * Mp.block<3, 3>(3 * c, 3 * d) * Ed;
    }
  }
  Eigen::GeneralizedSelfAdjointEigenSolver<Dense> ges;
  PetscCallCXX(ges.compute(0.5 * (Kpp + Kpp.transpose()), 0.5 * (Mpp + Mpp.transpose())));
  PetscCheck(ges.info() == Eigen::Success, comm, kErrInput,
             "interface reduction: the in-plane interface block's eigenproblem failed (M_pp not positive definite?)");
  Psi = ges.eigenvectors(); // M_pp-normalised, ascending eigenvalues
  lam.assign(ges.eigenvalues().data(), ges.eigenvalues().data() + 2 * nc);
  PetscFunctionReturn(0);
}

} // namespace

PetscErrorCode InterfaceReduction(MPI_Comm comm, const ContactSet &full, const Dense &Mp, const Dense &Kp, PetscInt k_max,
                                  PetscReal fmax, const char *prefix, PetscInt m, Dense &T, ContactSet &contacts,
                                  ReductionInfo &info)
{
  const PetscInt    nc = full.Size(), nB = 3 * nc, n2 = nB + m;
  const std::string pre = OptionName(prefix, "");
  PetscFunctionBeginUser;
  for (PetscInt c = 0; c < nc; ++c)
    PetscCheck(full.points[c].nodes.size() == 1, comm, kErrInput,
               "interface reduction: contact %" PetscInt_FMT " has %zu nodes; %sinterface_modes needs one node per contact point "
               "(drop the option)", c, full.points[c].nodes.size(), pre.c_str());
  PetscCheck(k_max <= 2 * nc, comm, kErrInput,
             "%sinterface_modes %" PetscInt_FMT " exceeds the %" PetscInt_FMT " in-plane interface DOFs (2 x %" PetscInt_FMT
             " contact points): give at most %" PetscInt_FMT, pre.c_str(), k_max, 2 * nc, nc, 2 * nc);
  Dense                  Psi;
  std::vector<PetscReal> lam;
  PetscCall(InPlaneModes(comm, full, Mp, Kp, Psi, lam));
  PetscInt k = 2 * nc;
  if (fmax > 0) {
    const PetscReal w2 = std::pow(2 * PETSC_PI * fmax, 2);
    k = (PetscInt)(std::upper_bound(lam.begin(), lam.end(), w2) - lam.begin());
    PetscCheck(k > 0, comm, kErrInput,
               "%sinterface_fmax %g Hz keeps no in-plane interface mode (the lowest is at %g Hz): raise it", pre.c_str(),
               (double)fmax, std::sqrt(std::max(lam[0], (PetscReal)0)) / (2 * PETSC_PI));
  }
  if (k_max >= 0) k = std::min(k, k_max);
  PetscCheck(k > 0, comm, kErrInput,
             "%sinterface_modes 0 keeps no in-plane interface mode: give k >= 1, or -1 (default) for no interface reduction",
             pre.c_str());
  T = Dense::Zero(n2, nc + k + m);
  for (PetscInt c = 0; c < nc; ++c) {
    const ContactPoint &p = full.points[c];
    T.block<3, 1>(3 * c, c) = p.n;
    for (PetscInt j = 0; j < k; ++j) T.block<3, 1>(3 * c, nc + j) = p.t * Psi(2 * c, j) + p.b * Psi(2 * c + 1, j);
  }
  for (PetscInt q = 0; q < m; ++q) T(nB + q, nc + k + q) = 1;
  info.n_normal        = nc;
  info.n_inplane_modes = k;
  info.inplane_freq.clear();
  for (PetscInt j = 0; j < k; ++j) info.inplane_freq.push_back(std::sqrt(std::max(lam[j], (PetscReal)0)) / (2 * PETSC_PI));
  contacts = full;
  for (PetscInt c = 0; c < nc; ++c) {
    ContactPoint   &p = contacts.points[c];
    const PetscReal w = p.nodes[0].weight;
    p.nodes.clear();
    for (ColumnEntries &col : p.cols) col.clear();
    // h_n selects the normal coordinate: the pivot elimination and the node-wise unilateral
    // law stay exact; h_t, h_b are rows of the in-plane mode matrix, dense over xi.
    p.cols[kN].emplace_back(c, w);
    for (PetscInt j = 0; j < k; ++j) {
      p.cols[kT].emplace_back(nc + j, w * Psi(2 * c, j));
      p.cols[kB].emplace_back(nc + j, w * Psi(2 * c + 1, j));
    }
  }
  PetscFunctionReturn(0);
}

} // namespace squeal::cb
