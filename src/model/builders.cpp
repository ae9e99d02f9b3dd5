#include "squeal/model/builders.h"
#include "squeal/model/pad.h"
#include "squeal/core/errors.h"
#include "squeal/core/options.h"
#include "squeal/core/sparse.h"
#include "squeal/io/matrix_io.h"
#include "squeal/io/calculix.h"
#include "squeal/model/fe_contact.h"

#include <petscviewerhdf5.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <map>
#include <sstream>
#include <utility>

namespace squeal {

namespace {

constexpr PetscReal kDeg = PETSC_PI / 180.0;

PetscErrorCode CreateDiagonal(MPI_Comm comm, PetscInt N, PetscReal value, Mat *A)
{
  Triplets t;
  PetscFunctionBeginUser;
  for (PetscInt i = 0; i < N; ++i) t.Add(i, i, value);
  PetscCall(MatCreateFromTriplets(comm, PETSC_DECIDE, PETSC_DECIDE, N, N, t, A, true));
  PetscFunctionReturn(0);
}

PetscErrorCode CheckThreeDofParams(MPI_Comm comm, const ThreeDofParams &p)
{
  PetscFunctionBeginUser;
  PetscCall(CheckReal(comm, "model_", "m", p.m, Range::Positive()));
  PetscCall(CheckReal(comm, "model_", "k1", p.k1, Range::Positive()));
  PetscCall(CheckReal(comm, "model_", "k2", p.k2, Range::Positive()));
  PetscCall(CheckReal(comm, "model_", "k3", p.k3, Range::NonNegative()));
  if (p.kn >= 0 || PetscIsInfOrNanReal(p.kn)) PetscCall(CheckReal(comm, "model_", "kn", p.kn, Range::Positive()));
  PetscCall(CheckReal(comm, "model_", "alpha", p.alpha, {-90, 90, true}));
  PetscCall(CheckReal(comm, "model_", "beta", p.beta, {-90, 90, true}));
  PetscCall(CheckReal(comm, "model_", "gamma", p.gamma, Range::Any()));
  PetscCall(CheckReal(comm, "model_", "c", p.c, Range::NonNegative()));
  PetscCall(CheckReal(comm, "model_", "fn", p.Fn, Range::Any()));
  PetscCall(CheckReal(comm, "contact_", "mu", p.mu, Range::NonNegative()));
  PetscCall(CheckReal(comm, "contact_", "v", p.V, Range::Positive()));
  PetscFunctionReturn(0);
}

} // namespace

void ThreeDofStiffness(const ThreeDofParams &p, PetscReal Kx[3][3], PetscReal Kt[3][3])
{
  const PetscReal ta = std::tan(p.alpha * kDeg), tb = std::tan(p.beta * kDeg);
  const PetscReal kn = p.kn >= 0 ? p.kn : p.k3 + p.k1 * ta * ta + p.k2 * tb * tb;
  const PetscReal K[3][3] = {{p.k1, 0, p.k1 * ta}, {0, p.k2, p.k2 * tb}, {p.k1 * ta, p.k2 * tb, kn}};
  const PetscReal c = std::cos(p.gamma * kDeg), s = std::sin(p.gamma * kDeg);
  const PetscReal R[3][3] = {{c, s, 0}, {-s, c, 0}, {0, 0, 1}}; // U_tbn = R U_xyn  (1.3)
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      Kx[i][j] = K[i][j];
      Kt[i][j] = 0;
      for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b) Kt[i][j] += R[i][a] * K[a][b] * R[j][b];
    }
}

PetscErrorCode BuildThreeDof(MPI_Comm comm, const ThreeDofParams &p, Model &model)
{
  PetscReal Kx[3][3], Kt[3][3];
  Triplets  t;
  PetscFunctionBeginUser;
  PetscCall(CheckThreeDofParams(comm, p));
  ThreeDofStiffness(p, Kx, Kt);
  const PetscReal(*K)[3] = p.spring_frame ? Kx : Kt;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      if (K[i][j] != 0) t.Add(i, j, K[i][j]);
  PetscCall(MatCreateFromTriplets(comm, PETSC_DECIDE, PETSC_DECIDE, 3, 3, t, model.K.out(), true));
  PetscCall(CreateDiagonal(comm, 3, p.m, model.M.out()));
  if (p.c > 0) PetscCall(CreateDiagonal(comm, 3, p.c, model.C.out()));
  else model.C.reset();
  PetscCall(io::VecCreateFromValues(comm, {0, 0, -p.Fn}, model.F.out()));

  ContactPoint pt;
  pt.nodes = {ContactNode{{0, 1, 2}, 1.0}};
  if (p.spring_frame) {
    const PetscReal g = p.gamma * kDeg;
    pt.t              = {std::cos(g), std::sin(g), 0};
  }
  model.contacts.points = {pt};
  model.contacts.law    = p.law;
  model.contacts.SetFriction(p.mu, p.V);
  model.name            = p.spring_frame ? "three_dof (spring frame)" : "three_dof";
  PetscCall(model.Validate());
  PetscFunctionReturn(0);
}

