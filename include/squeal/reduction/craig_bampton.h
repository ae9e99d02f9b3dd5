// Craig-Bampton reduction of a model to its contact DOFs plus fixed-interface modes
// (docs/method.md §4.4 route (b), §9), options prefix "reduce_".
//
// Partition the DOFs into the interface B (every translational DOF of every contact node, in the
// contact order: point c's node DOFs x, y, z at 3c .. 3c+2) and the interior I (the rest).
//   fixed-interface modes  K_II Phi = M_II Phi Omega^2,  Phi^T M_II Phi = I,  the m lowest
//                          (SLEPc EPS, GHEP, Krylov-Schur, shift-and-invert with a direct solver)
//                          with f <= fmax (-reduce_fmax) and/or the first nmodes (-reduce_nmodes);
//   constraint modes       Psi = -K_II^{-1} K_IB  (one factorisation of K_II, multi-RHS solves on
//                          blocks of the 3 n_c right-hand sides, -reduce_rhs_block; a signal
//                          is obeyed between blocks);
//   T = [ I_BB   0  ]      q = T [u_B; eta],   A_r = T^T A T for A = M, C, K,  F_r = T^T F.
//       [ Psi   Phi ]
// The reduced model has 3 n_c + m DOFs: the interface DOFs first, in contact order, so the contact
// set becomes a selection of the first 3 n_c DOFs (H stays a selection, Q a deletion), then the
// modal coordinates. C is the projection of the full C, so Rayleigh damping stays consistent.
// The result is an ordinary Model (same code path; -model_export writes it, -model_type file
// reads it back). Exact for static loads on the interface; the error on the eigenvalues in a band
// falls as fmax grows above it (the usual rule: fmax >= 1.5-2 x the top frequency of interest).
//
// Cost (N DOFs, n = 3 n_c + m): one MUMPS Cholesky of K_II shared by the eigensolver and the
// constraint modes, 3 n_c right-hand sides, and one symmetric product W^T (M_II W) of ~n^2 N flops
// (Eigen kernels on each rank's rows, summed); K_r has a closed form and Rayleigh C = a M + b K
// is reduced as a M_r + b K_r, so C costs a second product only when it is not Rayleigh.
// On several ranks (-reduce_redundant, default): every rank factorises the whole K_II on its own
// (PCREDUNDANT around the same Cholesky) and solves its share of the 3 n_c constraint-mode columns
// with no communication; the rows of Psi then go to their owners in one all-to-all. MUMPS's
// distributed solve phase with all the right-hand sides was no faster on 2 ranks than on one, and
// the scatter of its distributed solution into W came on top (docs/records.md, MPI speed-ups, item a).
// The price: every rank holds a whole factor, and the factorisation itself no longer splits.
// Interface reduction (-reduce_interface_modes k and/or -reduce_interface_fmax f; default off):
// each contact point keeps one physical coordinate, x_c = a_c^T u_c with h_n = w_0 a_c (w_0 its
// first node's weight): for one node its normal displacement, for a pad node against a disc node
// (weights +1, -1) their relative normal displacement. h_n stays a selection, so the equilibrium's
// and the linearisation's pivot elimination and the unilateral law stay exact point by point. The
// rest of the interface, u_c = q0_c x_c + Z_c s_c (q0_c = a_c / |a_c|^2, Z_c an orthonormal basis
// of a_c's complement: [t_c b_c] for one node; the tangential and the common motions of the two
// faces for a pair), is replaced by the k lowest characteristic constraint modes of the reduced
// interface block in s (K_ss Psi = M_ss Psi Lambda, Psi^T M_ss Psi = I, every x_c and the
// fixed-interface modes held):
//   u_c = q0_c x_c + Z_c Psi_c xi,   A_r <- T^T A_r T,   n_c + k + m DOFs,
// ordered [x (n_c), xi (k), eta (m)]. h_t, h_b of point c become h_e^T Z_c Psi_c (explicit column
// entries, dense over xi). With k = 3 n_nodes - n_c it is an exact change of basis. The contact
// problem of a time step still has 3 n_c unknowns: the Delassus matrix keeps its size, but its
// tangential block has rank <= k.
// Options: -reduce_type none|craig_bampton, -reduce_fmax (Hz), -reduce_nmodes, -reduce_rayleigh,
// -reduce_redundant, -reduce_rhs_block, -reduce_expand, -reduce_expand_records, and the eigensolver and the factorisation under -reduce_eps_* / -reduce_st_*
// (e.g. -reduce_st_mat_mumps_icntl_27 for the block size of the constraint-mode solves; with
// -reduce_redundant on several ranks the factor's options are -reduce_st_redundant_mat_mumps_*).
#pragma once

#include "squeal/core/handle.h"
#include "squeal/model/model.h"

#include <string>
#include <functional>
#include <utility>
#include <vector>

