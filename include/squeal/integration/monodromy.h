// The monodromy of the steady-sliding linearisation over one period of steps: shooting's and the
// torus's linear preconditioners (-shoot_linear_pc, -torus_linear_pc).
#pragma once

#include "squeal/integration/theta.h"

namespace squeal {

// P = S^steps, S the exact tangent of one step (ti set up at the step wanted) at the reactions r0
// with every status held (every point closed and sliding: r0 the equilibrium's reactions), on the
// state (U, dU) of 2N entries: one step tangent of 2N columns and log2(steps) squarings.
// Weakly damped structural modes put many multipliers near the unit circle, spread round it, where
// unpreconditioned GMRES needs about one iteration each; these are nearly the multipliers of P.
// Dense back end only.
// comm: ranks that each hold the whole model (the dense back end) and share the products of the
// powering, each forming a block of columns (compute-bound, so two ranks halve it); by default one.
// poll: if given, SIGINT/SIGTERM are polled on comm (collective, core/interrupt.h) within the
// products, which take seconds from N ~ 1500 (a product of order 3188 is about 65 Gflop).
// single: the powering's products in single precision (GemmFloat), S and P in double; P then
// carries float's relative error, about 1e-7 a product, which a preconditioner does not notice.
PetscErrorCode LinearMonodromy(ThetaIntegrator &ti, const Eigen::VectorXd &r0, PetscInt steps, Eigen::MatrixXd &P, MPI_Comm comm = PETSC_COMM_SELF,
                               const char *poll = nullptr, bool single = false);

} // namespace squeal
