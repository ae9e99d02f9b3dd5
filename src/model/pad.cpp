#include "squeal/model/pad.h"
#include "squeal/core/errors.h"

#include <Eigen/Dense>

#include <array>
#include <cmath>
#include <vector>

namespace squeal {

namespace {

constexpr PetscReal kDeg = PETSC_PI / 180.0;

// Structured polar grid of the pad: node (i, j, k), i radial, j circumferential, k through the
// thickness from the friction face.
struct PadGrid {
  const PadParams &p;
  PetscInt         nr, nt, nz;
  explicit PadGrid(const PadParams &pp) : p(pp), nr(pp.n_r), nt(pp.n_t), nz(pp.n_fric + pp.n_steel) {}
  PetscInt Nodes() const { return (nr + 1) * (nt + 1) * (nz + 1); }
  PetscInt Face() const { return (nr + 1) * (nt + 1); }
  PetscInt Id(PetscInt i, PetscInt j, PetscInt k) const { return k * Face() + j * (nr + 1) + i; }
  void     Ijk(PetscInt id, PetscInt &i, PetscInt &j, PetscInt &k) const
  {
    k = id / Face();
    j = (id % Face()) / (nr + 1);
    i = id % (nr + 1);
  }
  PetscReal Z(PetscInt k) const
  {
    return k <= p.n_fric ? p.h_fric * k / p.n_fric : p.h_fric + p.h_steel * (k - p.n_fric) / p.n_steel;
  }
  Eigen::Vector3d X(PetscInt i, PetscInt j, PetscInt k) const
  {
    const PetscReal r   = p.r_in + (p.r_out - p.r_in) * i / nr;
    const PetscReal phi = (-0.5 + (PetscReal)j / nt) * p.angle * kDeg;
    return {r * std::cos(phi), r * std::sin(phi), Z(k)};
  }
};

// Local node a of a hexahedron: offsets (di, dj, dk) and reference signs (xi, eta, zeta).
constexpr int kHex[8][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}};

using Mat24 = Eigen::Matrix<PetscReal, 24, 24>;

// Stiffness (2x2x2 Gauss) and lumped mass int rho N_a dV of one hexahedron.
void HexElement(const Eigen::Matrix<PetscReal, 8, 3> &X, PetscReal E, PetscReal nu, PetscReal rho, Mat24 &Ke,
                Eigen::Matrix<PetscReal, 8, 1> &me)
{
  const PetscReal lam = E * nu / ((1 + nu) * (1 - 2 * nu)), G = E / (2 * (1 + nu));
  Eigen::Matrix<PetscReal, 6, 6> D = Eigen::Matrix<PetscReal, 6, 6>::Zero();
  for (int a = 0; a < 3; ++a) {
    for (int b = 0; b < 3; ++b) D(a, b) = lam;
    D(a, a) = lam + 2 * G;
    D(3 + a, 3 + a) = G;
  }
  const PetscReal g = 1.0 / std::sqrt(3.0);
  Ke.setZero();
  me.setZero();
  for (int q = 0; q < 8; ++q) {
    const PetscReal xi[3] = {(q & 1) ? g : -g, (q & 2) ? g : -g, (q & 4) ? g : -g};
    Eigen::Matrix<PetscReal, 8, 1> N;
    Eigen::Matrix<PetscReal, 8, 3> dN;
    for (int a = 0; a < 8; ++a) {
      PetscReal s[3], f[3];
      for (int d = 0; d < 3; ++d) {
        s[d] = kHex[a][d] ? 1.0 : -1.0;
        f[d] = 0.5 * (1 + s[d] * xi[d]);
      }
      N(a) = f[0] * f[1] * f[2];
      dN(a, 0) = 0.5 * s[0] * f[1] * f[2];
      dN(a, 1) = 0.5 * s[1] * f[0] * f[2];
      dN(a, 2) = 0.5 * s[2] * f[0] * f[1];
    }
    const Eigen::Matrix3d J    = X.transpose() * dN; // J(a, b) = dx_a / dxi_b
    const PetscReal       detJ = J.determinant();
    const Eigen::Matrix<PetscReal, 8, 3> dNx = dN * J.inverse();
    Eigen::Matrix<PetscReal, 6, 24> B = Eigen::Matrix<PetscReal, 6, 24>::Zero();
    for (int a = 0; a < 8; ++a) {
      const PetscReal dx = dNx(a, 0), dy = dNx(a, 1), dz = dNx(a, 2);
      B(0, 3 * a) = dx;
      B(1, 3 * a + 1) = dy;
      B(2, 3 * a + 2) = dz;
      B(3, 3 * a) = dy, B(3, 3 * a + 1) = dx; // gamma_xy
      B(4, 3 * a + 1) = dz, B(4, 3 * a + 2) = dy; // gamma_yz
      B(5, 3 * a) = dz, B(5, 3 * a + 2) = dx; // gamma_xz
    }
    Ke.noalias() += B.transpose() * D * B * detJ;
    me += rho * N * detJ;
  }
}

// int N_a dA over a flat quadrilateral face z = const (nodes counter-clockwise in x-y).
Eigen::Vector4d QuadWeights(const std::array<Eigen::Vector3d, 4> &X)
{
  const PetscReal g = 1.0 / std::sqrt(3.0);
  const int       s[4][2] = {{-1, -1}, {1, -1}, {1, 1}, {-1, 1}};
  Eigen::Vector4d w       = Eigen::Vector4d::Zero();
  for (int q = 0; q < 4; ++q) {
    const PetscReal xi = (q & 1) ? g : -g, eta = (q & 2) ? g : -g;
    Eigen::Matrix2d J = Eigen::Matrix2d::Zero();
    Eigen::Vector4d N;
    for (int a = 0; a < 4; ++a) {
      N(a) = 0.25 * (1 + s[a][0] * xi) * (1 + s[a][1] * eta);
      const PetscReal dxi = 0.25 * s[a][0] * (1 + s[a][1] * eta), deta = 0.25 * s[a][1] * (1 + s[a][0] * xi);
      for (int d = 0; d < 2; ++d) {
        J(d, 0) += X[a](d) * dxi;
        J(d, 1) += X[a](d) * deta;
      }
    }
    w += N * std::abs(J.determinant());
  }
  return w;
}

PetscErrorCode CheckPadParams(MPI_Comm comm, const PadParams &p)
{
  PetscFunctionBeginUser;
  PetscCheck(p.r_in > 0 && p.r_out > p.r_in, comm, kErrInput,
             "pad radii -model_r_in %g, -model_r_out %g: expected 0 < r_in < r_out", (double)p.r_in, (double)p.r_out);
  PetscCheck(p.angle > 0 && p.angle < 180, comm, kErrInput, "option -model_angle = %g: expected a sector angle in (0, 180) degrees",
             (double)p.angle);
  const struct {
    const char *name;
    PetscInt    v;
  } counts[] = {{"n_r", p.n_r}, {"n_t", p.n_t}, {"n_fric", p.n_fric}, {"n_steel", p.n_steel}};
  for (const auto &c : counts)
    PetscCheck(c.v >= 1, comm, kErrInput, "option -model_%s = %" PetscInt_FMT ": expected >= 1 element", c.name, c.v);
  for (PetscReal nu : {p.nu_fric, p.nu_steel})
    PetscCheck(nu > -1 && nu < 0.5, comm, kErrInput, "Poisson ratio %g (-model_nu_fric / -model_nu_steel): expected in (-1, 0.5)",
               (double)nu);
  PetscFunctionReturn(0);
}

} // namespace

