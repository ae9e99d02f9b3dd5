# Sourced by the other scripts: build directory and MPI settings for running as root.
SQUEAL_ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
SQUEAL_BUILD="${SQUEAL_BUILD:-$SQUEAL_ROOT/build}"
if [ "$(id -u)" -eq 0 ]; then
  export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
fi
squeal_build() {
  cmake -S "$SQUEAL_ROOT" -B "$SQUEAL_BUILD" -DCMAKE_BUILD_TYPE=RelWithDebInfo >/dev/null
  cmake --build "$SQUEAL_BUILD" -j "$(nproc)"
}
