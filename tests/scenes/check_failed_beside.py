#!/usr/bin/env python3
"""A run that fails never replaces a complete results file (issue 20, item 6).

    check_failed_beside.py SQUEAL SCENE OUT.h5

1. a complete run writes OUT.h5 (status "complete");
2. a failing run with the same -output exits non-zero, leaves OUT.h5 as it was (same bytes) and
   writes its partial results to OUT.failed.h5 (status "failed: ..."), naming that file;
3. a failing run with no complete file in the way writes OUT.h5 itself.
"""
import hashlib
import os
import subprocess
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scripts"))
from squeal.results import Results, status_of  # noqa: E402

squeal, scene, out = sys.argv[1:4]
failed = out[:-3] + ".failed.h5"
for f in (out, failed):
    if os.path.exists(f):
        os.remove(f)


def run(*extra):
    cmd = [squeal, "-scene", scene, "-output", out, *extra]
    p = subprocess.run(cmd, capture_output=True, text=True)
    print("+", " ".join(cmd), "->", p.returncode)
    print(p.stdout[-2000:], p.stderr[-2000:])
    return p


def digest(f):
    return hashlib.sha256(open(f, "rb").read()).hexdigest()


bad = ["-analyses", "stability,shooting", "-shoot_snes_max_it", "1"]
ok = True
p = run("-analyses", "stability")
ok &= p.returncode == 0 and status_of(out) == "complete"
before = digest(out)

p = run(*bad)
ok &= p.returncode != 0
ok &= digest(out) == before
ok &= os.path.exists(failed) and status_of(failed).startswith("failed")
ok &= failed in p.stderr and "are kept" in p.stderr
with Results(failed) as r:
    ok &= "stability" in r  # the partial results are there

os.remove(out)
os.remove(failed)
p = run(*bad)
ok &= p.returncode != 0 and status_of(out).startswith("failed") and not os.path.exists(failed)
leftovers = [f for f in os.listdir(os.path.dirname(os.path.abspath(out))) if ".part-" in f and os.path.basename(out) in f]
ok &= not leftovers
print("PASS" if ok else "FAIL")
sys.exit(0 if ok else 1)
