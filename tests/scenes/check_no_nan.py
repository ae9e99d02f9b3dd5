#!/usr/bin/env python3
"""Run a squeal command (must exit 0), then check that no dataset and no attribute of its results
file holds a NaN, and optional attribute values:
  check_no_nan.py --output F [--attr /group name value]... -- cmd..."""
import argparse
import os
import subprocess
import sys

import h5py
import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scripts"))
from squeal.results import Results, decode  # noqa: E402

ap = argparse.ArgumentParser()
ap.add_argument("--output", required=True)
ap.add_argument("--attr", nargs=3, action="append", default=[], metavar=("OBJECT", "NAME", "VALUE"))
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
    return arr.dtype.kind == "f" and np.isnan(arr).any()


def visit(name, obj):
    for k, v in obj.attrs.items():
        if numeric_nan(v):
            bad.append(f"attribute {name}:{k}")
    if isinstance(obj, h5py.Dataset) and numeric_nan(obj[()]):
        bad.append(f"dataset {name}")


with Results(a.output) as r:
    f = r.h5
    for k, v in f.attrs.items():
        if numeric_nan(v):
            bad.append(f"attribute /:{k}")
    f.visititems(visit)
    for obj, name, value in a.attr:
        got = decode(f[obj].attrs[name])
        if str(got) != value and not (np.asarray(got).dtype.kind in "iuf" and float(got) == float(value)):
            bad.append(f"{obj}:{name} = {got!r}, expected {value}")
if bad:
    sys.exit("NaN or wrong value: " + "; ".join(bad))
print("no NaN; attributes as expected")
