"""Plot a squeal transient (limit cycle) from one results file.

Reads the /transient group written by `squeal -analyses transient` (t, U, V, R, status and the
attributes h, theta, period, ...) and draws one figure with
  (a) the time histories of three DOFs (for the 3-DOF model U_t, U_b, U_n) over the last
      few periods,
  (b) the phase portrait U vs dU of one DOF (default U_t): the whole run in light grey (the
      growth from the equilibrium onto the cycle) and the last periods coloured by the contact
      status, with the belt velocity V (the stick line) dashed,
  (c) the contact status strip (separated / stuck / sliding bands, one row per contact point)
      and the normal reaction r_n of one contact point over the same last periods.

The reactions are the one-step contact problem's unknowns; at an impact they carry the impulse
divided by h, so r_n has a spike of order m dU_n / h there. The r_n axis is clipped at the level
of the persistent contact force and the spikes are marked at the top edge instead.
"""

import argparse
import os

import numpy as np
from matplotlib.collections import LineCollection
from matplotlib.colors import ListedColormap
from matplotlib.patches import Patch

from ..results import PROG, fail, open_results
from .common import check_out_dir, plt, save_png

# Contact status codes written by squeal: 0 separated, 1 stuck, 2 sliding.
STATUS_NAMES = ("separated", "stuck", "sliding")
STATUS_COLOURS = ("#f4a259", "#3b7dd8", "#5bb36b")
DOF_COLOURS = ("#1f77b4", "#d62728", "#2ca02c")


def read_transient(path):
    with open_results(path) as r:
        g = r.require("transient", ("t", "U", "V"))
        d = {
            "t": g.array("t"),
            "U": g.array("U"),
            "V": g.array("V"),
            "R": g.array("R") if "R" in g else None,
            "status": g.array("status", int) if "status" in g else None,
        }
        for key in ("h", "theta", "period", "steps_per_period", "fraction_separated", "fraction_stuck",
                    "mean_fp_iterations", "complete"):
            d[key] = g.attrs.get(key)
        model = r.model if "model" in r else None
        d["model"] = model.get("name", "") if model is not None else ""
        d["V_belt"] = model.get("V") if model is not None else None
        d["mu"] = model.get("mu") if model is not None else None
        d["friction"] = model.get("friction", "") if model is not None else ""
        d["U_eq"] = np.asarray(r.h5["equilibrium/U"][()], dtype=float) if "equilibrium/U" in r else None
    n = d["t"].size
    if n < 2:
        fail(f"'{path}': /transient holds {n} record(s); nothing to plot")
    if d["U"].ndim != 2 or d["U"].shape[0] != n or d["V"].shape != d["U"].shape:
        fail(f"'{path}': /transient/U {d['U'].shape} and V {d['V'].shape} do not match t ({n},)")
    if d["R"] is not None and (d["R"].ndim != 3 or d["R"].shape[0] != n or d["R"].shape[2] != 3):
        fail(f"'{path}': /transient/R has shape {d['R'].shape}, expected ({n}, n_c, 3)")
    if d["status"] is not None and (d["status"].ndim != 2 or d["status"].shape[0] != n):
        fail(f"'{path}': /transient/status has shape {d['status'].shape}, expected ({n}, n_c)")
    return d


def parse_dofs(text, N):
    try:
        dofs = [int(x) for x in text.split(",") if x.strip() != ""]
    except ValueError:
        fail(f"--dofs '{text}': expected comma-separated integers")
    if not dofs or len(dofs) > 3:
        fail(f"--dofs '{text}': give one to three DOF indices")
    for j in dofs:
        if not 0 <= j < N:
            fail(f"--dofs: DOF {j} out of range (the model has {N} DOFs)")
    return dofs


def dof_label(d, j):
    if d["model"] == "three_dof" and d["U"].shape[1] == 3:
        return ("t", "b", "n")[j]
    return str(j)


