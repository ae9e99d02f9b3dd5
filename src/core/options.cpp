#include "squeal/core/options.h"
#include "squeal/core/errors.h"

#include <cstdio>
#include <cstring>

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

PetscErrorCode CheckUnusedOptions(MPI_Comm comm, bool skip_views)
{
  // Read by PETSc itself only at PetscFinalize(), so still "unused" here.
  static const char *const finalize_time[] = {"options_left", "malloc_dump", "malloc_view", "memory_view",
                                              "objects_dump", "log_view", "log_summary", "squeal_traceback",
                                              "help", "scene"};
  PetscInt n     = 0;
  char   **names = nullptr, **values = nullptr;
  std::string unused;
  int         count = 0;
  PetscFunctionBeginUser;
  PetscCall(PetscOptionsLeftGet(nullptr, &n, &names, &values));
  for (PetscInt i = 0; i < n; ++i) {
    bool known = false;
    for (const char *f : finalize_time) known = known || std::strcmp(names[i], f) == 0;
    const size_t len = std::strlen(names[i]);
    if (skip_views && (std::strstr(names[i], "_view") || std::strstr(names[i], "_monitor") ||
                       std::strstr(names[i], "converged_reason") ||
                       (len >= 4 && std::strcmp(names[i] + len - 4, "view") == 0)))
      continue;
    if (known) continue;
    if (count < 5) unused += std::string(count ? ", -" : "-") + names[i];
    ++count;
  }
  PetscCall(PetscOptionsLeftRestore(nullptr, &n, &names, &values));
  PetscCheck(count == 0, comm, kErrInput, "unknown option%s %s%s (mistyped? see -help)", count > 1 ? "s" : "",
             unused.c_str(), count > 5 ? ", ..." : "");
  PetscFunctionReturn(0);
}

} // namespace squeal