PetscReal PadMeshVolume(const PadParams &p, bool steel)
{
  const PetscReal area = 0.5 * p.n_t * (p.r_out * p.r_out - p.r_in * p.r_in) * std::sin(p.angle * kDeg / p.n_t);
  return area * (steel ? p.h_steel : p.h_fric);
}

PetscErrorCode PadOptions(PetscOptionItems *PetscOptionsObject, PadParams &p, OptionChecks &checks)
{
  PetscFunctionBeginUser;
  SquealOptionsReal("-r_in", "Pad: inner radius of the annular sector (m)", "BuildPad", &p.r_in, Range::Positive(), checks);
  SquealOptionsReal("-r_out", "Pad: outer radius (m)", "BuildPad", &p.r_out, Range::Positive(), checks);
  SquealOptionsReal("-angle", "Pad: opening angle of the sector (degrees)", "BuildPad", &p.angle, Range::Positive(), checks);
  SquealOptionsReal("-h_fric", "Pad: friction-material thickness (m)", "BuildPad", &p.h_fric, Range::Positive(), checks);
  SquealOptionsReal("-h_steel", "Pad: steel back plate thickness (m)", "BuildPad", &p.h_steel, Range::Positive(), checks);
  PetscCall(PetscOptionsInt("-n_r", "Pad: elements in the radial direction", "BuildPad", p.n_r, &p.n_r, nullptr));
  PetscCall(PetscOptionsInt("-n_t", "Pad: elements in the circumferential direction", "BuildPad", p.n_t, &p.n_t, nullptr));
  PetscCall(PetscOptionsInt("-n_fric", "Pad: element layers in the friction material", "BuildPad", p.n_fric, &p.n_fric, nullptr));
  PetscCall(PetscOptionsInt("-n_steel", "Pad: element layers in the back plate", "BuildPad", p.n_steel, &p.n_steel, nullptr));
  SquealOptionsReal("-e_fric", "Pad: Young's modulus of the friction material (Pa)", "BuildPad", &p.E_fric, Range::Positive(), checks);
  SquealOptionsReal("-nu_fric", "Pad: Poisson ratio of the friction material", "BuildPad", &p.nu_fric, Range::Any(), checks);
  SquealOptionsReal("-rho_fric", "Pad: density of the friction material (kg/m^3)", "BuildPad", &p.rho_fric, Range::Positive(), checks);
  SquealOptionsReal("-e_steel", "Pad: Young's modulus of the back plate (Pa)", "BuildPad", &p.E_steel, Range::Positive(), checks);
  SquealOptionsReal("-nu_steel", "Pad: Poisson ratio of the back plate", "BuildPad", &p.nu_steel, Range::Any(), checks);
  SquealOptionsReal("-rho_steel", "Pad: density of the back plate (kg/m^3)", "BuildPad", &p.rho_steel, Range::Positive(), checks);
  SquealOptionsReal("-support_kn", "Pad: normal support stiffness on the back face (N/m per m^2)", "BuildPad", &p.k_n,
                    Range::NonNegative(), checks);
  SquealOptionsReal("-support_kt", "Pad: tangential (in-plane) support stiffness on the back face (N/m per m^2)", "BuildPad",
                    &p.k_t, Range::NonNegative(), checks);
  SquealOptionsReal("-rayleigh_a", "Pad: Rayleigh damping C = a M + b K, mass factor a (1/s)", "BuildPad", &p.ray_a,
                    Range::NonNegative(), checks);
  SquealOptionsReal("-rayleigh_b", "Pad: Rayleigh stiffness factor b (s)", "BuildPad", &p.ray_b, Range::NonNegative(), checks);
  SquealOptionsReal("-pressure", "Pad: preload pressure on the back face (Pa), pushing onto the disc", "BuildPad", &p.pressure,
                    Range::Any(), checks);
  SquealOptionsReal("-r_ref", "Pad: radius at which the sliding speed is -contact_v (m); <= 0: mean radius", "BuildPad", &p.r_ref,
                    Range::Any(), checks);
  PetscFunctionReturn(0);
}

