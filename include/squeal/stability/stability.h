// Linear stability of steady sliding (docs/method.md §4.3-4.4): the regular QEP (4.5) solved by
// SLEPc PEP (TOAR, shift-and-invert about a real target, scalar scaling), options prefix
// "stab_" (-stab_pep_nev, -stab_pep_target, -stab_st_*, ...).
//
// Route: route (a) of docs/method.md, the PEP on the full reduced problem, for every model size.
// It computes the eigenvalues nearest the target 0 (the lowest |lambda|) and grows nev until the
// band is covered (-stab_fmax, default 20 kHz, the audible band; -stab_nev_max caps the growth).
//
// Completeness certificate: shift-and-invert about 0 makes TOAR converge eigenvalues in order of
// |lambda|, so when nconv >= nev, every eigenvalue with |lambda| < R_c, R_c = the nev-th smallest
// converged |lambda|, is in the table (the usual Krylov caveat aside: an eigenvector orthogonal to
// the start vector). "Complete up to X Hz" means R_c = 2 pi X: every eigenvalue with
// |lambda| < 2 pi X, hence every mode with f < X whose |lambda| < 2 pi X. When all 2 n_r
// eigenvalues converged the table is the whole spectrum (X = inf). The band is covered when
// R_c > 2 pi f_max; a stable verdict holds only up to X.
//
// Reported per eigenvalue (member with omega >= 0 of each pair): sigma, omega, f = omega/2pi,
// T = 2pi/omega, zeta = -sigma/|lambda|, unstable iff sigma > 0, PEP backward error, and the
// mode phi = Q xi normalised so that its largest tangential contact component is exactly 1.
#pragma once

#include "squeal/core/inf.h"
#include "squeal/core/handle.h"
#include "squeal/model/model.h"
#include "squeal/stability/equilibrium.h"
#include "squeal/stability/linearization.h"

#include <complex>
#include <string>
#include <vector>

namespace squeal {

struct Mode {
  PetscReal sigma = 0, omega = 0; // lambda = sigma + i omega, omega >= 0
  PetscReal error = 0;            // PEP backward error
  VecH      phi_re, phi_im;       // N-vectors (only when modes were asked for)

  PetscReal Frequency() const { return omega / (2 * PETSC_PI); }
  PetscReal Period() const { return omega > 0 ? 2 * PETSC_PI / omega : kInf; }
  PetscReal DampingRatio() const { return -sigma / PetscSqrtReal(sigma * sigma + omega * omega); }
  bool      Unstable() const { return sigma > 0; }
  bool      Oscillatory() const { return omega > 0; }
};

struct StabilityResult {
  std::vector<Mode>     modes;    // sorted by omega, then sigma
  std::vector<PetscInt> unstable; // indices into modes, most unstable first (in the band: InBand)
  PetscInt              requested = 0, converged = 0, n_r = 0, solves = 0;
  PetscReal             fmin = 0, fmax = 0;             // the band asked for (Hz); fmax 0: none
  PetscReal             complete_radius = 0;            // R_c (1/s), see above; inf: all eigenvalues
  bool                  all_eigenvalues = false;

  // X = R_c / 2 pi (Hz): every eigenvalue with |lambda| < 2 pi X is in the table.
  PetscReal CompleteUpTo() const { return complete_radius / (2 * PETSC_PI); }
  bool      BandCovered() const { return all_eigenvalues || complete_radius > 2 * PETSC_PI * fmax; }

  // Unstable: an unstable mode in the band (fmin <= f <= fmax). Stable: none, and the band is covered (or
  // the whole spectrum is known). Undecided: none among the eigenvalues computed, which do not
  // cover the band; energy, shooting and continuation refuse to go on from it.
  enum class Verdict { Unstable, Stable, Undecided };
  Verdict GetVerdict() const
  {
    if (!unstable.empty()) return Verdict::Unstable;
    return all_eigenvalues || (fmax > 0 && BandCovered()) ? Verdict::Stable : Verdict::Undecided;
  }
  // The band the user asked for: fmin <= f, and f <= fmax unless fmax is 0. The table lists the
  // modes outside it (the solve converges some above fmax), and nothing downstream starts from
  // them: a user who gives a band means the squeal in it.
  bool InBand(const Mode &m) const { return m.Frequency() >= fmin && (fmax <= 0 || m.Frequency() <= fmax); }
  // Unstable modes below the band (f < fmin) and above it (f > fmax): listed, not reported.
  PetscInt UnstableBelowBand() const
  {
    PetscInt n = 0;
    for (const Mode &m : modes) n += m.Unstable() && m.Frequency() < fmin;
    return n;
  }
  PetscInt UnstableAboveBand() const
  {
    PetscInt n = 0;
    for (const Mode &m : modes) n += m.Unstable() && fmax > 0 && m.Frequency() > fmax;
    return n;
  }