PetscErrorCode BuildChain(MPI_Comm comm, const ChainParams &p, Model &model)
{
  PetscReal Kx[3][3], Kt[3][3];
  Triplets  t;
  PetscFunctionBeginUser;
  PetscCall(CheckThreeDofParams(comm, p.cell));
  PetscCheck(p.cells >= 1, comm, kErrInput, "option -model_cells = %" PetscInt_FMT ": expected >= 1", p.cells);
  PetscCheck(p.contact_every >= 1, comm, kErrInput, "option -model_contact_every = %" PetscInt_FMT ": expected >= 1",
             p.contact_every);
  PetscCall(CheckReal(comm, "model_", "coupling", p.coupling, Range::NonNegative()));
  PetscCall(CheckReal(comm, "model_", "gamma_step", p.gamma_step, Range::Any()));
  PetscCall(CheckReal(comm, "model_", "speed_step", p.speed_step, Range::Any()));
  ThreeDofStiffness(p.cell, Kx, Kt);
  const PetscInt N = 3 * p.cells;
  std::vector<PetscReal> F(N, 0.0);
  model.contacts.points.clear();
  for (PetscInt i = 0; i < p.cells; ++i) {
    const PetscInt o = 3 * i;
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b)
        if (Kx[a][b] != 0) t.Add(o + a, o + b, Kx[a][b]);
    if (i + 1 < p.cells && p.coupling > 0)
      for (int a = 0; a < 3; ++a) {
        t.Add(o + a, o + a, p.coupling);
        t.Add(o + 3 + a, o + 3 + a, p.coupling);
        t.Add(o + a, o + 3 + a, -p.coupling);
        t.Add(o + 3 + a, o + a, -p.coupling);
      }
    if (i % p.contact_every != 0) continue;
    F[o + 2] = -p.cell.Fn;
    ContactPoint   pt;
    const PetscReal g = (p.cell.gamma + i * p.gamma_step) * kDeg;
    pt.nodes          = {ContactNode{{o, o + 1, o + 2}, 1.0}};
    pt.t              = {std::cos(g), std::sin(g), 0};
    pt.speed_factor   = 1.0 + i * p.speed_step;
    model.contacts.points.push_back(pt);
  }
  PetscCall(MatCreateFromTriplets(comm, PETSC_DECIDE, PETSC_DECIDE, N, N, t, model.K.out(), true));
  PetscCall(CreateDiagonal(comm, N, p.cell.m, model.M.out()));
  if (p.cell.c > 0) PetscCall(CreateDiagonal(comm, N, p.cell.c, model.C.out()));
  else model.C.reset();
  PetscCall(io::VecCreateFromValues(comm, F, model.F.out()));
  model.contacts.law = p.cell.law;
  model.contacts.SetFriction(p.cell.mu, p.cell.V);
  model.name         = "chain";
  PetscCall(model.Validate());
  PetscFunctionReturn(0);
}

namespace {

// One "cols" row of a contact table (after the word cols):
//   tx ty tz  nx ny nz  speed_factor g0  n_t n_b n_n  then n_t + n_b + n_n pairs "dof value"
// (h_t's entries, then h_b's, then h_n's): a point whose columns of H are given entry by entry.
PetscErrorCode ReadColumnsRow(MPI_Comm comm, const char *path, int lineno, std::istringstream &ss, ContactSet &set)
{
  std::vector<double> v;
  std::string         tok;
  PetscFunctionBeginUser;
  while (ss >> tok) {
    char  *end = nullptr;
    double x   = std::strtod(tok.c_str(), &end);
    PetscCheck(end && *end == '\0', comm, PETSC_ERR_FILE_UNEXPECTED, "contact table '%s', line %d: '%s' is not a number", path,
               lineno, tok.c_str());
    v.push_back(x);
  }
  PetscCheck(v.size() >= 11, comm, PETSC_ERR_FILE_UNEXPECTED,
             "contact table '%s', line %d: a cols row needs tx ty tz nx ny nz speed_factor g0 n_t n_b n_n, then the entries", path,
             lineno);
  ContactPoint pt;
  pt.t            = {v[0], v[1], v[2]};
  pt.n            = {v[3], v[4], v[5]};
  pt.speed_factor = v[6];
  pt.g0           = v[7];
  static const char *const count_name[3] = {"n_t", "n_b", "n_n"};
  size_t                   count[3], total = 0;
  for (int d = 0; d < 3; ++d) {
    // Bounded by the values on the line before the cast, so no count can overflow the sum.
    PetscCheck(v[8 + d] >= 0 && v[8 + d] == std::floor(v[8 + d]) && v[8 + d] <= (double)(v.size() - 11) / 2, comm,
               PETSC_ERR_FILE_UNEXPECTED,
               "contact table '%s', line %d: entry count %s = %g is not a non-negative integer within the %d value pairs of the row",
               path, lineno, count_name[d], v[8 + d], (int)((v.size() - 11) / 2));
    count[d] = (size_t)v[8 + d];
    total += count[d];
  }
  PetscCheck(v.size() == 11 + 2 * total, comm, PETSC_ERR_FILE_UNEXPECTED,
             "contact table '%s', line %d: %d values after the counts, expected %d (a DOF and a value per entry)", path, lineno,
             (int)(v.size() - 11), (int)(2 * total));
  size_t at = 11;
  for (int d = 0; d < 3; ++d)
    for (size_t e = 0; e < count[d]; ++e, at += 2) {
      PetscCheck(v[at] == std::floor(v[at]) && v[at] >= 0 && v[at] < (double)PETSC_MAX_INT, comm, PETSC_ERR_FILE_UNEXPECTED,
                 "contact table '%s', line %d: DOF index %.17g is not a non-negative integer below %" PetscInt_FMT, path,
                 lineno, v[at], (PetscInt)PETSC_MAX_INT);
      pt.cols[d].emplace_back((PetscInt)v[at], v[at + 1]);
    }
  set.points.push_back(pt);
  PetscFunctionReturn(0);
}

} // namespace

