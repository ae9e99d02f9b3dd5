// A finite-element brake pad on a rotating rigid disc: the project's own FE test model
// (docs/method.md §9).
//
// Geometry: an annular sector of the disc plane z = 0 (inner radius r_in, outer radius r_out,
// opening angle `angle`, centred on the x axis), extruded in +z: a friction-material layer of
// thickness h_fric on z in [0, h_fric], then a steel back plate of thickness h_steel. The disc
// rotates about the z axis (Omega along +z) and does not deform.
//
// Discretisation: 8-node trilinear hexahedra on a polar grid (n_r radial x n_t circumferential
// x (n_fric + n_steel) through the thickness), 2x2x2 Gauss points, isotropic linear elasticity per
// layer. Mass lumped by row sums (m_i = int rho N_i dV, positive, and sum m_i = rho * volume), so
// M is diagonal and M_r = Q^T M Q stays SPD (docs/method.md §4.2). Support springs to ground on the back
// face (z = h_fric + h_steel): foundation stiffness per unit area k_n (along z) and k_t (along x
// and y), lumped like the mass (k_i = k * int N_i dA), so refining the mesh keeps the physics.
// Rayleigh damping C = a M + b K (K including the springs). Preload: pressure p on the back face,
// consistent nodal forces F_i = -p int N_i dA e_z.
//
// Contact: every node of the friction face z = 0 is a contact point, n = +e_z (disc normal towards
// the pad), t = Omega x r / |Omega x r| = (-y, x, 0) / |r|, b = n x t (radial, inwards), speed
// factor |r| / r_ref so that V_c = Omega |r| with V (-contact_v) the speed at r_ref (default: the
// mean radius). Nodes are numbered layer by layer from the friction face, so the contact nodes
// are nodes 0 .. n_c - 1 and their translations the first 3 n_c DOFs.
//
// Assembly is distributed: rank p owns a contiguous range of nodes (3 DOFs each) and integrates
// only the elements touching its nodes, keeping the rows it owns (exact preallocation through
// MatCreateFromTriplets).
#pragma once

#include "squeal/core/options.h"
#include "squeal/model/model.h"

namespace squeal {

struct PadParams {
  PetscReal r_in = 0.10, r_out = 0.15, angle = 50; // m, m, degrees
  PetscReal h_fric = 0.010, h_steel = 0.006;       // m
  PetscInt  n_r = 6, n_t = 24, n_fric = 2, n_steel = 2;
  PetscReal E_fric = 1.5e9, nu_fric = 0.25, rho_fric = 2200;   // Pa, -, kg/m^3
  PetscReal E_steel = 210e9, nu_steel = 0.30, rho_steel = 7850;
  PetscReal k_n = 2.0e10, k_t = 5.0e10;   // support foundation (N/m per m^2 of back face)
  PetscReal ray_a = 0.0, ray_b = 2.0e-8;  // C = a M + b K (1/s, s)
  PetscReal pressure = 1.0e6;             // Pa on the back face
  PetscReal r_ref = -1;                   // m; <= 0: (r_in + r_out) / 2
  PetscReal mu = 0.2, V = 10.0;
  FrictionLaw law = FrictionLaw::Planar;
};

// Builds and validates the pad model. Collective on comm.
PetscErrorCode BuildPad(MPI_Comm comm, const PadParams &p, Model &model);

// Volume of the discretised pad (straight-edged sectors: n_t/2 (r_out^2 - r_in^2) sin(angle/n_t)
// times the thickness): the mesh's exact volume, for mass checks.
PetscReal PadMeshVolume(const PadParams &p, bool steel);

// Reads the -model_* options of the pad family into p (inside an open options block of prefix
// "model_"); the caller runs `checks` after PetscOptionsEnd().
PetscErrorCode PadOptions(PetscOptionItems *PetscOptionsObject, PadParams &p, OptionChecks &checks);

} // namespace squeal
