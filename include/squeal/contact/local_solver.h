// The one-step contact problem on the local reactions (docs/method.md §2, §5 (S6)-(S7)).
//
// Given the Delassus matrix W = H^T A^-1 H (3 n_c x 3 n_c, local (t, b, n) per point), the local
// free velocity w_f = H^T v_f and the modified gap at the start of the step g~^i_n, find r with
//   v = w_f + h W r,   g~_n = g~^i_n + h v_n,
//   r_n = max(0, r_n - rho_n g~_n),   r_T = proj_{D(mu r_n)}(r_T - rho_t s),   s = (v_t - V_c, v_b)
// (rectilinear: r_t clamped to [-mu r_n, mu r_n], r_b = 0), by block Gauss-Seidel passes over the
// points (v updated after each point; with one point this is the reference's Jacobi pass).
// Stop when sum_c ||r_c^(k+1) - r_c^(k)||_1 <= tol (R_ref + sum_c r_n,c).
// On run-time sizes the passes may be Anderson-mixed (SetFixedPointAnderson): each pass starts
// from the combination of the last passes' outputs whose changes combine to the least norm, which
// halves the passes where Gauss-Seidel is slow (a strongly coupled W, as a reduced FE model's).
// The problem is small and dense, so it is replicated on every rank: no communication, and every
// rank takes identical decisions. With many contacts W may be given sparse (Setup overload): the
// same passes in the same order, each costing O(nnz(W)). All storage is sized in Setup; Solve allocates nothing.
// The passes are written once (ContactPasses) for any storage: Solve runs them on run-time sizes,
// SolveSized on compile-time sizes for the fixed-size dense step kernels (integration/step_kernel.h),
// where fixed-size loops cost about half the instructions of the dynamic ones on 3 x 3 data.
//
// Alternative solver (SetSolver(kNewton)): a semi-smooth Newton on the same fixed-point equations,
// F(r) = r - P(r) = 0 with P one Jacobi pass of the projections above (Alart-Curnier augmented
// Lagrangian form). With x = r - D (v - (V_c, 0, 0)) (+ the gap term), D = diag(rho_t, rho_t, h rho_n)
// per point, v = w_f + h W r, a generalised Jacobian is J = I - G (I - D h W), G block diagonal: the
// Jacobian of each point's projection at x (open: 0; stick: I; slip: radial part of the disc, or the
// clamp's d/dx_n for rectilinear friction). Each iteration solves J d = -F by LU (sparse W: SparseLU
// on the block pattern of W). Dense W: G has rank m below 3 n_c (open points 0, a sliding point 2 on
// the disc or 1 on a line, a stuck one 3 or 2), G = P Q with P, Q block diagonal, so J = I - P Z,
// Z = Q - Q D h W, and by Woodbury J^-1 F = F + P S^-1 Z F with S = I_m - Z P (m x m): LAPACK's LU
// of S, not of J (on a sliding pad m ~ 2 n_c: a third of the LU's cost; SetNewtonCondensed(false)
// factorises J itself). The factorisation costs as much as tens of fixed-point passes, so it is kept,
// across iterations and steps, as long as the step it gives (a chord step, O((3 n_c)^2)) halves
// ||F||_2 (and, with SetNewtonRefactor(k), until a solve takes more than k Newton steps); otherwise J
// is refactorised at the current point and the Newton step halved until ||F||_2 decreases. The chord steps are
// Anderson-mixed over the last few (SetSolver's anderson), which turns their linear rate into
// about GMRES's on the chord's error operator. Converged (||F||_1 below the fixed point's criterion), the fixed-point
// passes run from the Newton solution, so that the result passes the same stopping test as the fixed
// point (usually one pass). Failure (non-finite step, no decrease, iteration limit) restarts the
// fixed point from the starting guess: the result is then the fixed point's own, and the fallback is
// reported (LocalSolveInfo::fallback, Fallbacks()). Iterations count Newton steps plus passes.
#pragma once

#include "squeal/contact/contact_set.h"
#include "squeal/core/hypot.h"

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/LU>
#include <Eigen/SparseCore>
#include <Eigen/SparseLU>

#include <algorithm>
#include <cmath>
#include <type_traits>
#if defined(__AVX2__) && defined(__FMA__)
#include <immintrin.h>
#endif
#include <vector>

