#include "squeal/core/options.h"
#include "squeal/core/errors.h"

#include <cstdio>
#include <cstring>
#include <functional>

#include <yaml.h>

namespace squeal {

std::string OptionName(const char *prefix, const char *name)
{
  std::string s = "-";
  if (prefix) s += prefix;
  s += (name[0] == '-') ? name + 1 : name;
  return s;
}

PetscErrorCode CheckReal(MPI_Comm comm, const char *prefix, const char *name, PetscReal v, const Range &r)
{
  // Numbers are formatted here: PETSc's own %g appends a '.' to integral values ("1.").
  auto num = [](PetscReal x) {
    char b[32];
    std::snprintf(b, sizeof b, "%g", (double)x);
    return std::string(b);
  };
  PetscFunctionBeginUser;
  const std::string opt = OptionName(prefix, name), val = num(v);
  PetscCheck(!PetscIsInfOrNanReal(v), comm, kErrInput, "option %s is %s: expected a finite number", opt.c_str(), val.c_str());
  if (r.lo_strict)
    PetscCheck(v > r.lo, comm, kErrInput, "option %s = %s: expected > %s", opt.c_str(), val.c_str(), num(r.lo).c_str());
  else PetscCheck(v >= r.lo, comm, kErrInput, "option %s = %s: expected >= %s", opt.c_str(), val.c_str(), num(r.lo).c_str());
  PetscCheck(v <= r.hi, comm, kErrInput, "option %s = %s: expected <= %s", opt.c_str(), val.c_str(), num(r.hi).c_str());
  PetscFunctionReturn(0);
}

PetscErrorCode OptionChecks::Run(MPI_Comm comm) const
{
  PetscFunctionBeginUser;
  for (const Item &it : items_) PetscCall(CheckReal(comm, it.prefix.c_str(), it.name.c_str(), *it.v, it.r));
  PetscFunctionReturn(0);
}

namespace {

// The options nobody read that `judged` keeps: up to five names ("-a, -b") and their count.
PetscErrorCode UnusedOptions(const std::function<bool(const char *)> &judged, std::string &list, int &count)
{
  PetscInt n     = 0;
  char   **names = nullptr, **values = nullptr;
  PetscFunctionBeginUser;
  list.clear(), count = 0;
  PetscCall(PetscOptionsLeftGet(nullptr, &n, &names, &values));
  for (PetscInt i = 0; i < n; ++i) {
    if (!judged(names[i])) continue;
    if (count < 5) list += std::string(count ? ", -" : "-") + names[i];
    ++count;
  }
  PetscCall(PetscOptionsLeftRestore(nullptr, &n, &names, &values));
  PetscFunctionReturn(0);
}

} // namespace

PetscErrorCode CheckUnusedOptions(MPI_Comm comm, bool skip_views)
{
  // Read by PETSc itself only at PetscFinalize(), so still "unused" here.
  static const char *const finalize_time[] = {"options_left", "malloc_dump", "malloc_view", "memory_view",
                                              "objects_dump", "log_view", "log_summary", "squeal_traceback",
                                              "help", "scene"};
  std::string unused;
  int         count = 0;
  PetscFunctionBeginUser;
  PetscCall(UnusedOptions(
    [&](const char *name) {
      bool known = false;
      for (const char *f : finalize_time) known = known || std::strcmp(name, f) == 0;
      const size_t len = std::strlen(name);
      if (skip_views && (std::strstr(name, "_view") || std::strstr(name, "_monitor") || std::strstr(name, "converged_reason") ||
                         (len >= 4 && std::strcmp(name + len - 4, "view") == 0)))
        return false;
      // Factorisation options (-eq_mat_mumps_icntl_14, -theta_mat_mumps_*) are read when a factor is
      // set up, after the first check, and not at all when a run needs no such factor; the Floquet
      // eigensolver's (-floquet_eps_*) once shooting has converged, and not at all by the block Arnoldi.
      return !(known || std::strstr(name, "mat_mumps_") || std::strstr(name, "floquet_eps_"));
    },
    unused, count));
  if (!skip_views && count > 0) {
    PetscCall(PetscFPrintf(comm, PETSC_STDERR, "warning: option%s %s%s never used (mistyped, or for an analysis this run did not do; see -help)\n",
                           count > 1 ? "s" : "", unused.c_str(), count > 5 ? ", ..." : ""));
    PetscFunctionReturn(0);
  }
  PetscCheck(count == 0, comm, kErrInput, "unknown option%s %s%s (mistyped? see -help)", count > 1 ? "s" : "",
             unused.c_str(), count > 5 ? ", ..." : "");
  PetscFunctionReturn(0);
}

PetscErrorCode CheckUnknownSquealOptions(MPI_Comm comm)
{
  static const char *const ours[]    = {"model_", "contact_", "reduce_", "stab_", "eq_", "sweep_",
                                        "theta_", "transient_", "energy_", "shoot_", "floquet_", "cont_", "steady_", "torus_"};
  // PETSc objects under our prefixes (-shoot_snes_monitor, -stab_pep_view): read when the object is
  // made, so judged only at the end of the run. Our own monitors and viewers (-floquet_monitor,
  // -stab_view) are read with the other options, so a name like -shoot_monitor, which no object
  // reads, is refused here: a long run used to show only an end-of-run warning for it, and an
  // interrupted one nothing.
  // An object's options may sit under PETSc's own inner prefixes too (-theta_sub_pc_type,
  // -eq_redundant_pc_type, -shoot_mass_ksp_type), so an object word anywhere exempts the name,
  // except in squeal's own options that contain one (-shoot_linear_pc_max, -cont_ds_min): their
  // typos are judged here.
  static const char *const objects[] = {"_ksp_", "_pc_", "_snes_", "_linesearch_", "_eps_", "_pep_", "_st_", "_bv_", "_ds_",
                                        "_rg_", "_fn_", "_mat_", "_svd_", "_vec_", "_is_", "_sf_", "_dm_", "_viewer_", "_draw_"};
  static const char *const own[]     = {"shoot_linear_pc_", "cont_ds_"};
  std::string unknown;
  int         count = 0;
  PetscFunctionBeginUser;
  PetscCall(UnusedOptions(
    [](const char *name) {
      bool squeal = false, object = false, mine = false;
      for (const char *p : ours) squeal = squeal || std::strncmp(name, p, std::strlen(p)) == 0;
      for (const char *o : objects) object = object || std::strstr(name, o) != nullptr;
      for (const char *p : own) mine = mine || std::strncmp(name, p, std::strlen(p)) == 0;
      return squeal && (mine || !object);
    },
    unknown, count));
  PetscCheck(count == 0, comm, kErrInput, "unknown option%s %s%s (mistyped? see -help)", count > 1 ? "s" : "", unknown.c_str(),
             count > 5 ? ", ..." : "");
  PetscFunctionReturn(0);
}

PetscErrorCode CheckYAMLFile(MPI_Comm comm, const char *path)
{
  PetscMPIInt rank;
  char        msg[512] = "";
  PetscFunctionBeginUser;
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  if (rank == 0) {
    FILE *fp = std::fopen(path, "rb");
    if (!fp) std::snprintf(msg, sizeof msg, "scene file '%s' cannot be opened", path);
    else {
      yaml_parser_t parser;
      yaml_parser_initialize(&parser);
      yaml_parser_set_input_file(&parser, fp);
      for (bool done = false; !done && !msg[0];) {
        yaml_document_t doc;
        if (!yaml_parser_load(&parser, &doc)) {
          std::snprintf(msg, sizeof msg, "scene file '%s', line %lu, column %lu: %s%s%s (YAML syntax)", path,
                        (unsigned long)parser.problem_mark.line + 1, (unsigned long)parser.problem_mark.column + 1,
                        parser.problem ? parser.problem : "parse error", parser.context ? " " : "", parser.context ? parser.context : "");
          break;
        }
        done = yaml_document_get_root_node(&doc) == nullptr; // the stream has ended
        yaml_document_delete(&doc);
      }
      yaml_parser_delete(&parser);
      std::fclose(fp);
    }
  }
  PetscCallMPI(MPI_Bcast(msg, sizeof msg, MPI_CHAR, 0, comm));
  PetscCheck(!msg[0], comm, kErrInput, "%s", msg);
  PetscFunctionReturn(0);
}

} // namespace squeal
