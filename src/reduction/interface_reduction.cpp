// Interface reduction of a Craig-Bampton model: one relative normal coordinate per contact point
// stays physical, the rest of the interface is replaced by the lowest characteristic constraint
// modes (include/squeal/reduction/craig_bampton.h; src/reduction/internal.h).
#include "internal.h"

#include "squeal/core/errors.h"
#include "squeal/core/options.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

namespace squeal::cb {

namespace {

// Point c's share of the interface: its 3 q_c DOFs (q_c nodes) at offset `at` of the contact
// order. With h_n = w_0 a (w_0 the first node's weight), the coordinate x_c = a^T u is the normal
// gap's increment over w_0: for one node (a = n) the normal displacement, for a pad node against a
// disc node (weights +1, -1: a = [n; -n]) their relative normal displacement. u = q0 x_c + Z s with
// q0 = a / |a|^2 and Z an orthonormal basis of a's complement (3 q_c - 1 columns; [t b] for one
// node, as the frame gives it).
struct PointBasis {
  PetscInt        at = 0, q = 0;
  Eigen::VectorXd q0;
  Dense           Z;
};

PointBasis MakePointBasis(const ContactPoint &p, PetscInt at)
{
  PointBasis pb;
  pb.at = at, pb.q = (PetscInt)p.nodes.size();
  const PetscInt  d  = 3 * pb.q;
  const PetscReal w0 = p.nodes[0].weight;
  Eigen::VectorXd a(d);
  for (PetscInt j = 0; j < pb.q; ++j) a.segment<3>(3 * j) = (p.nodes[j].weight / w0) * p.n;
  pb.q0 = a / a.squaredNorm();
  if (pb.q == 1) {
    pb.Z.resize(3, 2);
    pb.Z << p.t, p.b;
  } else {
    Eigen::HouseholderQR<Dense> qr(a);
    pb.Z = (qr.householderQ() * Dense::Identity(d, d)).rightCols(d - 1);
  }
  return pb;
}

// The characteristic constraint modes: with every x_c and every fixed-interface mode held at 0, the
// interface block in the coordinates s, K_ss(c, d) = Z_c^T K_r(c, d) Z_d (M_ss alike), gives
// K_ss Psi = M_ss Psi Lambda, Psi^T M_ss Psi = I; lam receives all its eigenvalues (ascending), so
// the caller chooses k. For one-node points s holds the in-plane DOFs (t, b).
PetscErrorCode ConstraintModesOfTheInterface(MPI_Comm comm, const std::vector<PointBasis> &pts, const std::vector<PetscInt> &sat,
                                             PetscInt ns, const Dense &Mp, const Dense &Kp, Dense &Kss, Dense &Mss, Dense &Psi,
                                             std::vector<PetscReal> &lam)
{
  const size_t nc = pts.size();
  PetscFunctionBeginUser;
  Kss.resize(ns, ns), Mss.resize(ns, ns);
  for (size_t c = 0; c < nc; ++c) {
    const PointBasis &pc = pts[c];
    for (size_t d = 0; d < nc; ++d) {
      const PointBasis &pd = pts[d];
      const PetscInt    rc = 3 * pc.q, rd = 3 * pd.q;
      Kss.block(sat[c], sat[d], rc - 1, rd - 1).noalias() = pc.Z.transpose() * Kp.block(pc.at, pd.at, rc, rd) * pd.Z;
      Mss.block(sat[c], sat[d], rc - 1, rd - 1).noalias() = pc.Z.transpose() * Mp.block(pc.at, pd.at, rc, rd) * pd.Z;
    }
  }
  Eigen::GeneralizedSelfAdjointEigenSolver<Dense> ges;
  Kss = 0.5 * (Kss + Kss.transpose()), Mss = 0.5 * (Mss + Mss.transpose());
  PetscCallCXX(ges.compute(Kss, Mss));
  PetscCheck(ges.info() == Eigen::Success, comm, kErrInput,
             "interface reduction: the interface block's eigenproblem failed (its mass block not positive definite?)");
  Psi = ges.eigenvectors(); // M_ss-normalised, ascending eigenvalues
  lam.assign(ges.eigenvalues().data(), ges.eigenvalues().data() + ns);
  PetscFunctionReturn(0);
}

// The static response of the interface to each x_c (the other x and the fixed-interface modes
// held): s = S x, S = -K_ss^{-1} K_sx. Added to the k modes kept, so that an opening point takes the
// condensed shape q0_c + Z S e_c rather than the spike q0_c of its own nodes: the basis becomes the
// Rayleigh-Ritz vectors of (K_ss, M_ss) on span[Psi_k, S] (M_ss-orthonormal, ascending lam).
PetscErrorCode AddStatics(MPI_Comm comm, const std::vector<PointBasis> &pts, const std::vector<PetscInt> &sat, const Dense &Kp,
                          const Dense &Kss, const Dense &Mss, Dense &Psi, std::vector<PetscReal> &lam)
{
  const PetscInt nc = (PetscInt)pts.size(), ns = (PetscInt)Kss.rows();
  PetscFunctionBeginUser;
  Dense Ksx(ns, nc);
  for (PetscInt c = 0; c < nc; ++c)
    for (PetscInt d = 0; d < nc; ++d) {
      const PointBasis &pc = pts[c], &pd = pts[d];
      Ksx.block(sat[c], d, 3 * pc.q - 1, 1).noalias() = pc.Z.transpose() * Kp.block(pc.at, pd.at, 3 * pc.q, 3 * pd.q) * pd.q0;
    }
  Eigen::LDLT<Dense> ldlt(Kss);
  PetscCheck(ldlt.info() == Eigen::Success && ldlt.isPositive(), comm, kErrInput,
             "interface reduction: the interface block with the contact normals held is not positive definite");
  Dense S = -ldlt.solve(Ksx);
  S -= Psi * (Psi.transpose() * (Mss * S)); // M_ss-orthogonal to the modes kept
  S -= Psi * (Psi.transpose() * (Mss * S));
  Eigen::SelfAdjointEigenSolver<Dense> g(S.transpose() * Mss * S);
  const PetscReal                      gmax = g.eigenvalues().maxCoeff();
  std::vector<PetscInt>                keep;
  for (PetscInt j = 0; j < nc; ++j)
    if (g.eigenvalues()(j) > 1e-10 * gmax) keep.push_back(j);
  Dense B(ns, Psi.cols() + (Eigen::Index)keep.size());
  B.leftCols(Psi.cols()) = Psi;
  for (size_t j = 0; j < keep.size(); ++j)
    B.col(Psi.cols() + j) = S * g.eigenvectors().col(keep[j]) / std::sqrt(g.eigenvalues()(keep[j]));
  Eigen::SelfAdjointEigenSolver<Dense> rr(B.transpose() * Kss * B);
  Psi = B * rr.eigenvectors();
  lam.assign(rr.eigenvalues().data(), rr.eigenvalues().data() + rr.eigenvalues().size());
  PetscFunctionReturn(0);
}

} // namespace

PetscErrorCode InterfaceReduction(MPI_Comm comm, const ContactSet &full, const Dense &Mp, const Dense &Kp, PetscInt k_max,
                                  PetscReal fmax, PetscInt statics, const char *prefix, PetscInt m, Dense &T, ContactSet &contacts,
                                  ReductionInfo &info)
{
  const PetscInt    nc  = full.Size();
  const std::string pre = OptionName(prefix, "");
  PetscFunctionBeginUser;
  std::vector<PointBasis> pts;
  std::vector<PetscInt>   sat; // point c's first coordinate in s
  PetscInt                nB = 0, ns = 0;
  bool                    single = true;
  for (PetscInt c = 0; c < nc; ++c) {
    const ContactPoint &p = full.points[c];
    PetscCheck(!p.nodes.empty() && p.nodes[0].weight != 0, comm, kErrInput,
               "interface reduction: contact %" PetscInt_FMT " has no node of non-zero weight", c);
    pts.push_back(MakePointBasis(p, nB));
    sat.push_back(ns);
    nB += 3 * pts.back().q, ns += 3 * pts.back().q - 1;
    single = single && pts.back().q == 1;
  }
  const PetscInt n2 = nB + m;
  PetscCheck(n2 == (PetscInt)Kp.rows(), comm, PETSC_ERR_PLIB, "interface reduction: %" PetscInt_FMT " interface DOFs + %" PetscInt_FMT " modes against a %" PetscInt_FMT "-row matrix",
             nB, m, (PetscInt)Kp.rows());
  char what[96]; // what the modes replace
  if (single) PetscCall(PetscSNPrintf(what, sizeof what, "in-plane interface DOFs (2 x %" PetscInt_FMT " contact points)", nc));
  else PetscCall(PetscSNPrintf(what, sizeof what, "interface DOFs besides the %" PetscInt_FMT " contact normals", nc));
  PetscCheck(k_max <= ns, comm, kErrInput, "%sinterface_modes %" PetscInt_FMT " exceeds the %" PetscInt_FMT " %s: give at most %" PetscInt_FMT,
             pre.c_str(), k_max, ns, what, ns);
  Dense                  Psi, Kss, Mss;
  std::vector<PetscReal> lam;
  PetscCall(ConstraintModesOfTheInterface(comm, pts, sat, ns, Mp, Kp, Kss, Mss, Psi, lam));
  PetscInt k = ns;
  if (fmax > 0) {
    const PetscReal w2 = std::pow(2 * PETSC_PI * fmax, 2);
    k = (PetscInt)(std::upper_bound(lam.begin(), lam.end(), w2) - lam.begin());
    PetscCheck(k > 0, comm, kErrInput,
               "%sinterface_fmax %g Hz keeps no interface constraint mode (the lowest is at %g Hz): raise it", pre.c_str(),
               (double)fmax, std::sqrt(std::max(lam[0], (PetscReal)0)) / (2 * PETSC_PI));
  }
  if (k_max >= 0) k = std::min(k, k_max);
  PetscCheck(k > 0, comm, kErrInput,
             "%sinterface_modes 0 keeps no interface constraint mode: give k >= 1, or -1 (default) for no interface reduction",
             pre.c_str());
  // Statics: by default for two-body pairs only (a node on a rigid counter-surface was measured
  // without them, docs/records.md), and only while the modes do not span s already.
  const bool with_statics = (statics < 0 ? !single : statics == 1) && k + nc <= ns;
  const PetscInt k_modes = k;
  if (with_statics) {
    Psi.conservativeResize(Eigen::NoChange, k);
    PetscCall(AddStatics(comm, pts, sat, Kp, Kss, Mss, Psi, lam));
    k = (PetscInt)Psi.cols();
  }
  info.n_interface_statics = k - k_modes;
  T = Dense::Zero(n2, nc + k + m);
  for (PetscInt c = 0; c < nc; ++c) {
    const PointBasis &pb = pts[c];
    const PetscInt    r  = 3 * pb.q;
    T.block(pb.at, c, r, 1) = pb.q0;
    T.block(pb.at, nc, r, k).noalias() = pb.Z * Psi.block(sat[c], 0, r - 1, k);
  }
  for (PetscInt q = 0; q < m; ++q) T(nB + q, nc + k + q) = 1;
  info.n_normal        = nc;
  info.n_inplane_modes = k;
  info.inplane_freq.clear();
  for (PetscInt j = 0; j < k; ++j) info.inplane_freq.push_back(std::sqrt(std::max(lam[j], (PetscReal)0)) / (2 * PETSC_PI));
  contacts = full;
  for (PetscInt c = 0; c < nc; ++c) {
    const PointBasis &pb = pts[c];
    ContactPoint     &p  = contacts.points[c];
    const PetscInt    r  = 3 * pb.q;
    // h_e over the point's interface DOFs (the nodes' weights times the frame's direction).
    const ContactPoint &pf = full.points[c];
    auto column = [&](const Eigen::Vector3d &e) {
      Eigen::VectorXd h(r);
      for (PetscInt j = 0; j < pb.q; ++j) h.segment<3>(3 * j) = pf.nodes[j].weight * e;
      return h;
    };
    const PetscReal w0 = pf.nodes[0].weight;
    p.nodes.clear();
    for (ColumnEntries &col : p.cols) col.clear();
    // h_n selects x_c (h_n^T Z = 0): the pivot elimination and the node-wise unilateral law stay
    // exact. h_t, h_b are orthogonal to h_n node by node, so h_t^T q0 = 0: they are dense rows over xi.
    p.cols[kN].emplace_back(c, w0);
    for (int dir : {kT, kB}) {
      const Eigen::RowVectorXd row = column(contacts.Axis(c, dir)).transpose() * pb.Z * Psi.block(sat[c], 0, r - 1, k);
      for (PetscInt j = 0; j < k; ++j) p.cols[dir].emplace_back(nc + j, row(j));
    }
  }
  PetscFunctionReturn(0);
}

} // namespace squeal::cb
