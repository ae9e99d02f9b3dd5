#include "squeal/io/calculix.h"

#include "squeal/core/errors.h"
#include "text_io.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <fstream>
#include <map>
#include <stdexcept>
#include <string>
#include <unordered_map>
#include <vector>

namespace squeal::io {

namespace {

using detail::AtEnd;
using detail::ReadNumber;

// The deck parser throws this with a complete message; the PETSc entry point turns it into one
// error raised on every rank (each rank parses the same files).
struct DeckError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

std::string Upper(std::string s)
{
  for (char &c : s) c = (char)std::toupper((unsigned char)c);
  return s;
}

std::string Trim(const std::string &s)
{
  const size_t a = s.find_first_not_of(" \t\r");
  if (a == std::string::npos) return "";
  const size_t b = s.find_last_not_of(" \t\r");
  return s.substr(a, b - a + 1);
}

std::vector<std::string> SplitCommas(const std::string &s)
{
  std::vector<std::string> out;
  size_t                   start = 0;
  while (true) {
    const size_t k = s.find(',', start);
    out.push_back(Trim(s.substr(start, k == std::string::npos ? std::string::npos : k - start)));
    if (k == std::string::npos) break;
    start = k + 1;
  }
  return out;
}

struct Line {
  std::string file;
  long        no;
  std::string text;
};

std::string Where(const Line &l) { return "deck '" + l.file + "', line " + std::to_string(l.no); }

std::string Folder(const std::string &path)
{
  const size_t k = path.find_last_of('/');
  return k == std::string::npos ? std::string() : path.substr(0, k + 1);
}

// Every line of the deck with its *INCLUDEs expanded in place, comments ("**") dropped.
void ReadLines(const std::string &path, std::vector<Line> &lines, int depth)
{
  if (depth > 16) throw DeckError("deck '" + path + "': *INCLUDE nested more than 16 deep (a file including itself?)");
  std::ifstream in(path);
  if (!in) throw DeckError("deck '" + path + "' cannot be opened");
  std::string text;
  long        no = 0;
  while (std::getline(in, text)) {
    ++no;
    const std::string t = Trim(text);
    if (t.empty() || t.rfind("**", 0) == 0) continue;
    if (t[0] == '*' && Upper(t).rfind("*INCLUDE", 0) == 0) {
      std::string file;
      for (const std::string &kv : SplitCommas(t)) {
        const size_t eq = kv.find('=');
        if (eq != std::string::npos && Upper(Trim(kv.substr(0, eq))) == "INPUT") file = Trim(kv.substr(eq + 1));
      }
      if (file.empty()) throw DeckError("deck '" + path + "', line " + std::to_string(no) + ": *INCLUDE without INPUT=");
      if (file[0] != '/') file = Folder(path) + file;
      ReadLines(file, lines, depth + 1);
      continue;
    }
    lines.push_back({path, no, t});
  }
}

// A keyword line: its name ("NODE") and parameters (upper-cased keys; values as written).
struct Keyword {
  std::string                        name;
  std::map<std::string, std::string> params;
  std::string Param(const char *key) const
  {
    auto it = params.find(key);
    return it == params.end() ? std::string() : it->second;
  }
  bool Has(const char *key) const { return params.count(key) > 0; }
};

Keyword ParseKeyword(const std::string &t)
{
  Keyword                  k;
  std::vector<std::string> parts = SplitCommas(t.substr(1));
  k.name                         = Upper(parts[0]);
  for (size_t i = 1; i < parts.size(); ++i) {
    if (parts[i].empty()) continue;
    const size_t eq = parts[i].find('=');
    if (eq == std::string::npos) k.params[Upper(parts[i])] = "";
    else k.params[Upper(Trim(parts[i].substr(0, eq)))] = Trim(parts[i].substr(eq + 1));
  }
  return k;
}

long ToLong(const std::string &s, const Line &l, const char *what)
{
  const char *p = s.c_str();
  long long   v = 0;
  if (!ReadNumber(p, &v) || !AtEnd(p)) throw DeckError(Where(l) + ": expected " + what + ", found '" + s + "'");
  return (long)v;
}

double ToDouble(const std::string &s, const Line &l)
{
  const char *p = s.c_str();
  double      v = 0;
  if (!ReadNumber(p, &v) || !AtEnd(p) || !std::isfinite(v))
    throw DeckError(Where(l) + ": expected a finite coordinate, found '" + s + "'");
  return v;
}

struct CellType {
  const char *xdmf;
  int         nodes;
};

// CalculiX's solid elements and their XDMF topologies; the node orders agree (Abaqus = VTK for
// these types), so connectivity is copied as written.
const CellType *SolidType(const std::string &type)
{
  static const std::map<std::string, CellType> table = {
    {"C3D4", {"Tetrahedron", 4}},     {"C3D10", {"Tetrahedron_10", 10}}, {"C3D6", {"Wedge", 6}},
    {"C3D15", {"Wedge_15", 15}},      {"C3D8", {"Hexahedron", 8}},       {"C3D8R", {"Hexahedron", 8}},
    {"C3D8I", {"Hexahedron", 8}},     {"C3D20", {"Hexahedron_20", 20}}, {"C3D20R", {"Hexahedron_20", 20}},
  };
  auto it = table.find(type);
  return it == table.end() ? nullptr : &it->second;
}

struct Deck {
  FeMesh                                        &mesh;
  std::unordered_map<long, long>                 node_index; // FE number -> mesh node
  std::map<std::string, std::vector<long>>       elsets;     // FE element numbers
  std::unordered_map<long, std::pair<int, long>> element;    // FE element number -> (block, cell), volume cells only
  long                                           skipped = 0;

