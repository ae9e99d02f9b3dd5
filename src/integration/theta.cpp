#include "squeal/integration/theta.h"
#include "squeal/core/errors.h"
#include "squeal/core/gather.h"
#include "squeal/core/options.h"
#include "squeal/core/solvers.h"
#include "squeal/core/sparse.h"

// The one private PETSc header in the build (the 3-DOF fast path below); configure with
// -DSQUEAL_PETSC_PRIVATE=OFF, or run with -theta_native_arrays 0, for the public API only (the
// same numbers: test Theta.NativeArraysAndPublicApiGiveTheSameSteps).
#if SQUEAL_PETSC_PRIVATE
  #include <petsc/private/vecimpl.h>
#endif

#include <algorithm>
#include <cmath>

namespace squeal {

namespace {

// The array of a PETSc-native Vec (VECSEQ, VECMPI) read as VecGetArray does it in PETSc 3.18
// (rvector.c: no getarray/restorearray method and petscnative set), without the two library calls
// per Vec and step that cost ~70 of a 3-DOF step's ~650 instructions; false for any other Vec
// (device, nest, ...), which then goes through VecGetArray.
inline bool NativeArray(Vec x, PetscScalar **a)
{
#if SQUEAL_PETSC_PRIVATE && PETSC_VERSION_GE(3, 18, 0) && PETSC_VERSION_LT(3, 19, 0)
  if (!x->ops->getarray && !x->ops->restorearray && x->petscnative) {
    *a = *(PetscScalar **)x->data;
    return true;
  }
#else
  (void)x, (void)a;
#endif
  return false;
}

// PetscObject's state, as VecRestoreArray increases it (private before PETSc 3.19's public field).
inline void IncreaseState(Vec x)
{
#if SQUEAL_PETSC_PRIVATE
  ((PetscObject)x)->state++;
#else
  (void)x;
#endif
}

// Full copy of a (small) distributed matrix on every rank, for the dense back end.
// The whole matrix on every rank: own rows filled, then summed over the ranks.
Eigen::MatrixXd DenseCopy(Mat A, PetscInt n, MPI_Comm comm)
{
  Eigen::MatrixXd D = Eigen::MatrixXd::Zero(n, n);
  if (!A) return D;
  PetscInt lo, hi;
  PetscCallAbort(comm, MatGetOwnershipRange(A, &lo, &hi));
  for (PetscInt i = lo; i < hi; ++i) {
    PetscInt           nc;
    const PetscInt    *cj;
    const PetscScalar *v;
    PetscCallAbort(PETSC_COMM_SELF, MatGetRow(A, i, &nc, &cj, &v));
    for (PetscInt k = 0; k < nc; ++k) D(i, cj[k]) = PetscRealPart(v[k]);
    PetscCallAbort(PETSC_COMM_SELF, MatRestoreRow(A, i, &nc, &cj, &v));
  }
  PetscMPIInt size;
  MPI_Comm_size(comm, &size);
  if (size > 1) MPI_Allreduce(MPI_IN_PLACE, D.data(), (int)(n * n), MPIU_REAL, MPI_SUM, comm);
  return D;
}

// Sparse H (N x 3 n_c), column 3c + dir = h_{dir,c}.
PetscErrorCode AssembleH(const ContactSet &cs, Vec like, Mat *H)
{
  PetscInt rstart, rend, n;
  MPI_Comm comm;
  Triplets t;
  PetscFunctionBeginUser;
  PetscCall(PetscObjectGetComm((PetscObject)like, &comm));
  PetscCall(VecGetOwnershipRange(like, &rstart, &rend));
  PetscCall(VecGetSize(like, &n));
  for (PetscInt c = 0; c < cs.Size(); ++c)
    for (int d = 0; d < 3; ++d)
      cs.ForEachEntry(c, d, [&](PetscInt j, PetscReal v) {
        if (j >= rstart && j < rend) t.Add(j, 3 * c + d, v);
      });
  PetscCall(MatCreateFromTriplets(comm, rend - rstart, PETSC_DECIDE, n, 3 * cs.Size(), t, H));
  PetscFunctionReturn(0);
}

} // namespace

ThetaIntegrator::~ThetaIntegrator()
{
  if (to_all_) PetscCallVoid(VecScatterDestroy(&to_all_));
}

PetscErrorCode ThetaIntegrator::SetOptionsPrefix(const char *prefix)
{
  PetscFunctionBeginUser;
  prefix_ = prefix ? prefix : "";
  PetscFunctionReturn(0);
}

PetscErrorCode ThetaIntegrator::SetTheta(PetscReal theta)
{
  PetscFunctionBeginUser;
  PetscCall(CheckReal(comm_, prefix_.c_str(), "theta", theta, Range::Closed(0.5, 1.0)));
  theta_ = theta;
  PetscFunctionReturn(0);
}

PetscErrorCode ThetaIntegrator::SetFixedPoint(PetscReal tol, PetscInt max_it)
{
  PetscFunctionBeginUser;
  PetscCall(CheckReal(comm_, prefix_.c_str(), "fp_tol", tol, Range::Positive()));
  PetscCheck(max_it >= 1, comm_, kErrInput, "option -%sfp_max_it = %" PetscInt_FMT ": expected >= 1", prefix_.c_str(), max_it);
  fp_tol_    = tol;
  fp_max_it_ = max_it;
  local_.SetTolerances(fp_tol_, fp_max_it_, r_ref_);
  PetscFunctionReturn(0);
}

// -theta_contact_solver auto: the fixed point, which with its passes mixed (-theta_fp_anderson) was
// the faster on every model measured, side by side (transients, 200 steps per period,
// docs/records.md): 451 points (pad_large_cycle.yaml, 800 steps) 10.3 s against 13.7 s for ssn
// (18.9 passes a step against 4.4 Newton iterations and polishing passes, its condensed LU
// refreshed after 3); 651 points (the size-2 brake reduced to 1594 DOFs, 400 steps) 23.9 s against
// 41.1 s before the condensed LU. A chord step reads h W twice and S once, a pass h W once in float.
// Before the mixing, auto took ssn from 450 points on.

PetscErrorCode ThetaIntegrator::SetContactSolver(const char *name, PetscInt ssn_max_it, PetscInt ssn_anderson)
{
  PetscFunctionBeginUser;
  const std::string n = name ? name : "";
  PetscCheck(n == "fp" || n == "ssn" || n == "auto", comm_, kErrInput, "option -%scontact_solver %s: expected fp, ssn or auto",
             prefix_.c_str(), name ? name : "(null)");
  PetscCheck(ssn_max_it >= 1, comm_, kErrInput, "option -%sssn_max_it = %" PetscInt_FMT ": expected >= 1", prefix_.c_str(), ssn_max_it);
  PetscCheck(ssn_anderson >= 0 && ssn_anderson <= 8, comm_, kErrInput, "option -%sssn_anderson = %" PetscInt_FMT ": expected 0 to 8",
             prefix_.c_str(), ssn_anderson);
  contact_solver_ = n == "fp" ? 0 : n == "ssn" ? 1 : 2;
  ssn_max_it_     = ssn_max_it;
  ssn_anderson_   = ssn_anderson;
  PetscFunctionReturn(0);
}

PetscErrorCode ThetaIntegrator::SetRhoScale(PetscReal s)
{
  PetscFunctionBeginUser;
  PetscCall(CheckReal(comm_, prefix_.c_str(), "rho_scale", s, Range::Positive()));
  rho_scale_ = s;
  PetscFunctionReturn(0);
}

// Up to 200 DOFs the dense step is the faster (crossover between N = 90 and 300 on the sparse chain,
// benchmarks/bench_step.cpp). A model whose K or M is dense (a Craig-Bampton reduction couples every
// interface DOF: 87 % non-zeros on the 562-DOF pad) gains nothing from the sparse back end, whose
// Cholesky factor is then full, and only the dense one gives shooting its exact step tangents:
// without them GMRES on finite-difference products broke down on the 562-DOF pad (issue 19).
// Dense up to 2000 DOFs there: ~10 N x N matrices on every rank, 320 MB at N = 2000 (the 1420-DOF
// reduced 31119-DOF pad ran dense).
bool ThetaIntegrator::DefaultDense(PetscInt n, PetscReal density)
{
  return n <= 200 || (density >= 0.25 && n <= 2000);
}

PetscErrorCode ThetaIntegrator::SetDenseMax(PetscInt n)
{
  PetscFunctionBeginUser;
  dense_max_ = n;
  PetscFunctionReturn(0);
}

PetscErrorCode ThetaIntegrator::SetDelassusMax(PetscInt n, PetscReal drop)
{
  PetscFunctionBeginUser;
  PetscCall(CheckReal(comm_, prefix_.c_str(), "delassus_drop", drop, Range::NonNegative()));
  PetscCheck(drop < 1, comm_, kErrInput, "option -%sdelassus_drop = %g: expected < 1 (a fraction of each column's largest entry)",
             prefix_.c_str(), (double)drop);
  delassus_max_  = n;
  delassus_drop_ = drop;
  PetscFunctionReturn(0);
}

PetscErrorCode ThetaIntegrator::SetFromOptions()
{
  PetscFunctionBeginUser;
  OptionChecks      checks;
  const char *const csolvers[] = {"fp", "ssn", "auto"};
  PetscOptionsBegin(comm_, prefix_.c_str(), "Non-smooth theta-method", "ThetaIntegrator");
  SquealOptionsReal("-theta", "theta in [0.5, 1] (0.5: trapezoidal, no numerical dissipation)", "ThetaIntegrator::SetTheta",
                    &theta_, Range::Closed(0.5, 1.0), checks);
  SquealOptionsReal("-fp_tol", "Fixed-point tolerance on sum ||dr||_1 / (R_ref + sum r_n)", "ThetaIntegrator::SetFixedPoint",
                    &fp_tol_, Range::Positive(), checks);
  PetscCall(PetscOptionsInt("-fp_max_it", "Fixed-point pass limit per step (hitting it is reported)",
                            "ThetaIntegrator::SetFixedPoint", fp_max_it_, &fp_max_it_, nullptr));
  SquealOptionsReal("-rho_scale", "Factor on the augmented-Lagrangian parameters rho of rule (2.4)",
                    "ThetaIntegrator::SetRhoScale", &rho_scale_, Range::Positive(), checks);
  PetscCall(PetscOptionsInt("-dense_max",
                            "Largest N for the dense back end, replicated on every rank (larger: sparse, distributed; default: 200, "
                            "or 2000 when at least a quarter of the entries of K or M are non-zero, as in a Craig-Bampton reduction)",
                            "ThetaIntegrator::SetDenseMax", dense_max_, &dense_max_, nullptr));
  PetscCall(PetscOptionsInt("-delassus_max",
                            "Sparse back end: largest 3 n_c with the dense Delassus matrix and Y = A^-1 H stored (larger: sparse W, one more solve "
                            "per step; < 0: when N 3 n_c <= 2 nnz(factor of A))",
                            "ThetaIntegrator::SetDelassusMax", delassus_max_, &delassus_max_, nullptr));
  SquealOptionsReal("-delassus_drop", "Sparse W: drop |W_ij| <= this x max_i |W_ij| (0: keep every non-zero)", "ThetaIntegrator::SetDelassusMax",
                    &delassus_drop_, Range::NonNegative(), checks);
  PetscCall(PetscOptionsBool("-native_arrays",
                             "Dense back end on one rank: read PETSc-native Vec arrays directly (PETSc 3.18 private layout; "
                             "false: VecGetArray, the same numbers, ~70 instructions more per step)",
                             "ThetaIntegrator::Step", native_arrays_, &native_arrays_, nullptr));
  PetscCall(PetscOptionsBool("-fixed_size", "Dense back end: run the step compiled for the model's sizes when available (false: run-time sizes)",
                             "ThetaIntegrator::SetUp", fixed_size_, &fixed_size_, nullptr));
  const char *const hstorage[] = {"auto", "dense", "sparse"};
  PetscCall(PetscOptionsEList("-h_storage",
                              "Dense back end: H^T (3 n_c x N) in the step's and the tangent's products as a dense matrix or by its "
                              "non-zeros (auto: sparse when at most 10 % of its entries are non-zero and N >= 64, as with physical contact DOFs)",
                              "ThetaIntegrator::SetFromOptions", hstorage, 3, hstorage[h_storage_], &h_storage_, nullptr));
  const char *const modal[] = {"auto", "false", "true"};
  PetscCall(PetscOptionsEList("-modal_tangent",
                              "Dense back end: shooting's and Floquet's step tangents in the modal coordinates of (K, M): where C is "
                              "diagonal there too, O(n_c N) a column and step instead of O(N^2); elsewhere with the dense G = A_m^-1, one "
                              "N x N product instead of two; auto: when the step is modal with G, or the products cost less than 0.8 x the "
                              "nodal ones",
                              "ThetaIntegrator::ModalTangent", modal, 3, modal[modal_tangent_], &modal_tangent_, nullptr));
  PetscCall(PetscOptionsEList("-modal_step",
                              "Dense back end: the step in the same modal coordinates (a step size's set-up without the nodal O(N^3) "
                              "solves; shooting sets up at every new period): diagonal where C is diagonal there to round-off, else with the "
                              "dense G = A_m^-1 (N^3 a set-up); auto: when a step reads no more than the nodal one and the caller sets up many "
                              "step sizes (shooting), or reads at most 0.8 of it (diagonal C only), N >= 64",
                              "ThetaIntegrator::ModalStep", modal, 3, modal[modal_step_], &modal_step_, nullptr));
  const char *const psolvers[] = {"auto", "direct", "cg", "redundant"};
  PetscCall(PetscOptionsEList("-parallel_solver",
                              "Sparse back end on several ranks: direct (MUMPS LU, distributed), cg (CG + block Jacobi, each rank's "
                              "block by Cholesky), redundant (every rank factorises the whole A by Cholesky: never slower than one "
                              "rank, up to a gather per solve), auto (redundant)",
                              "ThetaIntegrator::SetFromOptions", psolvers, 4, psolvers[psolver_], &psolver_, nullptr));
  SquealOptionsReal("-cg_rtol", "Relative residual tolerance of -theta_parallel_solver cg", "ThetaIntegrator::SetFromOptions", &cg_rtol_,
                    Range::Positive(), checks);
  PetscCall(PetscOptionsEList("-contact_solver",
                              "Local contact problem (S6-7): fp (projected Gauss-Seidel fixed point), ssn (semi-smooth Newton on the same "
                              "equations, dense or sparse LU per iteration, the fixed point as fallback), auto (fp: the faster on every model measured)",
                              "ThetaIntegrator::SetContactSolver", csolvers, 3, csolvers[contact_solver_], &contact_solver_, nullptr));
  PetscCall(PetscOptionsInt("-ssn_max_it", "Semi-smooth Newton iteration limit per step (then the fixed point; counted and reported)",
                            "ThetaIntegrator::SetContactSolver", ssn_max_it_, &ssn_max_it_, nullptr));
  PetscCall(PetscOptionsInt("-contact_predict",
                            "Starting guess of the contact problem along a trajectory: 0 the previous step's reactions, 1 or 2 their "
                            "linear or quadratic extrapolation (run-time-sized and sparse steps; the compile-time-sized 3-DOF kernels use 0)",
                            "LocalContactSolver::SetPredictor", contact_predict_, &contact_predict_, nullptr));
  PetscCall(PetscOptionsInt("-ssn_anderson",
                            "Semi-smooth Newton: Anderson mixing of this many past chord steps (steps with the kept LU), taken when it "
                            "halves the residual (0: plain chord steps; at most 8)",
                            "ThetaIntegrator::SetContactSolver", ssn_anderson_, &ssn_anderson_, nullptr));
  PetscCall(PetscOptionsInt("-ssn_refactor",
                            "Semi-smooth Newton: a fresh LU at a step's start when the step before took more than this many Newton "
                            "iterations (-1: only when a chord step fails to halve the residual; 3 halves -1's iterations in about its time, docs/records.md)",
                            "LocalContactSolver::SetNewtonRefactor", ssn_refactor_, &ssn_refactor_, nullptr));
  PetscCall(PetscOptionsBool("-ssn_condensed",
                             "Semi-smooth Newton on a dense W: factorise the system condensed on the closed points' rank of the projections' "
                             "Jacobian (Woodbury; about a third of the LU of J on a sliding pad) instead of J itself",
                             "LocalContactSolver::SetNewtonCondensed", ssn_condensed_, &ssn_condensed_, nullptr));
  PetscCall(PetscOptionsInt("-fp_anderson",
                            "Fixed point: Anderson mixing of this many past passes, each pass started from the mixed point "
                            "(run-time-sized and sparse steps; 0: plain passes; at most 8)",
                            "LocalContactSolver::SetFixedPointAnderson", fp_anderson_, &fp_anderson_, nullptr));
  PetscCall(PetscOptionsBool("-fp_symmetric",
                             "Fixed point on a dense W (run-time-sized steps): symmetric Gauss-Seidel sweeps, each reading half of W, "
                             "unmixed, instead of forward passes (iterations then count sweeps)",
                             "LocalContactSolver::SetFixedPointSymmetric", fp_symmetric_, &fp_symmetric_, nullptr));
  PetscCall(PetscOptionsInt("-fp_single",
                            "Fixed point on a dense W (forward passes): from this many contact unknowns (3 n_c) the passes read h W "
                            "rounded to float, v kept in double and remade with the double h W often enough that the solve passes "
                            "the same stopping test (0: never)",
                            "LocalContactSolver::SetFixedPointSingle", fp_single_, &fp_single_, nullptr));
  PetscCall(PetscOptionsInt("-tangent_single",
                            "Dense back end, step tangents (shooting's Jacobian products, Floquet's blocks): from this many DOFs their "
                            "products with the dense step matrices (nodal P1 - I, P2, Y; modal H^T Phi, and G - I, G (H^T Phi)^T) read "
                            "them rounded to float, half the time; the flows stay in double (0: never)",
                            "ThetaIntegrator::StepTangent", tangent_single_, &tangent_single_, nullptr));
  PetscOptionsEnd();
  PetscCall(checks.Run(comm_));
  PetscCheck(tangent_single_ >= 0, comm_, kErrInput, "option -%stangent_single = %" PetscInt_FMT ": expected a number of DOFs >= 0 (0: never)",
             prefix_.c_str(), tangent_single_);
  PetscCheck(fp_anderson_ >= 0 && fp_anderson_ <= 8, comm_, kErrInput, "option -%sfp_anderson = %" PetscInt_FMT ": expected 0 to 8",
             prefix_.c_str(), fp_anderson_);
  PetscCheck(fp_single_ >= 0, comm_, kErrInput, "option -%sfp_single = %" PetscInt_FMT ": expected a number of contact unknowns >= 0 (0: never)",
             prefix_.c_str(), fp_single_);
  PetscCheck(contact_predict_ >= 0 && contact_predict_ <= 2, comm_, kErrInput, "option -%scontact_predict %" PetscInt_FMT ": expected 0, 1 or 2",
             prefix_.c_str(), contact_predict_);
  PetscCheck(ssn_refactor_ >= -1, comm_, kErrInput, "option -%sssn_refactor %" PetscInt_FMT ": expected -1 (never) or >= 0", prefix_.c_str(),
             ssn_refactor_);
  PetscCall(SetContactSolver(csolvers[contact_solver_], ssn_max_it_, ssn_anderson_));
  PetscCall(SetFixedPoint(fp_tol_, fp_max_it_));
  PetscCall(SetDelassusMax(delassus_max_, delassus_drop_));
  PetscCall(ConfigureSolver());
  PetscFunctionReturn(0);
}

PetscErrorCode ThetaIntegrator::SetParallelSolver(const char *name, PetscReal cg_rtol)
{
  PetscFunctionBeginUser;
  const std::string n = name;
  PetscCheck(n == "auto" || n == "direct" || n == "cg" || n == "redundant", comm_, kErrInput,
             "option -%sparallel_solver %s: expected auto, direct, cg or redundant", prefix_.c_str(), name);
  PetscCheck(cg_rtol > 0 && cg_rtol < 1, comm_, kErrInput, "option -%scg_rtol = %g: expected in (0, 1)", prefix_.c_str(), (double)cg_rtol);
  psolver_ = n == "auto" ? 0 : n == "direct" ? 1 : n == "cg" ? 2 : 3;
  cg_rtol_ = cg_rtol;
  if (ksp_) PetscCall(ConfigureSolver());
  PetscFunctionReturn(0);
}

// The KSP of A (S1), rebuilt from the options database and the settings above.
PetscErrorCode ThetaIntegrator::ConfigureSolver()
{
  PetscFunctionBeginUser;
  ksp_.reset();
  PetscCall(KSPCreate(comm_, ksp_.out()));
  PetscCall(KSPSetOptionsPrefix(ksp_, prefix_.c_str()));
  PetscCall(UseDirectSolver(ksp_, Factorisation::SPD)); // A = M + h theta C + h^2 theta^2 K
  PetscMPIInt size;
  PetscCallMPI(MPI_Comm_size(comm_, &size));
  // A single model's step solves do not split well over ranks (docs/records.md "MPI speed-ups"): MUMPS's
  // distributed solve made the 30 000-DOF chain's transient 33x slower on 2 ranks, CG + block
  // Jacobi needed 3.8 block solves per solve on the 31119-DOF pad. auto therefore keeps one rank's
  // work per solve: every rank holds the whole A (PCREDUNDANT) factorised by PETSc's Cholesky, as
  // on one rank, and a solve costs that plus the gather of its right-hand side. direct (MUMPS) is
  // for models whose factor does not fit on one rank.
  if (size > 1 && (psolver_ == 0 || psolver_ == 3)) {
    PC  pc, ipc;
    KSP inner;
    PetscCall(KSPSetType(ksp_, KSPPREONLY));
    PetscCall(KSPGetPC(ksp_, &pc));
    PetscCall(PCSetType(pc, PCREDUNDANT));
    PetscCall(PCRedundantGetKSP(pc, &inner));
    PetscCall(KSPSetType(inner, KSPPREONLY));
    PetscCall(KSPGetPC(inner, &ipc));
    PetscCall(PCSetType(ipc, PCCHOLESKY));
    PetscCall(PCFactorSetMatSolverType(ipc, MATSOLVERPETSC));
  }
  cg_ = size > 1 && psolver_ == 2;
  if (cg_) {
    // MUMPS's distributed solve costs 10-35 ms on a 30 000-DOF chain (its per-front overhead on a
    // thin elimination tree, plus messages) against 0.35 ms for one rank's Cholesky solve. A is SPD
    // and, at transient step sizes, dominated by M: block Jacobi leaves out only the coupling
    // across the ranks' cut, so CG needs few iterations, each one local solve per rank.
    PC pc;
    PetscCall(KSPSetType(ksp_, KSPCG));
    PetscCall(KSPGetPC(ksp_, &pc));
    PetscCall(PCSetType(pc, PCBJACOBI));
    PetscCall(KSPSetTolerances(ksp_, cg_rtol_, 1e-300, PETSC_DEFAULT, 1000));
  }
  PetscCall(KSPSetFromOptions(ksp_));
  PetscFunctionReturn(0);
}

// With block Jacobi, each rank's block is factorised by PETSc's Cholesky (the default sub-solver
// is ILU(0), an approximation); -theta_sub_ksp_* / -theta_sub_pc_* still override it.
PetscErrorCode ThetaIntegrator::SetUpBlockSolvers()
{
  PC        pc;
  PetscBool isbj;
  PetscFunctionBeginUser;
  PetscCall(KSPGetPC(ksp_, &pc));
  PetscCall(PetscObjectTypeCompare((PetscObject)pc, PCBJACOBI, &isbj));
  if (!isbj) PetscFunctionReturn(0);
  PetscCall(KSPSetUp(ksp_));
  KSP     *sub;
  PetscInt nlocal;
  PetscCall(PCBJacobiGetSubKSP(pc, &nlocal, nullptr, &sub));
  for (PetscInt i = 0; i < nlocal; ++i) {
    PC spc;
    PetscCall(KSPSetType(sub[i], KSPPREONLY));
    PetscCall(KSPGetPC(sub[i], &spc));
    PetscCall(PCSetType(spc, PCCHOLESKY));
    PetscCall(PCFactorSetMatSolverType(spc, MATSOLVERPETSC));
    PetscCall(KSPSetFromOptions(sub[i]));
  }
  PetscFunctionReturn(0);
}

PetscErrorCode ThetaIntegrator::SetUp(const Model &model, PetscReal h)
{
  PetscMPIInt          size;
  static PetscLogEvent ev = 0; // every h: (S1)-(S3), W and the contact solver's set-up
  PetscFunctionBeginUser;
  PetscCheck(h > 0 && std::isfinite(h), comm_, kErrInput, "time step h = %g: expected > 0", (double)h);
  if (!ev) PetscCall(PetscLogEventRegister("ThetaSetUp", PETSC_OBJECT_CLASSID, &ev));
  PetscCall(PetscLogEventBegin(ev, 0, 0, 0, 0));
  if (!ksp_) PetscCall(SetFromOptions());
  PetscCallMPI(MPI_Comm_size(comm_, &size));
  model_ = &model;
  h_     = h;
  n_     = model.Size();
  nc_    = model.contacts.Size();
  // Small models run the dense step on every rank, on gathered states: cheaper than a
  // distributed factorisation of a few hundred unknowns, and the same numbers on any rank count.
  if (dense_max_ >= 0) dense_ = n_ <= dense_max_;
  else {
    PetscReal density = 0;
    for (Mat A : {(Mat)model.K, (Mat)model.M}) {
      MatInfo info;
      PetscCall(MatGetInfo(A, MAT_GLOBAL_SUM, &info));
      density = std::max(density, (PetscReal)info.nz_used / ((PetscReal)n_ * n_));
    }
    dense_ = DefaultDense(n_, density);
  }
  sparse_w_ = false; // decided in SetUpSparse, once A is factorised
  g0_.resize(nc_);
  for (PetscInt c = 0; c < nc_; ++c) g0_[c] = model.contacts.points[c].g0;
  wf_.resize(3 * nc_);
  gap_.resize(nc_);
  if (dense_) PetscCall(SetUpDense());
  else PetscCall(SetUpSparse());
  auto Wd = [&](PetscInt i) { return sparse_w_ ? Ws_.coeff(i, i) : W_(i, i); };
  if (nc_ > 0)
    for (PetscInt c = 0; c < nc_; ++c)
      PetscCheck(Wd(3 * c + kN) > 0 && Wd(3 * c + kT) > 0, comm_, PETSC_ERR_PLIB,
                 "Delassus matrix has a non-positive diagonal at contact %" PetscInt_FMT, c);
  if (sparse_w_) local_.Setup(model.contacts, Ws_, h, rho_scale_);
  else local_.Setup(model.contacts, W_, h, rho_scale_);
  local_.SetTolerances(fp_tol_, fp_max_it_, r_ref_);
  const bool ssn = contact_solver_ == 1;
  local_.SetNewtonCondensed(ssn_condensed_); // before SetSolver, which then sizes Newton's arrays once
  if (nc_ > 0 && ssn) local_.SetSolver(ContactSolver::kNewton, ssn_max_it_, ssn_anderson_);
  local_.SetNewtonRefactor(ssn_refactor_);
  local_.SetPredictor(contact_predict_);
  local_.SetFixedPointAnderson(fp_anderson_);
  local_.SetFixedPointSymmetric(fp_symmetric_);
  if (dense_) SetUpKernel();
  // The compile-time-sized kernels' passes are in double; Newton (ssn) runs a pass or two a solve.
  local_.SetFixedPointSingle(FixedSizeKernel() || ssn ? 0 : fp_single_);
  PetscCall(PetscLogEventEnd(ev, 0, 0, 0, 0));
  PetscFunctionReturn(0);
}

PetscErrorCode ThetaIntegrator::SetUpDense()
{
  const Model &m = *model_;
  PetscFunctionBeginUser;
  Md_ = DenseCopy(m.M, n_, comm_);
  Cd_ = DenseCopy(m.C, n_, comm_);
  Kd_ = DenseCopy(m.K, n_, comm_);
  dense_sum_ok_ = false; // ModalTangent sums them when it is first asked
  PetscCallMPI(MPI_Comm_size(comm_, &size_));
  if (size_ > 1 && (!gather_.Ready() || dense_for_ != model_)) {
    PetscCall(gather_.SetUp(m.F));
    dense_for_ = model_;
    full_U_.resize(n_), full_dU_.resize(n_);
  }
  Fd_.resize(n_);
  PetscCall(Gather(m.F, Fd_));
  modal_h_ = -1; // ModalTangent's per-h quantities, H^T Phi included (the contacts may have changed)
  Ht_.setZero(3 * nc_, n_);
  for (PetscInt c = 0; c < nc_; ++c)
    for (int d = 0; d < 3; ++d) m.contacts.ForEachEntry(c, d, [&](PetscInt j, PetscReal v) { Ht_(3 * c + d, j) += v; });
  // H^T also by its non-zeros where it is sparse: with the contact DOFs physical (a Craig-Bampton
  // model) a row has a few non-zeros of N, and its dense products were a third of the step's and of
  // the tangent's products on the reduced 2625-DOF pad (3 n_c = 525, N = 562).
  const PetscReal nnz = (PetscReal)(Ht_.array() != 0.0).count();
  ht_sparse_          = nc_ > 0 && (h_storage_ == 2 || (h_storage_ == 0 && n_ >= 64 && nnz <= 0.1 * (PetscReal)Ht_.size()));
  Htn_.resize(nc_, n_);
  for (PetscInt c = 0; c < nc_; ++c) Htn_.row(c) = Ht_.row(3 * c + kN);
  if (ht_sparse_) Hts_ = Ht_.sparseView(0.0, 0.0), Htns_ = Htn_.sparseView(0.0, 0.0), Htn_.resize(0, 0);
  else Hts_.resize(0, 0), Htns_.resize(0, 0);
  PetscCall(ModalStepSetUp());
  if (!modal_step_on_) {
    nodal_ready_ = false;
    PetscCall(EnsureNodal());
    // By H^T's non-zeros where it is sparse: the dense product was a fifth of the set-up on the
    // reduced 31119-DOF pad (0.2 of 1.05 s, 3 n_c = 1353, N = 1420), and shooting sets up at every
    // new period. Rows of one or two non-zeros give the dense product's sums exactly.
    if (ht_sparse_) W_.noalias() = Hts_ * Y_;
    else W_.noalias() = Ht_ * Y_;
  }
  vf_.resize(n_);
  dU0_.resize(n_);
  PetscFunctionReturn(0);
}

PetscErrorCode ThetaIntegrator::SetUpSparse()
{
  const Model &m = *model_;
  PetscFunctionBeginUser;
  const PetscReal h = h_, t = theta_;
  PetscCall(MatDuplicate(m.M, MAT_COPY_VALUES, A_.out()));
  PetscCall(MatDuplicate(m.M, MAT_COPY_VALUES, B_.out()));
  if (m.HasDamping()) {
    PetscCall(MatAXPY(A_, h * t, m.C, DIFFERENT_NONZERO_PATTERN));
    PetscCall(MatAXPY(B_, -h * (1 - t), m.C, DIFFERENT_NONZERO_PATTERN));
  }
  PetscCall(MatAXPY(A_, h * h * t * t, m.K, DIFFERENT_NONZERO_PATTERN));
  PetscCall(MatAXPY(B_, -h * h * t * (1 - t), m.K, DIFFERENT_NONZERO_PATTERN));
  PetscCall(KSPReset(ksp_));
  PetscCall(KSPSetOperators(ksp_, A_, A_));
  PetscCall(SetUpBlockSolvers());
  // CG starts each step's solve (S4) from the last one's v_f, which changes by O(h) from step to
  // step. (S8) and the set-up solves below start from zero: their right-hand sides jump (the last
  // W column's solution as the first (S8) guess made CG diverge on the 31119-DOF pad).
  if (cg_) PetscCall(KSPSetInitialGuessNonzero(ksp_, PETSC_TRUE));
  PetscCall(KSPSetUp(ksp_));
  PetscCall(VecDuplicate(m.F, rhs_.out()));
  PetscCall(VecDuplicate(m.F, vf_s_.out()));
  PetscCall(VecSet(vf_s_, 0.0)); // the first CG guess
  PetscCall(VecDuplicate(m.F, tmp_.out()));
  PetscCall(AssembleH(m.contacts, m.F, H_.out()));
  PetscCall(MatCreateVecs(H_, loc_.out(), nullptr));
  PetscCall(VecDuplicate(loc_, rloc_.out()));
  if (to_all_) PetscCall(VecScatterDestroy(&to_all_));
  PetscCall(VecScatterCreateToAll(loc_, &to_all_, loc_all_.out()));
  // Many contacts: no N x 3 n_c matrix, W sparse. Automatic (-delassus_max < 0): keep Y while its
  // product (N 3 n_c multiply-adds) costs no more than the extra solve (about 2 nnz(factor of A));
  // without a factorisation to count, while 3 n_c <= 30.
  if (delassus_max_ >= 0) sparse_w_ = 3 * nc_ > delassus_max_;
  else {
    PC        pc;
    PetscBool factored;
    double    nz = 0;
    PetscCall(KSPGetPC(ksp_, &pc));
    PetscCall(PetscObjectTypeCompareAny((PetscObject)pc, &factored, PCCHOLESKY, PCLU, ""));
    if (factored) {
      Mat     F;
      MatInfo info;
      PetscCall(PCFactorGetMatrix(pc, &F));
      PetscCall(MatGetInfo(F, MAT_GLOBAL_SUM, &info));
      nz = info.nz_used;
    }
    sparse_w_ = nz > 0 ? (double)n_ * 3 * nc_ > 2 * nz : 3 * nc_ > 30;
    PetscCall(PetscInfo(nullptr, "theta-method: factor of A with %g entries, N x 3 n_c = %g: %s\n", nz, (double)n_ * 3 * nc_,
                        sparse_w_ ? "sparse W, (S8) by a solve" : "dense W and Y"));
  }
  if (nc_ > 0 && sparse_w_) {
    PetscCall(SetUpSparseDelassus());
    PetscFunctionReturn(0);
  }
  Ws_.resize(0, 0);
  hr_.reset();
  yr_.reset();

  // Y = A^-1 H column by column (3 n_c solves, once per h), W = H^T Y.
  PetscInt rstart, rend;
  PetscCall(VecGetOwnershipRange(m.F, &rstart, &rend));
  PetscCall(MatCreateDense(comm_, rend - rstart, PETSC_DECIDE, n_, 3 * nc_, nullptr, Yd_.out()));
  W_.setZero(3 * nc_, 3 * nc_);
  VecH col, ycol;
  PetscCall(VecDuplicate(m.F, col.out()));
  PetscCall(VecDuplicate(m.F, ycol.out()));
  Eigen::VectorXd wcol;
  for (PetscInt j = 0; j < 3 * nc_; ++j) {
    PetscCall(MatGetColumnVector(H_, col, j));
    PetscCall(VecSet(ycol, 0.0));
    PetscCall(KSPSolve(ksp_, col, ycol));
    PetscCall(CheckSolve());
    const PetscScalar *y;
    PetscCall(VecGetArrayRead(ycol, &y));
    for (PetscInt i = rstart; i < rend; ++i) PetscCall(MatSetValue(Yd_, i, j, y[i - rstart], INSERT_VALUES));
    PetscCall(VecRestoreArrayRead(ycol, &y));
    PetscCall(ToLocal(ycol, wcol));
    W_.col(j) = wcol;
  }
  PetscCall(MatAssemblyBegin(Yd_, MAT_FINAL_ASSEMBLY));
  PetscCall(MatAssemblyEnd(Yd_, MAT_FINAL_ASSEMBLY));
  PetscFunctionReturn(0);
}

// An iterative solve that stops short is an error, not a silently wrong step.
PetscErrorCode ThetaIntegrator::CheckSolve()
{
  KSPConvergedReason reason;
  PetscFunctionBeginUser;
  PetscCall(KSPGetConvergedReason(ksp_, &reason));
  PetscCheck(reason >= 0 || !cg_, comm_, PETSC_ERR_NOT_CONVERGED,
             "theta-method: CG solve with A = M + h theta C + h^2 theta^2 K failed (%s): raise -%scg_rtol or use -%sparallel_solver direct",
             KSPConvergedReasons[reason], prefix_.c_str(), prefix_.c_str());
  PetscCheck(reason >= 0, comm_, PETSC_ERR_NOT_CONVERGED, "theta-method: solve with A = M + h theta C + h^2 theta^2 K failed (%s)",
             KSPConvergedReasons[reason]);
  PetscFunctionReturn(0);
}

PetscErrorCode ThetaIntegrator::SetUpSparseDelassus()
{
  PetscFunctionBeginUser;
  Yd_.reset();
  W_.resize(0, 0);
  PetscCall(VecDuplicate(model_->F, hr_.out()));
  PetscCall(VecDuplicate(model_->F, yr_.out()));
  // W = H^T A^-1 H column by column (3 n_c solves, once per h), only its kept entries stored.
  // Every rank sees the whole gathered column, so all ranks keep the same entries.
  std::vector<Eigen::Triplet<PetscReal>> t;
  Eigen::VectorXd                         wcol;
  w_dropped_     = 0;
  w_dropped_max_ = 0;
  for (PetscInt j = 0; j < 3 * nc_; ++j) {
    PetscCall(MatGetColumnVector(H_, hr_, j));
    PetscCall(VecSet(yr_, 0.0));
    PetscCall(KSPSolve(ksp_, hr_, yr_));
    PetscCall(CheckSolve());
    PetscCall(ToLocal(yr_, wcol));
    const PetscReal big = wcol.cwiseAbs().maxCoeff(), cut = delassus_drop_ * big;
    for (PetscInt i = 0; i < 3 * nc_; ++i) {
      const PetscReal a = std::abs(wcol[i]);
      if (a == 0) continue;
      if (a > cut || i == j) t.emplace_back(i, j, wcol[i]);
      else {
        ++w_dropped_;
        w_dropped_max_ = std::max(w_dropped_max_, a / big);
      }
    }
  }
  Ws_.resize(3 * nc_, 3 * nc_);
  Ws_.setFromTriplets(t.begin(), t.end());
  Ws_.makeCompressed();
  PetscCall(PetscInfo(nullptr, "theta-method: sparse Delassus matrix, %" PetscInt_FMT " x %" PetscInt_FMT ", %" PetscInt_FMT
                               " entries kept, %" PetscInt_FMT " dropped (largest dropped %g of its column's largest)\n",
                      3 * nc_, 3 * nc_, (PetscInt)Ws_.nonZeros(), w_dropped_, (double)w_dropped_max_));
  PetscFunctionReturn(0);
}

PetscErrorCode ThetaIntegrator::ToLocal(Vec x, Eigen::VectorXd &out)
{
  const PetscScalar *a;
  PetscFunctionBeginUser;
  PetscCall(MatMultTranspose(H_, x, loc_));
  PetscCall(VecScatterBegin(to_all_, loc_, loc_all_, INSERT_VALUES, SCATTER_FORWARD));
  PetscCall(VecScatterEnd(to_all_, loc_, loc_all_, INSERT_VALUES, SCATTER_FORWARD));
  PetscCall(VecGetArrayRead(loc_all_, &a));
  out.resize(3 * nc_);
  for (PetscInt k = 0; k < 3 * nc_; ++k) out[k] = PetscRealPart(a[k]);
  PetscCall(VecRestoreArrayRead(loc_all_, &a));
  PetscFunctionReturn(0);
}

PetscErrorCode ThetaIntegrator::Gather(Vec x, Eigen::VectorXd &out)
{
  const PetscScalar *a;
  PetscFunctionBeginUser;
  out.resize(n_);
  if (size_ == 1) {
    PetscCall(VecGetArrayRead(x, &a));
    for (PetscInt i = 0; i < n_; ++i) out[i] = PetscRealPart(a[i]);
    PetscCall(VecRestoreArrayRead(x, &a));
    PetscFunctionReturn(0);
  }
  PetscCall(gather_(x, out));
  PetscFunctionReturn(0);
}

PetscErrorCode ThetaIntegrator::Local(Vec x, Eigen::VectorXd &out)
{
  PetscFunctionBeginUser;
  if (dense_ && size_ == 1) {
    const PetscScalar *a;
    PetscCall(VecGetArrayRead(x, &a));
    if (ht_sparse_) out.noalias() = Hts_ * Eigen::Map<const Eigen::VectorXd>(a, n_);
    else out.noalias() = Ht_ * Eigen::Map<const Eigen::VectorXd>(a, n_);
    PetscCall(VecRestoreArrayRead(x, &a));
  } else if (dense_) {
    PetscCall(Gather(x, full_U_));
    if (ht_sparse_) out.noalias() = Hts_ * full_U_;
    else out.noalias() = Ht_ * full_U_;
  } else PetscCall(ToLocal(x, out));
  PetscFunctionReturn(0);
}

void ThetaIntegrator::LocalOf(const Eigen::Ref<const Eigen::VectorXd> &x, Eigen::VectorXd &out) const
{
  if (ht_sparse_) out.noalias() = Hts_ * x;
  else out.noalias() = Ht_ * x;
}

void ThetaIntegrator::SetUpKernel()
{
  if (modal_step_on_) {
    // Newton (-theta_contact_solver ssn) runs in Solve, which SolveSized<Dynamic> calls for it too.
    ModalStepData m{&Phi_, &PhiInv_, &Htm_, &p1m_, &p2m_, &p3m_, &ainvm_, &Ht_, ht_sparse_ ? &Hts_ : nullptr, &g0_, h_, theta_, &local_};
    if (modal_dense_) m.G = &G_, m.Ym = &Ym_, m.mk = &mk_;
    kernel_ = MakeModalStepKernel(m);
    return;
  }
  DenseStepData d{&P1_, &P2_, &Y_, &Ht_, ht_sparse_ ? &Hts_ : nullptr, &p3_, &g0_, h_, theta_, &local_};
  // The fixed-size kernels run the fixed point only (SolveSized); Newton runs in the run-time-sized one.
  kernel_ = MakeDenseStepKernel(d, fixed_size_ && local_.Solver() == ContactSolver::kFixedPoint);
}

PetscErrorCode ThetaIntegrator::DenseStep(Eigen::Ref<Eigen::VectorXd> Um, Eigen::Ref<Eigen::VectorXd> dUm, Eigen::VectorXd &r,
                                          StepInfo *info)
{
  PetscFunctionBeginUser;
  kernel_->Step(Um.data(), dUm.data(), r, &info->contact);
  PetscFunctionReturn(0);
}

PetscErrorCode ThetaIntegrator::Step(Vec U, Vec dU, Eigen::VectorXd &r, StepInfo *info)
{
  PetscFunctionBeginUser;
  // Small models on one rank: only the array access around the kernel, in a function without the
  // other cases' frame and register saves (measurable on a 3-DOF step of ~550 instructions).
  PetscScalar *u, *du;
  if (dense_ && size_ == 1 && native_arrays_ && NativeArray(U, &u) && NativeArray(dU, &du)) {
    PetscCall(VecSetErrorIfLocked(U, 1)); // as VecGetArray (debug builds of PETSc only)
    PetscCall(VecSetErrorIfLocked(dU, 2));
    // VecRestoreArray's state increase, done before the kernel writes (nothing reads U or dU in
    // between) so that nothing is left to do after the kernel.
    IncreaseState(U);
    IncreaseState(dU);
    kernel_->Step(u, du, r, &info->contact);
    PetscFunctionReturn(0);
  }
  PetscCall(StepGeneral(U, dU, r, info));
  PetscFunctionReturn(0);
}

PetscErrorCode ThetaIntegrator::StepGeneral(Vec U, Vec dU, Eigen::VectorXd &r, StepInfo *info)
{
  const PetscReal h = h_, t = theta_;
  PetscFunctionBeginUser;
  if (dense_ && size_ == 1) { // Vecs that NativeArray does not read (Step)
    PetscScalar *u, *du;
    PetscCall(VecGetArray(U, &u));
    PetscCall(VecGetArray(dU, &du));
    kernel_->Step(u, du, r, &info->contact);
    PetscCall(VecRestoreArray(dU, &du));
    PetscCall(VecRestoreArray(U, &u));
  } else if (dense_) {
    // Every rank steps the whole gathered state, then keeps its own rows.
    PetscCall(Gather(U, full_U_));
    PetscCall(Gather(dU, full_dU_));
    PetscCall(DenseStep(full_U_, full_dU_, r, info));
    PetscScalar *u, *du;
    PetscInt     lo, hi;
    PetscCall(VecGetOwnershipRange(U, &lo, &hi));
    PetscCall(VecGetArray(U, &u));
    PetscCall(VecGetArray(dU, &du));
    for (PetscInt i = lo; i < hi; ++i) u[i - lo] = full_U_[i], du[i - lo] = full_dU_[i];
    PetscCall(VecRestoreArray(dU, &du));
    PetscCall(VecRestoreArray(U, &u));
  } else {
    PetscCall(MatMult(B_, dU, rhs_));                // (S4)
    PetscCall(MatMult(model_->K, U, tmp_));
    PetscCall(VecAXPBYPCZ(rhs_, -h, h, 1.0, tmp_, model_->F));
    PetscCall(KSPSolve(ksp_, rhs_, vf_s_));
    if (cg_) PetscCall(CheckSolve());
    // (S9) needs dU^i after dU is overwritten: U += h (1 - theta) dU^i now, h theta dU^{i+1} later.
    if (nc_ > 0) {
      PetscCall(ToLocal(vf_s_, wf_));                // (S5)
      PetscCall(VecWAXPY(tmp_, h * (1 - t), dU, U));
      Eigen::VectorXd &g = rhat_;
      PetscCall(ToLocal(tmp_, g));
      for (PetscInt c = 0; c < nc_; ++c) gap_[c] = g[3 * c + kN] + g0_[c];
      info->contact = local_.Solve(wf_, gap_, r);    // (S6)-(S7)
    }
    PetscCall(VecAXPY(U, h * (1 - t), dU));
    PetscCall(VecCopy(vf_s_, dU));
    if (nc_ > 0 && r.any()) {                        // (S8); all points open: r = 0, nothing to add
      PetscScalar *rl;
      PetscInt     lo, hi;
      PetscCall(VecGetOwnershipRange(rloc_, &lo, &hi));
      PetscCall(VecGetArray(rloc_, &rl));
      for (PetscInt k = lo; k < hi; ++k) rl[k - lo] = h * r[k];
      PetscCall(VecRestoreArray(rloc_, &rl));
      if (sparse_w_) { // dU += A^-1 (H h r): one more solve with the factorised A instead of the N x 3 n_c Y
        PetscCall(MatMult(H_, rloc_, hr_));
        if (cg_) PetscCall(VecSet(yr_, 0.0));
        PetscCall(KSPSolve(ksp_, hr_, yr_));
        if (cg_) PetscCall(CheckSolve());
        PetscCall(VecAXPY(dU, 1.0, yr_));
      } else PetscCall(MatMultAdd(Yd_, rloc_, dU, dU));
    }
    PetscCall(VecAXPY(U, h * t, dU));                // (S9)
  }
  PetscFunctionReturn(0);
}

PetscErrorCode ThetaIntegrator::View(PetscViewer viewer) const
{
  PetscBool ascii;
  PetscFunctionBeginUser;
  PetscCall(PetscObjectTypeCompare((PetscObject)viewer, PETSCVIEWERASCII, &ascii));
  if (!ascii) PetscFunctionReturn(0);
  PetscCall(PetscViewerASCIIPrintf(viewer,
                                   "theta-method: theta = %g, h = %.6g s, %s back end, fixed point tol %g, at most %" PetscInt_FMT
                                   " passes, rho scale %g\n",
                                   (double)theta_, (double)h_, dense_ ? "dense" : "sparse (KSP)", (double)fp_tol_, fp_max_it_,
                                   (double)rho_scale_));
  if (dense_ && nc_ > 0)
    PetscCall(PetscViewerASCIIPrintf(viewer, "  H^T: %s (%" PetscInt_FMT " non-zeros of %" PetscInt_FMT " x %" PetscInt_FMT ", -%sh_storage)\n",
                                     ht_sparse_ ? "sparse" : "dense", (PetscInt)(ht_sparse_ ? Hts_.nonZeros() : (Ht_.array() != 0.0).count()),
                                     3 * nc_, n_, prefix_.c_str()));
  if (dense_)
    PetscCall(PetscViewerASCIIPrintf(viewer, "  step: %s (-%smodal_step %s%s%s)\n", modal_step_on_ ? "modal" : "nodal", prefix_.c_str(),
                                     modal_step_ == 0 ? "auto" : modal_step_ == 1 ? "false" : "true", modal_step_why_.empty() ? "" : ": ",
                                     modal_step_why_.c_str()));
  if (dense_ && modal_state_ >= 0)
    PetscCall(PetscViewerASCIIPrintf(viewer, "  step tangents: %s (-%smodal_tangent%s%s)%s\n", modal_on_ ? "modal" : "nodal", prefix_.c_str(),
                                     modal_why_.empty() ? "" : ": ", modal_why_.c_str(),
                                     TangentSingle() ? ", products in float (-theta_tangent_single)" : ""));
  if (nc_ > 0 && local_.Solver() == ContactSolver::kNewton)
    PetscCall(PetscViewerASCIIPrintf(viewer,
                                     "  contact solver: semi-smooth Newton (-%scontact_solver %s, at most %" PetscInt_FMT
                                     " iterations%s%s), %" PetscInt_FMT " solves, %.2f Newton iterations and %.3f factorisations per solve, %" PetscInt_FMT
                                     " fell back to the fixed point\n",
                                     prefix_.c_str(), contact_solver_ == 1 ? "ssn" : "auto", ssn_max_it_,
                                     sparse_w_ ? ", sparse LU" : local_.NewtonCondensed() ? ", condensed LU" : ", LU of J",
                                     ssn_refactor_ >= 0 ? (", fresh after " + std::to_string(ssn_refactor_) + " in a step").c_str() : "", local_.NewtonSolves(),
                                     local_.NewtonSolves() ? (double)local_.NewtonSteps() / local_.NewtonSolves() : 0.0,
                                     local_.NewtonSolves() ? (double)local_.Factorisations() / local_.NewtonSolves() : 0.0, local_.Fallbacks()));
  else if (nc_ > 0)
    PetscCall(PetscViewerASCIIPrintf(viewer, "  contact solver: fixed point (-%scontact_solver %s)%s\n", prefix_.c_str(),
                                     contact_solver_ == 0 ? "fp" : "auto", local_.FixedPointSingle() ? ", h W read in float" : ""));
  if (!dense_ && nc_ > 0) {
    if (sparse_w_)
      PetscCall(PetscViewerASCIIPrintf(viewer,
                                       "  contact operator: sparse W (3 n_c = %" PetscInt_FMT " > -%sdelassus_max %" PetscInt_FMT "), %" PetscInt_FMT
                                       " entries, %" PetscInt_FMT " below the drop tolerance %g dropped (largest %g), (S8) by a solve\n",
                                       3 * nc_, prefix_.c_str(), delassus_max_, (PetscInt)Ws_.nonZeros(), w_dropped_, (double)delassus_drop_,
                                       (double)w_dropped_max_));
    else
      PetscCall(PetscViewerASCIIPrintf(viewer, "  contact operator: dense W and Y = A^-1 H (3 n_c = %" PetscInt_FMT " <= -%sdelassus_max %" PetscInt_FMT ")\n",
                                       3 * nc_, prefix_.c_str(), delassus_max_));
  }
  if (!dense_ && ksp_) {
    PetscCall(PetscViewerASCIIPushTab(viewer));
    PetscCall(KSPView(ksp_, viewer));
    PetscCall(PetscViewerASCIIPopTab(viewer));
  }
  PetscFunctionReturn(0);
}

} // namespace squeal
