#!/usr/bin/env bash
# Installs the Debian packages squeal needs, only those that are missing.
set -euo pipefail

PACKAGES=(
  g++ cmake make pkg-config
  petsc-dev slepc-dev libhdf5-openmpi-dev libeigen3-dev libopenmpi-dev openmpi-bin
  libopenblas0-serial liblapack-dev
  libgtest-dev libbenchmark-dev libyaml-dev
  python3 python3-numpy python3-h5py python3-matplotlib
  python3-gmsh calculix-ccx python3-meshio
)

missing=()
for p in "${PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
[ ${#missing[@]} -eq 0 ] && exit 0

echo "squeal: installing ${missing[*]}" >&2
SUDO=""
if [ "$(id -u)" -ne 0 ]; then
  if command -v sudo >/dev/null; then SUDO=sudo; else
    echo "squeal: run as root: apt-get install -y ${missing[*]}" >&2
    exit 1
  fi
fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
