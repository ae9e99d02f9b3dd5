#!/usr/bin/env bash
# Second command of the README (and CI's): build if needed and run the whole test suite.
set -euo pipefail
source "$(dirname "$0")/env.sh"
bash "$SQUEAL_ROOT/scripts/install_deps.sh"
squeal_build
cd "$SQUEAL_BUILD"
ctest --output-on-failure -j "$(nproc)" "$@"
