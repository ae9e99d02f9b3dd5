// Non-smooth theta-method with impulses and the modified normal displacement (docs/method.md §5),
// split like Siconos' Moreau-Jean step: free step, one-step contact problem, update.
//
// Once per step size h (SetUp):
//   (S1) A = M + h theta C + h^2 theta^2 K (factorised),  B = M - h(1-theta) C - h^2 theta(1-theta) K
//   (S2) Y = A^-1 H (3 n_c solves),  W = H^T Y (Delassus, dense, replicated)
//   (S3) rho_n,c = 1/(h^2 W_nn,cc), rho_t,c = 1/(h W_tt,cc)   (times -theta_rho_scale)
// Every step:
//   (S4) A v_f = B dU^i - h K U^i + h F
//   (S5) w_f = H^T v_f,  g~^i_n = H_n^T (U^i + h(1-theta) dU^i) + g0
//   (S6-7) local fixed point on r, or semi-smooth Newton (-theta_contact_solver; LocalContactSolver)
//   (S8) dU^{i+1} = v_f + h Y r,   (S9) U^{i+1} = U^i + h (theta dU^{i+1} + (1-theta) dU^i)
// Sparse back end with many contacts (3 n_c > -theta_delassus_max; default -1: whenever the product
// with Y would cost more than one more solve, N 3 n_c > 2 nnz(factor of A)): no N x 3 n_c matrix is stored. (S2) keeps W = H^T A^-1 H sparse: each column from one solve, entries with
// |W_ij| <= -theta_delassus_drop (default 1e-15) x max_i |W_ij| dropped (counted, and the largest
// dropped ratio shown by View; 0 keeps every non-zero); (S6-7) runs the same passes on it at
// O(nnz(W)) each; (S8) dU^{i+1} = v_f + A^-1 (h H r) by one more solve with the factorised A.
// For a chain W is numerically banded; for a general model it may be dense and the passes then
// cost as much as with the dense W (the result is the same either way).
// Two back ends with identical equations: "dense" (N <= -theta_dense_max; by default N <= 200, or
// N <= 2000 when the model's matrices are dense, as a Craig-Bampton reduction's are: DefaultDense; under MPI
// every rank steps the gathered state, so a small model costs the same on any rank count;
// A^-1 B, A^-1 K, A^-1 F and Y precomputed, so a step is a few dense mat-vecs, as a hand-written
// loop would do) and "sparse" (distributed AIJ, A factorised once by KSP/PC: PETSc's Cholesky
// on one rank; on several, -theta_parallel_solver: MUMPS LU (direct) or CG preconditioned by
// block Jacobi with each rank's diagonal block of A factorised by PETSc's Cholesky (cg, to
// -theta_cg_rtol); options -theta_ksp_*, -theta_pc_*). The dense matrices are N x N, so
// the step becomes memory-bound past a few hundred DOFs: measured crossover between N = 90 and
// N = 300 (benchmarks/bench_step.cpp). Nothing is allocated per step or per fixed-point pass.
// The dense step runs in a DenseStepKernel chosen in SetUp (integration/step_kernel.h): compiled for
// fixed sizes when the model matches one (-theta_fixed_size, default true), run-time sizes otherwise,
// or in the modal coordinates of (K, M) where C is diagonal there (-theta_modal_step): then (S1)-(S2)
// form W from H^T Phi and no N x N matrix (theta_modal.cpp).
#pragma once

#include "squeal/contact/local_solver.h"
#include "squeal/integration/step_kernel.h"
#include "squeal/core/gather.h"
#include "squeal/core/handle.h"
#include "squeal/model/model.h"

#include <Eigen/Dense>
#include <Eigen/SparseCore>

#include <cstdint>
#include <string>