namespace squeal {

namespace cb { // the steps' data (src/reduction/internal.h)
struct Partition;
struct Interior;
} // namespace cb

struct ReductionInfo {
  PetscInt               N = 0, n_interface = 0, n_modes = 0;
  std::vector<PetscReal> freq;                // Hz, fixed-interface modes kept
  PetscReal              time_factor = 0, time_modes = 0, time_static = 0, time_project = 0, time_total = 0; // s
  // s, CPU time of the busiest rank in each stage: the work per rank, which a loaded machine
  // (other processes taking time slices) changes far less than the wall times above.
  PetscReal              cpu_factor = 0, cpu_modes = 0, cpu_static = 0, cpu_project = 0;
  bool                   rayleigh = false; // C detected as a M + b K and projected as a M_r + b K_r
  bool                   damping_split = false; // C = a M + b K + parts (Model::damping_extra): the parts projected alone
  PetscLogDouble         mem_peak = 0;        // bytes, resident set size after the reduction (sum over ranks)
  PetscLogDouble         mem_rank_hwm = 0;    // bytes, the largest rank's peak resident set size so far
  // Interface reduction (0: none): one normal coordinate per point kept, the interface's characteristic constraint modes kept and their frequencies (Hz).
  PetscInt               n_normal = 0, n_inplane_modes = 0; // n_inplane_modes: every column of the interface basis
  PetscInt               n_interface_statics = 0;           // of them, added for the contact normals' statics
  PetscInt               slice_parts = 0;                   // the fixed-interface modes by spectrum slicing in this many parts (0: one shift)
  std::vector<PetscInt>  slice_counts;                      // the modes each part found, in ascending order of the parts
  PetscInt               slice_per_shift = 0;               // the modes a slicing shift asks for (-reduce_slice_eps_krylovschur_nev)
  std::vector<PetscReal> inplane_freq;
  PetscInt               lanczos_block = 0, lanczos_columns = 0, lanczos_solves = 0, lanczos_slices = 0; // the fixed-interface modes by block Lanczos (0: not)
  PetscReal              time_expansion = 0; // s, building the kept expansion (0: none kept)
  size_t                 expansion_bytes = 0; // on rank 0
};

class CraigBampton {
public:
  explicit CraigBampton(MPI_Comm comm) : comm_(comm) {}
  PetscErrorCode SetOptionsPrefix(const char *prefix)
  {
    prefix_ = prefix ? prefix : "";
    return 0;
  }
  // The setters of the options below (plain assignments, read at Reduce).
  PetscErrorCode SetFMax(PetscReal fmax) { fmax_ = fmax, fmax_note_.clear(); return 0; }        // Hz; <= 0: no frequency cut-off
  PetscErrorCode SetNModes(PetscInt nmodes) { nmodes_ = nmodes, fmax_note_.clear(); return 0; } // < 0: no count limit
  PetscErrorCode SetFBand(PetscReal fband) { fband_ = fband; return 0; }      // Hz; > 0: refuse fmax below it
  PetscErrorCode SetMaxModes(PetscInt max_modes) { max_modes_ = max_modes; return 0; } // >= 1: the fixed-interface modes kept at most
  // true (default): a C found equal to a M + b K (to 1e-12) is reduced as a M_r + b K_r, saving one
  // dense product; false: C is always projected (-reduce_rayleigh).
  PetscErrorCode SetRayleighShortcut(bool on) { rayleigh_ = on ? PETSC_TRUE : PETSC_FALSE; return 0; }
  // true (default): on several ranks every rank factorises the whole K_II and solves its share of
  // the constraint modes alone; false: one distributed MUMPS factorisation and solve (-reduce_redundant).
  PetscErrorCode SetRedundantFactor(bool on) { redundant_ = on ? PETSC_TRUE : PETSC_FALSE; return 0; }
  // The constraint modes are solved in blocks of this many right-hand sides, with an interrupt
  // poll between blocks (<= 0: all in one solve; -reduce_rhs_block). The factor is the same:
  // only the right-hand side is split, and the modes agree to round-off.
  PetscErrorCode SetRHSBlock(PetscInt block) { rhs_block_ = block; return 0; }
  // The fixed-interface modes below the cut-off by spectrum slicing (1), at one shift (0), or where
  // slicing is estimated cheaper (-1, the default; -reduce_slice). The same modes either way.
  PetscErrorCode SetSlice(PetscInt slice) { slice_ = slice; return 0; }
  // The fixed-interface modes by block shift-and-invert Lanczos with blocks of b columns, with the
  // modes counted (and on several ranks the redundant factor; b > 0, default 8;
  // -reduce_lanczos_block), in slices of about `modes` modes each (-reduce_lanczos_slice_modes),
  // dealt out to the ranks; b = 0: by SLEPc as SetSlice says.
  PetscErrorCode SetLanczosBlock(PetscInt b) { lanczos_block_ = b; return 0; }
  PetscErrorCode SetLanczosSliceModes(PetscInt modes) { lanczos_slice_modes_ = modes; return 0; }
  PetscErrorCode SetLanczosMaxMB(PetscReal mb) { lanczos_max_mb_ = mb; return 0; } // -reduce_lanczos_max_mb
  PetscErrorCode SetSliceBalance(bool on) { slice_balance_ = on ? PETSC_TRUE : PETSC_FALSE; return 0; } // the parts at equal mode counts
  // Interface reduction: keep the k lowest characteristic constraint modes of the interface (k < 0: no
  // limit by count; -reduce_interface_modes) and/or those below fmax Hz (<= 0: no frequency
  // limit; -reduce_interface_fmax). Both unset (the default): no interface reduction.
  PetscErrorCode SetInterfaceModes(PetscInt k) { iface_modes_ = k; return 0; }
  PetscErrorCode SetInterfaceFMax(PetscReal fmax) { iface_fmax_ = fmax; return 0; }
  // Interface reduction: add the interface's static response to each contact normal (1), never (0),
  // or for two-body points only (-1, the default; -reduce_interface_statics).
  PetscErrorCode SetInterfaceStatics(PetscInt statics) { iface_statics_ = statics; return 0; }
  // Keep the expansion u_full = E u (Model::expansion, on rank 0: 8 N n bytes) in the reduced
  // model, so that results can be written on the full mesh. Off unless asked: -reduce_expand,
  // whose default the caller chooses (ExpansionOption).
  PetscErrorCode SetKeepExpansion(bool on) { keep_expansion_ = on; return 0; }
  // -reduce_expand as given: 1 or 0; -1 when not given.
  PetscInt       ExpansionOption() const { return expand_opt_; }
  // -reduce_type, -reduce_fmax, -reduce_nmodes, -reduce_fband; *enabled tells whether
  // -reduce_type asks for a reduction.
  PetscErrorCode SetFromOptions(bool *enabled = nullptr);
  // full -> reduced (on full's communicator). full is left untouched.
  PetscErrorCode Reduce(const Model &full, Model &reduced);
  PetscErrorCode View(PetscViewer viewer) const;
  const ReductionInfo &Info() const { return info_; }

private:
  // Steps of Reduce that read the options.
  PetscErrorCode FactorInterior(const Model &full, const cb::Partition &p, cb::Interior &in);
  PetscErrorCode FixedInterfaceModes(MPI_Comm comm, const cb::Partition &p, cb::Interior &in, std::vector<PetscReal> &lam,
                                     std::vector<PetscInt> &keep);
  // count(w2, &n, &ok): the modes below w2 by an inertia count (collective); nev of them below w2max.
  using ModeCount = std::function<PetscErrorCode(PetscReal, PetscInt *, bool *)>;
  PetscErrorCode SliceModes(MPI_Comm comm, cb::Interior &in, PetscReal w2max, PetscInt nev, const ModeCount &count, std::vector<PetscReal> &lam);

