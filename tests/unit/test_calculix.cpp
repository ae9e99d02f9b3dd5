// Models from CalculiX: the matrices ccx writes (*FREQUENCY, SOLVER=MATRIXSTORAGE) against ccx's
// own eigenfrequencies of the same deck, and contact pairs from the geometry against the closed
// forms of the frame (t = e x r, n the face normal) and of the interpolation.
// tests/data/calculix/tb.* were written by ccx 2.20 from two_blocks.py (plate + pad on springs);
// tb_frequencies.txt holds ccx's 10 lowest frequencies of the same deck.
#include "dense.h"
#include "squeal/io/calculix.h"
#include "squeal/model/builders.h"
#include "squeal/model/fe_contact.h"
#include "squeal/reduction/craig_bampton.h"

#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>

#include <cmath>
#include <cstdio>
#include <functional>
#include <fstream>
#include <sstream>
#include <string>

#include <unistd.h>

using namespace squeal;

namespace {

const std::string kData = std::string(SQUEAL_SOURCE_DIR) + "/tests/data/calculix/";

CalculixModelSpec TwoBlocks()
{
  CalculixModelSpec s;
  s.job                  = kData + "tb";
  s.pressure             = 1e5;
  s.pairing.axis         = Eigen::Vector3d(0, 0, 1);
  s.pairing.axis_point   = Eigen::Vector3d(-0.3, 0.02, 0);
  s.mu                   = 0.4;
  s.V                    = 5;
  return s;
}

// The two blocks with C = a M + b K + b_pad K_pad (the pad's own job, tb_pad).
CalculixModelSpec DampedPad(PetscReal a, PetscReal b, PetscReal b_pad)
{
  CalculixModelSpec s = TwoBlocks();
  s.ray_a             = a;
  s.ray_b             = b;
  s.part_jobs         = {"tb_pad"};
  s.part_b            = {b_pad};
  return s;
}

// A plate (x in [0, 0.12], z in [-0.004, 0]) and a block above it (x in [x0, x0 + 0.04],
// z in [0, 0.01]), both 0.04 wide in y, built directly as an FeMesh with every DOF free.
// cells_x: the block's cells along x; the plate has 6 (0.02 m each), 2 across y for both.
io::FeMesh TwoBlockMesh(double x0, int cells_x)
{
  io::FeMesh m;
  auto       grid = [&](double xa, double xb, int nx, double za, double zb, const char *face, bool face_top, const char *body) {
    std::vector<long> ids((nx + 1) * 3 * 2);
    for (int k = 0; k <= 1; ++k)
      for (int j = 0; j <= 2; ++j)
        for (int i = 0; i <= nx; ++i) {
          const long id = (long)m.x.size();
          ids[i + (nx + 1) * (j + 3 * k)] = id;
          m.x.push_back({xa + (xb - xa) * i / nx, 0.02 * j, za + (zb - za) * k});
          m.node_ids.push_back(id + 1);
          if (k == (face_top ? 1 : 0)) m.node_sets[face].push_back(id);
          m.node_sets[body].push_back(id);
        }
    if (m.blocks.empty()) m.blocks.push_back({"Hexahedron", 8, {}});
    for (int j = 0; j < 2; ++j)
      for (int i = 0; i < nx; ++i) {
        auto at = [&](int a, int b, int c) { return ids[a + (nx + 1) * (b + 3 * c)]; };
        for (long n : {at(i, j, 0), at(i + 1, j, 0), at(i + 1, j + 1, 0), at(i, j + 1, 0), at(i, j, 1), at(i + 1, j, 1),
                       at(i + 1, j + 1, 1), at(i, j + 1, 1)})
          m.blocks[0].conn.push_back(n);
      }
  };
  grid(0.0, 0.12, 6, -0.004, 0.0, "DISC_FACE", true, "DISC");
  grid(x0, x0 + 0.04, cells_x, 0.0, 0.01, "PAD_FACE", false, "PAD");
  for (size_t n = 0; n < m.x.size(); ++n) m.dof.push_back({(PetscInt)(3 * n), (PetscInt)(3 * n + 1), (PetscInt)(3 * n + 2)});
  m.full_size = (PetscInt)(3 * m.x.size());
  return m;
}

FacePairing Pairing()
{
  FacePairing f;
  f.axis       = Eigen::Vector3d(0, 0, 1);
  f.axis_point = Eigen::Vector3d(-0.3, 0.02, 0);
  return f;
}

Eigen::Vector3d NodeX(const io::FeMesh &m, PetscInt dof)
{
  for (size_t n = 0; n < m.dof.size(); ++n)
    if (m.dof[n][0] == dof) return Eigen::Vector3d(m.x[n][0], m.x[n][1], m.x[n][2]);
  return Eigen::Vector3d::Constant(NAN);
}

PetscErrorCode Quiet(const std::function<PetscErrorCode()> &f)
{
  PetscCallAbort(PETSC_COMM_WORLD, PetscPushErrorHandler(PetscReturnErrorHandler, nullptr));
  const PetscErrorCode ierr = f();
  PetscCallAbort(PETSC_COMM_WORLD, PetscPopErrorHandler());
  return ierr;
}

} // namespace

