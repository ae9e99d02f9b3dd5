// Builders: every way a model enters squeal. All produce the same Model (model.h).
#pragma once

#include "squeal/model/fe_contact.h"
#include "squeal/model/model.h"

namespace squeal {

// The reference 3-DOF system (docs/method.md §1.2, §8): a mass on three inclined springs pressed on
// a moving surface. DOFs ordered (t, b, n) in the sliding frame, H = I; with spring_frame the
// DOFs stay in the springs' (x, y, n) frame and the contact frame carries the rotation
// (H = R_gamma^T), which must give identical results.
struct ThreeDofParams {
  PetscReal   m = 1.0, k1 = 3.65e5, k2 = 2.555e5, k3 = 3.65e5;
  PetscReal   kn    = -1; // < 0: k3 + k1 tan^2(alpha) + k2 tan^2(beta)
  PetscReal   alpha = 30, beta = -60, gamma = 30; // degrees
  PetscReal   c = 20, Fn = 400, mu = 0.5, V = 3;
  FrictionLaw law          = FrictionLaw::Planar;
  bool        spring_frame = false;
};
PetscErrorCode BuildThreeDof(MPI_Comm comm, const ThreeDofParams &p, Model &model);

// Stiffness of the 3-DOF system in its springs' frame (x, y, n) and rotated to (t, b, n).
void ThreeDofStiffness(const ThreeDofParams &p, PetscReal Kxyn[3][3], PetscReal Ktbn[3][3]);

// Synthetic multi-contact model that keeps the general path honest: `cells` 3-DOF cells in
// global (x, y, z) coordinates, neighbours coupled by isotropic springs `coupling`; cell i slides
// along gamma + i * gamma_step at speed V (1 + i * speed_step), so every point has its own frame
// and speed, and H is not the identity.
struct ChainParams {
  ThreeDofParams cell;
  PetscInt       cells      = 4;
  PetscReal      coupling   = 5.0e4;
  PetscReal      gamma_step = 25;  // degrees
  PetscReal      speed_step = 0.2; // relative
  PetscInt       contact_every = 1; // cells 0, k, 2k, ... touch the surface (and carry the preload)
};
PetscErrorCode BuildChain(MPI_Comm comm, const ChainParams &p, Model &model);

// A model read from files: M, K (and optionally C) in PETSc binary or Matrix Market (.mtx),
// F in PETSc binary or HDF5 (dataset /F), the contact table in the text format of
// ReadContactTable. Friction law, mu and V come from the options.
struct FileModelSpec {
  std::string mass, damping, stiffness, load, contacts;
  PetscReal   mu = 0.5, V = 1.0;
  FrictionLaw law = FrictionLaw::Planar;
};
PetscErrorCode BuildFromFiles(MPI_Comm comm, const FileModelSpec &s, Model &model);

// A model straight from CalculiX (docs/fe-workflow.md): the mesh and node sets of job.inp, K and M
// from job.sti and job.mas, the DOF numbering of job.dof (io/calculix.h); damping a M + b K; the
// preload from a pressure on the faces of a node set and/or a load vector in the .dof numbering;
// the contact points from the geometry of the pad and disc faces (fe_contact.h). The model
// carries its mesh (Model::mesh) for results on the mesh.
struct CalculixModelSpec {
  std::string job;                                  // STEM of STEM.inp, .sti, .mas, .dof
  PetscReal   ray_a = 0, ray_b = 0;                 // Rayleigh factors
  // Damping of parts: C += b_i K_i, K_i the stiffness of a CalculiX job made of some of the
  // model's elements (PART.sti with its own PART.dof), e.g. a lining with its own loss factor.
  std::vector<std::string> part_jobs;
  std::vector<PetscReal>   part_b;
  PetscReal   pressure = 0;                         // Pa, on the faces of pressure_set
  std::string pressure_set = "PAD_BACK";
  std::string load;                                 // optional load vector file
  FacePairing pairing;
  PetscReal   mu = 0.5, V = 1.0;
  FrictionLaw law     = FrictionLaw::Planar;
  bool        verbose = false;                      // one summary line on stdout
};
PetscErrorCode BuildCalculix(MPI_Comm comm, const CalculixModelSpec &s, Model &model);

// Contact table, one point per line ('#' starts a comment):
//   x y z   tx ty tz   nx ny nz   [speed_factor [g0]]
// x y z: 0-based global DOF indices of the node's translations; t: unit sliding direction;
// n: unit normal of the counter-surface pointing towards the structure (b = n x t);
// speed_factor: V_c / V (default 1); g0: initial gap (default 0).
// Commas (CSV) separate like blanks; a first line of names (x y z tx ty tz nx ny nz, optional
// speed_factor g0, any order; "dof_x" for "x") maps the columns.
// A point whose columns of H are not one node's translations (several nodes, weights, the
// interface modes of a reduced model) is a row starting with the word cols:
//   cols  tx ty tz  nx ny nz  speed_factor g0  n_t n_b n_n  dof value  dof value ...
// with n_t entries of h_t, then n_b of h_b, then n_n of h_n (ContactPoint::cols). Both row forms
// may be mixed. WriteContactTable writes single-node points of weight 1 in the first form and
// every other point in the second, so any contact set reads back with the same columns.
PetscErrorCode ReadContactTable(MPI_Comm comm, const char *path, ContactSet &set);
PetscErrorCode WriteContactTable(MPI_Comm comm, const char *path, const ContactSet &set);

// Reads -model_type (three_dof | chain | file | pad | calculix) and the family's options, builds and validates.
// Options: -model_* for the structure, -contact_mu, -contact_v, -contact_friction. The directory
// given by -model_export (empty if none) is returned in export_dir; writing it is the caller's
// choice (a sweep builds one model per rank and must not write it from every rank).
// options_only: read and check every model and contact option, build nothing (so that a mistyped
// option fails before minutes of FE import). The reduction is a step of its own (Pipeline::Reduce).
PetscErrorCode ModelCreateFromOptions(MPI_Comm comm, Model &model, std::string *export_dir = nullptr, bool options_only = false);

} // namespace squeal