namespace squeal {

struct StepInfo {
  LocalSolveInfo contact;
};

class ThetaIntegrator {
public:
  explicit ThetaIntegrator(MPI_Comm comm) : comm_(comm) {}
  PetscErrorCode SetOptionsPrefix(const char *prefix);
  PetscErrorCode SetTheta(PetscReal theta);
  PetscErrorCode SetFixedPoint(PetscReal tol, PetscInt max_it); // also for the steps after it, without a new SetUp
  PetscReal      FixedPointTolerance() const { return fp_tol_; }
  void           SetFixedPointSymmetric(PetscBool on) { fp_symmetric_ = on; } // -theta_fp_symmetric; at the next SetUp
  void           SetFixedPointSingle(PetscInt min_unknowns) { fp_single_ = min_unknowns; } // -theta_fp_single; at the next SetUp
  PetscInt       FixedPointMaxIt() const { return fp_max_it_; }
  PetscErrorCode SetRhoScale(PetscReal s);
  PetscErrorCode SetDenseMax(PetscInt n); // PETSC_DECIDE: from the model (DefaultDense)
  // The back end chosen without -theta_dense_max for a model of n DOFs whose K and M have this
  // fraction of non-zeros (the larger of the two).
  static bool    DefaultDense(PetscInt n, PetscReal density);
  // Sparse back end: largest 3 n_c with the dense W and Y = A^-1 H (above: sparse W, (S8) by a solve;
  // < 0: by cost, see above), and the relative drop tolerance of the sparse W (0: exact non-zeros only).
  PetscErrorCode SetDelassusMax(PetscInt n, PetscReal drop);
  // -theta_theta, -theta_fp_tol, -theta_fp_max_it, -theta_rho_scale, -theta_dense_max,
  // Sparse back end on several ranks: "direct" (MUMPS LU), "cg" (CG + block Jacobi, each rank's
  // block by Cholesky, to relative residual cg_rtol), "redundant" (every rank factorises the whole A)
  // or "auto" (redundant); one rank always factorises A.
  PetscErrorCode SetParallelSolver(const char *name, PetscReal cg_rtol);
  // Local contact solver (S6-7): "fp" (fixed point), "ssn" (semi-smooth Newton, fixed point as
  // fallback, LocalContactSolver), "auto" (fp: with mixed passes the faster on every model measured, theta.cpp); Newton's iteration limit.
  PetscErrorCode SetContactSolver(const char *name, PetscInt ssn_max_it, PetscInt ssn_anderson = 5);
  // -theta_delassus_max, -theta_delassus_drop, -theta_parallel_solver, -theta_cg_rtol, -theta_ksp_*,
  // -theta_contact_solver, -theta_ssn_max_it.
  PetscErrorCode SetFromOptions();
  // (S1)-(S3) for step size h; call again whenever h changes.
  PetscErrorCode SetUp(const Model &model, PetscReal h);
  // One step in place: (U, dU) at t_i -> t_{i+1}; r: local reactions (3 n_c, warm start in, result out).
  PetscErrorCode Step(Vec U, Vec dU, Eigen::VectorXd &r, StepInfo *info);
  // Exact tangent of the last step (docs/method.md §6, "Exact tangent of the discrete step"), dense back
  // end only: the columns (dU, ddU) of a tangent at t_i become those at t_{i+1}, differentiating
  // (S4)-(S9) at the converged reactions r = r^{i+1} with every status held fixed; v_end: local
  // velocities H^T dU^{i+1} (for the slip directions). N x k columns, k arbitrary.
  PetscErrorCode StepTangent(const Eigen::VectorXd &r, const Eigen::VectorXd &v_end, Eigen::MatrixXd &dU, Eigen::MatrixXd &ddU);
  // The same tangent with a change dh of the step size per column as well (the shooting period
  // T = N_s h), along a stored step (U^i, dU^i) -> dU^{i+1}: the derivative of the discrete map
  // in h at fixed statuses, so that d Z / d T of shooting is exact without another factorisation.
  // c: StepTangentSource of that step; v_start: H^T dU^i.
  struct StepData {
    const Eigen::VectorXd *dUi, *dUn, *c, *v_start;
    // Optional: the LU of this step's closed-point tangent system (it depends on the step's
    // reactions and velocities, not on the columns), kept by the caller so that later tangent
    // products along the same stored flow skip the O((3 n_c)^3) factorisation. Reset it (valid =
    // false) whenever the flow or the step size changes.
    // With float products (-theta_tangent_single) the factor is computed and kept in float (luf,
    // perm; lu unused): half the memory, and the solves, which read a factor once per step from
    // main memory, take half the time (docs/records.md, "Step factors in float").
    struct Factor {
      bool                                                              valid = false;
      Eigen::PartialPivLU<Eigen::MatrixXd>                              lu;
      Eigen::MatrixXf                                                   luf;
      Eigen::PermutationMatrix<Eigen::Dynamic, Eigen::Dynamic, int>     perm;
    } *factor = nullptr;
    // The columns, c, dUi and dUn in the modal coordinates of ModalTangent (q = Phi^-1 U).
    bool modal = false;
  };
  PetscErrorCode StepTangent(const Eigen::VectorXd &r, const Eigen::VectorXd &v_end, const StepData &step, const Eigen::RowVectorXd &dh,
                             Eigen::MatrixXd &dU, Eigen::MatrixXd &ddU);
  // The order of that step's closed-point system (its factor holds the square of it): 3 per
  // sticking point, 2 per sliding one (1 rectilinear), 0 per open one.
  Eigen::Index TangentSystemSize(const Eigen::VectorXd &r, const Eigen::VectorXd &v_end);
  // Bytes of a stored factor (StepData::Factor) of a system of order m: 8 m (m + 1), half in float.
  double       TangentFactorBytes(Eigen::Index m) const { return (TangentSingle() ? 4.0 : 8.0) * (double)m * (double)(m + 1); }
  // c = d dU^{i+1} / dh at fixed (U^i, dU^i) and r: A^-1 [B' dU^i - K U^i + F - A' dU^{i+1}] + Y r, with
  // A' = theta C + 2 h theta^2 K and B' = -(1 - theta) C - 2 h theta (1 - theta) K. Dense back end.
  PetscErrorCode StepTangentSource(const Eigen::VectorXd &Ui, const Eigen::VectorXd &dUi, const Eigen::VectorXd &dUn,
                                   const Eigen::VectorXd &r, Eigen::VectorXd &c);
  // The same for s steps of a stored flow at once: U = [U^0 .. U^{s-1}], dU = [dU^0 .. dU^s], R =
  // [r^1 .. r^s] (3 n_c x s; none without contacts); C = [c^0 .. c^{s-1}].
  PetscErrorCode StepTangentSources(const Eigen::Ref<const Eigen::MatrixXd> &U, const Eigen::Ref<const Eigen::MatrixXd> &dU,
                                    const Eigen::Ref<const Eigen::MatrixXd> &R, Eigen::MatrixXd &C);
  // Tangents in the modal coordinates q of (K, M), U = Phi q with Phi^T M Phi = I, where Phi^T C Phi
  // is diagonal too (no damping, Rayleigh damping, modal damping): P1 and P2 are then diagonal and a
  // tangent step costs O(n_c N) a column instead of O(N^2). *on: whether StepTangent may be given
  // modal columns (StepData::modal) at the present step size; -theta_modal_tangent: auto (when C
  // is diagonal there and the products cost less than 0.6 x the nodal ones), true, false. The basis
  // is computed once per model (M, K and C unchanged), the diagonals and H^T Phi once per step size.
  PetscErrorCode ModalTangent(bool *on);
  // The nodal tangent's matrices now (StepTangent forms them when first asked): for replicas on
  // several ranks of which one alone would take a nodal tangent, so that StepTangentSource, which
  // reads them if formed, gives every rank the same numbers.
  PetscErrorCode EnsureNodalTangent() { return EnsureNodal(); }
  // The contact solver's carried state forgotten (LocalContactSolver::ForgetHistory).
  void           ForgetContactHistory() { local_.ForgetHistory(); }
  const Eigen::MatrixXd &ModalBasis() const { return Phi_; }      // U = Phi q
  // The forward step in the same modal coordinates (-theta_modal_step; theta_modal.cpp): taken, the
  // set-up of a step size costs O(n_c^2 N) (W from H^T Phi) instead of the O(N^3) of A^-1 B, A^-1 K
  // and A^-1 H, which are then formed only if a nodal tangent asks for them. Shooting sets up at
  // every new period: it says so (SetManySetUps), and the auto choice then takes the modal step.
  bool                   ModalStep() const { return modal_step_on_; }
  // The modal step or tangents at this step size use the dense G = A_m^-1 (C not diagonal in the basis).
  bool                   ModalDense() const { return modal_dense_ && modal_h_ == h_; }
  void                   SetManySetUps(bool many) { many_setups_ = many; }
  // The caller wants W alone and takes no step (the energy estimate's impact losses): auto keeps the
  // nodal set-up, which needs no eigensolve.
  void                   SetDelassusOnly(bool only) { delassus_only_ = only; }
  const Eigen::MatrixXd &ModalInverse() const { return PhiInv_; } // q = Phi^T M U
  // Local quantities x -> H^T x (replicated), e.g. gaps from U or contact velocities from dU.
  PetscErrorCode Local(Vec x, Eigen::VectorXd &out);
  PetscErrorCode View(PetscViewer viewer) const;

