#include "squeal/contact/local_solver.h"

#include <cmath>

namespace squeal {

void LocalContactSolver::Setup(const ContactSet &cs, const Eigen::MatrixXd &W, PetscReal h, PetscReal rho_scale)
{
  const Eigen::Index nc = cs.Size();
  cs_                   = &cs;
  p_.h                  = h;
  hW_                   = h * W;
  hWs_.resize(0, 0);
  sparse_ = false;
  v_.setZero(3 * nc);
  rho_n_.resize(nc);
  rho_t_.resize(nc);
  speed_.resize(nc);
  for (Eigen::Index c = 0; c < nc; ++c) {
    // (2.4): one pass solves an isolated direction exactly.
    rho_n_[c] = rho_scale / (h * h * W(3 * c + kN, 3 * c + kN));
    rho_t_[c] = rho_scale / (h * W(3 * c + kT, 3 * c + kT));
    speed_[c] = cs.Speed(c);
  }
}

void LocalContactSolver::Setup(const ContactSet &cs, const Eigen::SparseMatrix<PetscReal> &W, PetscReal h, PetscReal rho_scale)
{
  const Eigen::Index nc = cs.Size();
  cs_                   = &cs;
  p_.h                  = h;
  hWs_                  = h * W;
  hWs_.makeCompressed();
  hW_.resize(0, 0);
  sparse_ = true;
  v_.setZero(3 * nc);
  rho_n_.resize(nc);
  rho_t_.resize(nc);
  speed_.resize(nc);
  for (Eigen::Index c = 0; c < nc; ++c) {
    rho_n_[c] = rho_scale / (h * h * W.coeff(3 * c + kN, 3 * c + kN)); // (2.4), as in the dense Setup
    rho_t_[c] = rho_scale / (h * W.coeff(3 * c + kT, 3 * c + kT));
    speed_[c] = cs.Speed(c);
  }
}

LocalSolveInfo LocalContactSolver::Solve(const Eigen::VectorXd &w_f, const Eigen::VectorXd &gap0, Eigen::VectorXd &r)
{
  if (sparse_) {
    p_.mu          = cs_->mu;
    p_.rectilinear = cs_->law == FrictionLaw::Rectilinear;
    return ContactPasses(p_, hWs_, rho_n_, rho_t_, speed_, w_f, gap0, r, v_);
  }
  return SolveSized<Eigen::Dynamic>(w_f, gap0, r);
}

void LocalContactSolver::Status(const Eigen::VectorXd &r, std::vector<int> &status) const
{
  const Eigen::Index nc = rho_n_.size();
  status.resize(nc);
  for (Eigen::Index c = 0; c < nc; ++c) {
    const Eigen::Index o  = 3 * c;
    const PetscReal    rn = r[o + kN];
    if (rn <= 0) {
      status[c] = kOpen;
      continue;
    }
    // Stick: strictly inside the friction disc (docs/method.md §5, "Cost and status").
    const PetscReal rT = cs_->law == FrictionLaw::Rectilinear ? std::abs(r[o + kT]) : std::hypot(r[o + kT], r[o + kB]);
    status[c] = rT < (1 - 1e-9) * cs_->mu * rn ? kStick : kSlip;
  }
}

} // namespace squeal
