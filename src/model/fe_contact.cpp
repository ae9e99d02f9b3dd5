#include "squeal/model/fe_contact.h"

#include "squeal/core/errors.h"

#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <map>
#include <set>
#include <sstream>

namespace squeal {

namespace {

using Vec3 = Eigen::Vector3d;

Vec3 X(const io::FeMesh &mesh, long node) { return Vec3(mesh.x[node][0], mesh.x[node][1], mesh.x[node][2]); }

// Corner faces of each cell kind, as local corner indices (quadratic cells use their corners).
const std::vector<std::vector<int>> &CellFaces(const std::string &type, int *corners)
{
  static const std::vector<std::vector<int>> hex = {{0, 3, 2, 1}, {4, 5, 6, 7}, {0, 1, 5, 4}, {1, 2, 6, 5}, {2, 3, 7, 6}, {3, 0, 4, 7}};
  static const std::vector<std::vector<int>> tet = {{0, 2, 1}, {0, 1, 3}, {1, 2, 3}, {0, 3, 2}};
  static const std::vector<std::vector<int>> wedge = {{0, 2, 1}, {3, 4, 5}, {0, 1, 4, 3}, {1, 2, 5, 4}, {2, 0, 3, 5}};
  static const std::vector<std::vector<int>> none;
  if (type.rfind("Hexahedron", 0) == 0) return *corners = 8, hex;
  if (type.rfind("Tetrahedron", 0) == 0) return *corners = 4, tet;
  if (type.rfind("Wedge", 0) == 0) return *corners = 6, wedge;
  return *corners = 0, none;
}

std::string NodeName(const io::FeMesh &mesh, long node)
{
  std::ostringstream s;
  s << "node " << mesh.node_ids[node] << " (" << mesh.x[node][0] << ", " << mesh.x[node][1] << ", " << mesh.x[node][2] << ")";
  return s.str();
}

PetscErrorCode GetSet(MPI_Comm comm, const io::FeMesh &mesh, const std::string &name, const char *option,
                      const std::vector<long> **set)
{
  PetscFunctionBeginUser;
  auto it = mesh.node_sets.find(name);
  PetscCheck(it != mesh.node_sets.end() && !it->second.empty(), comm, kErrInput,
             "contact: node set '%s' (%s) %s in the deck; give the name of an *NSET", name.c_str(), option,
             it == mesh.node_sets.end() ? "is not defined" : "is empty");
  *set = &it->second;
  PetscFunctionReturn(0);
}

// Area-weighted outward normal of a set's facets at each of its nodes.
std::map<long, Vec3> NodeNormals(const std::vector<Facet> &facets)
{
  std::map<long, Vec3> n;
  for (const Facet &f : facets)
    for (long c : f.corners) {
      auto it = n.emplace(c, Vec3::Zero()).first;
      it->second += f.area * f.normal;
    }
  for (auto &e : n)
    if (e.second.norm() > 0) e.second.normalize();
  return n;
}

} // namespace

std::vector<Facet> SetFacets(const io::FeMesh &mesh, const std::vector<long> &set)
{
  std::vector<char> in(mesh.x.size(), 0);
  for (long n : set) in[n] = 1;
  std::map<std::vector<long>, std::pair<int, Facet>> found; // sorted corners -> (count, facet)
  for (const io::FeMesh::Block &b : mesh.blocks) {
    int         nc    = 0;
    const auto &faces = CellFaces(b.type, &nc);
    if (!nc) continue;
    const long cells = (long)b.conn.size() / b.nodes_per_cell;
    for (long e = 0; e < cells; ++e) {
      const long *cell = &b.conn[e * b.nodes_per_cell];
      Vec3        centre = Vec3::Zero();
      for (int k = 0; k < nc; ++k) centre += X(mesh, cell[k]);
      centre /= nc;
      for (const auto &face : faces) {
        bool all = true;
        for (int k : face) all = all && in[cell[k]];
        if (!all) continue;
        Facet f;
        for (int k : face) f.corners.push_back(cell[k]);
        // Newell's normal: exact area vector for planar polygons, robust for warped quadrilaterals.
        Vec3 a = Vec3::Zero(), fc = Vec3::Zero();
        for (size_t k = 0; k < f.corners.size(); ++k) {
          const Vec3 p = X(mesh, f.corners[k]), q = X(mesh, f.corners[(k + 1) % f.corners.size()]);
          a += 0.5 * p.cross(q);
          fc += p;
        }
        fc /= (double)f.corners.size();
        f.area   = a.norm();
        f.normal = f.area > 0 ? Vec3(a / f.area) : Vec3::Zero();
        if (f.normal.dot(fc - centre) < 0) f.normal = -f.normal;
        std::vector<long> key = f.corners;
        std::sort(key.begin(), key.end());
        auto it = found.find(key);
        if (it == found.end()) found.emplace(key, std::make_pair(1, f));
        else ++it->second.first;
      }
    }
  }
  std::vector<Facet> out;
  for (auto &e : found)
    if (e.second.first == 1) out.push_back(e.second.second); // a face two cells share is interior
  return out;
}

bool FacetWeights(const io::FeMesh &mesh, const Facet &f, const Vec3 &x, PetscReal slack, std::vector<PetscReal> &w, PetscReal *dist)
{
  const size_t      nc = f.corners.size();
  std::vector<Vec3> p(nc);
  for (size_t k = 0; k < nc; ++k) p[k] = X(mesh, f.corners[k]);
  w.assign(nc, 0.0);
  bool inside;
  if (nc == 3) {
    // Least-squares barycentric coordinates: the foot of the perpendicular from x.
    Eigen::Matrix<double, 3, 2> E;
    E.col(0) = p[1] - p[0];
    E.col(1) = p[2] - p[0];
    const Eigen::Vector2d s = E.colPivHouseholderQr().solve(x - p[0]);
    w                       = {1 - s(0) - s(1), s(0), s(1)};
    inside                  = std::min({w[0], w[1], w[2]}) >= -slack;
  } else {
    // Bilinear map on [-1, 1]^2; Gauss-Newton for the nearest point (exact in a few steps on a
    // flat facet).
    Eigen::Vector2d xi(0, 0);
    const double    sg[4][2] = {{-1, -1}, {1, -1}, {1, 1}, {-1, 1}};
    for (int it = 0; it < 20; ++it) {
      Vec3                        r = -x;
      Eigen::Matrix<double, 3, 2> J = Eigen::Matrix<double, 3, 2>::Zero();
      for (int k = 0; k < 4; ++k) {
        const double a = sg[k][0], b = sg[k][1];
        r += 0.25 * (1 + a * xi(0)) * (1 + b * xi(1)) * p[k];
        J.col(0) += 0.25 * a * (1 + b * xi(1)) * p[k];
        J.col(1) += 0.25 * b * (1 + a * xi(0)) * p[k];
      }
      const Eigen::Vector2d d = (J.transpose() * J).ldlt().solve(-J.transpose() * r);
      xi += d;
      if (d.norm() < 1e-14) break;
    }
    for (int k = 0; k < 4; ++k) w[k] = 0.25 * (1 + sg[k][0] * xi(0)) * (1 + sg[k][1] * xi(1));
    inside = std::abs(xi(0)) <= 1 + 2 * slack && std::abs(xi(1)) <= 1 + 2 * slack;
  }
  Vec3 y = Vec3::Zero();
  for (size_t k = 0; k < nc; ++k) y += w[k] * p[k];
  *dist = (x - y).norm();
  return inside;
}

namespace {

// Two separate bodies: no node, and no cell, on both faces.
PetscErrorCode CheckSeparateBodies(MPI_Comm comm, const io::FeMesh &mesh, const FacePairing &spec, const std::vector<long> &pad,
                                   const std::vector<long> &disc)
{
  std::vector<char> where(mesh.x.size(), 0);
  PetscFunctionBeginUser;
  for (long n : pad) where[n] |= 1;
  for (long n : disc) {
    PetscCheck(!(where[n] & 1), comm, kErrInput,
               "contact: %s is in both %s and %s; the pad and disc faces must be different nodes of two separate bodies",
               NodeName(mesh, n).c_str(), spec.pad_set.c_str(), spec.disc_set.c_str());
    where[n] |= 2;
  }
  for (const io::FeMesh::Block &b : mesh.blocks)
    for (size_t e0 = 0; e0 < b.conn.size(); e0 += b.nodes_per_cell) {
      int seen = 0;
      for (int k = 0; k < b.nodes_per_cell; ++k) seen |= where[b.conn[e0 + k]];
      PetscCheck(seen != 3, comm, kErrInput,
                 "contact: one cell holds nodes of both %s and %s (e.g. %s): the pairs would be on one body; give the "
                 "pad's friction face and the disc's face",
                 spec.pad_set.c_str(), spec.disc_set.c_str(), NodeName(mesh, b.conn[e0]).c_str());
    }
  PetscFunctionReturn(0);
}

// The frame, speed factor and initial gap of the point of pad node p (outward normal np of the pad
// face) paired with the disc point xd (outward normal n of the disc face).
PetscErrorCode SetFrame(MPI_Comm comm, const io::FeMesh &mesh, const FacePairing &spec, long p, const Vec3 &np, const Vec3 &xd,
                        const Vec3 &n, PetscReal r_ref, ContactPoint &pt)
{
  const Vec3 e = spec.axis.normalized();
  PetscFunctionBeginUser;
  // The disc's outward normal must face the pad: opposite to the pad face's own outward normal.
  PetscCheck(n.dot(np) < -0.5, comm, kErrInput,
             "contact: at pad %s the outward normals of %s and %s do not face each other (n_disc . n_pad = %.3g, "
             "expected near -1): check that the sets are the two faces that touch",
             NodeName(mesh, p).c_str(), spec.disc_set.c_str(), spec.pad_set.c_str(), n.dot(np));
  const Vec3      r = xd - spec.axis_point;
  const Vec3      v = e.cross(r);
  const Vec3      vt = v - v.dot(n) * n;
  const PetscReal speed = v.norm();
  PetscCheck(vt.norm() > 1e-9 * std::max(r.norm(), r_ref), comm, kErrInput,
             "contact: at pad %s the disc does not slide along its face (point on the axis, or face normal to the "
             "velocity): check -contact_axis and -contact_axis_point",
             NodeName(mesh, p).c_str());
  pt.n            = n;
  pt.t            = vt.normalized();
  pt.speed_factor = speed / r_ref;
  pt.g0           = (X(mesh, p) - xd).dot(n);
  PetscCheck(pt.g0 >= -spec.tol, comm, kErrInput,
             "contact: pad %s lies %g m inside the disc along the disc face's normal: overlapping bodies, or the normal "
             "of %s points the wrong way",
             NodeName(mesh, p).c_str(), -(double)pt.g0, spec.disc_set.c_str());
  PetscFunctionReturn(0);
}

} // namespace

PetscErrorCode PairContactFaces(MPI_Comm comm, const io::FeMesh &mesh, const FacePairing &spec, ContactSet &set,
                                PairingReport *report)
{
  const std::vector<long> *pad = nullptr, *disc = nullptr;
  PetscFunctionBeginUser;
  PetscCall(GetSet(comm, mesh, spec.pad_set, "-contact_pad_set", &pad));
  PetscCall(GetSet(comm, mesh, spec.disc_set, "-contact_disc_set", &disc));
  PetscCheck(mesh.dof.size() == mesh.x.size(), comm, PETSC_ERR_PLIB, "contact: the mesh has no DOF map");
  PetscCheck(spec.axis.allFinite() && spec.axis.norm() > 0 && spec.axis_point.allFinite(), comm, kErrInput,
             "contact: -contact_axis must be a non-zero, finite direction");
  PetscCheck(std::isfinite(spec.tol) && spec.tol >= 0, comm, kErrInput, "contact: -contact_pair_tol %g: expected >= 0", (double)spec.tol);
  const Vec3 e = spec.axis.normalized();

  PetscCall(CheckSeparateBodies(comm, mesh, spec, *pad, *disc));
  const std::vector<Facet> pad_facets = SetFacets(mesh, *pad), disc_facets = SetFacets(mesh, *disc);
  PetscCheck(!pad_facets.empty() && !disc_facets.empty(), comm, kErrInput,
             "contact: node set '%s' holds no cell face (its nodes must cover whole faces of volume cells)",
             pad_facets.empty() ? spec.pad_set.c_str() : spec.disc_set.c_str());
  const std::map<long, Vec3> pad_n = NodeNormals(pad_facets), disc_n = NodeNormals(disc_facets);

  PetscReal r_ref = spec.r_ref;
  if (r_ref <= 0) {
    r_ref = 0;
    for (long p : *pad) r_ref += e.cross(X(mesh, p) - spec.axis_point).norm();
    r_ref /= (PetscReal)pad->size();
  }
  PetscCheck(r_ref > 0, comm, kErrInput, "contact: the pad face lies on the rotation axis (-contact_axis, -contact_axis_point)");

  PairingReport          rep;
  rep.r_ref = r_ref;
  std::vector<std::string> missed;
  std::map<long, long>     disc_user; // disc node -> pad node using it
  set.points.clear();
  for (long p : *pad) {
    const Vec3 xp = X(mesh, p);
    long       best = -1;
    PetscReal  dbest = PETSC_MAX_REAL;
    for (long d : *disc) {
      const PetscReal dd = (X(mesh, d) - xp).norm();
      if (dd < dbest) dbest = dd, best = d;
    }
    ContactPoint pt;
    Vec3         xd, n;
    auto         dofs = [&](long node, std::array<PetscInt, 3> &out) -> bool {
      out = mesh.dof[node];
      return out[0] >= 0 && out[1] >= 0 && out[2] >= 0;
    };
    std::array<PetscInt, 3> dp{};
    PetscCheck(dofs(p, dp), comm, kErrInput,
               "contact: pad %s of %s has constrained DOFs (absent from the .dof map); a contact node must be free",
               NodeName(mesh, p).c_str(), spec.pad_set.c_str());
    pt.nodes.push_back({dp, 1.0});
    // A disc node joins this point: it must be free and, since ContactSet keeps each DOF in one
    // point (the linearisation eliminates each normal constraint through its own DOFs, docs/method.md
    // §4), used by no other pad node. Returns the pad node already using it, or -1.
    auto take_disc = [&](long d, std::array<PetscInt, 3> &dd) -> long {
      PetscCheck(dofs(d, dd), comm, kErrInput,
                 "contact: disc %s of %s has constrained DOFs (absent from the .dof map); a contact node must be free",
                 NodeName(mesh, d).c_str(), spec.disc_set.c_str());
      auto used = disc_user.emplace(d, p);
      return used.second ? -1 : used.first->second;
    };
    if (spec.mode != FacePairing::Mode::Surface && dbest <= spec.tol) {
      std::array<PetscInt, 3> dd{};
      const long              other = take_disc(best, dd);
      PetscCheck(other < 0, comm, kErrInput,
                 "contact: pad nodes %ld and %ld both pair with disc %s; lower -contact_pair_tol (now %g m)",
                 other < 0 ? 0 : mesh.node_ids[other], mesh.node_ids[p], NodeName(mesh, best).c_str(), (double)spec.tol);
      pt.nodes.push_back({dd, -1.0});
      xd = X(mesh, best);
      n  = disc_n.at(best);
      rep.node_pairs++;
      rep.max_distance = std::max(rep.max_distance, dbest);
    } else {
      // Node-to-surface: the disc facet nearest to the pad node.
      const Facet           *fbest = nullptr;
      std::vector<PetscReal> w, wbest;
      PetscReal              dist, dmin = PETSC_MAX_REAL;
      for (const Facet &f : disc_facets)
        if (FacetWeights(mesh, f, xp, 1e-9, w, &dist) && dist < dmin) dmin = dist, fbest = &f, wbest = w;
      if (spec.mode == FacePairing::Mode::Node || !fbest || dmin > spec.tol) {
        if (missed.size() < 5) {
          std::ostringstream s;
          s << NodeName(mesh, p) << ": nearest " << spec.disc_set << " node at " << dbest << " m";
          missed.push_back(s.str());
        } else missed.push_back("");
        continue;
      }
      // A pad node on a facet's edge or corner: the far corners' weights are round-off; dropped,
      // they do not tie the point to disc nodes it does not touch.
      PetscReal wsum = 0;
      for (PetscReal &w : wbest) wsum += (w = std::abs(w) < 1e-10 ? 0.0 : w);
      for (PetscReal &w : wbest) w /= wsum;
      xd = Vec3::Zero();
      for (size_t k = 0; k < fbest->corners.size(); ++k) {
        const long              c = fbest->corners[k];
        if (wbest[k] == 0) continue;
        std::array<PetscInt, 3> dd{};
        const long              other = take_disc(c, dd);
        PetscCheck(other < 0, comm, kErrInput,
                   "contact: pad nodes %ld and %ld project onto disc facets sharing %s; squeal's contact points need "
                   "distinct DOFs, so node-to-surface pairs must not share disc nodes: mesh the two faces conformingly "
                   "(node-to-node pairs, -contact_pairing node)",
                   other < 0 ? 0 : mesh.node_ids[other], mesh.node_ids[p], NodeName(mesh, c).c_str());
        pt.nodes.push_back({dd, -wbest[k]});
        xd += wbest[k] * X(mesh, c);
      }
      n = fbest->normal;
      rep.surface_pairs++;
      rep.max_distance = std::max(rep.max_distance, dmin);
    }
    PetscCall(SetFrame(comm, mesh, spec, p, pad_n.at(p), xd, n, r_ref, pt));
    set.points.push_back(pt);
  }
  if (!missed.empty()) {
    std::string list;
    for (const std::string &m : missed)
      if (!m.empty()) list += (list.empty() ? "" : "; ") + m;
    SETERRQ(comm, kErrInput, "contact: %zu node(s) of %s have no %s point within -contact_pair_tol %g m (%s pairing): %s%s",
            missed.size(), spec.pad_set.c_str(), spec.disc_set.c_str(), (double)spec.tol,
            spec.mode == FacePairing::Mode::Node ? "node-to-node" : "node-to-node or node-to-surface", list.c_str(),
            missed.size() > 5 ? "; ..." : "");
  }
  if (report) *report = rep;
  PetscFunctionReturn(0);
}

PetscErrorCode AddPressureLoad(MPI_Comm comm, const io::FeMesh &mesh, const std::string &name, PetscReal P,
                               std::vector<PetscReal> &F, Vec3 *total)
{
  const std::vector<long> *set = nullptr;
  PetscFunctionBeginUser;
  PetscCall(GetSet(comm, mesh, name, "-model_pressure_set", &set));
  const std::vector<Facet> facets = SetFacets(mesh, *set);
  PetscCheck(!facets.empty(), comm, kErrInput, "pressure: node set '%s' holds no cell face", name.c_str());
  Vec3 sum = Vec3::Zero();
  for (const Facet &f : facets) {
    const Vec3 share = -P * f.area * f.normal / (double)f.corners.size();
    for (long c : f.corners)
      for (int k = 0; k < 3; ++k) {
        sum(k) += share(k);
        if (mesh.dof[c][k] >= 0) F[mesh.dof[c][k]] += share(k);
      }
  }
  if (total) *total = sum;
  PetscFunctionReturn(0);
}

} // namespace squeal
