"""Plot the eigenvalues of a squeal linear stability analysis in the complex plane.

Reads /stability/eigenvalues (k x 2: sigma = Re lambda in 1/s, omega = Im lambda in rad/s,
the omega >= 0 member of each conjugate pair) from one squeal results file and draws
sigma on the x axis against the frequency omega / (2 pi) in Hz on the y axis. Unstable
eigenvalues (sigma > 0) are drawn in red and labelled, stable ones in blue.
"""
import argparse
import os

import numpy as np

from ..results import PROG, fail, open_results
from .common import check_out_dir, house_style, plt, save_tight


def read_stability(path):
    """Finite eigenvalues (k x 2) and the model's name, friction, mu, V (mu of the equilibrium)."""
    with open_results(path) as r:
        ev = r.require("stability", ("eigenvalues",)).eigenvalues
        if ev.ndim != 2 or ev.shape[1] != 2:
            fail(f"'{path}': /stability/eigenvalues has shape {ev.shape}, expected (k, 2)")
        ev = ev[np.all(np.isfinite(ev), axis=1)]
        info = {k: v for k, v in r.model.items() if k in ("name", "friction", "mu", "V")}
        if r.equilibrium is not None and "mu" in r.equilibrium.attrs:
            info["mu"] = r.equilibrium.attrs["mu"]
    return ev, info


def plot(ev, info, out, mirror=False, title=None, dpi=120, source=""):
    """Draws the eigenvalues `ev` (k x 2) into `out`; the title from `info` unless given."""
    sigma, freq = ev[:, 0], ev[:, 1] / (2.0 * np.pi)
    unstable = sigma > 0.0

    house_style()
    fig, ax = plt.subplots(figsize=(6.4, 4.6))
    ax.set_axisbelow(True)

    stable_c, unstable_c = "#1f77b4", "#d62728"
    if mirror:
        ax.scatter(sigma[~unstable], -freq[~unstable], s=30, facecolors="none", edgecolors=stable_c,
                   alpha=0.5, zorder=3)
        ax.scatter(sigma[unstable], -freq[unstable], s=30, facecolors="none", edgecolors=unstable_c,
                   alpha=0.5, zorder=3)
        ax.axhline(0.0, color="0.4", lw=0.7, zorder=1)
    ax.scatter(sigma[~unstable], freq[~unstable], s=42, color=stable_c, marker="o", zorder=4,
               label=f"stable ({(~unstable).sum()})")
    ax.scatter(sigma[unstable], freq[unstable], s=60, color=unstable_c, marker="o", zorder=5,
               edgecolors="black", linewidths=0.5, label=f"unstable ({unstable.sum()})")

    # Axis limits: the complex plane from omega = 0 (or -max with --mirror) up, sigma = 0 included,
    # with room on the right for the labels.
    if ev.shape[0]:
        smin, smax = min(sigma.min(), 0.0), max(sigma.max(), 0.0)
        span = smax - smin if smax > smin else max(abs(smax), 1.0)
        ax.set_xlim(smin - 0.12 * span, smax + 0.35 * span)
        fmax = max(freq.max(), 1e-12)
        ax.set_ylim(-1.25 * fmax if mirror else 0.0, 1.25 * fmax)
    xlo, xhi = ax.get_xlim()
    ax.axvline(0.0, color="0.25", lw=0.9, zorder=2)
    if xhi > 0:
        ax.axvspan(0.0, xhi, color=unstable_c, alpha=0.05, lw=0, zorder=0)
        ax.text(0.99, 0.02, "unstable", transform=ax.transAxes, ha="right", va="bottom",
                fontsize=8, color="#b22222")
    ax.set_xlim(xlo, xhi)

    # Label the unstable eigenvalues (most unstable first), and all of them when there are few.
    order = np.argsort(-sigma)
    n_lab = len(order) if len(order) <= 8 else int(unstable.sum())
    for i in order[:n_lab]:
        ax.annotate(f"{freq[i]:.1f} Hz\n$\\sigma$ = {sigma[i]:.1f} 1/s",
                    (sigma[i], freq[i]), xytext=(7, 5), textcoords="offset points",
                    fontsize=7.5, color=unstable_c if unstable[i] else "0.3")

    ax.set_xlabel(r"growth rate $\sigma$ = Re $\lambda$ (1/s)")
    ax.set_ylabel(r"frequency $\omega / 2\pi$ (Hz)")
    if title is None:
        parts = []
        if "name" in info:
            parts.append(str(info["name"]))
        if "mu" in info:
            parts.append(f"$\\mu$ = {float(info['mu']):g}")
        if "V" in info:
            parts.append(f"V = {float(info['V']):g} m/s")
        title = ", ".join(parts) if parts else os.path.basename(source)
    if title:
        ax.set_title(title, fontsize=10)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False, borderaxespad=0.0)

    save_tight(fig, out, dpi)


def main(argv=None, prog=PROG):
    ap = argparse.ArgumentParser(
        prog=prog,
        description="Plot the eigenvalues of /stability/eigenvalues of a squeal results file "
                    "in the complex plane (growth rate vs frequency); unstable ones in red.")
    ap.add_argument("file", metavar="RESULTS.h5", help="squeal results file with a /stability group")
    ap.add_argument("-o", "--output", default=None, metavar="OUT.png",
                    help="output image (default: RESULTS_stability.png next to the input)")
    ap.add_argument("--mirror", action="store_true",
                    help="also draw the complex-conjugate members (negative frequencies)")
    ap.add_argument("--title", default=None, help="figure title (default: model, mu and V from the file)")
    ap.add_argument("--dpi", type=int, default=120, help="resolution (default: 120)")
    args = ap.parse_args(argv)

    ev, info = read_stability(args.file)
    out = args.output or os.path.splitext(args.file)[0] + "_stability.png"
    check_out_dir(out)
    plot(ev, info, out, args.mirror, args.title, args.dpi, args.file)
    print(f"wrote {out}")
    return 0