TEST(Calculix, ImportedMatricesGiveCalculixsOwnFrequencies)
{
  Model model;
  ASSERT_EQ(BuildCalculix(PETSC_COMM_WORLD, TwoBlocks(), model), 0);
  ASSERT_TRUE(model.mesh);
  EXPECT_EQ(model.mesh->x.size(), 69u);
  EXPECT_EQ(model.Size(), 171);       // 69 nodes x 3, less 9 clamped plate nodes x 3 and 9 x 2 back-face DOFs
  EXPECT_EQ(model.mesh->full_size, 171);
  ASSERT_EQ(model.mesh->blocks.size(), 1u);
  EXPECT_EQ(model.mesh->blocks[0].conn.size(), 20u * 8); // 12 plate + 8 pad hexahedra; springs not drawn
  EXPECT_EQ(model.mesh->node_sets.at("DISC_CLAMP").size(), 6u);

  const Eigen::MatrixXd K = test::ToDense(model.K), M = test::ToDense(model.M);
  EXPECT_LT((K - K.transpose()).norm(), 1e-12 * K.norm()); // one triangle in the file, both in the Mat
  Eigen::GeneralizedSelfAdjointEigenSolver<Eigen::MatrixXd> ges(K, M);
  ASSERT_EQ(ges.info(), Eigen::Success);
  std::ifstream in(kData + "tb_frequencies.txt");
  std::string   line;
  int           checked = 0;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream ss(line);
    int                mode;
    double             lambda, f;
    ss >> mode >> lambda >> f;
    const double mine = std::sqrt(ges.eigenvalues()(mode - 1)) / (2 * M_PI);
    EXPECT_NEAR(mine / f, 1.0, 2e-6) << "mode " << mode; // ccx prints 7 digits
    ++checked;
  }
  EXPECT_EQ(checked, 10);

  // Preload: 1e5 Pa on the 0.04 x 0.04 m back face, along -z only.
  PetscScalar sum;
  ASSERT_EQ(VecSum(model.F, &sum), 0);
  EXPECT_NEAR(PetscRealPart(sum), -160.0, 1e-9);
}

TEST(Calculix, ConformingFacesPairNodeToNodeWithTheDiscsFrame)
{
  Model model;
  ASSERT_EQ(BuildCalculix(PETSC_COMM_WORLD, TwoBlocks(), model), 0);
  const ContactSet &cs = model.contacts;
  ASSERT_EQ(cs.Size(), 9);
  const Eigen::Vector3d e(0, 0, 1), a(-0.3, 0.02, 0);
  double                r_mean = 0;
  for (const ContactPoint &p : cs.points) r_mean += e.cross(NodeX(*model.mesh, p.nodes[0].dofs[0]) - a).norm();
  r_mean /= 9;
  for (const ContactPoint &p : cs.points) {
    ASSERT_EQ(p.nodes.size(), 2u);
    EXPECT_EQ(p.nodes[0].weight, 1.0);  // pad
    EXPECT_EQ(p.nodes[1].weight, -1.0); // disc
    const Eigen::Vector3d xp = NodeX(*model.mesh, p.nodes[0].dofs[0]), xd = NodeX(*model.mesh, p.nodes[1].dofs[0]);
    EXPECT_LT((xp - xd).norm(), 1e-15);
    EXPECT_LT((p.n - e).norm(), 1e-14); // the plate's top face, pointing at the pad
    const Eigen::Vector3d v = e.cross(xd - a);
    EXPECT_LT((p.t - v.normalized()).norm(), 1e-14);
    EXPECT_NEAR(p.speed_factor, v.norm() / r_mean, 1e-14);
    EXPECT_EQ(p.g0, 0.0);
  }
}