PetscErrorCode ReadContactTable(MPI_Comm comm, const char *path, ContactSet &set)
{
  PetscBool exists;
  PetscFunctionBeginUser;
  PetscCall(PetscTestFile(path, 'r', &exists));
  PetscCheck(exists, comm, PETSC_ERR_FILE_OPEN, "contact table '%s' not found", path);
  std::ifstream in(path);
  std::string   line;
  int           lineno = 0;
  // CSV as FE tools write it: commas separate, and a header line may name the columns (any order).
  static const char *const kColumns[] = {"x", "y", "z", "tx", "ty", "tz", "nx", "ny", "nz", "speed_factor", "g0"};
  std::vector<int>         column; // column[j]: canonical index of the j-th field (empty: positional)
  set.points.clear();
  while (std::getline(in, line)) {
    ++lineno;
    const auto hash = line.find('#');
    if (hash != std::string::npos) line.erase(hash);
    std::replace(line.begin(), line.end(), ',', ' ');
    std::replace(line.begin(), line.end(), ';', ' ');
    std::istringstream ss(line);
    std::vector<double> v;
    std::string         tok;
    {
      std::istringstream cs(line);
      std::string        first;
      if (cs >> first && first == "cols") { // a point given by its columns of H
        PetscCall(ReadColumnsRow(comm, path, lineno, cs, set));
        continue;
      }
    }
    if (set.points.empty() && column.empty()) {
      std::istringstream hs(line);
      std::string        first;
      char              *end = nullptr;
      if (hs >> first && (std::strtod(first.c_str(), &end), end == first.c_str())) { // not a number: a header
        bool seen[11] = {};
        for (std::string name = first; !name.empty(); name.clear(), hs >> name) {
          std::transform(name.begin(), name.end(), name.begin(), [](unsigned char c) { return (char)std::tolower(c); });
          if (name.rfind("dof_", 0) == 0) name = name.substr(4);
          int k = 0;
          while (k < 11 && name != kColumns[k]) ++k;
          PetscCheck(k < 11 && !seen[k], comm, PETSC_ERR_FILE_UNEXPECTED,
                     "contact table '%s', line %d: column '%s' %s (columns: x y z tx ty tz nx ny nz [speed_factor] [g0])", path, lineno,
                     name.c_str(), k < 11 ? "given twice" : "unknown");
          seen[k] = true;
          column.push_back(k);
        }
        for (int k = 0; k < 9; ++k)
          PetscCheck(seen[k], comm, PETSC_ERR_FILE_UNEXPECTED, "contact table '%s', line %d: header has no column '%s' (columns: x y z tx ty tz nx ny nz [speed_factor] [g0])",
                     path, lineno, kColumns[k]);
        continue;
      }
    }
    while (ss >> tok) {
      char  *end = nullptr;
      double x   = std::strtod(tok.c_str(), &end);
      PetscCheck(end && *end == '\0', comm, PETSC_ERR_FILE_UNEXPECTED, "contact table '%s', line %d: '%s' is not a number",
                 path, lineno, tok.c_str());
      v.push_back(x);
    }
    if (v.empty()) continue;
    if (!column.empty()) {
      PetscCheck(v.size() == column.size(), comm, PETSC_ERR_FILE_UNEXPECTED,
                 "contact table '%s', line %d: %d values, the header names %d columns", path, lineno, (int)v.size(), (int)column.size());
      std::vector<double> w(11, 0.0);
      w[9] = 1.0; // speed_factor default; g0 defaults to 0
      for (size_t j = 0; j < v.size(); ++j) w[column[j]] = v[j];
      v = w;
    }
    PetscCheck(v.size() >= 9 && v.size() <= 11, comm, PETSC_ERR_FILE_UNEXPECTED,
               "contact table '%s', line %d: %d values, expected 9 to 11 (x y z tx ty tz nx ny nz [speed_factor [g0]])", path,
               lineno, (int)v.size());
    ContactPoint pt;
    ContactNode  nd;
    for (int k = 0; k < 3; ++k) {
      // Range-checked before the cast: a value beyond PetscInt wrapped (to -2147483648 for 2^32) and the
      // model's range check then named that number instead of the one in the file.
      PetscCheck(v[k] == std::floor(v[k]) && v[k] >= 0 && v[k] < (double)PETSC_MAX_INT, comm, PETSC_ERR_FILE_UNEXPECTED,
                 "contact table '%s', line %d: DOF index %.17g is not a non-negative integer below %" PetscInt_FMT, path, lineno,
                 v[k], (PetscInt)PETSC_MAX_INT);
      nd.dofs[k] = (PetscInt)v[k];
    }
    pt.nodes        = {nd};
    pt.t            = {v[3], v[4], v[5]};
    pt.n            = {v[6], v[7], v[8]};
    pt.speed_factor = v.size() > 9 ? v[9] : 1.0;
    pt.g0           = v.size() > 10 ? v[10] : 0.0;
    set.points.push_back(pt);
  }
  PetscCheck(!set.points.empty(), comm, PETSC_ERR_FILE_UNEXPECTED, "contact table '%s' has no contact point", path);
  PetscFunctionReturn(0);
}

