#include "squeal/contact/local_solver.h"

#include <petscblaslapack.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

namespace squeal {

void LocalContactSolver::Setup(const ContactSet &cs, const Eigen::MatrixXd &W, PetscReal h, PetscReal rho_scale)
{
  const Eigen::Index nc = cs.Size();
  cs_                   = &cs;
  p_.h                  = h;
  hW_                   = h * W;
  hWs_.resize(0, 0);
  sparse_ = false;
  single_ = false, hWf_.resize(0, 0);
  v_.setZero(3 * nc);
  hist_.setZero(3 * nc, 3), n_hist_ = 0;
  solver_ = ContactSolver::kFixedPoint; // SetSolver sizes Newton's arrays for this W
  anderson_ = fp_anderson_ = a_n_ = 0;
  newton_solves_ = fallbacks_ = newton_steps_ = factorisations_ = mixed_ = mixed_passes_ = 0;
  rho_n_.resize(nc);
  rho_t_.resize(nc);
  speed_.resize(nc);
  for (Eigen::Index c = 0; c < nc; ++c) {
    // (2.4): one pass solves an isolated direction exactly.
    rho_n_[c] = rho_scale / (h * h * W(3 * c + kN, 3 * c + kN));
    rho_t_[c] = rho_scale / (h * W(3 * c + kT, 3 * c + kT));
    speed_[c] = cs.Speed(c);
  }
  friction_state_ = cs.FrictionState();
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
  single_ = false, hWf_.resize(0, 0);
  v_.setZero(3 * nc);
  hist_.setZero(3 * nc, 3), n_hist_ = 0;
  solver_ = ContactSolver::kFixedPoint;
  anderson_ = fp_anderson_ = a_n_ = 0;
  newton_solves_ = fallbacks_ = newton_steps_ = factorisations_ = mixed_ = mixed_passes_ = 0;
  rho_n_.resize(nc);
  rho_t_.resize(nc);
  speed_.resize(nc);
  for (Eigen::Index c = 0; c < nc; ++c) {
    rho_n_[c] = rho_scale / (h * h * W.coeff(3 * c + kN, 3 * c + kN)); // (2.4), as in the dense Setup
    rho_t_[c] = rho_scale / (h * W.coeff(3 * c + kT, 3 * c + kT));
    speed_[c] = cs.Speed(c);
  }
  friction_state_ = cs.FrictionState();
}

LocalSolveInfo LocalContactSolver::Solve(const Eigen::VectorXd &w_f, const Eigen::VectorXd &gap0, Eigen::VectorXd &r)
{
  if (sparse_) {
    RefreshFriction();
    if (solver_ == ContactSolver::kNewton) return SolveNewton(w_f, gap0, r);
    Predict(r);
    const LocalSolveInfo info = Passes(w_f, gap0, r);
    Remember(r);
    return info;
  }
  return SolveSized<Eigen::Dynamic>(w_f, gap0, r);
}

void LocalContactSolver::SetSolver(ContactSolver s, PetscInt newton_max_it, PetscInt anderson)
{
  const Eigen::Index m = v_.size();
  solver_              = s;
  newton_max_it_       = newton_max_it;
  anderson_            = std::max<PetscInt>(0, std::min(anderson, kMaxAnderson));
  factor_valid_        = false;
  a_n_                 = 0;
  if (s != ContactSolver::kNewton) {
    anderson_ = 0;
    J_.resize(0, 0), Js_.resize(0, 0), lu_ = Eigen::PartialPivLU<Eigen::MatrixXd>();
    SizeAnderson();
    return;
  }
  for (Eigen::VectorXd *x : {&r0_, &F_, &Ft_, &d_, &rt_, &vt_, &hWd_}) x->setZero(m);
  SizeAnderson();
  g_.setZero(3, m), gd_.setZero(3, m);
  last_steps_ = 0;
  if (!sparse_) {
    if (!condensed_) {
      J_.setZero(m, m);
      lu_ = Eigen::PartialPivLU<Eigen::MatrixXd>(m); // compute() on m x m then reuses its storage
      hWP_.resize(0, 0), S_.resize(0, 0);
      return;
    }
    J_.resize(0, 0), lu_ = Eigen::PartialPivLU<Eigen::MatrixXd>();
    const Eigen::Index nc = m / 3;
    for (auto *x : {&pc_, &qc_, &pf_, &qf_, &qdf_}) x->setZero(3, m);
    mc_.assign(nc, 0), mf_.assign(nc, 0), kf_.assign(nc, 0);
    hWP_.setZero(m, m), S_.setZero(m, m); // at most m columns each: S's order is at most 3 n_c
    t_.setZero(m), z_.setZero(m);
    ipiv_.assign(m, 0);
    ms_ = 0;
    return;
  }
  // Row block c of J is G_c D_c times rows 3c..3c+2 of h W, plus the diagonal block: the pattern is
  // every row of a block in which W has an entry, and the diagonal blocks. Fixed for this W, so the
  // ordering (analyzePattern) is done once.
  std::vector<Eigen::Triplet<PetscReal>> t;
  t.reserve(3 * hWs_.nonZeros() + 3 * m);
  for (Eigen::Index j = 0; j < m; ++j) {
    for (Eigen::SparseMatrix<PetscReal>::InnerIterator it(hWs_, j); it; ++it)
      for (int a = 0; a < 3; ++a) t.emplace_back(3 * (it.index() / 3) + a, j, 0.0);
    for (int a = 0; a < 3; ++a) t.emplace_back(3 * (j / 3) + a, j, 0.0);
  }
  Js_.resize(m, m);
  Js_.setFromTriplets(t.begin(), t.end());
  Js_.makeCompressed();
  slu_.analyzePattern(Js_);
}

void LocalContactSolver::SetNewtonCondensed(bool on)
{
  condensed_ = on;
  if (solver_ == ContactSolver::kNewton && !sparse_) SetSolver(solver_, newton_max_it_, anderson_);
}

void LocalContactSolver::SetFixedPointAnderson(PetscInt depth)
{
  fp_anderson_ = std::max<PetscInt>(0, std::min(depth, kMaxAnderson));
  a_n_         = 0;
  SizeAnderson();
}

void LocalContactSolver::SizeAnderson()
{
  const Eigen::Index m = v_.size(), depth = std::max(anderson_, fp_anderson_);
  const Eigen::Index na = depth > 0 ? depth + 1 : 0;
  a_f_.setZero(m, na), a_g_.setZero(m, na), a_v_.setZero(m, na), a_df_.setZero(m, std::max<Eigen::Index>(na - 1, 0));
  const bool mixing_or_newton = na > 0 || solver_ == ContactSolver::kNewton;
  rt_.setZero(mixing_or_newton ? m : 0), vt_.setZero(mixing_or_newton ? m : 0), rin_.setZero(fp_anderson_ > 0 ? m : 0);
}

bool LocalContactSolver::SetFixedPointSingle(PetscInt min_unknowns)
{
  const Eigen::Index m = hW_.rows();
  single_              = !sparse_ && !fp_symmetric_ && min_unknowns > 0 && m >= min_unknowns;
  // Entries beyond float's range (or not finite) would not round to within 2^-24 of themselves.
  if (single_) single_ = hW_.allFinite() && hW_.cwiseAbs().maxCoeff() < 1e30;
  refreshes_ = 0;
  if (!single_) {
    hWf_.resize(0, 0), rx_.resize(0), vx_.resize(0);
    return false;
  }
  hWf_ = hW_.cast<float>();
  rx_.setZero(m), vx_.setZero(m);
  // kappa = max_j sum_i g_i (|h W_ij| + 2^-126), g_i the factor from row i's velocity to its
  // reaction: below float's normal range an entry rounds to within 2^-150 (absolute), not 2^-24 of it.
  Eigen::VectorXd g(m);
  for (Eigen::Index c = 0; c < m / 3; ++c) g[3 * c + kT] = g[3 * c + kB] = rho_t_[c], g[3 * c + kN] = p_.h * rho_n_[c];
  const PetscReal floor = std::ldexp(1.0, -126) * g.sum();
  kappa_                = 0;
  for (Eigen::Index j = 0; j < m; ++j) kappa_ = std::max(kappa_, hW_.col(j).cwiseAbs().dot(g) + floor);
  return true;
}

PetscReal LocalContactSolver::DriftBound(CRef r, PetscReal change) const
{
  const Eigen::Index nc     = rho_n_.size();
  PetscReal          rn_sum = 0;
  for (Eigen::Index c = 0; c < nc; ++c) rn_sum += r[3 * c + kN];
  const PetscReal u = std::ldexp(1.0, -24);
  return 2 * (1 + p_.mu) * u * kappa_ * ((r - rx_).lpNorm<1>() / (p_.r_ref + rn_sum) + change);
}

LocalSolveInfo LocalContactSolver::Passes(CRef w_f, CRef gap0, Ref r)
{
  p_.mu          = cs_->Mu();
  p_.rectilinear = cs_->law == FrictionLaw::Rectilinear;
  // The storage types of SolveSized<Eigen::Dynamic>, so that a fallback repeats the fixed point's
  // operations exactly (Eigen may order a product differently on a Map than on a Matrix).
  const Eigen::Index                    nc = rho_n_.size();
  using MapC                            = Eigen::Map<const Eigen::VectorXd>;
  const Eigen::Map<const Eigen::MatrixXd> hW(hW_.data(), sparse_ ? 0 : 3 * nc, sparse_ ? 0 : 3 * nc);
  const MapC                            rho_n(rho_n_.data(), nc), rho_t(rho_t_.data(), nc), speed(speed_.data(), nc);
  Eigen::Map<Eigen::VectorXd>           v(v_.data(), 3 * nc);
  const Eigen::Map<const Eigen::MatrixXf> hWf(hWf_.data(), hWf_.rows(), hWf_.cols());
  const bool single = single_ && !fp_symmetric_ && p_.max_it >= 1;
  auto run = [&](const FixedPointParams &p) {
    if (sparse_) return ContactPasses(p, hWs_, rho_n_, rho_t_, speed_, w_f, gap0, r, v_);
    if (!single) return ContactPasses(p, hW, rho_n, rho_t, speed, w_f, gap0, r, v);
    if (!p.v_current) v.noalias() = w_f + hW * r, rx_ = r; // the float passes only update v
    FixedPointParams ps = p;
    ps.v_current        = true;
    ps.tol              = -1; // DriftBound's test instead
    return ContactPasses(ps, hWf, rho_n, rho_t, speed, w_f, gap0, r, v);
  };
  if (fp_symmetric_ && !sparse_ && p_.max_it >= 1) return SymmetricSweeps(w_f, gap0, r);
  if ((fp_anderson_ == 0 && !single) || p_.max_it < 1) return run(p_);
  // One pass at a time, each from the mixed point of the last ones (SetFixedPointAnderson).
  FixedPointParams p1 = p_;
  p1.max_it           = 1;
  PetscReal last      = std::numeric_limits<PetscReal>::infinity();
  LocalSolveInfo info;
  a_n_ = 0;
  for (PetscInt it = 1; it <= p_.max_it; ++it) {
    if (fp_anderson_ > 0) rin_ = r;
    p1.v_current = it > 1;
    info         = run(p1);
    if (single && !std::isnan(info.residual)) {
      const PetscReal b = DriftBound(r, info.residual);
      info.converged    = info.residual + b <= p_.tol;
      if (!info.converged && b > 0.5 * std::max(info.residual, p_.tol)) {
        // v again with the double h W; the history's v by the same shift (linear in r).
        vx_.noalias() = w_f + hW * r;
        vx_ -= v_;
        v_ += vx_;
        if (a_n_ > 0) a_v_.colwise() += vx_;
        rx_ = r;
        ++refreshes_;
      }
    }
    if (info.converged || std::isnan(info.residual)) return {it, info.residual, info.converged};
    if (fp_anderson_ == 0) continue;
    // A pass that changed r more than the last one: the history no longer describes the map.
    if (info.residual > last) a_n_ = 0;
    last                 = info.residual;
    if (it == p_.max_it) break; // a capped solve returns the last pass's output, not a mixed point
    const Eigen::Index j = AndersonSlot(fp_anderson_);
    a_f_.col(j)          = r - rin_;
    a_g_.col(j)          = r;
    a_v_.col(j)          = v_;
    if (Mix()) {
      r  = rt_;
      v_ = vt_;
      ++mixed_passes_;
    }
  }
  return {p_.max_it, info.residual, false};
}

// The fixed point's projections in symmetric Gauss-Seidel order (SetFixedPointSymmetric), same point
// update and stopping test as ContactPassesLaw. s_c = sum_{j<c} hW_cj r_j and t_c = sum_{j>c} hW_cj r_j:
// a forward sweep rebuilds s from zero (each new r_c into the rows below c) and reads t, which the
// backward sweep before it left exact for the points after c, not yet visited; a backward sweep the
// other way round. The start needs t and the end the stale one of the two again: two half products.
LocalSolveInfo LocalContactSolver::SymmetricSweeps(CRef w_f, CRef gap0, Ref r)
{
  const Eigen::Index nc = rho_n_.size(), m = 3 * nc;
  const Eigen::Map<const Eigen::MatrixXd> hW(hW_.data(), m, m);
  const PetscReal    h = p_.h, mu = p_.mu;
  const bool         rect = p_.rectilinear;
  sw_s_.setZero(m), sw_t_.setZero(m);
  auto upper = [&](Eigen::VectorXd &t) { // t = (strictly upper block part of h W) r
    t.setZero();
    for (Eigen::Index c = 1; c < nc; ++c) {
      const Eigen::Index o = 3 * c;
      if (r.segment<3>(o).isZero(0)) continue;
      t.head(o).noalias() += hW.block(0, o, o, 3) * r.segment<3>(o);
    }
  };
  auto lower = [&](Eigen::VectorXd &s) { // s = (strictly lower block part of h W) r
    s.setZero();
    for (Eigen::Index c = 0; c + 1 < nc; ++c) {
      const Eigen::Index o = 3 * c;
      if (r.segment<3>(o).isZero(0)) continue;
      s.tail(m - o - 3).noalias() += hW.block(o + 3, o, m - o - 3, 3) * r.segment<3>(o);
    }
  };
  upper(sw_t_);
  PetscReal residual = 0;
  PetscInt  it       = 1;
  bool      forward  = true, done = false;
  for (; it <= p_.max_it; ++it, forward = !forward) {
    PetscReal change = 0, rn_sum = 0;
    if (forward) sw_s_.setZero();
    else sw_t_.setZero();
    for (Eigen::Index k = 0; k < nc; ++k) {
      const Eigen::Index c = forward ? k : nc - 1 - k, o = 3 * c;
      const Eigen::Vector3d vc = w_f.segment<3>(o) + sw_s_.segment<3>(o) + sw_t_.segment<3>(o) + hW.block<3, 3>(o, o) * r.segment<3>(o);
      const PetscReal       gn = gap0[c] + h * vc[kN];
      const PetscReal       rn = std::max(0.0, r[o + kN] - rho_n_[c] * gn);
      PetscReal             rt = r[o + kT] - rho_t_[c] * (vc[kT] - speed_[c]);
      PetscReal             rb = r[o + kB] - rho_t_[c] * vc[kB];
      ProjectFriction(rect, mu * rn, rt, rb);
      change += std::abs(rt - r[o + kT]) + std::abs(rb - r[o + kB]) + std::abs(rn - r[o + kN]);
      rn_sum += rn;
      r[o + kT] = rt, r[o + kB] = rb, r[o + kN] = rn;
      if (rt == 0 && rb == 0 && rn == 0) continue;
      if (forward) {
        if (o + 3 < m) sw_s_.tail(m - o - 3).noalias() += hW.block(o + 3, o, m - o - 3, 3) * r.segment<3>(o);
      } else if (o > 0) sw_t_.head(o).noalias() += hW.block(0, o, o, 3) * r.segment<3>(o);
    }
    residual = change / (p_.r_ref + rn_sum);
    if (!(residual > p_.tol)) {
      done = true;
      break;
    }
  }
  // v = w_f + h W r for the result: the sum the last sweep left stale made again.
  const bool last_forward = done ? forward : !forward;
  if (last_forward) upper(sw_t_);
  else lower(sw_s_);
  for (Eigen::Index c = 0; c < nc; ++c) {
    const Eigen::Index o = 3 * c;
    v_.segment<3>(o) = w_f.segment<3>(o) + sw_s_.segment<3>(o) + sw_t_.segment<3>(o) + hW.block<3, 3>(o, o) * r.segment<3>(o);
  }
  if (done) return {it, residual, !std::isnan(residual)};
  return {p_.max_it, residual, false};
}

// One Jacobi pass of the fixed point's projections, r -> P(r), written as the passes write it (the
// same expressions, so that F = 0 is exactly their fixed point), and its generalised Jacobian.
PetscReal LocalContactSolver::Residual(CRef gap0, CRef r, CRef v, Eigen::VectorXd &F, bool jac)
{
  const Eigen::Index nc   = rho_n_.size();
  const PetscReal    mu   = cs_->Mu(), h = p_.h;
  const bool         rect = cs_->law == FrictionLaw::Rectilinear;
  for (Eigen::Index c = 0; c < nc; ++c) {
    const Eigen::Index o  = 3 * c;
    const PetscReal    gn = gap0[c] + h * v[o + kN];
    const PetscReal    xn = r[o + kN] - rho_n_[c] * gn;
    const PetscReal    xt = r[o + kT] - rho_t_[c] * (v[o + kT] - speed_[c]);
    const PetscReal    xb = r[o + kB] - rho_t_[c] * v[o + kB];
    const PetscReal    rn = std::max(0.0, xn), a = mu * rn;
    PetscReal          rt = xt, rb = xb;
    ProjectFriction(rect, a, rt, rb);
    F[o + kT] = r[o + kT] - rt;
    F[o + kB] = r[o + kB] - rb;
    F[o + kN] = r[o + kN] - rn;
    if (!jac) continue;
    // G_c = dP_c/dx_c (rows: output t, b, n; columns: x_t, x_b, x_n). On a kink (x_n = 0, |x_T| = a)
    // either side's derivative is a valid element of the generalised Jacobian: open and slip are taken.
    auto G = g_.middleCols<3>(o);
    G.setZero();
    // G_c = P_c Q_c, of rank mc (condensed Newton on dense W): column j of P (pc_) and row j of Q (qc_).
    const bool cond = condensed_ && !sparse_;
    int        mcc  = 0;
    auto       pq   = [&](PetscReal pt, PetscReal pb, PetscReal pn, PetscReal qt, PetscReal qb, PetscReal qn) {
      if (!cond) return;
      pc_(kT, o + mcc) = pt, pc_(kB, o + mcc) = pb, pc_(kN, o + mcc) = pn;
      qc_(kT, o + mcc) = qt, qc_(kB, o + mcc) = qb, qc_(kN, o + mcc) = qn;
      ++mcc;
    };
    if (xn > 0) {
      G(kN, kN) = 1;
      if (rect) {
        if (std::abs(xt) < a) {
          G(kT, kT) = 1;
          pq(1, 0, 0, 1, 0, 0), pq(0, 0, 1, 0, 0, 1);
        } else {
          G(kT, kN) = xt > 0 ? mu : (xt < 0 ? -mu : 0.0);
          pq(G(kT, kN), 0, 1, 0, 0, 1);
        }
      } else {
        const PetscReal m = std::hypot(xt, xb);
        if (m < a) {
          G(kT, kT) = G(kB, kB) = 1;
          pq(1, 0, 0, 1, 0, 0), pq(0, 1, 0, 0, 1, 0), pq(0, 0, 1, 0, 0, 1);
        } else if (m > 0) { // a x_T / |x_T|: (a / m)(I - u u^T) in x_T, mu u in x_n
          const PetscReal ut = xt / m, ub = xb / m, f = a / m;
          G(kT, kT) = f * (1 - ut * ut);
          G(kT, kB) = G(kB, kT) = -f * ut * ub;
          G(kB, kB) = f * (1 - ub * ub);
          G(kT, kN) = mu * ut;
          G(kB, kN) = mu * ub;
          pq(mu * ut, mu * ub, 1, 0, 0, 1); // (e_n + mu u) e_n^T
          if (f > 0) pq(-f * ub, f * ut, 0, -ub, ut, 0); // f s s^T, s = (-u_b, u_t) (I - u u^T = s s^T)
        } else pq(0, 0, 1, 0, 0, 1);
      }
    }
    if (cond) mc_[c] = mcc;
    // dx/dr = I - D h W, D = diag(rho_t, rho_t, h rho_n)
    auto GD = gd_.middleCols<3>(o);
    GD.col(kT) = G.col(kT) * rho_t_[c];
    GD.col(kB) = G.col(kB) * rho_t_[c];
    GD.col(kN) = G.col(kN) * (h * rho_n_[c]);
  }
  const PetscReal n = F.norm();
  return std::isfinite(n) ? n : NAN;
}

void LocalContactSolver::AssembleJacobian()
{
  const Eigen::Index nc = rho_n_.size();
  if (!sparse_) {
    for (Eigen::Index c = 0; c < nc; ++c) {
      const Eigen::Index o = 3 * c;
      if (gd_.middleCols<3>(o).isZero(0)) J_.middleRows<3>(o).setZero(); // open: J rows = I
      else J_.middleRows<3>(o).noalias() = gd_.middleCols<3>(o) * hW_.middleRows<3>(o);
      J_.block<3, 3>(o, o) += Eigen::Matrix3d::Identity() - g_.middleCols<3>(o);
    }
    return;
  }
  std::fill(Js_.valuePtr(), Js_.valuePtr() + Js_.nonZeros(), 0.0);
  for (Eigen::Index j = 0; j < hWs_.outerSize(); ++j)
    for (Eigen::SparseMatrix<PetscReal>::InnerIterator it(hWs_, j); it; ++it) {
      const Eigen::Index i = it.index(), o = 3 * (i / 3);
      for (int a = 0; a < 3; ++a) {
        const PetscReal gd = gd_(a, i);
        if (gd != 0) Js_.coeffRef(o + a, j) += gd * it.value();
      }
    }
  for (Eigen::Index c = 0; c < nc; ++c)
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b) Js_.coeffRef(3 * c + a, 3 * c + b) += (a == b ? 1.0 : 0.0) - g_(a, 3 * c + b);
}