PetscErrorCode BuildPad(MPI_Comm comm, const PadParams &p, Model &model)
{
  PetscFunctionBeginUser;
  PetscCall(CheckPadParams(comm, p));
  const PadGrid  grid(p);
  const PetscInt nn = grid.Nodes(), N = 3 * nn;
  PetscInt       nloc = PETSC_DECIDE, nglob = nn;
  PetscCall(PetscSplitOwnership(comm, &nloc, &nglob));
  PetscInt n0 = 0;
  PetscCallMPI(MPI_Scan(&nloc, &n0, 1, MPIU_INT, MPI_SUM, comm));
  n0 -= nloc;
  const PetscInt n1 = n0 + nloc;
  auto           owned = [&](PetscInt id) { return id >= n0 && id < n1; };

  // Exact preallocation from the grid: node (i, j, k) couples to the nodes of the <= 27 cells
  // around it.
  std::vector<PetscInt> dnz(3 * nloc), onz(3 * nloc);
  for (PetscInt id = n0; id < n1; ++id) {
    PetscInt i, j, k, d = 0, o = 0;
    grid.Ijk(id, i, j, k);
    for (PetscInt kk = PetscMax(k - 1, 0); kk <= PetscMin(k + 1, grid.nz); ++kk)
      for (PetscInt jj = PetscMax(j - 1, 0); jj <= PetscMin(j + 1, grid.nt); ++jj)
        for (PetscInt ii = PetscMax(i - 1, 0); ii <= PetscMin(i + 1, grid.nr); ++ii) (owned(grid.Id(ii, jj, kk)) ? d : o) += 3;
    for (int c = 0; c < 3; ++c) dnz[3 * (id - n0) + c] = d, onz[3 * (id - n0) + c] = o;
  }
  PetscCall(MatCreate(comm, model.K.out()));
  PetscCall(MatSetSizes(model.K, 3 * nloc, 3 * nloc, N, N));
  PetscCall(MatSetType(model.K, MATAIJ));
  PetscCall(MatSeqAIJSetPreallocation(model.K, 0, dnz.data()));
  PetscCall(MatMPIAIJSetPreallocation(model.K, 0, dnz.data(), 0, onz.data()));
  PetscCall(MatSetOption(model.K, MAT_NEW_NONZERO_ALLOCATION_ERR, PETSC_TRUE));

  std::vector<PetscReal> mass(3 * nloc, 0.0), force(3 * nloc, 0.0), spring(3 * nloc, 0.0);
  Mat24                          Ke;
  Eigen::Matrix<PetscReal, 8, 1> me;
  Eigen::Matrix<PetscReal, 8, 3> X;
  std::array<PetscInt, 8>        ids;
  std::array<PetscInt, 24>       dofs, rows;
  std::array<PetscReal, 24 * 24> vals;
  // Elements touching owned nodes: those in layers k-1 and k of every owned node's layer k.
  PetscInt kmin, kmax, tmp;
  grid.Ijk(n0, tmp, tmp, kmin);
  grid.Ijk(PetscMax(n1 - 1, n0), tmp, tmp, kmax);
  for (PetscInt k = PetscMax(kmin - 1, 0); nloc > 0 && k <= PetscMin(kmax, grid.nz - 1); ++k) {
    const bool      steel = k >= p.n_fric;
    const PetscReal E = steel ? p.E_steel : p.E_fric, nu = steel ? p.nu_steel : p.nu_fric, rho = steel ? p.rho_steel : p.rho_fric;
    for (PetscInt j = 0; j < grid.nt; ++j)
      for (PetscInt i = 0; i < grid.nr; ++i) {
        bool any = false;
        for (int a = 0; a < 8; ++a) {
          ids[a] = grid.Id(i + kHex[a][0], j + kHex[a][1], k + kHex[a][2]);
          X.row(a) = grid.X(i + kHex[a][0], j + kHex[a][1], k + kHex[a][2]).transpose();
          any = any || owned(ids[a]);
        }
        if (!any) continue;
        HexElement(X, E, nu, rho, Ke, me);
        PetscInt nrows = 0;
        for (int a = 0; a < 8; ++a)
          for (int c = 0; c < 3; ++c) {
            dofs[3 * a + c] = 3 * ids[a] + c;
            if (owned(ids[a])) {
              mass[3 * (ids[a] - n0) + c] += me(a);
              rows[nrows] = 3 * a + c;
              for (int b = 0; b < 24; ++b) vals[nrows * 24 + b] = Ke(3 * a + c, b);
              ++nrows;
            }
          }
        std::array<PetscInt, 24> grow;
        for (PetscInt r = 0; r < nrows; ++r) grow[r] = dofs[rows[r]];
        PetscCall(MatSetValues(model.K, nrows, grow.data(), 24, dofs.data(), vals.data(), ADD_VALUES));
      }
  }
  // Back face: consistent pressure load and lumped support springs.
  const PetscInt ktop = grid.nz;
  for (PetscInt j = 0; j < grid.nt; ++j)
    for (PetscInt i = 0; i < grid.nr; ++i) {
      const PetscInt q[4][2] = {{i, j}, {i + 1, j}, {i + 1, j + 1}, {i, j + 1}};
      std::array<Eigen::Vector3d, 4> Xq;
      bool                           any = false;
      for (int a = 0; a < 4; ++a) {
        Xq[a] = grid.X(q[a][0], q[a][1], ktop);
        any   = any || owned(grid.Id(q[a][0], q[a][1], ktop));
      }
      if (!any) continue;
      const Eigen::Vector4d w = QuadWeights(Xq);
      for (int a = 0; a < 4; ++a) {
        const PetscInt id = grid.Id(q[a][0], q[a][1], ktop);
        if (!owned(id)) continue;
        const PetscInt l = 3 * (id - n0);
        force[l + 2] -= p.pressure * w(a);
        spring[l + 0] += p.k_t * w(a);
        spring[l + 1] += p.k_t * w(a);
        spring[l + 2] += p.k_n * w(a);
      }
    }
  for (PetscInt l = 0; l < 3 * nloc; ++l)
    if (spring[l] != 0) PetscCall(MatSetValue(model.K, 3 * n0 + l, 3 * n0 + l, spring[l], ADD_VALUES));
  PetscCall(MatAssemblyBegin(model.K, MAT_FINAL_ASSEMBLY));
  PetscCall(MatAssemblyEnd(model.K, MAT_FINAL_ASSEMBLY));

  // Lumped mass: a diagonal AIJ matrix with K's layout.
  VecH m;
  PetscCall(MatCreateVecs(model.K, nullptr, m.out()));
  PetscCall(MatCreateVecs(model.K, nullptr, model.F.out()));
  {
    PetscScalar *a, *f;
    PetscCall(VecGetArray(m, &a));
    PetscCall(VecGetArray(model.F, &f));
    for (PetscInt l = 0; l < 3 * nloc; ++l) a[l] = mass[l], f[l] = force[l];
    PetscCall(VecRestoreArray(m, &a));
    PetscCall(VecRestoreArray(model.F, &f));
  }
  PetscCall(MatCreateAIJ(comm, 3 * nloc, 3 * nloc, N, N, 1, nullptr, 0, nullptr, model.M.out()));
  PetscCall(MatDiagonalSet(model.M, m, INSERT_VALUES));
  if (p.ray_a > 0 || p.ray_b > 0) {
    PetscCall(MatDuplicate(model.K, MAT_COPY_VALUES, model.C.out()));
    PetscCall(MatScale(model.C, p.ray_b));
    PetscCall(VecScale(m, p.ray_a));
    PetscCall(MatDiagonalSet(model.C, m, ADD_VALUES));
  } else model.C.reset();

  // Contact points: the friction-face nodes, replicated on every rank.
  const PetscReal r_ref = p.r_ref > 0 ? p.r_ref : 0.5 * (p.r_in + p.r_out);
  model.contacts.points.clear();
  model.contacts.points.reserve(grid.Face());
  for (PetscInt j = 0; j <= grid.nt; ++j)
    for (PetscInt i = 0; i <= grid.nr; ++i) {
      const Eigen::Vector3d x  = grid.X(i, j, 0);
      const PetscReal       r  = std::hypot(x(0), x(1));
      const PetscInt        id = grid.Id(i, j, 0);
      ContactPoint          pt;
      pt.nodes        = {ContactNode{{3 * id, 3 * id + 1, 3 * id + 2}, 1.0}};
      pt.t            = Eigen::Vector3d(-x(1), x(0), 0) / r;
      pt.n            = Eigen::Vector3d(0, 0, 1);
      pt.speed_factor = r / r_ref;
      model.contacts.points.push_back(pt);
    }
  model.contacts.law = p.law;
  model.contacts.SetFriction(p.mu, p.V);
  char name[128];
  PetscCall(PetscSNPrintf(name, sizeof(name), "pad %" PetscInt_FMT "x%" PetscInt_FMT "x(%" PetscInt_FMT "+%" PetscInt_FMT ")",
                          p.n_r, p.n_t, p.n_fric, p.n_steel));
  model.name = name;
  PetscCall(model.Validate());
  PetscFunctionReturn(0);
}

} // namespace squeal
