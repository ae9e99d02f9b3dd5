// The finite-element mesh a model came from (node coordinates, cells, node sets, and where each
// node's translations sit among the model's DOFs). It lets the contact pairs be found from the
// geometry and lets results be written on the mesh (XDMF) for a viewer. Models that were not
// read from an FE code (3-DOF, chain, matrices from files) carry none.
#pragma once

#include <petscsys.h>

#include <array>
#include <map>
#include <string>
#include <vector>

namespace squeal::io {

struct FeMesh {
  // Cells of one kind. `type` is the XDMF topology name ("Hexahedron", "Tetrahedron",
  // "Hexahedron_20", "Tetrahedron_10", "Wedge", "Quadrilateral", "Triangle"); `conn` holds
  // nodes_per_cell mesh-node indices (0-based, into node_ids/x) per cell, in XDMF's node order.
  struct Block {
    std::string       type;
    int               nodes_per_cell = 0;
    std::vector<long> conn;
  };

  std::vector<long>                  node_ids; // the FE code's node numbers, index = mesh node
  std::vector<std::array<double, 3>> x;        // coordinates (m)
  std::vector<Block>                 blocks;
  std::map<std::string, std::vector<long>> node_sets; // mesh-node indices, by the deck's name
  // Global DOF of the *full* (unreduced) model for each node's x, y, z translation; -1 where the
  // FE code constrained or omitted it.
  std::vector<std::array<PetscInt, 3>> dof;
  PetscInt full_size = 0; // number of DOFs of the full model
  // True when the dof map covers only some nodes (a reduced model keeps the contact nodes'
  // DOFs physical; the other nodes have -1 and no value on the mesh).
  bool partial = false;
  // A reduced model that keeps its expansion (Model::expansion): the full model's dof map, into
  // whose numbering the expanded results (/expanded in the results file) are written. Empty otherwise.
  std::vector<std::array<PetscInt, 3>> dof_full;
};

} // namespace squeal::io