namespace squeal {

enum ContactStatus : int { kOpen = 0, kStick = 1, kSlip = 2 };

// Local contact solver: projected Gauss-Seidel fixed point, or semi-smooth Newton (with the fixed
// point as fallback).
enum class ContactSolver : int { kFixedPoint = 0, kNewton = 1 };

struct LocalSolveInfo {
  PetscInt  iterations = 0; // fixed point: passes; Newton: Newton steps + passes (polish or fallback)
  PetscReal residual   = 0; // last sum ||dr||_1 / (R_ref + sum r_n)
  bool      converged  = false;
  bool      fallback   = false; // Newton failed and the fixed point from the starting guess gave r
};

// Scalars of the fixed point, shared by every instantiation of ContactPasses.
struct FixedPointParams {
  PetscReal h = 0, mu = 0, tol = 1e-12, r_ref = 1.0;
  PetscInt  max_it      = 500;
  bool      rectilinear = false;
  bool      v_current   = false; // v already holds w_f + h W r (run-time sizes then skip that product)
};

// v += hW(:, o + kT) dt + hW(:, o + kB) db + hW(:, o + kN) dn on a sparse (column-major) W, where a
// pass then costs O(nnz(W)) instead of O(n_c^2).
template <class VecV>
EIGEN_ALWAYS_INLINE void AddColumns(const Eigen::SparseMatrix<PetscReal> &hW, Eigen::Index o, PetscReal dt, PetscReal db, PetscReal dn,
                                    VecV &v)
{
  const PetscReal d[3] = {dt, db, dn}; // kT, kB, kN
  const int       j[3] = {kT, kB, kN};
  for (int k = 0; k < 3; ++k)
    for (Eigen::SparseMatrix<PetscReal>::InnerIterator it(hW, o + j[k]); it; ++it) v[it.index()] += it.value() * d[k];
}

// v += w0 d0 + w1 d1 + w2 d2 with the columns w in float and v, d in double (SetFixedPointSingle):
// each column element is widened to double before its product, so the only rounding against the
// double columns is that of W's entries to float.
EIGEN_ALWAYS_INLINE void AddColumnsSingle(Eigen::Index n, const float *w0, const float *w1, const float *w2, PetscReal d0, PetscReal d1,
                                          PetscReal d2, PetscReal *v)
{
  Eigen::Index i = 0;
#if defined(__AVX2__) && defined(__FMA__)
  const __m256d a0 = _mm256_set1_pd(d0), a1 = _mm256_set1_pd(d1), a2 = _mm256_set1_pd(d2);
  for (; i + 4 <= n; i += 4) {
    __m256d x = _mm256_loadu_pd(v + i);
    x         = _mm256_fmadd_pd(_mm256_cvtps_pd(_mm_loadu_ps(w0 + i)), a0, x);
    x         = _mm256_fmadd_pd(_mm256_cvtps_pd(_mm_loadu_ps(w1 + i)), a1, x);
    x         = _mm256_fmadd_pd(_mm256_cvtps_pd(_mm_loadu_ps(w2 + i)), a2, x);
    _mm256_storeu_pd(v + i, x);
  }
#endif
  for (; i < n; ++i) v[i] += PetscReal(w0[i]) * d0 + PetscReal(w1[i]) * d1 + PetscReal(w2[i]) * d2;
}

// (r_t, r_b) onto the friction set of radius a: the disc (planar) or [-a, a] x {0} (rectilinear).
// Shared by the fixed point and the semi-smooth Newton's residual, so that both solve one problem.
// Inline: |(r_t, r_b)| by core/hypot.h's Hypot (libm's number without the call), else std::hypot.
template <bool Inline = false>
EIGEN_ALWAYS_INLINE void ProjectFriction(bool rectilinear, PetscReal a, PetscReal &rt, PetscReal &rb)
{
  if (rectilinear) {
    rt = std::min(a, std::max(-a, rt));
    rb = 0;
    return;
  }
  const PetscReal m = Inline ? Hypot(rt, rb) : std::hypot(rt, rb);
  if (m > a) {
    const PetscReal f = m > 0 ? a / m : 0.0;
    rt *= f;
    rb *= f;
  }
}

// The fixed-point passes on any Eigen storage (dynamic or fixed size): hW = h W (3 n_c square),
// rho_n, rho_t, speed, gap0 per point, w_f and r per local row; v = w_f + h W r on return.
// Always inlined: on fixed sizes r and v then stay in registers across the passes.
// A float hW (SetFixedPointSingle) only updates v: the caller gives v (p.v_current).
template <bool Rectilinear, class MatW, class VecC, class VecG, class VecF, class VecR, class VecV>
EIGEN_ALWAYS_INLINE LocalSolveInfo ContactPassesLaw(const FixedPointParams &p, const MatW &hW, const VecC &rho_n, const VecC &rho_t,
                                                    const VecC &speed, const VecF &w_f, const VecG &gap0, VecR &r, VecV &v)
{
  constexpr bool     kFixed  = MatW::SizeAtCompileTime != Eigen::Dynamic;
  constexpr bool     kSingle = std::is_same_v<typename MatW::Scalar, float>;
  const Eigen::Index nc     = rho_n.size();
  PetscReal          residual = 0; // a local, not info's member: stays in a register across the passes
  if constexpr (!kSingle)
    if (kFixed || !p.v_current) v.noalias() = w_f + hW * r; // the fixed-size kernels never mix passes
  for (PetscInt it = 1; it <= p.max_it; ++it) {
    PetscReal change = 0, rn_sum = 0;
    for (Eigen::Index c = 0; c < nc; ++c) {
      const Eigen::Index o  = 3 * c;
      const PetscReal    gn = gap0[c] + p.h * v[o + kN];
      const PetscReal    rn = std::max(0.0, r[o + kN] - rho_n[c] * gn);
      PetscReal          rt, rb;
      const PetscReal    a = p.mu * rn;
      if constexpr (kFixed && !Rectilinear) {
        // Hypot inlined (~35 instructions a point and pass less than the call). The two products
        // rounded before the differences: so the compiled fixed-size kernels did around the call
        // (GCC paired the two rows in vector registers, which left them unfused), and so the
        // reactions stay bit for bit those of std::hypot's kernels; inlined, GCC fused them.
        rt = r[o + kT] - Rounded(rho_t[c] * (v[o + kT] - speed[c]));
        rb = r[o + kB] - Rounded(rho_t[c] * v[o + kB]);
        ProjectFriction<true>(false, a, rt, rb);
      } else {
        rt = r[o + kT] - rho_t[c] * (v[o + kT] - speed[c]);
        rb = r[o + kB] - rho_t[c] * v[o + kB];
        ProjectFriction(Rectilinear, a, rt, rb);
      }
      const PetscReal dt = rt - r[o + kT], db = rb - r[o + kB], dn = rn - r[o + kN];
      // Only changed points update v (one branch instead of three), except on compile-time sizes,
      // where adding hW times zeros (v unchanged) costs less than the test.
      if (kFixed || (dt != 0) | (db != 0) | (dn != 0)) {
        if constexpr (std::is_base_of_v<Eigen::SparseMatrixBase<MatW>, MatW>) AddColumns(hW, o, dt, db, dn, v);
        else if constexpr (kSingle) AddColumnsSingle(v.size(), hW.col(o + kT).data(), hW.col(o + kB).data(), hW.col(o + kN).data(), dt, db, dn, v.data());
        else v.noalias() += hW.col(o + kT) * dt + hW.col(o + kB) * db + hW.col(o + kN) * dn;
        r[o + kT] = rt;
        r[o + kB] = rb;
        r[o + kN] = rn;
      }
      change += std::abs(dt) + std::abs(db) + std::abs(dn);
      rn_sum += rn;
    }
    residual = change / (p.r_ref + rn_sum);
    if (!(residual > p.tol)) return {it, residual, !std::isnan(residual)}; // also stops on NaN, which the caller reports
  }
  return {p.max_it, residual, false};
}

// The passes with the friction law's branch taken once per solve instead of once per point and pass.
template <class MatW, class VecC, class VecG, class VecF, class VecR, class VecV>
EIGEN_ALWAYS_INLINE LocalSolveInfo ContactPasses(const FixedPointParams &p, const MatW &hW, const VecC &rho_n, const VecC &rho_t, const VecC &speed,
                                    const VecF &w_f, const VecG &gap0, VecR &r, VecV &v)
{
  if (p.rectilinear) return ContactPassesLaw<true>(p, hW, rho_n, rho_t, speed, w_f, gap0, r, v);
  return ContactPassesLaw<false>(p, hW, rho_n, rho_t, speed, w_f, gap0, r, v);
}

class LocalContactSolver {
public:
  // W is 3n_c x 3n_c; rho_scale multiplies the rules (2.4) (1 = docs/method.md).
  void Setup(const ContactSet &cs, const Eigen::MatrixXd &W, PetscReal h, PetscReal rho_scale);
  // The same with W sparse (many contacts): the same passes, each O(nnz(W)); Solve then uses it
  // (SolveSized needs the dense Setup).
  void Setup(const ContactSet &cs, const Eigen::SparseMatrix<PetscReal> &W, PetscReal h, PetscReal rho_scale);
  void SetTolerances(PetscReal tol, PetscInt max_it, PetscReal r_ref)
  {
    p_.tol    = tol;
    p_.max_it = max_it;
    p_.r_ref  = r_ref;
  }
  // The solver of Solve (after Setup; default fixed point) and Newton's iteration limit. Newton's
  // work arrays (a 3 n_c square matrix and its LU) are sized here, not in Solve. SolveSized always
  // runs the fixed point.
  // anderson: depth of the Anderson mixing of the chord steps (0: plain chord steps).
  void SetSolver(ContactSolver s, PetscInt newton_max_it = 30, PetscInt anderson = 0);
  ContactSolver Solver() const { return solver_; }
  // Dense W: Newton's system factorised through its condensed form S (default) or as J itself (the
  // same steps to rounding; tests compare the two). Before SetSolver, or after it (then resizes its arrays).
  void SetNewtonCondensed(bool on);
  bool NewtonCondensed() const { return condensed_; }
  // Refactorise J at a solve's start when the solve before took more than k Newton steps (-1: only
  // when a chord step fails to halve ||F||). The kept factor ages along a trajectory (slip directions
  // turn) and its chord steps slow down; a fresh one at the extrapolated start converges in about two.
  void     SetNewtonRefactor(PetscInt k) { refactor_after_ = k < 0 ? -1 : k; }
  PetscInt NewtonRefactor() const { return refactor_after_; }
  // Starting guess on the run-time-sized paths (not the compile-time-sized kernels of SolveSized):
  // 0 the r given (the previous step's reaction), 1 or 2 its linear or quadratic extrapolation
  // from the last solutions, when the r given is the last solution returned (a step continuing a
  // trajectory; any other r starts the history again). Reactions are smooth in time between
  // events, so the extrapolation starts O(h) closer: measured 21 % fewer fixed-point passes on a
  // 175-point pad, 24 % on a 451-point one (docs/records.md). History sized in Setup.
  void     SetPredictor(PetscInt order) { predict_ = std::max<PetscInt>(0, std::min<PetscInt>(order, 2)), n_hist_ = 0; }
  // Drop what one solve hands the next (the predictor's solutions, Newton's kept factor, the mixing
  // history): the next solve starts as the first would. For replicas of this solver on several ranks
  // of which one alone has solved since (shooting's flows on several ranks), so that all start alike.
  void     ForgetHistory() { n_hist_ = 0, factor_valid_ = false, a_n_ = 0, last_steps_ = 0; }
  // Anderson mixing of the fixed point's passes over the last `depth` (0: plain passes; at most 8),
  // on the run-time-sized and sparse paths (also the Newton's fallback); after Setup. A pass is
  // r -> G(r) (one Gauss-Seidel sweep); the next pass starts from the combination of the last
  // G(r) whose changes G(r) - r combine to the least norm, and v follows by linearity (no product
  // with W). The history restarts when a pass changes r more than the one before. The result is
  // always a pass's own output, so it passes the same stopping test as the plain passes (and a
  // solve capped by max_it returns the last pass's output, inside the friction set). Setup resets
  // the depth to 0: call this after it.
  void     SetFixedPointAnderson(PetscInt depth);
  PetscInt FixedPointAnderson() const { return fp_anderson_; }
  // Dense W on run-time sizes: symmetric Gauss-Seidel sweeps (forward, backward, ...) instead of the
  // forward passes, unmixed. A point's velocity is w_f + its diagonal block's share + the sums of
  // W's row over the points before it (s) and after it (t), both kept by axpys with the columns
  // of the points visited: a forward sweep adds each new r_c to the rows below c only (and reads
  // the t the backward sweep before it left), a backward sweep to the rows above, so a sweep reads
  // half of h W where a pass reads all of it (SymmetricSweeps). No symmetry of W is assumed.
  // Iterations then count sweeps.
  void SetFixedPointSymmetric(bool on) { fp_symmetric_ = on, single_ = single_ && !on; }
  bool FixedPointSymmetric() const { return fp_symmetric_; }
  // Dense W on run-time sizes, forward passes: the passes' updates of v read h W rounded to float,
  // half the memory a pass streams (a large W outgrows the caches: on 651 points, 1953^2 doubles
  // are 30 MB, and a pass then costs 3 times a float one, docs/records.md). v is still kept and
  // summed in double, and, being linear in r, is exactly v(r) + E (r - r_x), E = float(h W) - h W
  // (|E_ij| <= 2^-24 |h W_ij| + 2^-150), r_x the reactions of the last
  // product with the double h W. Summed over the points, that error moves their projections (each
  // taken at the pass's own intermediate state; the projections are non-expansive, the friction
  // radius follows r_n) by at most b = 2 (1 + mu) 2^-24 kappa (||r - r_x||_1 + the pass's change), in
  // the stopping test's measure, kappa the largest column sum of |h W| weighted by each row's rho
  // (rho_t, h rho_n), each entry raised by 2^-126. A pass then stops the solve when its change plus b is below the tolerance,
  // and when b reaches half the change v is made again with the double h W (r_x = r; the mixing
  // history follows by linearity). b does not cover how one point's error reaches the later points
  // of the same pass through h W; checked against exact passes from the same starts, the difference
  // stayed below 0.01 b (a review's long-double runs on the test's strongly coupled W).
  // Taken from min_unknowns local unknowns (3 n_c; 0: never), forward passes only (not with
  // SetFixedPointSymmetric), not on entries beyond float's range; after Setup and
  // SetFixedPointSymmetric. Returns whether taken.
  bool SetFixedPointSingle(PetscInt min_unknowns);
  bool FixedPointSingle() const { return single_; }
  PetscInt Refreshes() const { return refreshes_; } // products with the double h W made to bound E's error (since SetFixedPointSingle)
  PetscInt Predictor() const { return predict_; }
  // Counters since Setup: Newton solves, of which fell back to the fixed point, and Newton steps.
  PetscInt NewtonSolves() const { return newton_solves_; }
  PetscInt Fallbacks() const { return fallbacks_; }
  PetscInt NewtonSteps() const { return newton_steps_; }
  PetscInt Factorisations() const { return factorisations_; }
  PetscInt MixedSteps() const { return mixed_; }
  PetscInt MixedPasses() const { return mixed_passes_; } // fixed-point passes started from a mixed point
  // r holds the starting guess (the previous step's reaction) and returns the solution.
  LocalSolveInfo Solve(const Eigen::VectorXd &w_f, const Eigen::VectorXd &gap0, Eigen::VectorXd &r);
  // The same on NC points known at compile time (Eigen::Dynamic: any); NC must equal Setup's n_c.
  template <int NC, class VecF, class VecG, class VecR>
  EIGEN_ALWAYS_INLINE LocalSolveInfo SolveSized(const VecF &w_f, const VecG &gap0, VecR &r)
  {
    constexpr int      M  = NC == Eigen::Dynamic ? Eigen::Dynamic : 3 * NC;
    const Eigen::Index nc = rho_n_.size();
    using MapC            = Eigen::Map<const Eigen::Matrix<PetscReal, NC, 1>>;
    const Eigen::Map<const Eigen::Matrix<PetscReal, M, M>> hW(hW_.data(), 3 * nc, 3 * nc);
    const MapC                                             rho_n(rho_n_.data(), nc), rho_t(rho_t_.data(), nc), speed(speed_.data(), nc);
    Eigen::Map<Eigen::Matrix<PetscReal, M, 1>>             v(v_.data(), 3 * nc);
    RefreshFriction();
    p_.mu          = cs_->Mu(); // read at every solve, as callers may change mu between steps
    p_.rectilinear = cs_->law == FrictionLaw::Rectilinear;
    if constexpr (M == Eigen::Dynamic) {
      if (solver_ == ContactSolver::kNewton) return SolveNewton(w_f, gap0, r); // predicts itself
      Predict(r);
      const LocalSolveInfo info = Passes(w_f, gap0, r); // with Anderson mixing when asked for
      Remember(r);
      return info;
    }
    else { // work on local copies, which the compiler can keep in registers
      Eigen::Matrix<PetscReal, M, 1> rl = r, vl;
      const LocalSolveInfo           info = ContactPasses(p_, hW, rho_n, rho_t, speed, w_f, gap0, rl, vl);
      r = rl, v = vl;
      return info;
    }
  }
  // Local velocity at the end of the step for the last solution: v = w_f + h W r (with h W in float,
  // plus E (r - r_x), SetFixedPointSingle).
  const Eigen::VectorXd &Velocity() const { return v_; }
  // Status of each point for reaction r: open (r_n = 0), stick (|r_T| < mu r_n), slip.
  void Status(const Eigen::VectorXd &r, std::vector<int> &status) const;