TEST(Calculix, NonConformingWeightsInterpolateThePadNodeExactly)
{
  const io::FeMesh   m     = TwoBlockMesh(0.065, 1); // pad nodes at x = 0.065 and 0.105: inside plate facets
  const auto         disc  = SetFacets(m, m.node_sets.at("DISC_FACE"));
  EXPECT_EQ(disc.size(), 12u); // the plate's top: 6 x 2 cells' faces
  for (const Facet &f : disc) EXPECT_LT((f.normal - Eigen::Vector3d(0, 0, 1)).norm(), 1e-14);

  ContactSet    cs;
  PairingReport rep;
  ASSERT_EQ(PairContactFaces(PETSC_COMM_WORLD, m, Pairing(), cs, &rep), 0);
  EXPECT_EQ(rep.node_pairs, 0);
  EXPECT_EQ(rep.surface_pairs, 6);
  for (const ContactPoint &p : cs.points) {
    const Eigen::Vector3d xp = NodeX(m, p.nodes[0].dofs[0]);
    Eigen::Vector3d       y  = Eigen::Vector3d::Zero();
    double                w  = 0;
    for (size_t k = 1; k < p.nodes.size(); ++k) {
      y -= p.nodes[k].weight * NodeX(m, p.nodes[k].dofs[0]);
      w -= p.nodes[k].weight;
    }
    EXPECT_NEAR(w, 1.0, 1e-14);
    EXPECT_LT((y - xp).norm(), 1e-15); // the disc point under the pad node is the pad node itself
  }
  // A facet's weights reproduce any point of it, and only inside it.
  std::vector<PetscReal> wts;
  PetscReal              dist;
  const Eigen::Vector3d  x(0.0137, 0.0071, 0.002);
  const Facet           *f = nullptr;
  for (const Facet &g : disc)
    if (FacetWeights(m, g, x, 1e-12, wts, &dist)) f = &g;
  ASSERT_NE(f, nullptr);
  ASSERT_TRUE(FacetWeights(m, *f, x, 1e-12, wts, &dist));
  Eigen::Vector3d y = Eigen::Vector3d::Zero();
  for (size_t k = 0; k < wts.size(); ++k) y += wts[k] * NodeX(m, m.dof[f->corners[k]][0]);
  EXPECT_LT((y - Eigen::Vector3d(0.0137, 0.0071, 0)).norm(), 1e-15);
  EXPECT_NEAR(dist, 0.002, 1e-15);
}

TEST(Calculix, BadGeometryAndFilesAreRefusedByName)
{
  ContactSet cs;
  {
    // Two pad nodes per plate node row in x: their facets share plate nodes.
    const io::FeMesh m = TwoBlockMesh(0.065, 2);
    EXPECT_NE(Quiet([&] { return PairContactFaces(PETSC_COMM_WORLD, m, Pairing(), cs); }), 0);
    FacePairing node = Pairing();
    node.mode        = FacePairing::Mode::Node; // no plate node within 1e-6 m
    EXPECT_NE(Quiet([&] { return PairContactFaces(PETSC_COMM_WORLD, m, node, cs); }), 0);
  }
  {
    const io::FeMesh m = TwoBlockMesh(0.06, 2);
    FacePairing      same = Pairing();
    same.pad_set          = "DISC_FACE";
    EXPECT_NE(Quiet([&] { return PairContactFaces(PETSC_COMM_WORLD, m, same, cs); }), 0); // one body
    FacePairing      missing = Pairing();
    missing.disc_set         = "NO_SUCH_SET";
    EXPECT_NE(Quiet([&] { return PairContactFaces(PETSC_COMM_WORLD, m, missing, cs); }), 0);
    FacePairing axis = Pairing();
    axis.axis        = Eigen::Vector3d(1, 0, 0); // the disc would move along its normal at x = 0.06 ... and elsewhere
    axis.axis_point  = Eigen::Vector3d(0, 0.02, 0);
    EXPECT_NE(Quiet([&] { return PairContactFaces(PETSC_COMM_WORLD, m, axis, cs); }), 0);
    ASSERT_EQ(PairContactFaces(PETSC_COMM_WORLD, m, Pairing(), cs), 0); // the same mesh, well described
    EXPECT_EQ(cs.Size(), 9);
  }
  {
    // The plate's bottom face as the "disc face": its normal points away from the pad.
    io::FeMesh m = TwoBlockMesh(0.06, 2);
    std::vector<long> bottom;
    for (long n : m.node_sets.at("DISC"))
      if (m.x[n][2] < -0.003) bottom.push_back(n);
    m.node_sets["BOTTOM"] = bottom;
    FacePairing f         = Pairing();
    f.disc_set            = "BOTTOM";
    f.tol                 = 0.01;
    EXPECT_NE(Quiet([&] { return PairContactFaces(PETSC_COMM_WORLD, m, f, cs); }), 0);
  }
  {
    // A constrained pad node.
    io::FeMesh m                        = TwoBlockMesh(0.06, 2);
    m.dof[m.node_sets.at("PAD_FACE")[0]] = {-1, -1, -1};
    EXPECT_NE(Quiet([&] { return PairContactFaces(PETSC_COMM_WORLD, m, Pairing(), cs); }), 0);
  }
  // Files: a missing job, and a matrix file that is not CalculiX's (a Matrix Market header).
  {
    Model             model;
    CalculixModelSpec s = TwoBlocks();
    s.job               = kData + "no_such_job";
    EXPECT_NE(Quiet([&] { return BuildCalculix(PETSC_COMM_WORLD, s, model); }), 0);
    Mat A = nullptr;
    EXPECT_NE(Quiet([&] {
                return io::MatLoadCalculix(PETSC_COMM_WORLD, (std::string(SQUEAL_SOURCE_DIR) + "/tests/data/calculix/tb.inp").c_str(),
                                           171, &A);
              }),
              0);
    EXPECT_EQ(A, nullptr);
  }
}

