#!/usr/bin/env python3
"""Run a squeal command (must exit 0), then check that no dataset and no attribute of its results
file holds a NaN or a large finite sentinel (|x| >= 1e300: PETSC_INFINITY is 4.49e307, where IEEE
inf is meant), and optional attribute and dataset values:
  check_no_nan.py --output F [--attr /group name value]... [--dataset /path value]... -- cmd...
--dataset: every entry of the dataset equals value (e.g. inf)."""
import argparse
import os
import subprocess
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scripts"))
from squeal.results import Results  # noqa: E402

ap = argparse.ArgumentParser()
ap.add_argument("--output", required=True)
ap.add_argument("--attr", nargs=3, action="append", default=[], metavar=("OBJECT", "NAME", "VALUE"))
ap.add_argument("--dataset", nargs=2, action="append", default=[], metavar=("PATH", "VALUE"))
ap.add_argument("cmd", nargs=argparse.REMAINDER)
a = ap.parse_args()
cmd = a.cmd[1:] if a.cmd and a.cmd[0] == "--" else a.cmd
print("+", " ".join(cmd), flush=True)
rc = subprocess.call(cmd)
if rc != 0:
    sys.exit(f"exit code {rc}")

bad = []


def numeric_nan(v):
    arr = np.asarray(v)
    return arr.dtype.kind == "f" and (np.isnan(arr).any() or (np.isfinite(arr) & (np.abs(arr) >= 1e300)).any())


with Results(a.output) as r:
    for name, attrs, data in r.walk():
        bad += [f"attribute {name}:{k}" for k, v in attrs.items() if numeric_nan(v)]
        if data is not None and numeric_nan(data):
            bad.append(f"dataset {name}")
    for obj, name, value in a.attr:
        got = (r.attrs if obj == "/" else r.group(obj.strip("/")).attrs)[name]
        if str(got) != value and not (np.asarray(got).dtype.kind in "iuf" and float(got) == float(value)):
            bad.append(f"{obj}:{name} = {got!r}, expected {value}")
    for path, value in a.dataset:
        top, _, rest = path.strip("/").partition("/")
        got = np.asarray(r.group(top)[rest], dtype=float)
        if got.size == 0 or not (got == float(value)).all():
            bad.append(f"{path} = {got!r}, expected every entry {value}")
if bad:
    sys.exit("NaN, sentinel or wrong value: " + "; ".join(bad))
print("no NaN, no finite sentinel; attributes and datasets as expected")