PetscErrorCode WriteContactTable(MPI_Comm comm, const char *path, const ContactSet &set)
{
  PetscMPIInt rank;
  PetscFunctionBeginUser;
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  if (rank == 0) {
    std::ofstream out(path);
    PetscCheck(out.good(), PETSC_COMM_SELF, PETSC_ERR_FILE_OPEN, "cannot write contact table '%s'", path);
    out << "# squeal contact table: x y z  tx ty tz  nx ny nz  speed_factor g0\n";
    if (set.HasExplicitColumns()) out << "# or: cols  tx ty tz  nx ny nz  speed_factor g0  n_t n_b n_n  (dof value) per entry of h_t, h_b, h_n\n";
    out.precision(17);
    for (PetscInt c = 0; c < set.Size(); ++c) {
      const ContactPoint &p = set.points[c];
      bool explicit_cols = p.nodes.size() != 1 || p.nodes[0].weight != 1;
      for (const ColumnEntries &col : p.cols) explicit_cols = explicit_cols || !col.empty();
      if (!explicit_cols) {
        const ContactNode &nd = p.nodes[0];
        out << nd.dofs[0] << ' ' << nd.dofs[1] << ' ' << nd.dofs[2] << "  " << p.t[0] << ' ' << p.t[1] << ' ' << p.t[2] << "  "
            << p.n[0] << ' ' << p.n[1] << ' ' << p.n[2] << "  " << p.speed_factor << ' ' << p.g0 << '\n';
        continue;
      }
      // Anything else (several nodes, weights, explicit entries) as its columns, entries on one DOF summed.
      std::map<PetscInt, PetscReal> col[3];
      for (int d = 0; d < 3; ++d) set.ForEachEntry(c, d, [&](PetscInt j, PetscReal v) { col[d][j] += v; });
      out << "cols  " << p.t[0] << ' ' << p.t[1] << ' ' << p.t[2] << "  " << p.n[0] << ' ' << p.n[1] << ' ' << p.n[2] << "  "
          << p.speed_factor << ' ' << p.g0 << "  " << col[0].size() << ' ' << col[1].size() << ' ' << col[2].size();
      for (int d = 0; d < 3; ++d)
        for (const auto &e : col[d]) out << "  " << e.first << ' ' << e.second;
      out << '\n';
    }
  }
  PetscCallMPI(MPI_Barrier(comm));
  PetscFunctionReturn(0);
}

PetscErrorCode BuildFromFiles(MPI_Comm comm, const FileModelSpec &s, Model &model)
{
  PetscFunctionBeginUser;
  PetscCheck(!s.mass.empty() && !s.stiffness.empty() && !s.load.empty() && !s.contacts.empty(), comm, kErrInput,
             "a file model needs -model_mass, -model_stiffness, -model_load and -model_contacts");
  PetscCall(io::MatLoadFromFile(comm, s.mass.c_str(), model.M.out()));
  PetscCall(io::MatLoadFromFile(comm, s.stiffness.c_str(), model.K.out()));
  if (!s.damping.empty()) PetscCall(io::MatLoadFromFile(comm, s.damping.c_str(), model.C.out()));
  else model.C.reset();
  PetscInt mK, nK, mM, nM;
  PetscCall(MatGetSize(model.K, &mK, &nK));
  PetscCall(MatGetSize(model.M, &mM, &nM));
  PetscCheck(mK == mM && nK == nM, comm, kErrInput,
             "mismatched matrix sizes: M ('%s') is %" PetscInt_FMT " x %" PetscInt_FMT ", K ('%s') is %" PetscInt_FMT
             " x %" PetscInt_FMT,
             s.mass.c_str(), mM, nM, s.stiffness.c_str(), mK, nK);

  PetscCall(io::VecLoadFromFile(comm, s.load.c_str(), model.F.out()));
  PetscInt nF;
  PetscCall(VecGetSize(model.F, &nF));
  PetscCheck(nF == mK, comm, kErrInput, "mismatched sizes: load vector F ('%s') has %" PetscInt_FMT " entries, K is %" PetscInt_FMT " x %" PetscInt_FMT,
             s.load.c_str(), nF, mK, nK);
  // VecLoad picks its own layout; give F the layout of K's rows.
  {
    Vec Fk;
    PetscCall(MatCreateVecs(model.K, nullptr, &Fk));
    PetscCall(VecCopy(model.F, Fk));
    PetscCall(VecDestroy(model.F.out()));
    *model.F.out() = Fk;
  }

  PetscCall(ReadContactTable(comm, s.contacts.c_str(), model.contacts));
  model.contacts.law = s.law;
  model.contacts.SetFriction(s.mu, s.V);
  model.name         = "file:" + s.stiffness;
  PetscCall(model.Validate());
  PetscFunctionReturn(0);
}

