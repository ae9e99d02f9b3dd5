#!/bin/bash
# squeal runs OpenBLAS's kernels for the CPU it runs on (src/core/blas_core.cpp): where OpenBLAS
# falls back to its generic "Prescott" kernels on a CPU with AVX2 and FMA, the program starts again
# with OPENBLAS_CORETYPE set, and the kernels of that start are not the generic ones. A user's own
# OPENBLAS_CORETYPE is kept. Without OpenBLAS (another libblas.so.3) there is nothing to check.
#   blas_kernels.sh SQUEAL_EXE SCENE OUTPUT.h5
set -u
exe=$1 scene=$2 h5=$3
out=$(OPENBLAS_VERBOSE=2 "$exe" -scene "$scene" -analyses stability -output "$h5" 2>&1) || { echo "$out"; echo "FAIL: the run failed"; exit 1; }
cores=$(printf '%s\n' "$out" | sed -n 's/^Core: *//p')
echo "OpenBLAS kernels, in the order of the starts: $(printf "%s " ${cores:-none})"
[ -z "$cores" ] && { echo "PASS (no OpenBLAS)"; exit 0; }
last=$(printf '%s\n' "$cores" | tail -n 1)
if grep -qw avx2 /proc/cpuinfo && grep -qw fma /proc/cpuinfo && [ "$last" = Prescott ]; then
  echo "FAIL: the run used OpenBLAS's generic kernels on a CPU with AVX2 and FMA"
  exit 1
fi
kept=$(OPENBLAS_CORETYPE=Prescott OPENBLAS_VERBOSE=2 "$exe" -scene "$scene" -analyses stability -output "$h5" 2>&1 | sed -n 's/^Core: *//p')
if [ "$kept" != Prescott ]; then
  echo "FAIL: with OPENBLAS_CORETYPE=Prescott given, the kernels were: $kept"
  exit 1
fi
echo PASS