  long NodeIndex(long id, const Line &l) const
  {
    auto it = node_index.find(id);
    if (it == node_index.end()) throw DeckError(Where(l) + ": node " + std::to_string(id) + " is not defined by *NODE");
    return it->second;
  }
  int Block(const CellType &ct)
  {
    for (size_t b = 0; b < mesh.blocks.size(); ++b)
      if (mesh.blocks[b].type == ct.xdmf) return (int)b;
    mesh.blocks.push_back({ct.xdmf, ct.nodes, {}});
    return (int)mesh.blocks.size() - 1;
  }
};

// The entries of a set's data lines: numbers, "a, b, step" with GENERATE, or names of sets
// of the same kind.
void ReadSetLine(const Line &l, bool generate, const std::map<std::string, std::vector<long>> &sets, std::vector<long> &out)
{
  std::vector<std::string> f = SplitCommas(l.text);
  while (!f.empty() && f.back().empty()) f.pop_back();
  if (generate) {
    if (f.size() < 2 || f.size() > 3) throw DeckError(Where(l) + ": GENERATE expects 'first, last[, step]'");
    const long a = ToLong(f[0], l, "a number"), b = ToLong(f[1], l, "a number"), s = f.size() == 3 ? ToLong(f[2], l, "a step") : 1;
    if (s <= 0 || b < a) throw DeckError(Where(l) + ": GENERATE needs first <= last and a positive step");
    for (long v = a; v <= b; v += s) out.push_back(v);
    return;
  }
  for (const std::string &s : f) {
    if (s.empty()) continue;
    if (std::isdigit((unsigned char)s[0]) || s[0] == '-' || s[0] == '+') {
      out.push_back(ToLong(s, l, "a number"));
      continue;
    }
    auto it = sets.find(Upper(s));
    if (it == sets.end()) throw DeckError(Where(l) + ": set '" + s + "' is not defined before it is used");
    out.insert(out.end(), it->second.begin(), it->second.end());
  }
}

void ParseDeck(const std::vector<Line> &lines, Deck &d)
{
  std::map<std::string, std::vector<long>> nsets_ids; // FE node numbers, by set
  size_t                                   i = 0;
  auto data = [&](size_t j) { return j < lines.size() && lines[j].text[0] != '*'; };
  while (i < lines.size()) {
    const Line &kl = lines[i];
    if (kl.text[0] != '*') throw DeckError(Where(kl) + ": data line outside any keyword block");
    const Keyword k = ParseKeyword(kl.text);
    ++i;
    if (k.name == "NODE") {
      const std::string set = Upper(k.Param("NSET"));
      for (; data(i); ++i) {
        std::vector<std::string> f = SplitCommas(lines[i].text);
        while (!f.empty() && f.back().empty()) f.pop_back();
        if (f.size() < 2 || f.size() > 4) throw DeckError(Where(lines[i]) + ": expected 'node, x, y[, z]'");
        const long id = ToLong(f[0], lines[i], "a node number");
        std::array<double, 3> x{0, 0, 0};
        for (size_t c = 1; c < f.size(); ++c) x[c - 1] = ToDouble(f[c], lines[i]);
        if (d.node_index.count(id)) throw DeckError(Where(lines[i]) + ": node " + std::to_string(id) + " defined twice");
        d.node_index[id] = (long)d.mesh.x.size();
        d.mesh.node_ids.push_back(id);
        d.mesh.x.push_back(x);
        if (!set.empty()) nsets_ids[set].push_back(id);
      }
    } else if (k.name == "ELEMENT") {
      const std::string type = Upper(k.Param("TYPE")), set = Upper(k.Param("ELSET"));
      if (type.empty()) throw DeckError(Where(kl) + ": *ELEMENT without TYPE=");
      const CellType *ct    = SolidType(type);
      const int       block = ct ? d.Block(*ct) : -1;
      while (data(i)) {
        // A cell may continue over several lines (a line ending in a comma continues).
        const Line              &first = lines[i];
        std::vector<std::string> f;
        do {
          std::vector<std::string> more = SplitCommas(lines[i].text);
          const bool               cont = !more.empty() && more.back().empty();
          if (cont) more.pop_back();
          f.insert(f.end(), more.begin(), more.end());
          ++i;
          if (!cont) break;
        } while (data(i));
        const long id = ToLong(f[0], first, "an element number");
        if (!set.empty()) d.elsets[set].push_back(id);
        if (!ct) {
          ++d.skipped;
          continue;
        }
        if ((int)f.size() != ct->nodes + 1)
          throw DeckError(Where(first) + ": element " + std::to_string(id) + " of type " + type + " needs " +
                          std::to_string(ct->nodes) + " nodes, found " + std::to_string(f.size() - 1));
        FeMesh::Block &b = d.mesh.blocks[block];
        if (d.element.count(id)) throw DeckError(Where(first) + ": element " + std::to_string(id) + " defined twice");
        d.element[id] = {block, (long)(b.conn.size() / b.nodes_per_cell)};
        for (int n = 1; n <= ct->nodes; ++n) b.conn.push_back(d.NodeIndex(ToLong(f[n], first, "a node number"), first));
      }
    } else if (k.name == "NSET" || k.name == "ELSET") {
      const bool        nset = k.name == "NSET";
      const std::string name = Upper(k.Param(nset ? "NSET" : "ELSET"));
      if (name.empty()) throw DeckError(Where(kl) + ": *" + k.name + " without " + k.name + "=");
      auto &sets = nset ? nsets_ids : d.elsets;
      std::vector<long> &out = sets[name];
      for (; data(i); ++i) ReadSetLine(lines[i], k.Has("GENERATE"), sets, out);
    } else {
      while (data(i)) ++i; // materials, steps, boundary conditions: not the mesh
    }
  }
  for (auto &s : nsets_ids) {
    std::vector<long> &idx = d.mesh.node_sets[s.first];
    idx.clear();
    for (long id : s.second) {
      auto it = d.node_index.find(id);
      if (it == d.node_index.end())
        throw DeckError("deck: node set " + s.first + " lists node " + std::to_string(id) + ", which *NODE does not define");
      idx.push_back(it->second);
    }
    std::sort(idx.begin(), idx.end());
    idx.erase(std::unique(idx.begin(), idx.end()), idx.end());
  }
}

} // namespace

PetscErrorCode ReadCalculixDeck(MPI_Comm comm, const char *path, FeMesh &mesh, PetscInt *skipped)
{
  std::string err;
  PetscFunctionBeginUser;
  PetscCall(detail::CheckReadable(comm, path, "CalculiX deck"));
  mesh = FeMesh();
  try {
    std::vector<Line> lines;
    ReadLines(path, lines, 0);
    Deck d{mesh, {}, {}, {}, 0};
    ParseDeck(lines, d);
    if (mesh.x.empty()) throw DeckError(std::string("deck '") + path + "' defines no *NODE");
    if (skipped) *skipped = (PetscInt)d.skipped;
  } catch (const std::exception &e) {
    err = e.what();
  }
  PetscCheck(err.empty(), comm, kErrInput, "%s", err.c_str());
  PetscFunctionReturn(0);
}

namespace {

// One line of a .dof file, "node.direction", read as two integers around the dot (a real would
// turn 7.10 into 7.1). False on anything else.
bool ParseDofLine(const std::string &t, long long *node, long long *dir)
{
  const size_t dot = t.find('.');
  if (dot == std::string::npos) return false;
  const std::string a = t.substr(0, dot), b = t.substr(dot + 1);
  const char       *p = a.c_str(), *q = b.c_str();
  return ReadNumber(p, node) && AtEnd(p) && ReadNumber(q, dir) && AtEnd(q) && *dir >= 1 && *dir <= 3;
}

// Calls visit(lineno, node index in the mesh, direction 0-2) for each DOF of the file in order.
template <class Visit>
PetscErrorCode ForEachDof(MPI_Comm comm, const char *path, const FeMesh &mesh, const char *what, Visit visit)
{
  std::ifstream                  in;
  std::string                    line;
  long long                      lineno = 0;
  std::unordered_map<long, long> index;
  PetscFunctionBeginUser;
  PetscCall(detail::CheckReadable(comm, path, what));
  for (size_t k = 0; k < mesh.node_ids.size(); ++k) index[mesh.node_ids[k]] = (long)k;
  PetscCallCXX(in.open(path));
  while (std::getline(in, line)) {
    ++lineno;
    const std::string t = Trim(line);
    if (t.empty()) continue;
    long long node = -1, dir = -1;
    PetscCheck(ParseDofLine(t, &node, &dir), comm, kErrInput,
               "%s '%s', line %lld: expected 'node.direction' with direction 1, 2 or 3, found '%s' "
               "(is this the .dof file that ccx writes with *FREQUENCY, SOLVER=MATRIXSTORAGE?)",
               what, path, lineno, t.c_str());
    auto it = index.find((long)node);
    PetscCheck(it != index.end(), comm, kErrInput,
               "%s '%s', line %lld: node %lld is not a node of the deck (deck and matrices of different models?)", what, path, lineno,
               node);
    PetscCall(visit(lineno, (size_t)it->second, (int)(dir - 1)));
  }
  PetscFunctionReturn(0);
}

} // namespace

PetscErrorCode ReadCalculixDofMap(MPI_Comm comm, const char *path, FeMesh &mesh)
{
  PetscInt row = 0;
  PetscFunctionBeginUser;
  mesh.dof.assign(mesh.x.size(), {-1, -1, -1});
  PetscCall(ForEachDof(comm, path, mesh, "CalculiX DOF map", [&](long long lineno, size_t k, int d) -> PetscErrorCode {
    PetscFunctionBeginUser;
    PetscCheck(mesh.dof[k][d] < 0, comm, kErrInput, "CalculiX DOF map '%s', line %lld: DOF %ld.%d listed twice", path, lineno,
               mesh.node_ids[k], d + 1);
    mesh.dof[k][d] = row++;
    PetscFunctionReturn(0);
  }));
  PetscCheck(row > 0, comm, kErrInput, "CalculiX DOF map '%s' is empty", path);
  mesh.full_size = row;
  PetscFunctionReturn(0);
}

PetscErrorCode ReadCalculixPartDofMap(MPI_Comm comm, const char *path, const FeMesh &mesh, std::vector<PetscInt> &rows)
{
  std::vector<char> seen(3 * mesh.x.size(), 0);
  PetscFunctionBeginUser;
  rows.clear();
  PetscCall(ForEachDof(comm, path, mesh, "CalculiX DOF map of a part", [&](long long lineno, size_t k, int d) -> PetscErrorCode {
    PetscFunctionBeginUser;
    PetscCheck(!seen[3 * k + d], comm, kErrInput, "CalculiX DOF map of a part '%s', line %lld: DOF %ld.%d listed twice", path, lineno,
               mesh.node_ids[k], d + 1);
    seen[3 * k + d] = 1;
    PetscCallCXX(rows.push_back(mesh.dof[k][d]));
    PetscFunctionReturn(0);
  }));
  PetscCheck(!rows.empty(), comm, kErrInput, "CalculiX DOF map of a part '%s' is empty", path);
  PetscFunctionReturn(0);
}

PetscErrorCode MatLoadCalculix(MPI_Comm comm, const char *path, PetscInt N, Mat *A, const std::vector<PetscInt> *rows)
{
  std::ifstream              in;
  std::string                line;
  long long                  lineno = 0, found = 0;
  PetscInt                   rstart, rend;
  std::vector<detail::Entry> owned;
  PetscFunctionBeginUser;
  PetscCall(detail::CheckReadable(comm, path, "CalculiX matrix file"));
  PetscCall(detail::OwnedRange(comm, N, &rstart, &rend));
  PetscCallCXX(in.open(path));
  while (std::getline(in, line)) {
    ++lineno;
    const char *p = line.c_str();
    if (AtEnd(p)) continue;
    long long i = 0, j = 0;
    double    v = 0;
    PetscCheck(ReadNumber(p, &i) && ReadNumber(p, &j) && ReadNumber(p, &v) && AtEnd(p), comm, kErrInput,
               "CalculiX matrix file '%s', line %lld: expected 'row column value' (the .sti/.mas files of "
               "*FREQUENCY, SOLVER=MATRIXSTORAGE)",
               path, lineno);
    PetscCheck(std::isfinite(v), comm, kErrInput, "CalculiX matrix file '%s', line %lld: value is NaN or infinite", path, lineno);
    const PetscInt n_file = rows ? (PetscInt)rows->size() : N;
    PetscCheck(i >= 1 && j >= 1 && i <= n_file && j <= n_file, comm, kErrInput,
               "CalculiX matrix file '%s', line %lld: entry (%lld, %lld) outside the %" PetscInt_FMT
               " DOFs of the .dof map (files of different jobs?)",
               path, lineno, i, j, n_file);
    PetscCheck(i <= j, comm, kErrInput,
               "CalculiX matrix file '%s', line %lld: entry (%lld, %lld) below the diagonal; CalculiX writes the upper "
               "triangle only",
               path, lineno, i, j);
    ++found;
    PetscInt r = (PetscInt)(i - 1), c = (PetscInt)(j - 1);
    if (rows) {
      r = (*rows)[r], c = (*rows)[c];
      if (r < 0 || c < 0) continue; // a DOF the model constrains
    }
    if (r >= rstart && r < rend) PetscCallCXX(owned.push_back({r, c, v}));
    if (r != c && c >= rstart && c < rend) PetscCallCXX(owned.push_back({c, r, v}));
  }
  PetscCheck(found > 0, comm, kErrInput, "CalculiX matrix file '%s' has no entries", path);
  PetscCall(detail::AssembleOwnedEntries(comm, N, N, owned, A));
  PetscFunctionReturn(0);
}

} // namespace squeal::io
