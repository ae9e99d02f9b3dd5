#!/bin/bash
# Unstable modes above the band that the time integration carries (-stab_guard_fmax, by default the
# top of the reduction). The 2625-DOF pad reduced by Craig-Bampton at 30 kHz, mu = 0.3, V = 10 m/s:
# the band 0-6 kHz holds one unstable mode (4 173.5 Hz, 32.3 1/s), and before the energy estimate
# the guard lists those above it up to the reduction's top mode (29 996.9 Hz). Checked against
# the table of a second run whose band is the whole of it (-stab_fmax 30000): the same unstable
# modes above 6 kHz, frequencies and growth rates to 1e-6 of |lambda| (two eigensolves, each
# converged to about 1e-8). Then -stab_guard_fmax 0 turns it off.
#   guard_above_band.sh SQUEAL SCENE OUT_DIR
set -euo pipefail
squeal=$1 scene=$2 out=$3
mkdir -p "$out"
op=(-scene "$scene" -contact_mu 0.3 -contact_v 10 -reduce_type craig_bampton -reduce_fmax 30000)
"$squeal" "${op[@]}" -analyses stability,energy -stab_fmax 6000 -output "$out/guard.h5" > "$out/guard.log"
grep -E "^WARNING: [0-9]+ unstable mode\(s\) above the band \(-stab_fmax = 6000 Hz\), up to 29996\.9 Hz" "$out/guard.log" \
  || { echo "no guard warning:"; cat "$out/guard.log"; exit 1; }
"$squeal" "${op[@]}" -analyses stability -stab_fmax 30000 -stab_modes 0 -output "$out/wide.h5" > /dev/null
"$squeal" "${op[@]}" -analyses stability,energy -stab_fmax 6000 -stab_guard_fmax 0 -output "$out/off.h5" > "$out/off.log"
if grep -E "above the band up to|WARNING: [0-9]+ unstable mode" "$out/off.log"; then echo "-stab_guard_fmax 0 still guarded"; exit 1; fi
exec /usr/bin/python3 - "$out/guard.h5" "$out/wide.h5" <<'PY'
import sys, h5py, numpy as np
g = h5py.File(sys.argv[1], 'r')['stability']
w = h5py.File(sys.argv[2], 'r')['stability']
top = g.attrs['guard_fmax']
ev = w['eigenvalues'][()]
sigma, f = ev[:, 0], ev[:, 1] / (2 * np.pi)
pick = (sigma > 0) & (f > 6000) & (f <= top)
ref = sorted(zip(sigma[pick], f[pick]), reverse=True)
n = int(g.attrs['unstable_above_band'])
got = list(zip(g.attrs['unstable_above_band_sigma'], g.attrs['unstable_above_band_f'])) if n else []
print(f"guard up to {top:.1f} Hz: {n} unstable above 6 kHz; the whole band's table: {len(ref)}")
assert n == len(ref) and n > 0, (n, len(ref))
for (s1, f1), (s2, f2) in zip(got, ref):
    lam = np.hypot(s2, 2 * np.pi * f2)  # two eigensolves: agreement to their convergence, relative to |lambda|
    assert 2 * np.pi * abs(f1 - f2) <= 1e-6 * lam and abs(s1 - s2) <= 1e-6 * lam, ((f1, s1), (f2, s2))
print(f"most unstable above the band: {got[0][1]:.1f} Hz, sigma {got[0][0]:.1f} 1/s; all {n} match")
PY
