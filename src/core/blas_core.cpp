// OpenBLAS picks its kernels from the CPU model when it is loaded. Debian 12's OpenBLAS 0.3.21 does
// not know the newest Xeons and falls back to its generic SSE3 ("Prescott") kernels there, although
// they have AVX-512. Every BLAS call of MUMPS, SLEPc and LAPACK then runs at a fraction of the
// machine's speed: the Craig-Bampton reduction and stability analysis of the 31119-DOF pad took
// 43.8 s with them and 25.1 s with the AVX-512 kernels (docs/records.md). The choice is made before
// main runs and cannot be redone in the process, so the program starts again with it
// (OPENBLAS_CORETYPE, OpenBLAS's documented override). squeal's own dense algebra is Eigen's, except
// the block products of the step tangents and the Floquet basis (core/dense_blas.h), which go to BLAS.
#include "squeal/core/blas_core.h"

#include <dlfcn.h>
#include <unistd.h>

#include <cstdlib>
#include <cstring>

namespace squeal {

const char *BlasCoreName()
{
  // dlsym rather than a link-time reference: the reference BLAS (or another implementation) may
  // stand behind libblas.so.3, and then there is no OpenBLAS to ask.
  using CoreName = char *(*)();
  const auto corename = reinterpret_cast<CoreName>(dlsym(RTLD_DEFAULT, "openblas_get_corename"));
  return corename ? corename() : nullptr;
}

void RestartWithMatchingBlasKernels(char **argv)
{
  if (std::getenv("OPENBLAS_CORETYPE")) return; // the user's choice, or this is the new start
  // Under valgrind the new start would run outside the tool (callgrind counts, memcheck).
  const char *preload = std::getenv("LD_PRELOAD");
  if (preload && std::strstr(preload, "vgpreload")) return;
  const char *core = BlasCoreName();
  if (!core || std::strcmp(core, "Prescott") != 0) return;
#if defined(__GNUC__) && (defined(__x86_64__) || defined(__i386__))
  __builtin_cpu_init();
  const char *kernels = nullptr;
  if (__builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512cd") && __builtin_cpu_supports("avx512bw") &&
      __builtin_cpu_supports("avx512dq") && __builtin_cpu_supports("avx512vl"))
    kernels = "SkylakeX";
  else if (__builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma")) kernels = "Haswell";
  if (!kernels) return; // an old CPU: the generic kernels are the right ones
  if (setenv("OPENBLAS_CORETYPE", kernels, 1) != 0) return;
  execv("/proc/self/exe", argv);
  unsetenv("OPENBLAS_CORETYPE"); // execv failed (no /proc): go on as we are
#else
  (void)argv;
#endif
}

} // namespace squeal
