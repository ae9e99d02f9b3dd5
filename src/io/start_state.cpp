#include "squeal/io/start_state.h"
#include "squeal/core/errors.h"
#include "squeal/io/h5.h"

#include <cmath>
#include <cstdio>

namespace squeal::io {

const char *const kStartSources[kNumStartSources] = {"auto", "transient", "steady", "shooting", "expanded_end", "expanded", "energy"};

PetscErrorCode StartOptions(PetscOptionItems *PetscOptionsObject, const char *owner, const char *help, std::string &file, std::string &from)
{
  char      buf[PETSC_MAX_PATH_LEN] = "";
  PetscBool set                     = PETSC_FALSE;
  PetscInt  k                       = 0;
  PetscFunctionBeginUser;
  PetscCall(PetscOptionsString("-start", help, owner, file.c_str(), buf, sizeof buf, &set));
  if (set) file = buf;
  for (PetscInt i = 0; i < kNumStartSources; ++i)
    if (from == kStartSources[i]) k = i;
  PetscCall(PetscOptionsEList("-start_from",
                              "Which state of the start file (auto: the first of transient, steady, shooting, expanded_end, expanded, "
                              "energy with the model's number of DOFs: where the file's run ended first)",
                              owner, kStartSources, kNumStartSources, kStartSources[k], &k, nullptr));
  from = kStartSources[k];
  PetscFunctionReturn(0);
}

PetscErrorCode CheckStartFile(MPI_Comm comm, const std::string &file, const char *option)
{
  H5Reader in;
  PetscFunctionBeginUser;
  PetscCall(in.Open(comm, file.c_str(), option));
  PetscFunctionReturn(0);
}


PetscErrorCode ReadStartState(MPI_Comm comm, const std::string &file, const std::string &from, PetscInt N, PetscInt nc,
                              const char *option, StartState &out)
{
  H5Reader in;
  PetscFunctionBeginUser;
  out = StartState{};
  PetscCall(in.Open(comm, file.c_str(), option));
  struct Source {
    const char *from, *dataset;
  };
  const Source sources[] = {{"transient", "/transient/U"},       {"steady", "/steady_state/Z_end"}, {"shooting", "/shooting/Z0"},
                            {"expanded_end", "/expanded/Z_end"}, {"expanded", "/expanded/Z0"},      {"energy", "/energy/Z0"}};
  std::string  seen;
  for (const Source &src : sources) {
    if (from != "auto" && from != src.from) continue;
    std::vector<hsize_t> dims;
    PetscCall(in.Dims(src.dataset, dims));
    if (dims.empty()) continue;
    // A transient holds N values a record, a Z0 2N values.
    const bool   records = std::string(src.from) == "transient";
    const size_t values  = records ? (dims.size() == 2 ? (size_t)dims[1] : 0) : (dims.size() == 1 ? (size_t)dims[0] / 2 : 0);
    if (records && dims[0] == 0) {
      seen += std::string(seen.empty() ? "" : ", ") + src.dataset + " with no record";
      continue;
    }
    if (values != (size_t)N || (!records && dims[0] != 2 * (hsize_t)N)) {
      char b[160];
      std::snprintf(b, sizeof b, "%s%s of a %zu-DOF model", seen.empty() ? "" : ", ", src.dataset, values);
      seen += b;
      continue;
    }
    if (records) {
      const hsize_t last = dims[0] - 1;
      PetscCall(in.Read("/transient/U", out.U, last));
      PetscCall(in.Read("/transient/V", out.dU, last));
      std::vector<hsize_t> rd;
      PetscCall(in.Dims("/transient/R", rd));
      if (rd.size() == 3 && rd[0] == dims[0] && rd[1] == (hsize_t)nc && rd[2] == 3) PetscCall(in.Read("/transient/R", out.R, last));
      std::vector<PetscReal> t;
      PetscCall(in.Read("/transient/t", t, last));
      char b[200];
      std::snprintf(b, sizeof b, "the last record of /transient (t = %.9g s, record %llu) of %s", (double)t[0], (unsigned long long)last,
                    file.c_str());
      out.what = b;
      // The settled period, where the run says it settled.
      PetscReal settled;
      bool      f1, f2;
      PetscCall(in.ReadScalar("/transient", "settled", &settled, &f1));
      if (f1 && settled != 0) PetscCall(in.ReadScalar("/transient", "period", &out.period, &f2));
    } else {
      std::vector<PetscReal> z;
      PetscCall(in.Read(src.dataset, z));
      out.U.assign(z.begin(), z.begin() + N);
      out.dU.assign(z.begin() + N, z.end());
      out.what = std::string(src.dataset) + " of " + file;
      bool              f;
      const std::string d = src.dataset;
      if (d == "/energy/Z0") PetscCall(in.ReadScalar("/energy", "T0", &out.period, &f));
      else if (d == "/steady_state/Z_end" || d == "/expanded/Z_end") {
        // One spectral base: the motion's fundamental f1 (a periodic verdict), so the period 1 / f1.
        PetscReal f1;
        PetscCall(in.ReadScalar("/steady_state", "bases", &f1, &f));
        if (f && f1 > 0) out.period = 1 / f1;
      }
      else if (d == "/shooting/Z0" || d == "/expanded/Z0") PetscCall(in.ReadScalar("/shooting/period", nullptr, &out.period, &f));
    }
    for (PetscReal x : out.U) PetscCheck(std::isfinite(x), comm, kErrInput, "%s: %s has a NaN or infinite entry", option, out.what.c_str());
    for (PetscReal x : out.dU) PetscCheck(std::isfinite(x), comm, kErrInput, "%s: %s has a NaN or infinite entry", option, out.what.c_str());
    if (in.Status() != "complete") out.what += " (the file's status is not \"complete\")";
    PetscFunctionReturn(0);
  }
  std::string looked;
  for (const Source &src : sources)
    if (from == "auto" || from == src.from) looked += std::string(looked.empty() ? "" : ", ") + src.dataset;
  SETERRQ(comm, kErrInput, "%s '%s' has no start state for this model of %" PetscInt_FMT " DOFs (%s_from %s): %s", option, file.c_str(), N,
          option, from.c_str(), seen.empty() ? ("no " + looked).c_str() : ("it has " + seen).c_str());
}

} // namespace squeal::io