  PetscReal RhoN(PetscInt c) const { return rho_n_[c]; }
  PetscReal RhoT(PetscInt c) const { return rho_t_[c]; }

private:
  // The sliding speeds V_c follow ContactSet::SetFriction (a continuation in V, a sweep point)
  // without a new Setup: one comparison per solve.
  void RefreshFriction()
  {
    if (cs_->FrictionState() == friction_state_) return;
    for (Eigen::Index c = 0; c < speed_.size(); ++c) speed_[c] = cs_->Speed(c);
    friction_state_ = cs_->FrictionState();
  }
  using CRef = Eigen::Ref<const Eigen::VectorXd>;
  using Ref  = Eigen::Ref<Eigen::VectorXd>;
  LocalSolveInfo SolveNewton(CRef w_f, CRef gap0, Ref r);
  void Predict(Ref r)
  {
    if (predict_ == 0) return;
    if (n_hist_ == 0 || r != hist_.col(0)) {
      n_hist_ = 0;
      return;
    }
    if (predict_ == 2 && n_hist_ >= 3) r = 3 * (hist_.col(0) - hist_.col(1)) + hist_.col(2);
    else if (n_hist_ >= 2) r = 2 * hist_.col(0) - hist_.col(1);
  }
  void Remember(CRef r)
  {
    if (predict_ == 0) return;
    hist_.col(2) = hist_.col(1);
    hist_.col(1) = hist_.col(0);
    hist_.col(0) = r;
    n_hist_      = std::min<PetscInt>(n_hist_ + 1, 3);
  }
  LocalSolveInfo Passes(CRef w_f, CRef gap0, Ref r); // the fixed point on the dense or sparse W
  // F = r - P(r) at v = w_f + h W r; returns ||F||_2 (NaN if not finite). With jac, also the
  // per-point G_c D_c (gd_) and G_c (g_) of the generalised Jacobian.
  PetscReal Residual(CRef gap0, CRef r, CRef v, Eigen::VectorXd &F, bool jac);
  void      AssembleJacobian(); // J = I - G + G D h W from g_, gd_
  bool      Factor();           // assembles and factorises J at the current point; false if unusable
  bool      Direction();        // d_ = -J^-1 F_ and hWd_ = h W d_ with the factor held; false if not finite
  bool      FactorCondensed();  // Factor on dense W: S from the current P, Q (kept with it as pf_, qf_, qdf_)
  // Anderson mixing of a map r -> g(r) with f = g(r) - r: the chord map r - J0^-1 F(r) (J0 the
  // factor held) or a fixed-point pass. Mix writes to rt_, vt_ the combination of the history's g
  // (and, v being linear in r, of their v) whose f combine to the least norm. False when the
  // history holds fewer than two entries or the least-squares problem is singular.
  // Storage: AndersonSlot(depth) makes room for one more entry (dropping the oldest when depth + 1
  // are held) and returns its column, which the caller fills (a_f_: f, a_g_: g, a_v_: v(g)).
  Eigen::Index AndersonSlot(PetscInt depth);
  bool         Mix();
  void         SizeAnderson(); // the history for max(anderson_ (Newton), fp_anderson_) + 1 entries