  PetscReal                 Theta() const { return theta_; }
  PetscReal                 StepSize() const { return h_; }
  bool                      Dense() const { return dense_; }
  bool                      SparseHt() const { return ht_sparse_; } // H^T by its non-zeros in the dense step and tangent (-theta_h_storage)
  bool                      FixedSizeKernel() const { return kernel_ && kernel_->FixedSize(); }
  // The dense step kernel on one rank (else null), for callers that hold the state in arrays of their
  // own and step them without a Vec (the transient's loop): Step on Vecs over those arrays does the same.
  DenseStepKernel          *OneRankKernel() const { return dense_ && size_ == 1 ? kernel_.get() : nullptr; }
  // The same kernel on any number of ranks (the dense back end holds the whole model on each), for a
  // caller that steps the whole state on one rank for all (shooting's flows on several ranks); null
  // for the sparse back end. LocalOf: H^T x of such a whole state, on this rank alone.
  DenseStepKernel          *ReplicatedKernel() const { return dense_ ? kernel_.get() : nullptr; }
  void                      LocalOf(const Eigen::Ref<const Eigen::VectorXd> &x, Eigen::VectorXd &out) const;
  const Eigen::MatrixXd    &Delassus() const { return W_; } // empty when SparseDelassus()
  bool                      SparseDelassus() const { return sparse_w_; }
  const Eigen::SparseMatrix<PetscReal> &DelassusSparse() const { return Ws_; }
  const LocalContactSolver &Contact() const { return local_; }
  const Model              &GetModel() const { return *model_; }
  const std::string        &Prefix() const { return prefix_; }

private:
  PetscErrorCode SetUpDense();
  PetscErrorCode ModalBasisUpdate(); // the basis of (K, M) and modal_state_, for Md_, Kd_, Cd_
  PetscErrorCode ModalPerStepSize(bool dense); // p1m_, p2m_, ainvm_, Htm_, Htmn_ at h_; dense: G_, Ym_ too
  PetscErrorCode ModalStepSetUp();   // decides modal_step_on_; taken: W and p3m_ from the modal quantities
  PetscErrorCode EnsureNodal();      // P1_, P2_, p3_, Y_ and llt_ when the modal step skipped them
  PetscErrorCode DenseStep(Eigen::Ref<Eigen::VectorXd> U, Eigen::Ref<Eigen::VectorXd> dU, Eigen::VectorXd &r, StepInfo *info);
  void           SetUpKernel(); // after SetUpDense and local_.Setup
  PetscErrorCode StepGeneral(Vec U, Vec dU, Eigen::VectorXd &r, StepInfo *info); // non-native Vecs, gathered dense or sparse
  PetscErrorCode Gather(Vec x, Eigen::VectorXd &out); // the whole vector on every rank (dense back end)
  PetscErrorCode SetUpSparse();
  PetscErrorCode ToLocal(Vec x, Eigen::VectorXd &out); // sparse back end: H^T x gathered