bool LocalContactSolver::FactorCondensed()
{
  const Eigen::Index nc = rho_n_.size(), n = 3 * nc;
  Eigen::Index       m  = 0;
  for (Eigen::Index c = 0; c < nc; ++c) {
    const Eigen::Index o = 3 * c;
    Eigen::Vector3d    dd; // D_c
    dd[kT] = dd[kB] = rho_t_[c], dd[kN] = p_.h * rho_n_[c];
    mf_[c] = mc_[c], kf_[c] = int(m);
    for (int j = 0; j < mc_[c]; ++j) {
      pf_.col(o + j)  = pc_.col(o + j);
      qf_.col(o + j)  = qc_.col(o + j);
      qdf_.col(o + j) = qc_.col(o + j).cwiseProduct(dd);
    }
    m += mc_[c];
  }
  ms_ = m;
  if (m == 0) return true; // every point open: J = I
  // h W P, then S = I - Q P + (Q D)(h W P).
  Eigen::Map<Eigen::MatrixXd> hWP(hWP_.data(), n, m), S(S_.data(), m, m);
  for (Eigen::Index c = 0; c < nc; ++c) {
    const Eigen::Index o = 3 * c;
    for (int j = 0; j < mf_[c]; ++j)
      hWP.col(kf_[c] + j).noalias() = hW_.col(o + kT) * pf_(kT, o + j) + hW_.col(o + kB) * pf_(kB, o + j) + hW_.col(o + kN) * pf_(kN, o + j);
  }
  // Column by column (both matrices column-major): block row c of S is m_c rows of Q_c D_c times
  // rows 3c .. 3c + 2 of h W P. (Eigen's product per block row packed the whole of h W P each time.)
  for (Eigen::Index j = 0; j < m; ++j) {
    const PetscReal *x = hWP.col(j).data();
    PetscReal       *y = S.col(j).data();
    for (Eigen::Index c = 0; c < nc; ++c) {
      const Eigen::Index o = 3 * c;
      const PetscReal    x0 = x[o], x1 = x[o + 1], x2 = x[o + 2];
      for (int i = 0; i < mf_[c]; ++i) *y++ = qdf_(0, o + i) * x0 + qdf_(1, o + i) * x1 + qdf_(2, o + i) * x2;
    }
  }
  for (Eigen::Index c = 0; c < nc; ++c) {
    const Eigen::Index o = 3 * c, k = kf_[c], mcc = mf_[c];
    if (mcc == 0) continue;
    S.block(k, k, mcc, mcc) -= qf_.middleCols(o, mcc).transpose() * pf_.middleCols(o, mcc);
    S.block(k, k, mcc, mcc).diagonal().array() += 1.0;
  }
  PetscBLASInt bm = static_cast<PetscBLASInt>(m), info = 0; // m <= 3 n_c; a NaN in S reaches the direction, which is checked
  LAPACKgetrf_(&bm, &bm, S.data(), &bm, ipiv_.data(), &info);
  return info == 0; // info > 0: S (so J) exactly singular
}

