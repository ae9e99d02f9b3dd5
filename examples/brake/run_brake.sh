#!/usr/bin/env bash
# The brake example in one command: mesh (gmsh), assemble (CalculiX), analyse (squeal).
#   bash examples/brake/run_brake.sh [SIZE] [squeal options...]
# builds build/brake-SIZE/brake.{inp,sti,mas,dof} (unless they are there already) and runs
# build/squeal -scene examples/brake/brake.yaml there with the options given, e.g.
#   bash examples/brake/run_brake.sh 1 -analyses stability -contact_mu 0.3
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
source "$here/../../scripts/env.sh"
size="${1:-1}"
[ $# -gt 0 ] && shift
out="$SQUEAL_BUILD/brake-$size"
[ -x "$SQUEAL_BUILD/squeal" ] || { echo "run_brake.sh: build squeal first (bash scripts/quickstart.sh)" >&2; exit 1; }
if [ ! -s "$out/brake.sti" ] || [ ! -s "$out/brake_lining.sti" ]; then  # the lining job came later
  /usr/bin/python3 "$here/make_brake.py" "$out" --size "$size"
fi
cd "$out"
exec "$SQUEAL_BUILD/squeal" -scene "$here/brake.yaml" -output "$out/brake.h5" "$@"