  MPI_Comm     comm_;
  std::string  prefix_   = "theta_";
  PetscReal    theta_    = 0.5, h_ = 0, fp_tol_ = 1e-12, rho_scale_ = 1.0, r_ref_ = 1.0;
  PetscInt     fp_max_it_ = 500, dense_max_ = PETSC_DECIDE;
  PetscInt     contact_solver_ = 0, ssn_max_it_ = 30; // -theta_contact_solver: 0 fp, 1 ssn, 2 auto
  PetscInt     contact_predict_ = 2;                 // -theta_contact_predict: order of the starting guess's extrapolation
  PetscInt     ssn_refactor_ = 3;                    // -theta_ssn_refactor: LocalContactSolver::SetNewtonRefactor
  PetscBool    ssn_condensed_ = PETSC_TRUE;          // -theta_ssn_condensed: LocalContactSolver::SetNewtonCondensed
  PetscInt     ssn_anderson_ = 5;                    // -theta_ssn_anderson: depth of the mixing of Newton's chord steps
  PetscInt     fp_anderson_ = 5;                     // -theta_fp_anderson: depth of the mixing of the fixed point's passes
  PetscBool    fp_symmetric_ = PETSC_FALSE;          // -theta_fp_symmetric: symmetric Gauss-Seidel sweeps (dense W, run-time sizes)
  PetscInt     fp_single_ = 512;                     // -theta_fp_single: passes read h W in float from this many 3 n_c
  PetscInt     tangent_single_ = 512;                // -theta_tangent_single: step tangents read their dense step matrices in float from this many DOFs
  bool         dense_     = true;
  const Model *model_     = nullptr;
  PetscInt     n_ = 0, nc_ = 0;