// Damping of parts: the plate's and the pad's own jobs (tb_disc, tb_pad: their cells alone, no
// springs, no boundary, each with its own .dof) mapped by node and direction onto the model.
// Their stiffnesses sum to the model's less its springs, so with both factors 1, K - C is the
// springs alone: 2e6 N/m on the z DOF of each of the pad's 9 back-face nodes, zero elsewhere.
TEST(Calculix, DampedPartsMapOntoTheModelByNodeAndDirection)
{
  Model             model;
  CalculixModelSpec s = TwoBlocks();
  s.part_jobs         = {"tb_disc", "tb_pad"}; // relative: in the folder of the model's job
  s.part_b            = {1.0, 1.0};
  ASSERT_EQ(BuildCalculix(PETSC_COMM_WORLD, s, model), 0);
  ASSERT_TRUE(model.C);
  const Eigen::MatrixXd K = test::ToDense(model.K), C = test::ToDense(model.C);
  const Eigen::MatrixXd D = K - C;
  std::vector<PetscInt> springs;
  for (long n : model.mesh->node_sets.at("PAD_BACK")) springs.push_back(model.mesh->dof[n][2]);
  ASSERT_EQ(springs.size(), 9u);
  Eigen::MatrixXd S = Eigen::MatrixXd::Zero(K.rows(), K.cols());
  for (PetscInt r : springs) {
    ASSERT_GE(r, 0);
    S(r, r) = 2.0e6;
  }
  EXPECT_LT((D - S).cwiseAbs().maxCoeff(), 1e-12 * K.cwiseAbs().maxCoeff());

  // The pad alone with its own factor, and Rayleigh on top: C = a M + b K + b_pad K_pad, whose
  // pad part vanishes on the rows of the plate's nodes.
  Model m2;
  ASSERT_EQ(BuildCalculix(PETSC_COMM_WORLD, DampedPad(3.0, 1e-6, 2e-5), m2), 0);
  Model             m3;
  CalculixModelSpec s3 = TwoBlocks();
  s3.part_jobs         = {"tb_pad"};
  s3.part_b            = {1.0};
  ASSERT_EQ(BuildCalculix(PETSC_COMM_WORLD, s3, m3), 0);
  const Eigen::MatrixXd Kp = test::ToDense(m3.C), M = test::ToDense(model.M);
  EXPECT_LT((test::ToDense(m2.C) - (3.0 * M + 1e-6 * K + 2e-5 * Kp)).cwiseAbs().maxCoeff(), 1e-12 * (1e-6 * K.cwiseAbs().maxCoeff()));
  for (size_t n = 0; n < model.mesh->node_ids.size(); ++n) {
    if (model.mesh->node_ids[n] > 1000) continue; // the pad's nodes are numbered from 1001
    for (PetscInt r : model.mesh->dof[n]) {
      if (r < 0) continue;
      EXPECT_EQ(Kp.row(r).cwiseAbs().maxCoeff(), 0.0) << "plate row " << r;
    }
  }
  EXPECT_GT(Kp.cwiseAbs().maxCoeff(), 1e6);
}

