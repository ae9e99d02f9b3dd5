// Linear stability of steady sliding (method.md §4.3-4.4): the regular QEP (4.5) solved by
// SLEPc PEP (TOAR, shift-and-invert about a real target, scalar scaling), options prefix
// "stab_" (-stab_pep_nev, -stab_pep_target, -stab_st_*, ...).
//
// Route: route (a) of method.md, the PEP on the full reduced problem, for every model size.
// It computes the nev eigenvalues nearest the target (default 0, i.e. the lowest frequencies),
// which is what a squeal study asks for; the two-stage modal route (b) for high frequency bands
// of very large models is not implemented yet.
//
// Reported per eigenvalue (member with omega >= 0 of each pair): sigma, omega, f = omega/2pi,
// T = 2pi/omega, zeta = -sigma/|lambda|, unstable iff sigma > 0, PEP backward error, and the
// mode phi = Q xi normalised so that its largest tangential contact component is exactly 1.
#pragma once

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
  PetscReal Period() const { return omega > 0 ? 2 * PETSC_PI / omega : PETSC_INFINITY; }
  PetscReal DampingRatio() const { return -sigma / PetscSqrtReal(sigma * sigma + omega * omega); }
  bool      Unstable() const { return sigma > 0; }
  bool      Oscillatory() const { return omega > 0; }
};

struct StabilityResult {
  std::vector<Mode>     modes;    // sorted by omega, then sigma
  std::vector<PetscInt> unstable; // indices into modes, most unstable first
  PetscInt              requested = 0, converged = 0;

  // Largest growth rate over oscillatory modes (flutter); -inf if none.
  PetscReal MaxOscillatorySigma(PetscInt *which = nullptr) const;
};

class StabilitySolver {
public:
  explicit StabilitySolver(MPI_Comm comm) : comm_(comm) {}
  PetscErrorCode SetOptionsPrefix(const char *prefix);
  PetscErrorCode SetComputeModes(bool modes);
  // -stab_view, -stab_modes, and everything of the PEP under -stab_.
  PetscErrorCode SetFromOptions();
  PetscErrorCode Solve(const Model &model, const SlidingEquilibrium &eq, StabilityResult &res);
  PetscErrorCode View(const StabilityResult &res, PetscViewer viewer) const;
  PetscErrorCode ViewFromOptions(const StabilityResult &res) const;
  PEP            GetPEP() const { return pep_; }

private:
  PetscErrorCode NormaliseMode(const Model &model, Mode &m) const;

  MPI_Comm    comm_;
  std::string prefix_ = "stab_";
  bool        modes_  = true;
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
