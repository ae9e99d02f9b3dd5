"""Plot the stability map (friction-coefficient sweep) written by squeal.

Reads the /sweep group of one or more squeal results files and draws a two-panel
figure against the friction coefficient mu:

  top     growth rate sigma = Re(lambda) (1/s) of every eigenvalue, with sigma = 0 marked
  bottom  frequency omega / (2 pi) (Hz) of every eigenvalue

One colour per file, or per sliding velocity V when a file holds several V values.
A dashed vertical line marks each critical mu (flutter onset), its value in the legend.

HDF5 layout read (written by `squeal -analyses sweep`):
  /sweep/mu           (n_mu)
  /sweep/V            (n_V), attribute units = m/s
  /sweep/eigenvalues  (n_V, n_mu, k, 2): [..., 0] = sigma (1/s), [..., 1] = omega (rad/s), NaN: absent
  /sweep/failed       (n_V, n_mu) int, 1 = no steady sliding at that point (skipped)
  /sweep attributes   critical_mu (n_V, NaN: no crossing), coalescence_frequency (n_V, Hz)
"""
import argparse
import os

import numpy as np

from ..results import PROG, fail, open_results
from .common import check_out_dir, house_style, plt, save_tight

DESCRIPTION = ("Plot growth rate and frequency of every eigenvalue against the friction coefficient from the /sweep "
               "group of squeal results files.")


def read_sweep(path):
    """Return a list of dicts, one per V value of the sweep in `path` (squeal.results.Sweep.runs)."""
    with open_results(path) as r:
        return r.require("sweep", ("mu", "eigenvalues")).runs(path)


def plot(series, out, title=None, dpi=120):
    """`series`: runs of read_sweep, each with a "label"."""
    house_style(**{"axes.titlesize": 10, "axes.labelsize": 10})
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]

    fig, (ax_s, ax_f) = plt.subplots(2, 1, sharex=True, figsize=(7.0, 6.2),
                                     gridspec_kw=dict(hspace=0.08))
    ax_s.axhline(0.0, color="0.25", lw=0.9, zorder=1)
    many = len(series) > 1
    mu_lo, mu_hi = np.inf, -np.inf
    for n, r in enumerate(series):
        c = colours[n % len(colours)]
        mu = r["mu"]
        mu_lo, mu_hi = min(mu_lo, np.nanmin(mu)), max(mu_hi, np.nanmax(mu))
        k = r["sigma"].shape[1]
        ms = 2.6 if many else 3.0
        for s in range(k):
            sig, om = r["sigma"][:, s], r["omega"][:, s]
            ax_s.plot(mu, sig, ls="none", marker="o", ms=ms, mew=0, color=c, alpha=0.85,
                      label=r["label"] if s == 0 else None, zorder=3)
            ax_f.plot(mu, om / (2.0 * np.pi), ls="none", marker="o", ms=ms, mew=0, color=c,
                      alpha=0.85, zorder=3)
        if r["failed"].any():  # mark points without steady sliding on the sigma = 0 line
            ax_s.plot(mu[r["failed"]], np.zeros(r["failed"].sum()), ls="none", marker="x", ms=4,
                      color=c, alpha=0.7, label=f"{r['label']}: no steady sliding", zorder=2)
        if np.isfinite(r["mu_c"]):
            txt = f"$\\mu_c$ = {r['mu_c']:.4f}"
            if np.isfinite(r["f_c"]):
                txt += f" ($f$ = {r['f_c']:.1f} Hz)"
            for ax in (ax_s, ax_f):
                ax.axvline(r["mu_c"], color=c, ls="--", lw=1.1, alpha=0.9, zorder=2,
                           label=txt if ax is ax_s else None)
            if np.isfinite(r["f_c"]):
                ax_f.plot([r["mu_c"]], [r["f_c"]], marker="D", ms=5, mfc="white", mec=c, mew=1.3, zorder=4)

    ax_s.set_ylabel(r"growth rate $\sigma$ = Re $\lambda$ (1/s)")
    ax_f.set_ylabel(r"frequency $\omega / 2\pi$ (Hz)")
    ax_f.set_xlabel(r"friction coefficient $\mu$ (–)")
    if np.isfinite(mu_lo) and mu_hi > mu_lo:
        ax_f.set_xlim(mu_lo, mu_hi)
    # Shade the unstable half (sigma > 0) lightly.
    ylo, yhi = ax_s.get_ylim()
    if yhi > 0:
        ax_s.axhspan(0, yhi, color="#d62728", alpha=0.05, lw=0, zorder=0)
        ax_s.text(0.01, 0.97, "unstable", transform=ax_s.transAxes, ha="left", va="top",
                  fontsize=8, color="#b22222")
    ax_s.set_ylim(ylo, yhi)
    ax_s.legend(loc="lower left", frameon=True, framealpha=0.92, edgecolor="0.8", markerscale=2.0)
    if title:
        ax_s.set_title(title)
    for ax in (ax_s, ax_f):
        ax.set_axisbelow(True)
    fig.align_ylabels((ax_s, ax_f))

    check_out_dir(out)
    save_tight(fig, out, dpi)


def main(argv=None, prog=PROG):
    ap = argparse.ArgumentParser(prog=prog, description=DESCRIPTION)
    ap.add_argument("files", nargs="+", metavar="RESULTS.h5", help="squeal results file(s) with a /sweep group")
    ap.add_argument("-o", "--output", required=True, metavar="OUT.png", help="output image (PNG)")
    ap.add_argument("--label", action="append", default=[], metavar="LABEL",
                    help="legend label, once per file in order (default: file name and V)")
    ap.add_argument("--title", default=None, help="figure title (default: none)")
    ap.add_argument("--dpi", type=int, default=120, help="resolution (default: 120)")
    args = ap.parse_args(argv)

    if args.label and len(args.label) != len(args.files):
        fail(f"got {len(args.label)} --label value(s) for {len(args.files)} file(s); give one per file or none")

    series = []
    for j, path in enumerate(args.files):
        runs = read_sweep(path)
        for r in runs:
            vtxt = f"V = {r['V']:g} {r['V_units']}" if np.isfinite(r["V"]) else ""
            if args.label:
                lab = args.label[j] + (f", {vtxt}" if len(runs) > 1 and vtxt else "")
            else:
                stem = os.path.splitext(os.path.basename(path))[0]
                lab = f"{stem}, {vtxt}" if vtxt else stem
            r["label"] = lab
            series.append(r)
    plot(series, args.output, args.title, args.dpi)
    print(f"wrote {args.output}")
    return 0