def status_runs(st):
    """(start index, end index exclusive, value) of the runs of equal values in st."""
    if st.size == 0:
        return []
    cut = np.flatnonzero(np.diff(st)) + 1
    starts = np.concatenate(([0], cut))
    ends = np.concatenate((cut, [st.size]))
    return list(zip(starts, ends, st[starts]))


def plot(d, out, last_periods=5.0, dofs=(0, 1, 2), phase_dof=0, point=0, title=None, dpi=100):
    """Draws the transient `d` (read_transient) into the PNG `out`."""
    t, U, V = d["t"], d["U"], d["V"]
    N = U.shape[1]
    nc = d["status"].shape[1] if d["status"] is not None else 0

    # The window: the last few settled periods (the reference period if the cycle was not found).
    T = d["period"] if d["period"] and d["period"] > 0 else None
    if T is None and d["h"] and d["steps_per_period"]:
        T = d["h"] * d["steps_per_period"]
    if T is None:
        T = (t[-1] - t[0]) / 10
    t_from = max(t[0], t[-1] - last_periods * T)
    w = t >= t_from
    tw = t[w]
    ms = 1e3  # plot displacements in mm

    fig = plt.figure(figsize=(13.0, 7.4), dpi=dpi)
    gs = fig.add_gridspec(3, 2, width_ratios=(1.55, 1.0), height_ratios=(2.3, 0.42, 1.6),
                          left=0.065, right=0.985, bottom=0.075, top=0.835, wspace=0.2, hspace=0.14)
    ax_u = fig.add_subplot(gs[0, 0])
    ax_s = fig.add_subplot(gs[1, 0], sharex=ax_u)
    ax_r = fig.add_subplot(gs[2, 0], sharex=ax_u)
    ax_p = fig.add_subplot(gs[:, 1])

    # (a) time histories.
    for c, j in enumerate(dofs):
        lab = dof_label(d, j)
        p2p = np.ptp(U[w, j]) * ms
        p2p = 0.0 if p2p < 1e-9 * max(np.ptp(U[w]) * ms, 1e-300) else p2p  # round-off, e.g. U_n in contact
        ax_u.plot(tw, U[w, j] * ms, color=DOF_COLOURS[c % 3], lw=1.4,
                  label=f"$U_{{{lab}}}$ (p-p {p2p:.3g} mm)")
    ax_u.axhline(0.0, color="0.6", lw=0.6, zorder=0)
    ax_u.set_ylabel("displacement (mm)")
    ax_u.legend(loc="lower right", bbox_to_anchor=(1.0, 1.0), ncol=len(dofs), fontsize=9, frameon=False,
                borderaxespad=0.15, handlelength=1.5, columnspacing=1.2)
    ax_u.grid(alpha=0.3)
    ax_u.set_title("(a) displacements", loc="left", fontsize=11)
    ax_u.tick_params(labelbottom=False)

    # (c) contact status strip + normal reaction.
    cmap = ListedColormap(STATUS_COLOURS)
    if nc:
        st = d["status"][w]
        ax_s.imshow(st.T, aspect="auto", cmap=cmap, vmin=-0.5, vmax=2.5, interpolation="nearest",
                    extent=(tw[0], tw[-1], nc - 0.5, -0.5))
        ax_s.set_yticks(range(nc) if nc <= 6 else [0, nc - 1])
        ax_s.set_ylabel("point", fontsize=9)
        handles = [Patch(facecolor=STATUS_COLOURS[k], label=STATUS_NAMES[k]) for k in range(3)]
        ax_s.legend(handles=handles, loc="lower right", bbox_to_anchor=(1.0, 1.0), ncol=3, fontsize=9,
                    frameon=False, handlelength=1.5, borderaxespad=0.15, columnspacing=1.2)
        ax_s.set_title("(c) contact status and normal reaction", loc="left", fontsize=11)
    else:
        ax_s.text(0.5, 0.5, "no contact points", ha="center", va="center", transform=ax_s.transAxes)
        ax_s.set_yticks([])
    ax_s.tick_params(labelbottom=False)

    if d["R"] is not None and nc:
        rn = d["R"][w, point, 2]
        stp = d["status"][w, point]
        # Shade the separated intervals so that r_n = 0 there reads as "open", not as a dip.
        for i0, i1, v in status_runs(stp):
            if v == 0:
                ax_r.axvspan(tw[i0], tw[min(i1, tw.size - 1)], color=STATUS_COLOURS[0], alpha=0.18, lw=0)
        closed = rn[stp != 0]
        ax_r.plot(tw, rn, color="k", lw=1.1)
        top = None
        if closed.size:
            base = np.percentile(closed, 98.0)
            if rn.max() > 2.0 * base > 0:  # impact impulses / h dominate: clip and mark them
                top = 1.3 * base
                spikes = np.flatnonzero(rn > top)
                # one marker per impact (consecutive records belong to the same impact)
                if spikes.size:
                    keep = np.concatenate(([True], np.diff(spikes) > 1))
                    sp = spikes[keep]
                    ax_r.plot(tw[sp], np.full(sp.size, top * 0.955), "v", color="#c0392b", ms=7)
                    ax_r.set_title(f"\u25bc impacts: $r_n$ up to {rn.max() / 1e3:.3g} kN there "
                                   "(impulse / h), clipped", loc="right", fontsize=9, color="#c0392b")
                ax_r.set_ylim(min(0.0, rn.min()) - 0.03 * top, top)
        if top is None:
            lo, hi = min(0.0, rn.min()), max(rn.max(), 1e-300)
            ax_r.set_ylim(lo - 0.04 * (hi - lo), hi + 0.08 * (hi - lo))
        pt = f" (point {point})" if nc > 1 else ""
        ax_r.set_ylabel(f"$r_n${pt} (N)")
        ax_r.grid(alpha=0.3)
    else:
        ax_r.text(0.5, 0.5, "no reactions recorded", ha="center", va="center", transform=ax_r.transAxes)
    ax_r.set_xlabel(f"time t (s): the last {last_periods:g} periods of the run")
    ax_r.set_xlim(tw[0], tw[-1])

    # (b) phase portrait.
    jp = phase_dof
    lab = dof_label(d, jp)
    ax_p.plot(U[:, jp] * ms, V[:, jp], color="0.78", lw=0.5, zorder=1, label="whole run")
    pts = np.column_stack((U[w, jp] * ms, V[w, jp]))
    if nc:
        segs = np.stack((pts[:-1], pts[1:]), axis=1)
        stp = d["status"][w, point]
        lc = LineCollection(segs, colors=[STATUS_COLOURS[k] for k in stp[1:]], linewidths=2.0, zorder=3)
        ax_p.add_collection(lc)
        handles = [plt.Line2D([], [], color="0.78", lw=1.5, label="whole run (growth onto the cycle)")]
        for k in range(3):
            if np.any(stp == k):
                handles.append(plt.Line2D([], [], color=STATUS_COLOURS[k], lw=2.5,
                                          label=f"last {last_periods:g} periods: {STATUS_NAMES[k]}"))
    else:
        ax_p.plot(pts[:, 0], pts[:, 1], color=DOF_COLOURS[0], lw=1.8, zorder=3)
        handles = None
    if d["U_eq"] is not None and d["U_eq"].size == N:
        ax_p.plot(d["U_eq"][jp] * ms, 0.0, "kx", ms=8, mew=2, zorder=4)
        if handles is not None:
            handles.append(plt.Line2D([], [], color="k", marker="x", ls="", ms=7, mew=2,
                                      label="sliding equilibrium"))
    if d["V_belt"] is not None and lab == "t":
        ax_p.axhline(d["V_belt"], color="0.25", ls="--", lw=1.0, zorder=2)
        if handles is not None:
            handles.append(plt.Line2D([], [], color="0.25", ls="--", lw=1.0,
                                      label=f"$\\dot U_t$ = V = {d['V_belt']:g} m/s (stick)"))
    ax_p.set_xlabel(f"$U_{{{lab}}}$ (mm)")
    ax_p.set_ylabel(f"$\\dot U_{{{lab}}}$ (m/s)")
    ax_p.grid(alpha=0.3)
    ax_p.set_title(f"(b) phase portrait of $U_{{{lab}}}$", loc="left", fontsize=11)
    # Room at the top for the legend.
    y0, y1 = ax_p.get_ylim()
    ax_p.set_ylim(y0, y1 + 0.32 * (y1 - y0))
    if handles is not None:
        ax_p.legend(handles=handles, loc="upper left", fontsize=8.5, framealpha=0.92)

    # Title and summary line.
    if not title:
        bits = [d["model"] or "squeal"]
        if d["V_belt"] is not None:
            bits.append(f"V = {d['V_belt']:g} m/s")
        if d["mu"] is not None:
            bits.append(f"$\\mu$ = {d['mu']:g}")
        title = "transient: " + ", ".join(bits)
    fig.suptitle(title, x=0.065, ha="left", y=0.975, fontsize=13, fontweight="bold")
    summ = []
    if d["period"] and d["period"] > 0:
        summ.append(f"settled period {d['period'] * 1e3:.4f} ms ({1 / d['period']:.2f} Hz)")
    if nc and d["fraction_separated"] is not None and d["fraction_stuck"] is not None:
        fs, fk = d["fraction_separated"], d["fraction_stuck"]
        summ.append(f"last 20 %: separated {100 * fs:.1f} %, stuck {100 * fk:.1f} %, "
                    f"sliding {100 * (1 - fs - fk):.1f} %")
    num = []
    if d["h"]:
        spp = f" (T/{d['steps_per_period']:.0f})" if d["steps_per_period"] else ""
        num.append(f"h = {d['h']:.4g} s{spp}")
    if d["theta"] is not None:
        num.append(f"$\\theta$ = {d['theta']:g}")
    num.append(f"t = {t[-1]:.4g} s, {t.size} records")
    if d["complete"] is not None and not d["complete"]:
        num.append("INCOMPLETE RUN")
    fig.text(0.065, 0.922, "   |   ".join(summ), fontsize=10.5)
    fig.text(0.065, 0.893, ", ".join(num), fontsize=9, color="0.35")

    check_out_dir(out)
    save_png(fig, out, dpi)