namespace {

// The contact_ options of a model whose contact comes from its geometry (fe_contact.h).
PetscErrorCode FacePairingOptions(MPI_Comm comm, FacePairing &f, PetscBool help)
{
  const char *const modes[] = {"node", "surface", "auto"};
  PetscInt          mode    = (PetscInt)f.mode, n;
  char              buf[256];
  PetscBool         set;
  PetscReal         v[3];
  OptionChecks      checks;
  PetscFunctionBeginUser;
  PetscOptionsBegin(comm, "contact_", "Contact from the FE geometry (-model_type calculix)", "PairContactFaces");
  PetscCall(PetscOptionsString("-pad_set", "Node set of the pad's friction face", "PairContactFaces", f.pad_set.c_str(), buf,
                               sizeof(buf), &set));
  if (set) f.pad_set = buf;
  PetscCall(PetscOptionsString("-disc_set", "Node set of the disc's face that the pad touches", "PairContactFaces", f.disc_set.c_str(),
                               buf, sizeof(buf), &set));
  if (set) f.disc_set = buf;
  struct {
    const char      *opt, *text;
    Eigen::Vector3d *dst;
  } vecs[] = {{"-axis", "Rotation axis of the disc (x,y,z); the disc turns positively about it", &f.axis},
              {"-axis_point", "A point of the rotation axis (x,y,z, m)", &f.axis_point}};
  for (auto &a : vecs) {
    n = 3;
    for (int k = 0; k < 3; ++k) v[k] = (*a.dst)(k);
    PetscCall(PetscOptionsRealArray(a.opt, a.text, "PairContactFaces", v, &n, &set));
    PetscCheck(!set || n == 3, comm, kErrInput, "option -contact_%s needs three comma-separated numbers, got %" PetscInt_FMT, a.opt + 1, n);
    if (set) *a.dst = Eigen::Vector3d(v[0], v[1], v[2]);
  }
  SquealOptionsReal("-r_ref", "Radius at which the disc's speed is -contact_v (m); <= 0: mean radius of the pad face", "PairContactFaces",
                    &f.r_ref, Range::Any(), checks);
  SquealOptionsReal("-pair_tol", "Largest pad-to-disc distance of a contact pair (m)", "PairContactFaces", &f.tol, Range::NonNegative(),
                    checks);
  PetscCall(PetscOptionsEList("-pairing", "Pairs: node (conforming faces), surface (projection on disc facets), auto (node where one is "
                              "within the tolerance)", "PairContactFaces", modes, 3, modes[mode], &mode, nullptr));
  PetscOptionsEnd();
  PetscCall(checks.Run(comm));
  (void)help;
  f.mode = (FacePairing::Mode)mode;
  PetscFunctionReturn(0);
}

} // namespace