  LocalContactSolver local_;
  Eigen::MatrixXd    W_;
  Eigen::VectorXd    g0_, wf_, gap_, rhat_;

  // dense back end
  Eigen::MatrixXd P1_, P2_, Y_, Ht_, Md_, Cd_, Kd_;
  SparseRowMatrix Hts_;                      // H^T's non-zeros, when ht_sparse_
  // H^T's normal rows (n_c x N; by their non-zeros when ht_sparse_): the tangent's gap change needs
  // only those, a third of H^T's products.
  Eigen::MatrixXd Htn_;
  SparseRowMatrix Htns_;
  bool            ht_sparse_ = false;
  PetscInt        h_storage_ = 0;            // -theta_h_storage: 0 auto, 1 dense, 2 sparse
  // ModalTangent: the basis (for the matrices with checksum modal_sum_), its state (-1 undecided,
  // 0 not diagonal, 1 diagonal), the modal K and C, and per step size modal_h_ the diagonals of P1,
  // P2, H^T Phi and 1/a (Phi^-1 Y = diag(1/a) (H^T Phi)^T, read from Htm_ in place). modal_why_:
  // the reason when not taken.
  PetscInt        modal_tangent_ = 0;        // -theta_modal_tangent: 0 auto, 1 false, 2 true
  int             modal_state_   = -1;
  std::uint64_t   modal_sum_     = 0;
  std::uint64_t   dense_sum_     = 0;        // checksum of Md_, Kd_, Cd_ as SetUpDense copied them
  bool            dense_sum_ok_  = false;
  PetscReal       modal_h_       = -1, modal_offdiag_ = 0;
  bool            modal_on_      = false;
  Eigen::MatrixXd Phi_, PhiInv_, Htm_, Htmn_; // Htmn_: Htm_'s normal rows
  Eigen::VectorXd mk_, mc_, p1m_, p2m_, ainvm_;
  // Where C is not diagonal in the basis: C_m = Phi^T C Phi, and at modal_h_ (modal_dense_) G = A_m^-1
  // and Ym = G (H^T Phi)^T; -theta_tangent_single: G - I, H^T Phi, its normal rows and Ym in float.
  Eigen::MatrixXd Cm_, G_, Ym_;
  Eigen::MatrixXf Gf_, Htmf_, Htmnf_, Ymf_;
  bool            modal_dense_ = false, modal_f_ready_ = false;
  std::string     modal_why_;
  PetscInt        modal_step_ = 0;           // -theta_modal_step: 0 auto, 1 false, 2 true
  bool            modal_step_on_ = false, many_setups_ = false, delassus_only_ = false;
  bool            nodal_ready_   = true;     // P1_, P2_, p3_, Y_, llt_ formed at h_
  std::string     modal_step_why_;
  Eigen::VectorXd p3m_;                      // Phi^-1 p3 = h diag(1/a) Phi^T F
  Eigen::MatrixXd Gt_;                       // diag(1/a)^(1/2) (H^T Phi)^T: W = Gt^T Gt
  Eigen::VectorXd p3_, Fd_, vf_, dU0_;
  PetscMPIInt     size_ = 1;                 // ranks of comm_: above 1 the dense step runs on gathered states
  std::unique_ptr<DenseStepKernel> kernel_; // (S4)-(S9) on the matrices above, sizes fixed at compile time if possible
  PetscBool       fixed_size_ = PETSC_TRUE; // -theta_fixed_size
  PetscBool       native_arrays_ = PETSC_TRUE; // -theta_native_arrays (see theta.cpp: SQUEAL_PETSC_PRIVATE)
  AllGather       gather_;
  const Model    *dense_for_ = nullptr;
  Eigen::VectorXd full_U_, full_dU_;
  Eigen::MatrixXd tvf_, tdr_; // StepTangent work arrays
  // -theta_tangent_single: [P1 - I, P2] and Y rounded to float (formed at the first nodal tangent after a
  // set-up), and the float work arrays of their products.
  Eigen::MatrixXf P12f_, Yf_, tXf_, tvff_, tdrff_, tHvf_, tGnf_;
  bool            nodal_f_ready_ = false;
  bool            TangentSingle() const { return tangent_single_ > 0 && n_ >= tangent_single_; }
  std::vector<int> tstatus_;
  // An unknown of the closed-point tangent system (theta_tangent.cpp): delta r(o..o+2) += g x; its
  // row d x + h e^T (W delta r)(o..o+2) = -e^T delta w(o..o+2), minus delta g~_n / h if normal.
  struct TangentUnknown {
    Eigen::Index o;
    PetscReal    g[3], e[3], d;
    bool         normal;
  };
  std::vector<TangentUnknown> tunk_;
  void TangentUnknowns(const Eigen::VectorXd &r, const Eigen::VectorXd &v_end); // tunk_ of a step
  Eigen::MatrixXd tAc_, trc_, tX_, tHv_, tGn_, tdrf_, tWG_, tYr_;
  Eigen::VectorXd tG3_;
  Eigen::LLT<Eigen::MatrixXd> llt_;                 // A, for the tangent in h
  PetscErrorCode StepTangentImpl(const Eigen::VectorXd &r, const Eigen::VectorXd &v_end, const StepData *step, const Eigen::RowVectorXd *dh,
                                 Eigen::MatrixXd &dU, Eigen::MatrixXd &ddU);

