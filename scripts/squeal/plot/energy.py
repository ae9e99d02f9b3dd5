"""Energy estimate of a squeal results file: mean damping power and mean (saturated) reaction
power against the modal amplitude q, and their first balance q0 (docs/method.md §7).

    plot_energy.py RESULTS.h5 [RESULTS2.h5 ...] -o energy.png [--label LABEL ...]
"""
import argparse

from ..results import fail, open_results
from .common import plt


def plot(paths, out, labels=(), dpi=120, span=3.0):
    fig, ax = plt.subplots(figsize=(7, 4.5))
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    qmax, pmax = 0.0, 0.0
    for i, path in enumerate(paths):
        with open_results(path) as r:
            g = r.require("energy")
            if "q" not in g:
                fail(f"'{path}' has no amplitude scan in /energy (the sliding equilibrium was stable)")
            q, pc, pr = g["q"] * 1e3, g["P_damping"], g["P_reactions"]
        label = labels[i] if labels else path
        c = colours[i % len(colours)]
        ax.plot(q, pr, color=c, lw=1.8, label=f"{label}: reactions $\\bar P_R$")
        ax.plot(q, pc, color=c, lw=1.2, ls="--", label=f"{label}: damping $\\bar P_c$")
        if g.attrs.get("found", 0):
            q0 = g.attrs["q0"] * 1e3
            ax.axvline(q0, color=c, lw=0.8, ls=":")
            k = abs(q - q0).argmin()
            ax.plot([q0], [pc[k]], "o", color=c, label=f"{label}: $q_0$ = {q0:.3f} mm")
            qmax = max(qmax, span * q0)
        sel = q <= (qmax if qmax > 0 else q[-1])
        pmax = max(pmax, pr[sel].max(), pc[sel].max())
    ax.set_xlabel("modal amplitude q (mm, largest tangential contact component of $\\phi$)")
    ax.set_ylabel("mean power over a period (W)")
    ax.set_xlim(0, qmax if qmax > 0 else None)
    ax.set_ylim(0, 1.1 * pmax if pmax > 0 else None)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title("Energy estimate of the limit-cycle amplitude")
    fig.tight_layout()
    fig.savefig(out, dpi=dpi)


def main(argv=None, prog=None):
    ap = argparse.ArgumentParser(prog=prog, description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("files", nargs="+")
    ap.add_argument("-o", "--output", required=True)
    ap.add_argument("--label", action="append", default=[])
    ap.add_argument("--dpi", type=int, default=120)
    ap.add_argument("--span", type=float, default=3.0, help="plot q up to this multiple of the largest q0")
    a = ap.parse_args(argv)
    if a.label and len(a.label) != len(a.files):
        fail("give one --label per file")
    plot(a.files, a.output, a.label, a.dpi, a.span)
    print(f"plot_energy: wrote {a.output}")
