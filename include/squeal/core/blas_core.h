// OpenBLAS's kernels on CPUs newer than the OpenBLAS that Debian ships (see blas_core.cpp).
#pragma once

namespace squeal {

// Before anything else in main: where OpenBLAS fell back to its generic "Prescott" kernels on a CPU
// with AVX-512 (or AVX2 and FMA), and neither the user nor an earlier start set OPENBLAS_CORETYPE,
// starts the program again (same process, arguments and environment) with OPENBLAS_CORETYPE set to
// the matching kernels. Returns only when it does not (the common case), or when the new start failed.
void RestartWithMatchingBlasKernels(char **argv);

// The name of the kernels OpenBLAS runs ("SkylakeX", "Prescott", ...), or null without OpenBLAS.
const char *BlasCoreName();

} // namespace squeal
