#!/usr/bin/env bash
# First command of the README: install what is missing, build, run the default 3-DOF scene.
set -euo pipefail
source "$(dirname "$0")/env.sh"
bash "$SQUEAL_ROOT/scripts/install_deps.sh"
squeal_build
cd "$SQUEAL_BUILD"
./squeal -scene "$SQUEAL_ROOT/examples/three_dof/case1_separation_slip.yaml" "$@"