  // sparse back end
  KSPH       ksp_;
  PetscInt   psolver_ = 0;                    // -theta_parallel_solver: 0 auto, 1 direct, 2 cg, 3 redundant
  bool       cg_      = false;                // CG + block Jacobi (each rank's block by Cholesky) in use
  PetscReal  cg_rtol_ = 1e-13;                // -theta_cg_rtol
  MatH       A_, B_, H_, Yd_;                 // Yd_ only with the dense W (3 n_c <= delassus_max_)
  PetscInt   delassus_max_ = -1;              // < 0: automatic (SetUpSparse)
  PetscReal  delassus_drop_ = 1e-15, w_dropped_max_ = 0; // largest |dropped W_ij| / max_i |W_ij|
  PetscInt   w_dropped_ = 0;
  bool       sparse_w_  = false;
  Eigen::SparseMatrix<PetscReal> Ws_;
  VecH       hr_, yr_;                        // H (h r) and A^-1 H (h r), sparse W only
  PetscErrorCode SetUpSparseDelassus();
  PetscErrorCode SetUpBlockSolvers(); // sub-solvers of block Jacobi (-theta_parallel_solver cg)
  PetscErrorCode CheckSolve();
  PetscErrorCode ConfigureSolver();
  VecH       rhs_, vf_s_, tmp_, loc_, rloc_, loc_all_;
  VecScatter to_all_ = nullptr;

public:
  ~ThetaIntegrator();
};

} // namespace squeal