PetscErrorCode BuildCalculix(MPI_Comm comm, const CalculixModelSpec &s, Model &model)
{
  auto          mesh = std::make_shared<io::FeMesh>();
  PetscInt      skipped = 0;
  PairingReport rep;
  PetscFunctionBeginUser;
  PetscCheck(!s.job.empty(), comm, kErrInput, "a CalculiX model needs -model_ccx_job STEM (STEM.inp, STEM.sti, STEM.mas, STEM.dof)");
  PetscCheck(std::isfinite(s.ray_a) && std::isfinite(s.ray_b) && s.ray_a >= 0 && s.ray_b >= 0, comm, kErrInput,
             "Rayleigh factors -model_rayleigh_a %g, -model_rayleigh_b %g: expected finite and >= 0", (double)s.ray_a, (double)s.ray_b);
  const std::string inp = s.job + ".inp", dof = s.job + ".dof", sti = s.job + ".sti", mas = s.job + ".mas";
  PetscCall(io::ReadCalculixDeck(comm, inp.c_str(), *mesh, &skipped));
  PetscCall(io::ReadCalculixDofMap(comm, dof.c_str(), *mesh));
  const PetscInt N = mesh->full_size;
  PetscCall(io::MatLoadCalculix(comm, sti.c_str(), N, model.K.out()));
  PetscCall(io::MatLoadCalculix(comm, mas.c_str(), N, model.M.out()));
  PetscCheck(s.part_jobs.size() == s.part_b.size(), comm, kErrInput,
             "-model_ccx_damping_parts names %zu job(s) but -model_ccx_damping_b gives %zu factor(s): give one factor per part",
             s.part_jobs.size(), s.part_b.size());
  for (size_t i = 0; i < s.part_b.size(); ++i)
    PetscCheck(std::isfinite(s.part_b[i]) && s.part_b[i] >= 0, comm, kErrInput,
               "-model_ccx_damping_b: factor %g of part '%s': expected finite and >= 0", (double)s.part_b[i], s.part_jobs[i].c_str());
  if (s.ray_a > 0 || s.ray_b > 0 || !s.part_jobs.empty()) {
    PetscCall(MatDuplicate(model.K, MAT_COPY_VALUES, model.C.out()));
    PetscCall(MatScale(model.C, s.ray_b));
    PetscCall(MatAXPY(model.C, s.ray_a, model.M, DIFFERENT_NONZERO_PATTERN));
    MatH extra; // sum of the parts' b_i K_i
    for (size_t i = 0; i < s.part_jobs.size(); ++i) {
      // The part's own job: its .dof numbers only its DOFs, so its rows are mapped by node and
      // direction onto the model's. A relative part is in the model's folder, as the deck's
      // *INCLUDE files are.
      std::string  part = s.part_jobs[i];
      const size_t slash = s.job.find_last_of('/');
      if (!part.empty() && part[0] != '/' && slash != std::string::npos) part = s.job.substr(0, slash + 1) + part;
      const std::string      pdof = part + ".dof", psti = part + ".sti";
      std::vector<PetscInt> rows;
      MatH                   Kp;
      PetscCall(io::ReadCalculixPartDofMap(comm, pdof.c_str(), *mesh, rows));
      PetscCall(io::MatLoadCalculix(comm, psti.c_str(), N, Kp.out(), &rows));
      if (!extra) {
        PetscCall(MatDuplicate(Kp, MAT_COPY_VALUES, extra.out()));
        PetscCall(MatScale(extra, s.part_b[i]));
      } else PetscCall(MatAXPY(extra, s.part_b[i], Kp, DIFFERENT_NONZERO_PATTERN));
    }
    if (extra) {
      PetscCall(MatAXPY(model.C, 1.0, extra, DIFFERENT_NONZERO_PATTERN));
      model.damping_a = s.ray_a, model.damping_b = s.ray_b, model.damping_extra = std::move(extra);
    }
  } else model.C.reset();

  // Preload: a pressure on a face and/or a load vector in the .dof numbering.
  std::vector<PetscReal> F(N, 0.0);
  Eigen::Vector3d        total = Eigen::Vector3d::Zero();
  if (s.pressure != 0) PetscCall(AddPressureLoad(comm, *mesh, s.pressure_set, s.pressure, F, &total));
  PetscCall(io::VecCreateFromValues(comm, F, model.F.out()));
  if (!s.load.empty()) {
    VecH L;
    PetscInt nL;
    PetscCall(io::VecLoadFromFile(comm, s.load.c_str(), L.out()));
    PetscCall(VecGetSize(L, &nL));
    PetscCheck(nL == N, comm, kErrInput, "load vector '%s' has %" PetscInt_FMT " entries; the .dof map '%s' has %" PetscInt_FMT " DOFs",
               s.load.c_str(), nL, dof.c_str(), N);
    Vec Fl;
    PetscCall(VecDuplicate(model.F, &Fl));
    PetscCall(VecCopy(L, Fl)); // same global size; VecCopy needs the same layout, which PETSC_DECIDE gives both
    PetscCall(VecAXPY(model.F, 1.0, Fl));
    PetscCall(VecDestroy(&Fl));
  }
  {
    // F in the layout of K's rows.
    Vec Fk;
    PetscCall(MatCreateVecs(model.K, nullptr, &Fk));
    PetscCall(VecCopy(model.F, Fk));
    PetscCall(VecDestroy(model.F.out()));
    *model.F.out() = Fk;
  }
  PetscCall(PairContactFaces(comm, *mesh, s.pairing, model.contacts, &rep));
  model.contacts.law = s.law;
  model.contacts.SetFriction(s.mu, s.V);
  model.name         = "calculix:" + s.job;
  model.mesh         = mesh;
  PetscCall(model.Validate());
  if (s.verbose) {
    PetscCall(PetscPrintf(PETSC_COMM_SELF,
                          "CalculiX model '%s': %zu nodes, %" PetscInt_FMT " DOFs, %" PetscInt_FMT " contact pairs (%" PetscInt_FMT
                          " node-to-node, %" PetscInt_FMT " node-to-surface, largest distance %.3g m), r_ref = %.6g m",
                          s.job.c_str(), mesh->x.size(), N, model.contacts.Size(), rep.node_pairs, rep.surface_pairs,
                          (double)rep.max_distance, (double)rep.r_ref));
    if (s.pressure != 0)
      PetscCall(PetscPrintf(PETSC_COMM_SELF, ", pressure %g Pa on %s: force (%.6g, %.6g, %.6g) N", (double)s.pressure, s.pressure_set.c_str(),
                            total(0), total(1), total(2)));
    if (skipped) PetscCall(PetscPrintf(PETSC_COMM_SELF, ", %" PetscInt_FMT " non-solid element(s) not drawn", skipped));
    PetscCall(PetscPrintf(PETSC_COMM_SELF, "\n"));
  }
  PetscFunctionReturn(0);
}

