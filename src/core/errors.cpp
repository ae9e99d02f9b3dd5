#include "squeal/core/errors.h"

#include <cstdio>
#include <cstring>
#include <sstream>
#include <string>
#include <vector>

namespace squeal {

namespace {

// PETSc's conversion errors ("Input string abc has no numeric value") do not name the option:
// find the option(s) holding that value in the database. Empty if the message is not one of them.
std::string NameBadValue(const char *mess)
{
  static const struct {
    const char *head, *tail, *expected;
  } kinds[] = {{"Input string ", " has no numeric value", "a real number"},
               {"Input string ", " has no integer value", "an integer"},
               {"Unknown logical value: ", "", "a boolean (true, false, yes, no, 1, 0)"}};
  const std::string m = mess ? mess : "";
  for (const auto &k : kinds) {
    if (m.compare(0, std::strlen(k.head), k.head) != 0) continue;
    const size_t end = k.tail[0] ? m.find(k.tail) : m.size();
    if (end == std::string::npos) continue;
    const std::string value = m.substr(std::strlen(k.head), end - std::strlen(k.head));
    char             *all   = nullptr;
    if (PetscOptionsGetAll(nullptr, &all) || !all) return "";
    std::istringstream       in(all);
    std::vector<std::string> tok;
    for (std::string t; in >> t;) tok.push_back(t);
    PetscFree(all);
    std::string names;
    for (size_t i = 0; i + 1 < tok.size(); ++i)
      if (tok[i].size() > 1 && tok[i][0] == '-' && tok[i + 1] == value) names += (names.empty() ? "" : " or ") + tok[i];
    if (names.empty()) return "";
    return "option " + names + " = '" + value + "': expected " + k.expected + " (command line or scene file)";
  }
  return "";
}

PetscErrorCode OneLineHandler(MPI_Comm comm, int line, const char *fun, const char *file, PetscErrorCode n,
                              PetscErrorType p, const char *mess, void *)
{
  // Only the place where the error was raised has the message; the callers that pass it
  // upwards (PETSC_ERROR_REPEAT) stay silent.
  if (p != PETSC_ERROR_INITIAL) return n;
  PetscMPIInt rank = 0, initialized = 0;
  MPI_Initialized(&initialized);
  if (initialized && comm != MPI_COMM_NULL) MPI_Comm_rank(comm, &rank);
  if (rank == 0) {
    const std::string named = NameBadValue(mess);
    if (!named.empty()) {
      std::fprintf(stderr, "squeal: error: %s\n", named.c_str());
    } else if (mess && mess[0]) {
      std::fprintf(stderr, "squeal: error: %s\n", mess);
    } else {
      const char *text = nullptr;
      PetscErrorMessage(n, &text, nullptr);
      std::fprintf(stderr, "squeal: error: %s (in %s, %s:%d; rerun with -squeal_traceback)\n", text ? text : "unknown",
                   fun, file, line);
    }
    std::fflush(stderr);
  }
  return n;
}

// The handler PushErrorHandler installed (PETSc's traceback where it was not called, as in the tests).
PetscErrorCode (*installed)(MPI_Comm, int, const char *, const char *, PetscErrorCode, PetscErrorType, const char *,
                            void *) = PetscTraceBackErrorHandler;

PetscErrorCode QuietOnSignalHandler(MPI_Comm comm, int line, const char *fun, const char *file, PetscErrorCode n,
                                    PetscErrorType p, const char *mess, void *ctx)
{
  if (n == PETSC_ERR_SIG) return n;
  return installed(comm, line, fun, file, n, p, mess, ctx);
}

} // namespace

PetscErrorCode PushErrorHandler()
{
  PetscBool traceback = PETSC_FALSE;
  PetscFunctionBeginUser;
  PetscCall(PetscOptionsGetBool(nullptr, nullptr, "-squeal_traceback", &traceback, nullptr));
  installed = traceback ? PetscTraceBackErrorHandler : OneLineHandler;
  PetscCall(PetscPushErrorHandler(installed, nullptr));
  PetscFunctionReturn(0);
}

PetscErrorCode PushErrorHandlerQuietOnSignal()
{
  PetscFunctionBeginUser;
  PetscCall(PetscPushErrorHandler(QuietOnSignalHandler, nullptr));
  PetscFunctionReturn(0);
}

} // namespace squeal
