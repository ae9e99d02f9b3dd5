"""Plot the limit-cycle branch (continuation in mu or V) written by squeal.

Reads the /continuation group of one or more squeal results files and draws a two-panel figure
against the continuation parameter:

  top     amplitude: largest peak-to-peak displacement over the DOFs (m)
  bottom  period T (s)

Stable cycles (every non-trivial Floquet multiplier inside the unit circle) are solid lines,
unstable ones dashed; regime changes, folds, stability changes and the Hopf point are marked.

HDF5 layout read (written by `squeal -analyses continuation`):
  /continuation/param, period, amplitude (n), stable (n, int), frac_separated, frac_stuck (n)
  /continuation/events/param (n_e), attribute types: comma-separated event names
  /continuation attribute parameter: "mu" or "v"
"""
import argparse
import os

import numpy as np

from ..results import open_results
from .common import plt

MARKERS = {"lift-off": "^", "separation-ends": "v", "stick": "s", "stick-ends": "D", "fold": "o",
           "period-doubling": "*", "neimark-sacker": "P", "cyclic-fold": "X", "hopf": "h"}


def read(path):
    with open_results(path) as r:
        g = r.require("continuation", ("param", "period", "amplitude", "stable"))
        d = {k: np.asarray(g[k]) for k in ("param", "period", "amplitude", "stable")}
        d["name"] = str(g.parameter)
        d["events"] = g.events()
    return d


def segments(x, y, stable):
    """Runs of equal stability, each sharing its end point with the next so the line is continuous."""
    start = 0
    for i in range(1, len(x) + 1):
        if i == len(x) or stable[i] != stable[start]:
            j = min(i + 1, len(x))
            yield x[start:j], y[start:j], bool(stable[start])
            start = i


def plot(paths, out, labels=()):
    fig, (ax1, ax2) = plt.subplots(2, 1, sharex=True, figsize=(7, 6))
    for k, path in enumerate(paths):
        d = read(path)
        colour = f"C{k}"
        label = labels[k] if k < len(labels) else os.path.basename(path)
        for n, (x, y, st) in enumerate(segments(d["param"], d["amplitude"], d["stable"])):
            ax1.plot(x, y, "-" if st else "--", color=colour, label=label if n == 0 else None)
        for x, y, st in segments(d["param"], d["period"], d["stable"]):
            ax2.plot(x, y, "-" if st else "--", color=colour)
        ax1.plot(d["param"], d["amplitude"], ".", color=colour, ms=3)
        for t, p in d["events"]:
            if t not in MARKERS:
                continue
            i = int(np.argmin(np.abs(d["param"] - p)))
            ax1.plot([p], [d["amplitude"][i]], MARKERS[t], color="k", mfc="none", ms=8)
            ax1.annotate(t, (p, d["amplitude"][i]), textcoords="offset points", xytext=(6, -10), fontsize=7)
        xlabel = "friction coefficient mu" if d["name"] == "mu" else "sliding speed V (m/s)"
    ax1.set_ylabel("amplitude: max peak-to-peak (m)")
    ax2.set_ylabel("period T (s)")
    ax2.set_xlabel(xlabel)
    ax1.legend(fontsize=8, title="solid: stable cycle, dashed: unstable", title_fontsize=8)
    for ax in (ax1, ax2):
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out, dpi=120)


def main(argv=None, prog=None):
    ap = argparse.ArgumentParser(prog=prog, description=__doc__.splitlines()[0])
    ap.add_argument("files", nargs="+")
    ap.add_argument("-o", "--output", required=True)
    ap.add_argument("--label", action="append", default=[])
    a = ap.parse_args(argv)
    plot(a.files, a.output, a.label)
    print(f"wrote {a.output}")