PetscErrorCode ModelCreateFromOptions(MPI_Comm comm, Model &model, std::string *export_dir, bool options_only)
{
  const char *const types[] = {"three_dof", "chain", "file", "pad", "calculix"};
  const char *const laws[]  = {"planar", "rectilinear"};
  const char *const frames[] = {"sliding", "spring"};
  PetscInt          type = 0, law = 0, frame = 0;
  ChainParams       ch;
  ThreeDofParams   &p = ch.cell;
  FileModelSpec     fs;
  PadParams         pad;
  CalculixModelSpec ccx;
  char              buf[PETSC_MAX_PATH_LEN] = "";
  char              exportdir[PETSC_MAX_PATH_LEN] = "";
  PetscBool         help = PETSC_FALSE, set;
  PetscFunctionBeginUser;
  OptionChecks checks;
  PetscCall(PetscOptionsHasHelp(nullptr, &help));

  PetscOptionsBegin(comm, "contact_", "Contact and friction", "Model");
  SquealOptionsReal("-mu", "Coulomb friction coefficient", "ContactSet", &p.mu, Range::NonNegative(), checks);
  SquealOptionsReal("-v", "Counter-surface speed V (m/s); point c slides at speed_factor_c * V", "ContactSet", &p.V,
                    Range::Positive(), checks);
  PetscCall(PetscOptionsEList("-friction", "Friction law: planar (disc |r_T| <= mu r_n) or rectilinear (along t only)",
                              "ContactSet", laws, 2, laws[law], &law, nullptr));
  PetscOptionsEnd();
  PetscCall(checks.Run(comm));

  PetscOptionsBegin(comm, "model_", "Structural model", "Model");
  PetscCall(PetscOptionsEList("-type", "Model: three_dof (reference system), chain (synthetic multi-contact), file, pad (FE brake pad), calculix (CalculiX deck and matrices)",
                              "ModelCreateFromOptions", types, 5, types[type], &type, nullptr));
  if (type == 0 || type == 1 || help) {
    SquealOptionsReal("-m", "Mass (kg)", "BuildThreeDof", &p.m, Range::Positive(), checks);
    SquealOptionsReal("-k1", "Spring 1 stiffness projected on x (N/m)", "BuildThreeDof", &p.k1, Range::Positive(), checks);
    SquealOptionsReal("-k2", "Spring 2 stiffness projected on y (N/m)", "BuildThreeDof", &p.k2, Range::Positive(), checks);
    SquealOptionsReal("-k3", "Normal spring stiffness (N/m)", "BuildThreeDof", &p.k3, Range::NonNegative(), checks);
    SquealOptionsReal("-kn", "K_nn (N/m); negative: k3 + k1 tan^2(alpha) + k2 tan^2(beta)", "BuildThreeDof", &p.kn,
                      Range::Any(), checks);
    SquealOptionsReal("-alpha", "Inclination of spring 1 in the x-n plane (degrees)", "BuildThreeDof", &p.alpha,
                      Range::OpenBelow(-90, 90), checks);
    SquealOptionsReal("-beta", "Inclination of spring 2 in the y-n plane (degrees)", "BuildThreeDof", &p.beta,
                      Range::OpenBelow(-90, 90), checks);
    SquealOptionsReal("-gamma", "Angle from spring axis x to the sliding direction t (degrees)", "BuildThreeDof", &p.gamma,
                      Range::Any(), checks);
    SquealOptionsReal("-c", "Isotropic viscous damping C = c I (N s/m)", "BuildThreeDof", &p.c, Range::NonNegative(), checks);
    SquealOptionsReal("-fn", "Preload Fn (N), F = (0, 0, -Fn) pushes onto the surface", "BuildThreeDof", &p.Fn, Range::Any(), checks);
    PetscCall(PetscOptionsEList("-frame", "DOF frame of the 3-DOF system: sliding (t,b,n; H = I) or spring (x,y,n; H = R^T)",
                                "BuildThreeDof", frames, 2, frames[frame], &frame, nullptr));
  }
  if (type == 1 || help) {
    PetscCall(PetscOptionsInt("-cells", "Number of 3-DOF cells (one contact point each)", "BuildChain", ch.cells, &ch.cells,
                              nullptr));
    SquealOptionsReal("-coupling", "Stiffness of the springs between neighbouring cells (N/m)", "BuildChain", &ch.coupling,
                      Range::NonNegative(), checks);
    SquealOptionsReal("-gamma_step", "Change of sliding direction from cell to cell (degrees)", "BuildChain", &ch.gamma_step,
                      Range::Any(), checks);
    SquealOptionsReal("-speed_step", "Relative change of sliding speed from cell to cell", "BuildChain", &ch.speed_step,
                      Range::Any(), checks);
    PetscCall(PetscOptionsInt("-contact_every", "Only every k-th cell touches the surface", "BuildChain", ch.contact_every,
                              &ch.contact_every, nullptr));
  }
  if (type == 2 || help) {
    struct {
      const char  *opt, *text;
      std::string *dst;
    } files[] = {{"-mass", "Mass matrix file (PETSc binary, or Matrix Market .mtx)", &fs.mass},
                 {"-stiffness", "Stiffness matrix file (PETSc binary, or .mtx)", &fs.stiffness},
                 {"-damping", "Damping matrix file (optional; PETSc binary, or .mtx)", &fs.damping},
                 {"-load", "Load vector F (PETSc binary, HDF5 .h5 with dataset /F, Matrix Market .mtx, text column .txt/.dat/.csv)", &fs.load},
                 {"-contacts", "Contact table (text: x y z tx ty tz nx ny nz [speed_factor [g0]]; or .csv with a header naming these columns)", &fs.contacts}};
    for (auto &f : files) {
      buf[0] = '\0';
      PetscCall(PetscOptionsString(f.opt, f.text, "BuildFromFiles", buf, buf, sizeof(buf), &set));
      if (set) *f.dst = buf;
    }
  }
  if (type == 3 || help) PetscCall(PadOptions(PetscOptionsObject, pad, checks));
  if (type == 4 || help) {
    buf[0] = '\0';
    PetscCall(PetscOptionsString("-ccx_job", "CalculiX job STEM: reads STEM.inp (mesh, node sets) and STEM.sti, STEM.mas, STEM.dof "
                                 "(*FREQUENCY, SOLVER=MATRIXSTORAGE)", "BuildCalculix", buf, buf, sizeof(buf), &set));
    if (set) ccx.job = buf;
    SquealOptionsReal("-ccx_rayleigh_a", "CalculiX model: Rayleigh damping C = a M + b K, mass factor a (1/s)", "BuildCalculix",
                      &ccx.ray_a, Range::NonNegative(), checks);
    SquealOptionsReal("-ccx_rayleigh_b", "CalculiX model: Rayleigh stiffness factor b (s)", "BuildCalculix", &ccx.ray_b,
                      Range::NonNegative(), checks);
    {
      char     *jobs[16];
      PetscReal bs[16];
      PetscInt  nj = 16, nb = 16;
      PetscBool sj = PETSC_FALSE, sb = PETSC_FALSE;
      PetscCall(PetscOptionsStringArray("-ccx_damping_parts", "CalculiX model: jobs PART,... each made of some of the model's elements "
                                        "(PART.sti, PART.dof); C += b_i K_PART for each", "BuildCalculix", jobs, &nj, &sj));
      PetscCall(PetscOptionsRealArray("-ccx_damping_b", "CalculiX model: stiffness factor b_i (s) of each -model_ccx_damping_parts job",
                                      "BuildCalculix", bs, &nb, &sb));
      if (sj) {
        ccx.part_jobs.clear();
        for (PetscInt i = 0; i < nj; ++i) {
          ccx.part_jobs.push_back(jobs[i]);
          PetscCall(PetscFree(jobs[i]));
        }
      }
      if (sb) ccx.part_b.assign(bs, bs + nb);
    }
    SquealOptionsReal("-ccx_pressure", "CalculiX model: preload pressure (Pa) on the faces of -model_ccx_pressure_set, pushing into the body",
                      "BuildCalculix", &ccx.pressure, Range::Any(), checks);
    PetscCall(PetscOptionsString("-ccx_pressure_set", "CalculiX model: node set whose faces carry -model_ccx_pressure", "BuildCalculix",
                                 ccx.pressure_set.c_str(), buf, sizeof(buf), &set));
    if (set) ccx.pressure_set = buf;
    PetscCall(PetscOptionsString("-ccx_load", "CalculiX model: load vector in the .dof numbering (formats as -model_load), added to the pressure",
                                 "BuildCalculix", "", buf, sizeof(buf), &set));
    if (set) ccx.load = buf;
  }
  PetscCall(PetscOptionsString("-export", "Write the built model (M, C, K, F, contacts.txt) to this directory", "Model::Export",
                               exportdir, exportdir, sizeof(exportdir), nullptr));
  PetscOptionsEnd();
  PetscCall(checks.Run(comm));
  if (type == 4 || help) PetscCall(FacePairingOptions(comm, ccx.pairing, help));

  p.law          = law == 0 ? FrictionLaw::Planar : FrictionLaw::Rectilinear;
  p.spring_frame = frame == 1;
  fs.mu          = p.mu;
  fs.V           = p.V;
  fs.law         = p.law;
  pad.mu         = p.mu;
  pad.V          = p.V;
  pad.law        = p.law;
  {
    PetscMPIInt wrank;
    PetscCallMPI(MPI_Comm_rank(PETSC_COMM_WORLD, &wrank));
    ccx.verbose = wrank == 0;
  }
  ccx.mu         = p.mu;
  ccx.V          = p.V;
  ccx.law        = p.law;
  if (!options_only) switch (type) {
    case 0: PetscCall(BuildThreeDof(comm, p, model)); break;
    case 1: PetscCall(BuildChain(comm, ch, model)); break;
    case 3: PetscCall(BuildPad(comm, pad, model)); break;
    case 4: PetscCall(BuildCalculix(comm, ccx, model)); break;
    default: PetscCall(BuildFromFiles(comm, fs, model)); break;
    }
  if (export_dir) *export_dir = exportdir;
  PetscFunctionReturn(0);
}

} // namespace squeal