  // Largest growth rate over oscillatory modes (flutter); -inf if none.
  PetscReal MaxOscillatorySigma(PetscInt *which = nullptr) const;
};

// Top of the band (Hz) when -stab_fmax is not given: the audible band. The reduction's default
// cut-off is a multiple of it (CraigBampton::SetFromOptions).
inline constexpr PetscReal kDefaultBandHz = 20000;

class StabilitySolver {
public:
  explicit StabilitySolver(MPI_Comm comm) : comm_(comm) {}
  PetscErrorCode SetOptionsPrefix(const char *prefix)
  {
    prefix_ = prefix ? prefix : "";
    return 0;
  }
  PetscErrorCode SetComputeModes(bool modes);
  // -stab_view, -stab_modes, -stab_fmax, -stab_fmin, -stab_nev_max, and everything of the PEP
  // under -stab_.
  PetscErrorCode SetFromOptions();
  PetscErrorCode Solve(const Model &model, const SlidingEquilibrium &eq, StabilityResult &res);
  // The eigenvalues over the band (0, fmax] without the modes' vectors: the unstable modes above
  // the band that the time integration carries (-stab_guard_fmax). Up to 2 n_r =
  // -stab_guard_dense_max all of them by LAPACK, else the same eigensolve as Solve's.
  PetscErrorCode SolveUpTo(const Model &model, const SlidingEquilibrium &eq, PetscReal fmax, StabilityResult &res);
  // -stab_guard_fmax (Hz): < 0 the top of a reduction made in this run, 0 off.
  PetscReal      GuardFMax() const { return guard_fmax_; }
  // -stab_guard_route: -analyses auto takes the statistical steady state without shooting when a
  // mode above the band grows faster than the band's.
  bool           GuardRoute() const { return guard_route_; }
  PetscErrorCode View(const StabilityResult &res, PetscViewer viewer) const;
  PetscErrorCode ViewFromOptions(const StabilityResult &res) const;
  // One line: "complete up to X Hz (...)" or "complete: all ... eigenvalues", and whether the band
  // was covered.
  PetscErrorCode ViewCompleteness(const StabilityResult &res, PetscViewer viewer) const;
  PEP            GetPEP() const { return pep_; }

private:
  PetscErrorCode NormaliseMode(const Model &model, Mode &m) const;
  // SolveUpTo's route for small reduced problems (2 n_r <= -stab_guard_dense_max): all 2 n_r
  // eigenvalues by LAPACK on rank 0, no vectors. *done false where M_r is singular or dgeev fails
  // (the PEP then takes over).
  PetscErrorCode SolveAllDense(const ReducedProblem &rp, StabilityResult &res, bool *done) const;

  MPI_Comm    comm_;
  std::string prefix_ = "stab_";
  bool        modes_  = true;
  PetscReal   fmax_ = kDefaultBandHz, fmin_ = 0;
  PetscInt    nev_max_ = 1000;
  PetscReal   guard_fmax_ = -1;
  PetscInt    guard_dense_max_ = 4000;
  PetscBool   guard_route_ = PETSC_TRUE;
  PEPH        pep_;
};

} // namespace squeal

namespace squeal {
namespace io {
class H5Writer;
}
// /stability/eigenvalues (k x 2: re, im), /stability/modes/re and /im (N x k), /stability/unstable,
// frequency, period, damping ratio and backward error per eigenvalue, with units.
PetscErrorCode WriteStability(const StabilityResult &res, io::H5Writer &out);
// /equilibrium/U, /equilibrium/R (global contact force), /equilibrium/r (n_c x 3 local t, b, n),
// /equilibrium/N, /equilibrium/active.
PetscErrorCode WriteEquilibrium(const Model &model, const SlidingEquilibrium &eq, io::H5Writer &out);
} // namespace squeal