bool LocalContactSolver::Factor()
{
  ++factorisations_;
  factor_valid_ = false;
  if (!sparse_ && condensed_) {
    if (!FactorCondensed()) return false;
    factor_valid_ = true;
    return true;
  }
  AssembleJacobian();
  if (!sparse_) lu_.compute(J_);
  else {
    slu_.factorize(Js_);
    if (slu_.info() != Eigen::Success) return false;
  }
  factor_valid_ = true;
  return true;
}

bool LocalContactSolver::Direction()
{
  if (sparse_ || !condensed_) {
    if (!sparse_) d_.noalias() = lu_.solve(F_);
    else d_ = slu_.solve(F_);
    d_ = -d_;
    if (sparse_) hWd_.noalias() = hWs_ * d_;
    else hWd_.noalias() = hW_ * d_;
    return d_.allFinite();
  }
  // J^-1 F = F + P y, S y = Z F = Q F - (Q D)(h W F); h W J^-1 F = h W F + (h W P) y.
  const Eigen::Index nc = rho_n_.size(), n = 3 * nc, m = ms_;
  t_.noalias() = hW_ * F_;
  d_ = F_, hWd_ = t_;
  if (m > 0) {
    // Per point at most 3 x 3: written out (Eigen's dynamic-size products dispatch a kernel each).
    auto z = z_.head(m);
    for (Eigen::Index c = 0; c < nc; ++c) {
      const Eigen::Index o = 3 * c, k = kf_[c];
      for (int j = 0; j < mf_[c]; ++j)
        z[k + j] = qf_.col(o + j).dot(F_.segment<3>(o)) - qdf_.col(o + j).dot(t_.segment<3>(o));
    }
    PetscBLASInt bm = static_cast<PetscBLASInt>(m), one = 1, info = 0; // m <= 3 n_c, the order of W
    LAPACKgetrs_("N", &bm, &one, S_.data(), &bm, ipiv_.data(), z.data(), &bm, &info);
    if (info != 0) return false;
    for (Eigen::Index c = 0; c < nc; ++c) {
      const Eigen::Index o = 3 * c, k = kf_[c];
      for (int j = 0; j < mf_[c]; ++j) d_.segment<3>(o) += pf_.col(o + j) * z[k + j];
    }
    hWd_.noalias() += Eigen::Map<const Eigen::MatrixXd>(hWP_.data(), n, m) * z;
  }
  d_ = -d_, hWd_ = -hWd_;
  return d_.allFinite() && hWd_.allFinite();
}

