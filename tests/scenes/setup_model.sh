#!/bin/bash
# Fixture for the file-model tests:
#   setup_model.sh <squeal> <scene.yaml> <dir>
# Exports the built-in 3-DOF model of <scene.yaml> to <dir> (M.bin K.bin C.bin F.bin
# contacts.txt, stability results in <dir>/builtin.h5), then writes broken variants next to it
# (make_broken_models.py).
set -eu
if [ $# -ne 3 ]; then
  echo "usage: $0 <squeal> <scene.yaml> <dir>" >&2
  exit 2
fi
squeal=$1
scene=$2
dir=$3
here=$(cd "$(dirname "$0")" && pwd)

rm -rf "$dir"
mkdir -p "$(dirname "$dir")"
echo "+ $squeal -scene $scene -analyses stability -output $dir.builtin.h5 -model_export $dir"
"$squeal" -scene "$scene" -analyses stability -output "$dir.builtin.h5" -model_export "$dir" </dev/null
mv "$dir.builtin.h5" "$dir/builtin.h5"
for f in M.bin K.bin C.bin F.bin contacts.txt builtin.h5; do
  if [ ! -s "$dir/$f" ]; then
    echo "FAIL: $dir/$f missing or empty after export" >&2
    exit 1
  fi
done
/usr/bin/python3 "$here/make_broken_models.py" "$dir"
ls -l "$dir"
echo "PASS"