  const ContactSet *cs_ = nullptr;
  unsigned long     friction_state_ = 0; // cs_->FrictionState() that speed_ holds
  Eigen::MatrixXd   hW_; // h W
  Eigen::SparseMatrix<PetscReal> hWs_; // h W when set up sparse (then hW_ is empty)
  bool              sparse_ = false;
  Eigen::VectorXd   v_, rho_n_, rho_t_, speed_;
  FixedPointParams  p_;
  PetscInt          predict_ = 0, n_hist_ = 0; // SetPredictor
  Eigen::MatrixXd   hist_;                     // the last 3 solutions, newest first (3 n_c x 3)
  // Newton
  ContactSolver   solver_        = ContactSolver::kFixedPoint;
  PetscInt        newton_max_it_ = 30;
  PetscInt        newton_solves_ = 0, fallbacks_ = 0, newton_steps_ = 0, factorisations_ = 0;
  bool            factor_valid_  = false; // lu_ / slu_ hold a J from an earlier point (kept across solves)
  Eigen::VectorXd r0_, F_, Ft_, d_, rt_, vt_, hWd_;
  // Anderson history (columns oldest to newest; cleared when the factor or the problem changes):
  // at most depth + 1 entries, so the least-squares problem has at most depth unknowns.
  static constexpr PetscInt kMaxAnderson = 8;
  PetscInt        anderson_ = 0, a_n_ = 0;
  Eigen::MatrixXd a_f_, a_g_, a_v_, a_df_;
  PetscInt        mixed_ = 0; // chord steps replaced by the mixed point (counter since Setup)
  PetscInt        fp_anderson_ = 0, mixed_passes_ = 0;
  bool            fp_symmetric_ = false;
  Eigen::VectorXd sw_s_, sw_t_; // SymmetricSweeps' sums over the points before and after each point
  LocalSolveInfo  SymmetricSweeps(CRef w_f, CRef gap0, Ref r);
  Eigen::VectorXd rin_; // the fixed point with mixing: the start of the current pass
  // SetFixedPointSingle: h W in float, kappa, r_x and a work vector
  bool            single_ = false;
  Eigen::MatrixXf hWf_;
  PetscReal       kappa_ = 0;
  PetscInt        refreshes_ = 0;
  Eigen::VectorXd rx_, vx_;
  PetscReal       DriftBound(CRef r, PetscReal change) const; // b of SetFixedPointSingle
  Eigen::Matrix<PetscReal, 3, Eigen::Dynamic> g_, gd_; // per point (3 x 3 blocks side by side): G_c, G_c D_c
  Eigen::MatrixXd                       J_;            // dense W, !condensed_
  // Dense W, condensed_: per point c, columns 3c .. 3c + m_c - 1 hold P_c's columns (pc_) and Q_c's
  // rows (qc_) at the last Jacobian's point; pf_, qf_, qdf_ (Q_c D_c's rows), mf_, kf_ (offset in S)
  // those of the factor held; hWP_ = h W P (3 n_c x m) and S_ (m x m, LAPACK's LU in place) in
  // storage sized once (3 n_c square each); t_ = h W F, z_ = Z F.
  bool                                        condensed_ = true;
  PetscInt                                    refactor_after_ = -1, last_steps_ = 0;
  Eigen::Matrix<PetscReal, 3, Eigen::Dynamic> pc_, qc_, pf_, qf_, qdf_;
  std::vector<int>                            mc_, mf_, kf_;
  Eigen::Index                                ms_ = 0;
  Eigen::MatrixXd                             hWP_, S_;
  Eigen::VectorXd                             t_, z_;
  std::vector<PetscBLASInt>                   ipiv_;
  Eigen::PartialPivLU<Eigen::MatrixXd>  lu_;
  Eigen::SparseMatrix<PetscReal>        Js_;           // sparse W: J on the 3 x 3 block pattern of W
  Eigen::SparseLU<Eigen::SparseMatrix<PetscReal>, Eigen::COLAMDOrdering<int>> slu_;
};

} // namespace squeal