Eigen::Index LocalContactSolver::AndersonSlot(PetscInt depth)
{
  const Eigen::Index na = depth + 1;
  if (a_n_ >= na) { // full: drop the oldest
    const Eigen::Index k = na - 1, o = a_n_ - k;
    for (Eigen::Index j = 0; j < k; ++j) {
      a_f_.col(j) = a_f_.col(j + o);
      a_g_.col(j) = a_g_.col(j + o);
      a_v_.col(j) = a_v_.col(j + o);
    }
    a_n_ = k;
  }
  return a_n_++;
}

bool LocalContactSolver::Mix()
{
  const PetscInt p = a_n_ - 1;
  if (p < 1) return false;
  // gamma = argmin || f_p - dF gamma ||_2, dF_j = f_{j+1} - f_j: normal equations of at most
  // kMaxAnderson unknowns on fixed-capacity storage (no allocation), the columns scaled to unit norm.
  using Small = Eigen::Matrix<PetscReal, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxAnderson, kMaxAnderson>;
  using SmallV = Eigen::Matrix<PetscReal, Eigen::Dynamic, 1, 0, kMaxAnderson, 1>;
  auto  dF = a_df_.leftCols(p);
  SmallV s(p), b(p);
  for (PetscInt j = 0; j < p; ++j) {
    dF.col(j) = a_f_.col(j + 1) - a_f_.col(j);
    const PetscReal n = dF.col(j).norm();
    if (!(n > 0) || !std::isfinite(n)) return false;
    s[j] = 1 / n;
    dF.col(j) *= s[j];
  }
  Small A(p, p);
  A.noalias() = dF.transpose() * dF;
  b.noalias() = dF.transpose() * a_f_.col(p);
  Eigen::LDLT<Small> ldlt(A);
  if (ldlt.info() != Eigen::Success || !(ldlt.rcond() > 1e-12)) return false;
  SmallV gamma = ldlt.solve(b);
  // r_mix = g_p - sum_j gamma_j (g_{j+1} - g_j) s_j, and the same combination of the v(g).
  rt_ = a_g_.col(p);
  vt_ = a_v_.col(p);
  for (PetscInt j = 0; j < p; ++j) {
    const PetscReal c = gamma[j] * s[j];
    rt_ -= c * (a_g_.col(j + 1) - a_g_.col(j));
    vt_ -= c * (a_v_.col(j + 1) - a_v_.col(j));
  }
  return rt_.allFinite() && vt_.allFinite();
}

