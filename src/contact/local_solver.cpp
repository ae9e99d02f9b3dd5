#include "squeal/contact/local_solver.h"

#include <cmath>

namespace squeal {

void LocalContactSolver::Setup(const ContactSet &cs, const Eigen::MatrixXd &W, PetscReal h, PetscReal rho_scale)
{
  const Eigen::Index nc = cs.Size();
  cs_                   = &cs;
  h_                    = h;
  hW_                   = h * W;
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

LocalSolveInfo LocalContactSolver::Solve(const Eigen::VectorXd &w_f, const Eigen::VectorXd &gap0, Eigen::VectorXd &r)
{
  const Eigen::Index nc          = rho_n_.size();
  const PetscReal    mu          = cs_->mu;
  const bool         rectilinear = cs_->law == FrictionLaw::Rectilinear;
  LocalSolveInfo     info;
  v_.noalias() = w_f + hW_ * r;
  for (info.iterations = 1; info.iterations <= max_it_; ++info.iterations) {
    PetscReal change = 0, rn_sum = 0;
    for (Eigen::Index c = 0; c < nc; ++c) {
      const Eigen::Index o  = 3 * c;
      const PetscReal    gn = gap0[c] + h_ * v_[o + kN];
      const PetscReal    rn = std::max(0.0, r[o + kN] - rho_n_[c] * gn);
      PetscReal          rt = r[o + kT] - rho_t_[c] * (v_[o + kT] - speed_[c]);
      PetscReal          rb = r[o + kB] - rho_t_[c] * v_[o + kB];
      const PetscReal    a  = mu * rn;
      if (rectilinear) {
        rt = std::min(a, std::max(-a, rt));
        rb = 0;
      } else {
        const PetscReal m = std::hypot(rt, rb);
        if (m > a) {
          const PetscReal f = m > 0 ? a / m : 0.0;
          rt *= f;
          rb *= f;
        }
      }
      const PetscReal dt = rt - r[o + kT], db = rb - r[o + kB], dn = rn - r[o + kN];
      if (dt != 0 || db != 0 || dn != 0) {
        v_.noalias() += hW_.col(o + kT) * dt + hW_.col(o + kB) * db + hW_.col(o + kN) * dn;
        r[o + kT] = rt;
        r[o + kB] = rb;
        r[o + kN] = rn;
      }
      change += std::abs(dt) + std::abs(db) + std::abs(dn);
      rn_sum += rn;
    }
    info.residual = change / (r_ref_ + rn_sum);
    if (!(info.residual > tol_)) { // also stops on NaN, which the caller reports
      info.converged = !std::isnan(info.residual);
      return info;
    }
  }
  info.iterations = max_it_;
  return info;
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
    // Stick: strictly inside the friction disc (method.md §5, "Cost and status").
    const PetscReal rT = cs_->law == FrictionLaw::Rectilinear ? std::abs(r[o + kT]) : std::hypot(r[o + kT], r[o + kB]);
    status[c] = rT < (1 - 1e-9) * cs_->mu * rn ? kStick : kSlip;
  }
}

} // namespace squeal
