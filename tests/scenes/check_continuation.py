#!/usr/bin/env python3
"""Checks of the continuation's results file (issue 11).

  check_continuation.py interrupt --output F [--signal INT|TERM] [--after-points K] [--wait S]
                        [--within S] -- cmd...
      Starts cmd (with -cont_monitor), waits for the K-th point line of the first leg (default 3)
      and S seconds more (default 0), sends the signal, and checks: the stop within --within
      seconds (if given), exit code in 1..127, stderr names the signal and F, root status
      "interrupted ...", /continuation holds at least K + 1 points (start included) with finite
      periods, attribute interrupted = 1.
  check_continuation.py branch --output F --param mu|v --min A --max B [--event TYPE[@LO:HI]]... -- cmd...
      Runs cmd (exit 0), then checks /continuation: parameter name, points within [A, B] reaching
      both ends, finite positive periods, and every listed event present (located inside [LO, HI]).
"""
import os
import subprocess
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scripts"))
import check_results_io  # noqa: E402
from check_results_io import ok, signal_after  # noqa: E402
from squeal.results import Results  # noqa: E402


def parse(argv):
    if "--" not in argv:
        sys.exit("usage: see the docstring")
    i = argv.index("--")
    opts, cmd = argv[:i], argv[i + 1:]
    args = {"events": []}
    k = 1
    while k < len(opts):
        if opts[k] == "--event":
            args["events"].append(opts[k + 1])
        else:
            args[opts[k]] = opts[k + 1]
        k += 2
    return opts[0], args, cmd


def interrupt(args, cmd):
    out = args["--output"]
    k = int(args.get("--after-points", "3"))
    within = float(args["--within"]) if "--within" in args else None
    name = signal_after(cmd, out, r"^cont [+-]\s*%d:" % k, args.get("--signal", "INT"), float(args.get("--wait", "0")), within)
    if not ok(os.path.exists(out), f"{out} exists"):
        return
    with Results(out) as r:
        ok(r.status.startswith("interrupted (" + name), f"root status '{r.status}'")
        if not ok("continuation/param" in r, "has /continuation/param"):
            return
        c = r.continuation
        lam = np.asarray(c["param"])
        T = np.asarray(c["period"])
        ok(lam.size >= k + 1, f"{lam.size} points kept (>= {k + 1})")
        ok(np.all(np.isfinite(T)) and np.all(T > 0), "periods finite and positive")
        ok(int(c.attrs["interrupted"]) == 1, "/continuation interrupted = 1")
        ok(name in c.attrs.get("leg_end"), f"leg_end '{c.attrs.get('leg_end')}' names {name}")


def branch(args, cmd):
    out = args["--output"]
    if os.path.exists(out):
        os.remove(out)
    print("+ " + " ".join(cmd))
    p = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    print(p.stdout[-6000:])
    print("--- stderr:\n" + p.stderr)
    if not ok(p.returncode == 0, f"exit code {p.returncode}"):
        return
    lo, hi = float(args["--min"]), float(args["--max"])
    with Results(out) as r:
        g = r.continuation
        ok(g.attrs.get("parameter") == args["--param"], f"parameter '{g.attrs.get('parameter')}'")
        lam = np.asarray(g["param"])
        T = np.asarray(g["period"])
        ok(lam.min() >= lo - 1e-12 and lam.max() <= hi + 1e-12, f"points in [{lo}, {hi}]: [{lam.min()}, {lam.max()}]")
        ok(abs(lam.min() - lo) < 1e-12 and abs(lam.max() - hi) < 1e-12, "both ends of the range reached")
        ok(np.all(np.isfinite(T)) and np.all(T > 0), "periods finite and positive")
        types = g["events"].attrs.get("types").split(",") if "events" in g else []
        ep = np.asarray(g["events/param"]) if "events/param" in g else np.array([])
        for e in args["events"]:
            t, _, rng = e.partition("@")
            idx = [i for i, s in enumerate(types) if s == t]
            if not ok(len(idx) > 0, f"event {t} reported (events: {types})"):
                continue
            if rng:
                a, b = map(float, rng.split(":"))
                ok(any(a <= ep[i] <= b for i in idx), f"event {t} at {[float(ep[i]) for i in idx]} in [{a}, {b}]")


def main():
    mode, args, cmd = parse(sys.argv[1:])
    {"interrupt": interrupt, "branch": branch}[mode](args, cmd)
    sys.exit(1 if check_results_io.failures else 0)


if __name__ == "__main__":
    main()