LocalSolveInfo LocalContactSolver::SolveNewton(CRef w_f, CRef gap0, Ref r)
{
  const Eigen::Index nc = rho_n_.size();
  p_.mu                 = cs_->Mu();
  ++newton_solves_;
  if (refactor_after_ >= 0 && last_steps_ > refactor_after_) factor_valid_ = false; // SetNewtonRefactor
  Predict(r);
  r0_ = r; // the fallback's start: the fixed point's own guess
  if (sparse_) v_.noalias() = hWs_ * r;
  else v_.noalias() = hW_ * r;
  v_ += w_f;
  PetscReal phi = Residual(gap0, r, v_, F_, true);
  PetscInt  k   = 0;
  bool      ok  = false;
  a_n_          = 0; // the chord map changes with w_f and gap0
  for (;; ++k) {
    if (std::isnan(phi)) break;
    PetscReal rn_sum = 0;
    for (Eigen::Index c = 0; c < nc; ++c) rn_sum += r[3 * c + kN];
    // The fixed point's test, on one Jacobi pass: the polishing passes below then stop at once.
    if (!(F_.lpNorm<1>() > p_.tol * (p_.r_ref + rn_sum))) {
      ok = true;
      break;
    }
    if (k == newton_max_it_) break;
    // A kept factorisation first (chord step, accepted if it halves ||F||); else a fresh one at r
    // with backtracking on ||F||_2 (Armijo with a small slope, as F is only semi-smooth).
    bool accepted = false;
    for (int attempt = 0; attempt < 2 && !accepted; ++attempt) {
      // In the second half of the iteration budget, plain Newton (a fresh J at every iteration):
      // chord steps that only halve ||F|| would otherwise run into the limit and the fallback.
      const bool fresh = !factor_valid_ || 2 * k >= newton_max_it_;
      if (fresh) a_n_ = 0; // another J0, another chord map
      if (fresh && !Factor()) break;
      if (!Direction()) {
        factor_valid_ = false;
        if (fresh) break;
        continue;
      }
      // Anderson mixing: the chord map is nearly linear between status changes, where the mixed
      // point converges as GMRES on the chord's error operator would, at O(3 n_c depth) per step
      // instead of the chord's linear rate. Taken when it halves ||F||, else the chord step.
      bool mixed = false;
      if (!fresh && anderson_ > 0) {
        const Eigen::Index j = AndersonSlot(anderson_);
        a_f_.col(j)          = d_;
        a_g_.col(j)          = r + d_;
        a_v_.col(j)          = v_ + hWd_;
        mixed                = Mix();
      }
      if (mixed) {
        const PetscReal phia = Residual(gap0, rt_, vt_, Ft_, false);
        if (phia <= 0.5 * phi) {
          accepted = true;
          ++mixed_;
          break;
        }
      }
      PetscReal alpha = 1;
      for (int ls = 0; ls < (fresh ? 30 : 1) && !accepted; ++ls, alpha *= 0.5) {
        rt_                  = r + alpha * d_;
        vt_                  = v_ + alpha * hWd_;
        const PetscReal phit = Residual(gap0, rt_, vt_, Ft_, false);
        accepted             = fresh ? phit <= (1 - 1e-4 * alpha) * phi : phit <= 0.5 * phi;
      }
      if (!accepted) {
        factor_valid_ = false;
        if (fresh) break;
      }
    }
    if (!accepted) break;
    r  = rt_;
    v_ = vt_;
    phi = Residual(gap0, r, v_, F_, true);
  }
  newton_steps_ += k;
  last_steps_ = k;
  LocalSolveInfo info;
  if (ok) info = Passes(w_f, gap0, r); // the fixed point's own stopping test (and v = w_f + h W r)
  if (!ok || !info.converged) {
    // Newton failed (or left a point the passes could not finish from): the fixed point from the
    // starting guess, which is then exactly the fixed point's own solve.
    ++fallbacks_;
    r             = r0_;
    info          = Passes(w_f, gap0, r);
    info.fallback = true;
  }
  info.iterations += k;
  Remember(r);
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
    // Stick: strictly inside the friction disc (docs/method.md §5, "Cost and status").
    const PetscReal rT = cs_->law == FrictionLaw::Rectilinear ? std::abs(r[o + kT]) : std::hypot(r[o + kT], r[o + kB]);
    status[c] = rT < (1 - 1e-9) * cs_->Mu() * rn ? kStick : kSlip;
  }
}

} // namespace squeal