  MPI_Comm      comm_;
  std::string   prefix_ = "reduce_";
  PetscReal     fmax_   = 0;
  PetscInt      nmodes_ = -1;
  PetscReal     fband_  = 0;
  PetscReal     fmax_factor_ = 6; // -reduce_fmax_factor: the default cut-off in units of the band
  PetscInt      slice_       = -1;  // -reduce_slice: spectrum slicing of the fixed-interface modes (-1: where it is estimated cheaper)
  std::string   fmax_note_;       // how the default cut-off was chosen, said by Reduce
  PetscInt      max_modes_ = 1000;
  PetscBool     rayleigh_  = PETSC_TRUE;
  PetscBool     sparse_rhs_ = PETSC_TRUE;
  PetscBool     count_modes_ = PETSC_TRUE;
  PetscBool     slice_balance_ = PETSC_TRUE; // -reduce_slice_balance: the parts' boundaries at equal mode counts
  PetscBool     redundant_   = PETSC_TRUE;
  PetscInt      rhs_block_   = 32;
  PetscInt      lanczos_block_  = 8;    // -reduce_lanczos_block (0: SLEPc)
  PetscReal     lanczos_max_mb_ = 2048; // -reduce_lanczos_max_mb
  PetscInt      lanczos_slice_modes_ = 150; // -reduce_lanczos_slice_modes
  PetscBool     lanczos_monitor_ = PETSC_FALSE; // -reduce_lanczos_monitor
  PetscReal     lanczos_tol_ = 1e-10; // -reduce_lanczos_tol
  PetscInt      iface_modes_ = -1;
  PetscReal     iface_fmax_  = 0;
  PetscInt      iface_statics_ = -1;
  PetscInt      expand_opt_  = -1;
  PetscInt      expand_records_ = 200;
  PetscReal     expand_max_mb_  = 2048; // the default expansion's largest E (-reduce_expand_max_mb)
  bool          keep_expansion_ = false;
  ReductionInfo info_;
};

} // namespace squeal