def main(argv=None, prog=PROG):
    ap = argparse.ArgumentParser(prog=prog, description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("results", metavar="RESULTS.h5", help="squeal results file with a /transient group")
    ap.add_argument("-o", "--output", default=None, help="output PNG (default: RESULTS_transient.png)")
    ap.add_argument("--last-periods", type=float, default=5.0,
                    help="how many settled periods to show in (a), (c) and in colour in (b) (default 5)")
    ap.add_argument("--dofs", default="0,1,2", help="DOFs of panel (a), comma-separated (default 0,1,2)")
    ap.add_argument("--phase-dof", type=int, default=0, help="DOF of the phase portrait (default 0, U_t)")
    ap.add_argument("--point", type=int, default=0, help="contact point whose r_n is drawn (default 0)")
    ap.add_argument("--title", default=None, help="figure title")
    ap.add_argument("--dpi", type=int, default=100, help="resolution (default 100)")
    args = ap.parse_args(argv)

    if args.last_periods <= 0:
        fail("--last-periods must be > 0")
    d = read_transient(args.results)
    out = args.output or os.path.splitext(args.results)[0] + "_transient.png"
    N = d["U"].shape[1]
    dofs = parse_dofs(args.dofs, N)
    if not 0 <= args.phase_dof < N:
        fail(f"--phase-dof {args.phase_dof} out of range (the model has {N} DOFs)")
    nc = d["status"].shape[1] if d["status"] is not None else 0
    if nc and not 0 <= args.point < nc:
        fail(f"--point {args.point} out of range ({nc} contact point(s))")
    plot(d, out, args.last_periods, dofs, args.phase_dof, args.point, args.title, args.dpi)
    print(f"{PROG}: wrote {out}")