TEST(Calculix, DampedPartsRefusedByName)
{
  auto build = [](std::vector<std::string> jobs, std::vector<PetscReal> b) {
    Model             model;
    CalculixModelSpec s = TwoBlocks();
    s.part_jobs         = std::move(jobs);
    s.part_b            = std::move(b);
    return Quiet([&] { return BuildCalculix(PETSC_COMM_WORLD, s, model); });
  };
  EXPECT_NE(build({"tb_pad"}, {}), 0);                 // no factor
  EXPECT_NE(build({"tb_pad"}, {-1.0}), 0);             // negative
  EXPECT_NE(build({"tb_pad"}, {NAN}), 0);              // NaN
  EXPECT_NE(build({"no_such_part"}, {1.0}), 0);        // missing files
  EXPECT_EQ(build({kData + "tb_pad"}, {1.0}), 0);      // an absolute path is taken as it is
  // A part of another model: a node the deck does not have.
  // Rank 0 writes the files, named after its process (test runs go on side by side); every rank
  // reads them.
  PetscMPIInt rank;
  MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
  long pid = (long)getpid();
  MPI_Bcast(&pid, 1, MPI_LONG, 0, PETSC_COMM_WORLD);
  const std::string stem = ::testing::TempDir() + "squeal_bad_part_" + std::to_string(pid);
  auto write = [&](const char *dof) {
    if (rank == 0) {
      std::ofstream(stem + ".dof") << dof;
      std::ofstream(stem + ".sti") << "1 1 1.0\n1 2 0.5\n2 2 1.0\n";
    }
    MPI_Barrier(PETSC_COMM_WORLD);
  };
  write("1001.1\n99999.3\n");
  EXPECT_NE(build({stem}, {1.0}), 0);
  MPI_Barrier(PETSC_COMM_WORLD); // read by every rank before rank 0 rewrites it
  write("1001.1\n1001.2\n");
  EXPECT_EQ(build({stem}, {1.0}), 0); // the same files with nodes of the deck
  MPI_Barrier(PETSC_COMM_WORLD);
  if (rank == 0) std::remove((stem + ".dof").c_str()), std::remove((stem + ".sti").c_str());
}

// Craig-Bampton of a model with a part damped on its own: C = a M + b K + b_p K_pad. The
// reduction projects K_pad alone (on the rows it touches) and adds a M_r + b K_r; the general
// path projects the whole C. The two reduced models have the same invariants of a change of basis
// (on 2 ranks two reductions may rotate a degenerate pair of modes), to 1e-10.
TEST(Calculix, DampedPartsProjectedAloneByCraigBampton)
{
  Model                   full;
  const CalculixModelSpec s = DampedPad(20.0, 1e-7, 4e-6);
  ASSERT_EQ(BuildCalculix(PETSC_COMM_WORLD, s, full), 0);
  ASSERT_GE(full.damping_a, 0.0);
  auto reduce = [&](bool shortcut, Model &red, ReductionInfo &info) {
    CraigBampton cb(full.comm());
    ASSERT_EQ(cb.SetFMax(3e5), 0);
    ASSERT_EQ(cb.SetRayleighShortcut(shortcut), 0);
    ASSERT_EQ(cb.Reduce(full, red), 0);
    info = cb.Info();
  };
  // Invariants of a change of basis T (M' = T^T M T, ...: M'^-1 C' = T^-1 M^-1 C T): traces of
  // products of M^-1 C and M^-1 K.
  auto invariants = [](const Model &m) {
    const Eigen::MatrixXd M = test::ToDense(m.M), C = test::ToDense(m.C), K = test::ToDense(m.K);
    const Eigen::MatrixXd A = M.ldlt().solve(C), B = M.ldlt().solve(K);
    return Eigen::Vector3d(A.trace(), (A * A).trace(), (A * B).trace());
  };
  Model         split, general;
  ReductionInfo is, ig;
  reduce(true, split, is);
  reduce(false, general, ig);
  EXPECT_TRUE(is.damping_split);
  EXPECT_FALSE(is.rayleigh);
  EXPECT_FALSE(ig.damping_split);
  ASSERT_GT(is.n_modes, 0);
  const Eigen::Vector3d a = invariants(split), b = invariants(general);
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(a(k) / b(k), 1.0, 1e-10) << "invariant " << k;
  // The lining's damping is felt: tr(M_r^-1 C_r) is larger than Rayleigh's alone.
  Model             rayleigh;
  CalculixModelSpec r = s;
  r.part_jobs.clear(), r.part_b.clear();
  ASSERT_EQ(BuildCalculix(PETSC_COMM_WORLD, r, rayleigh), 0);
  Model         rr;
  ReductionInfo ir;
  {
    CraigBampton cb(rayleigh.comm());
    ASSERT_EQ(cb.SetFMax(3e5), 0);
    ASSERT_EQ(cb.Reduce(rayleigh, rr), 0);
    ir = cb.Info();
  }
  EXPECT_TRUE(ir.rayleigh);
  EXPECT_GT(a(0), 1.5 * invariants(rr)(0));
}
