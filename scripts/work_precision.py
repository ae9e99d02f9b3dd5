#!/usr/bin/python3
"""Work-precision study of the squeal transient (theta-method) on the two 3-DOF reference cases.

For case 1 (V = 3 m/s, separation/slip) and case 2 (V = 0.75 m/s, stick/slip) this runs
`squeal -analyses transient` for the same simulated duration (-transient_periods, in periods of
the unstable linear mode) at 125 ... 8000 steps per period with the fixed-point tolerance 1e-12,
and at 1000 steps per period also with the tolerances 1e-6 and 1e-9. Each run is timed with
time.perf_counter around the subprocess (the whole program: equilibrium, stability, transient
and the HDF5 output; the minimum over --repeat runs), and the settled-cycle period and the
peak-to-peak amplitudes are parsed from the stdout summary. Errors are taken against the finest
run (8000 steps per period, tolerance 1e-12): the relative error of the period and of the largest
peak-to-peak amplitude (U_t in both cases).

Precision of the numbers: stdout prints the period with 6 and the amplitudes with 5 significant
digits, which would floor the relative errors at ~1e-6 and ~1e-5. The script therefore also reads
the same quantities at full precision from the results file (the /transient period attribute;
the peak-to-peak amplitudes recomputed from /transient/U exactly as squeal does, over the last
20 % of the records), checks that they agree with stdout to the printed digits and uses them
for the errors. squeal computes the summary from the recorded steps, so -transient_keep_every k
is chosen as steps_per_period / --records-per-period (default 500 records per period, k = 1 up
to 500 steps per period): that keeps the files small and the recording cost the same in every
run. The effect of k is checked on the reference run of each case (rerun with k = 1) and
reported. The script also checks that the cycle has settled (period and amplitude over the
60-80 % and the 80-100 % windows of the run) and warns when they drift.

Outputs: work_precision.csv (case, steps_per_period, fp_tol, wall_s, period, p2p_t, p2p_b, p2p_n,
err_period, err_amplitude) and work_precision.png (error vs wall time, log-log, plus error vs
steps per period); the observed convergence orders are printed: the slope of log err vs log h
between successive step sizes (errors against the finest run) and, as a check that does not
depend on the reference, the order from successive differences of the computed quantity.

Usage:
  work_precision.py --squeal PATH [--out-dir DIR] [--csv FILE] [--quick] [--periods P]
                    [--repeat R] [--records-per-period N] [--examples DIR]
"""

import argparse
import csv
import math
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

try:
    import h5py  # noqa: E402
except ImportError:  # pragma: no cover
    sys.exit("work_precision.py: error: the h5py module is required (apt-get install python3-h5py)")

PROG = os.path.basename(sys.argv[0]) if sys.argv and sys.argv[0] else "work_precision.py"
HERE = os.path.dirname(os.path.abspath(__file__))

CASES = (("case1", "case1_separation_slip.yaml", "case 1: V = 3 m/s (separation/slip)"),
         ("case2", "case2_stick_slip.yaml", "case 2: V = 0.75 m/s (stick/slip)"))
CASE_COLOURS = {"case1": "#1f77b4", "case2": "#d95f02"}
FULL_STEPS = (125, 250, 500, 1000, 2000, 4000, 8000)
QUICK_STEPS = (125, 250, 500, 1000, 2000)
TOLS = (1e-6, 1e-9, 1e-12)
TOL_STEPS = 1000  # the steps per period of the tolerance study
REF_TOL = 1e-12

CSV_COLUMNS = ("case", "steps_per_period", "fp_tol", "wall_s", "period", "p2p_t", "p2p_b", "p2p_n",
               "err_period", "err_amplitude")

RE_PERIOD = re.compile(r"settled cycle period\s+([-+0-9.eE]+)\s*s")
RE_P2P = re.compile(r"peak-to-peak \(m\), last 20 %:\s*(.+)")
RE_STEPS = re.compile(r"transient:\s*(\d+)\s+steps of h =\s*([-+0-9.eE]+)\s*s")
RE_CONTACT = re.compile(r"contact, last 20 %: separated\s*([0-9.]+) %, stuck\s*([0-9.]+) %, "
                        r"sliding\s*([0-9.]+) %(?:\s*\(([^)]*)\))?")
RE_FP = re.compile(r"mean fixed-point passes per step\s+([0-9.eE+-]+)")


def fail(msg):
    print(f"{PROG}: error: {msg}", file=sys.stderr)
    sys.exit(1)


def warn(msg):
    print(f"{PROG}: warning: {msg}", file=sys.stderr)


# --------------------------------------------------------------------------------------------
# One run.

def parse_summary(text, cmd):
    """The transient summary printed by squeal (period, peak-to-peak amplitudes, ...)."""
    m_steps, m_per, m_p2p = RE_STEPS.search(text), RE_PERIOD.search(text), RE_P2P.search(text)
    if not (m_steps and m_per and m_p2p):
        tail = "\n".join(text.strip().splitlines()[-12:])
        fail("could not find the transient summary (steps, settled cycle period, peak-to-peak) in the "
             f"output of\n  {' '.join(cmd)}\n--- last lines of stdout ---\n{tail}")
    p2p = [float(x) for x in m_p2p.group(1).replace("...", "").split(",") if x.strip()]
    out = {"steps": int(m_steps.group(1)), "h": float(m_steps.group(2)), "period": float(m_per.group(1)),
           "p2p": p2p}
    m = RE_CONTACT.search(text)
    if m:
        out["contact"] = (float(m.group(1)), float(m.group(2)), float(m.group(3)), m.group(4) or "")
    m = RE_FP.search(text)
    if m:
        out["fp"] = float(m.group(1))
    return out


def summarise_records(t, U, a, b):
    """squeal's summary (TransientAnalysis::Summarise) on the records a..b-1: the peak-to-peak of
    every DOF and the mean spacing of the up-crossings of the mid-range of the DOF with the largest
    peak-to-peak, the crossings linearly interpolated in time."""
    u, tt = U[a:b], t[a:b]
    p2p = u.max(axis=0) - u.min(axis=0)
    x = u[:, int(np.argmax(p2p))]
    mid = 0.5 * (x.min() + x.max())
    xa, xb = x[:-1] - mid, x[1:] - mid
    k = np.flatnonzero((xa < 0) & (xb >= 0))
    cross = tt[k] + (tt[k + 1] - tt[k]) * (-xa[k]) / (xb[k] - xa[k])
    period = (cross[-1] - cross[0]) / (cross.size - 1) if cross.size >= 2 else 0.0
    return period, p2p


def read_full_precision(path):
    """Period (attribute) and peak-to-peak amplitudes over the last 20 % of the records (squeal's
    window) at full precision, plus the same over the preceding 20 % for the settling check."""
    if not os.path.isfile(path):
        fail(f"squeal did not write '{path}'")
    with h5py.File(path, "r") as f:
        if "transient" not in f:
            fail(f"'{path}' has no /transient group")
        g = f["transient"]
        for name in ("t", "U"):
            if name not in g:
                fail(f"'{path}': /transient/{name} is missing")
        t = np.asarray(g["t"][()], dtype=float)
        U = np.asarray(g["U"][()], dtype=float)
        attr_period = float(g.attrs["period"]) if "period" in g.attrs else None
        complete = int(g.attrs["complete"]) if "complete" in g.attrs else 1
    n = t.size
    if n < 10:
        fail(f"'{path}': only {n} records")
    win = max(n // 5, 2)
    period, p2p = summarise_records(t, U, n - win, n)
    period_prev, p2p_prev = summarise_records(t, U, n - 2 * win, n - win + 1)
    return {"period": attr_period if attr_period else period, "period_records": period, "p2p": p2p,
            "period_prev": period_prev, "p2p_prev": p2p_prev, "records": n, "complete": complete}


def run_squeal(squeal, scene, periods, steps, tol, keep_every, h5, repeat, summary=True):
    cmd = [squeal, "-scene", scene, "-analyses", "transient", "-transient_periods", f"{periods:g}",
           "-transient_steps_per_period", str(steps), "-transient_keep_every", str(keep_every),
           "-theta_fp_tol", f"{tol:g}", "-output", h5]
    walls = []
    for _ in range(max(1, repeat)):
        if os.path.exists(h5):
            os.remove(h5)
        t0 = time.perf_counter()
        try:
            p = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        except OSError as e:
            fail(f"cannot run '{squeal}': {e}")
        walls.append(time.perf_counter() - t0)
        if p.returncode != 0:
            tail = "\n".join((p.stderr or p.stdout).strip().splitlines()[-15:])
            fail(f"squeal failed (exit {p.returncode}):\n  {' '.join(cmd)}\n{tail}")
    if not summary:
        return {"wall": min(walls), "walls": walls, "cmd": cmd}
    s = parse_summary(p.stdout, cmd)
    if "pass limit hit" in p.stdout:
        warn(f"the contact fixed point hit its pass limit in {' '.join(cmd)}")
    full = read_full_precision(h5)
    if not full["complete"]:
        warn(f"the run {' '.join(cmd)} is marked incomplete")
    # The full-precision numbers must round to what squeal printed.
    if abs(full["period"] - s["period"]) > 0.6e-7 + 1e-12:
        warn(f"period from the file {full['period']:.10g} s does not match stdout {s['period']} s ({' '.join(cmd)})")
    for j, (a, b) in enumerate(zip(full["p2p"], s["p2p"])):
        if abs(a - b) > 0.6e-4 * max(abs(b), 1e-300) and abs(b) > 1e-15:
            warn(f"peak-to-peak of DOF {j} from the file {a:.8g} does not match stdout {b:.4e}")
    return {"wall": min(walls), "walls": walls, "stdout": s, "full": full, "cmd": cmd}


# --------------------------------------------------------------------------------------------
# Orders.

def orders_vs_ref(hs, errs):
    """Slope of log err vs log h between successive step sizes (None where an error is zero)."""
    out = []
    for i in range(len(hs) - 1):
        e0, e1 = errs[i], errs[i + 1]
        out.append(math.log(e0 / e1) / math.log(hs[i] / hs[i + 1]) if e0 > 0 and e1 > 0 else None)
    return out


def orders_successive(hs, q):
    """Order from successive differences d_i = q_i - q_{i+1}: p = log(|d_i| / |d_{i+1}|) / log(h_i / h_{i+1})."""
    d = [q[i] - q[i + 1] for i in range(len(q) - 1)]
    out = []
    for i in range(len(d) - 1):
        out.append(math.log(abs(d[i]) / abs(d[i + 1])) / math.log(hs[i] / hs[i + 1])
                   if d[i] != 0 and d[i + 1] != 0 else None)
    return out


def fmt_order(p):
    return "   -  " if p is None else f"{p:6.2f}"


# --------------------------------------------------------------------------------------------
# Figure.

def plot(rows, steps, out_png, title_extra, fixed_wall=None):
    from matplotlib.lines import Line2D
    from matplotlib.ticker import FormatStrFormatter, LogLocator

    fig, axes = plt.subplots(1, 3, figsize=(15.0, 5.4), dpi=100,
                             gridspec_kw={"width_ratios": (1, 1, 1), "wspace": 0.27})
    kinds = (("err_period", "relative error of the period", "o"),
             ("err_amplitude", "relative error of the max peak-to-peak amplitude", "s"))
    walls = [r["wall_s"] for r in rows if r["err_period"] > 0 or r["err_amplitude"] > 0]
    walls += [fixed_wall] if fixed_wall else []
    for ax, (key, label, marker) in zip(axes[:2], kinds):
        for case, _, clabel in CASES:
            rs = [r for r in rows if r["case"] == case and r["fp_tol"] == REF_TOL and r[key] > 0]
            rs.sort(key=lambda r: r["steps_per_period"])
            if not rs:
                continue
            col = CASE_COLOURS[case]
            ax.plot([r["wall_s"] for r in rs], [r[key] for r in rs], "-", marker=marker, color=col, ms=7, lw=1.3)
            right = case == CASES[0][0]  # case 1 labelled to the right of its points, case 2 to the left
            for r in rs:
                ax.annotate(f"{r['steps_per_period']}", (r["wall_s"], r[key]), textcoords="offset points",
                            xytext=(7, 2) if right else (-7, -9), ha="left" if right else "right", fontsize=8,
                            color=col)
            tr = [r for r in rows if r["case"] == case and r["fp_tol"] != REF_TOL and r[key] > 0]
            for r in tr:
                ax.plot(r["wall_s"], r[key], marker="^" if r["fp_tol"] > 1e-8 else "v", ls="", ms=9, mfc="none",
                        mec=col, mew=1.5)
        if fixed_wall:
            ax.axvline(fixed_wall, color="0.45", ls=":", lw=1.2)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlim(min(walls) / 1.25, max(walls) * 1.35)
        ax.xaxis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 3.0, 5.0)))
        ax.xaxis.set_minor_locator(LogLocator(base=10, subs=tuple(range(1, 10))))
        ax.xaxis.set_major_formatter(FormatStrFormatter("%g"))
        ax.xaxis.set_minor_formatter(FormatStrFormatter(""))
        ax.set_xlabel("wall time of the run (s)")
        ax.set_ylabel(label)
        ax.grid(True, which="both", alpha=0.25)
        ax.set_title(("(a) period" if key == "err_period" else "(b) amplitude") +
                     ": error vs wall time", loc="left", fontsize=11)
    handles = [Line2D([], [], color=CASE_COLOURS[c], lw=1.3, label=lab) for c, _, lab in CASES]
    handles += [Line2D([], [], color="0.3", marker="o", ls="", label="period error"),
                Line2D([], [], color="0.3", marker="s", ls="", label="amplitude error"),
                Line2D([], [], color="0.3", marker="^", mfc="none", ls="", ms=8,
                       label=f"{TOL_STEPS} steps/period, fixed-point tol 1e-6"),
                Line2D([], [], color="0.3", marker="v", mfc="none", ls="", ms=8, label=f"{TOL_STEPS} steps/period, tol 1e-9")]
    if fixed_wall:
        handles.append(Line2D([], [], color="0.45", ls=":", lw=1.2,
                              label=f"fixed cost of a run ({fixed_wall:.2f} s, 1 period)"))
    fig.legend(handles=handles, loc="lower center", ncol=4, fontsize=8.5, frameon=False,
               bbox_to_anchor=(0.5, 0.0))
    # (c) error vs steps per period with slope guides.
    ax = axes[2]
    for case, _, clabel in CASES:
        col = CASE_COLOURS[case]
        for key, label, marker in kinds:
            rs = [r for r in rows if r["case"] == case and r["fp_tol"] == REF_TOL and r[key] > 0]
            rs.sort(key=lambda r: r["steps_per_period"])
            if rs:
                ax.plot([r["steps_per_period"] for r in rs], [r[key] for r in rs], "-" if key == "err_period" else "--",
                        marker=marker, color=col, ms=6, lw=1.2,
                        label=f"{clabel.split(':')[0]}, {'period' if key == 'err_period' else 'amplitude'}")
    S = np.array([min(steps), max(steps) / 2], dtype=float)
    first = [r[k] for r in rows for k in ("err_period", "err_amplitude")
             if r["fp_tol"] == REF_TOL and r["steps_per_period"] == min(steps) and r[k] > 0]
    anchor = 2.0 * max(first) if first else 1e-3
    for p, ls in ((1, ":"), (2, "-.")):
        ax.plot(S, anchor * (S / S[0]) ** (-p), color="0.4", ls=ls, lw=1.0)
        ax.annotate(f"order {p}", (S[-1], anchor * (S[-1] / S[0]) ** (-p)), fontsize=8, color="0.3",
                    textcoords="offset points", xytext=(4, -2))
    ax.set_xscale("log", base=2)
    ax.set_yscale("log")
    ax.set_xticks(list(steps))
    ax.set_xticklabels([str(s) for s in steps], fontsize=8)
    ax.set_xlabel("steps per period  (h = T_lin / steps)")
    ax.set_ylabel("relative error vs the finest run")
    ax.grid(True, which="both", alpha=0.25)
    ax.legend(fontsize=8, loc="lower left", framealpha=0.9)
    ax.set_title("(c) error vs step size (tol 1e-12)", loc="left", fontsize=11)
    fig.suptitle("squeal transient, theta = 0.5: work-precision on the 3-DOF cases " + title_extra,
                 x=0.06, ha="left", fontsize=12.5, fontweight="bold")
    fig.subplots_adjust(left=0.06, right=0.985, bottom=0.22, top=0.87)
    save_png(fig, out_png)


def save_png(fig, out):
    """Save as PNG, quantised to a 256-colour palette when Pillow is there (a third of the size)."""
    try:
        from PIL import Image
    except ImportError:  # pragma: no cover
        fig.savefig(out)
        return
    import io
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    buf.seek(0)
    with Image.open(buf) as im:
        im.convert("RGB").quantize(colors=256, method=Image.Quantize.MEDIANCUT).save(out, optimize=True)


# --------------------------------------------------------------------------------------------

def main():
    ap = argparse.ArgumentParser(prog=PROG, description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--squeal", required=True, help="path of the squeal executable")
    ap.add_argument("--out-dir", default=".", help="directory of work_precision.png (and of the CSV unless --csv)")
    ap.add_argument("--csv", default=None, help="CSV path (default OUT_DIR/work_precision.csv)")
    ap.add_argument("--quick", action="store_true",
                    help="smoke test: 125 ... 1000 steps per period against 2000, fewer periods")
    ap.add_argument("--periods", type=float, default=None,
                    help="simulated duration in periods of the linear mode (default 200, quick 50)")
    ap.add_argument("--repeat", type=int, default=1, help="run each case R times, keep the least wall time")
    ap.add_argument("--records-per-period", type=int, default=500,
                    help="-transient_keep_every = max(1, steps_per_period // N) (default 500)")
    ap.add_argument("--examples", default=os.path.join(HERE, "..", "examples", "three_dof"),
                    help="directory of the case YAML files (default: ../examples/three_dof next to this script)")
    ap.add_argument("--no-keep-check", action="store_true",
                    help="skip the rerun of each reference with -transient_keep_every 1")
    args = ap.parse_args()

    squeal = os.path.abspath(args.squeal)
    if not os.path.isfile(squeal):
        fail(f"squeal executable '{args.squeal}' not found (build it: cd build && make squeal_app)")
    if not os.access(squeal, os.X_OK):
        fail(f"'{args.squeal}' is not executable")
    scenes = {}
    for case, yaml, _ in CASES:
        p = os.path.abspath(os.path.join(args.examples, yaml))
        if not os.path.isfile(p):
            fail(f"scene file '{p}' not found (see --examples)")
        scenes[case] = p
    if not os.path.isdir(args.out_dir):
        fail(f"output directory '{args.out_dir}' does not exist")
    csv_path = args.csv or os.path.join(args.out_dir, "work_precision.csv")
    if not os.path.isdir(os.path.dirname(os.path.abspath(csv_path))):
        fail(f"directory of '{csv_path}' does not exist")
    png_path = os.path.join(args.out_dir, "work_precision.png")
    if args.records_per_period < 1:
        fail("--records-per-period must be >= 1")

    steps = QUICK_STEPS if args.quick else FULL_STEPS
    periods = args.periods if args.periods else (50.0 if args.quick else 200.0)
    ref_steps = steps[-1]
    plan = [(s, REF_TOL) for s in steps] + [(TOL_STEPS, tol) for tol in TOLS if tol != REF_TOL]

    def keep_for(s):
        return max(1, s // args.records_per_period)

    print(f"squeal: {squeal} (the study runs a private copy of it)")
    print(f"duration {periods:g} periods of the linear mode; steps per period {', '.join(map(str, steps))}; "
          f"tolerances {', '.join(f'{t:g}' for t in TOLS)} at {TOL_STEPS}; reference {ref_steps} steps, tol {REF_TOL:g}; "
          f"keep_every = steps // {args.records_per_period}; wall time = min over {max(1, args.repeat)} run(s)")
    rows, orders = [], {}
    with tempfile.TemporaryDirectory(prefix="squeal_wp_") as tmp:
        # Run a private copy, so that a rebuild of the executable during the study cannot mix two builds.
        snap = os.path.join(tmp, "squeal")
        try:
            shutil.copy2(squeal, snap)
        except OSError as e:
            fail(f"cannot copy '{squeal}' to '{snap}': {e}")
        squeal = snap
        # The fixed cost of one run (start-up, equilibrium, stability, output), a 1-period transient.
        r0 = run_squeal(squeal, scenes[CASES[0][0]], 1, min(steps), REF_TOL, 1, os.path.join(tmp, "fixed.h5"),
                        max(3, args.repeat), summary=False)
        fixed_wall = r0["wall"]
        print(f"fixed cost of a run (1 period at {min(steps)} steps/period, min of {max(3, args.repeat)}): "
              f"{fixed_wall:.3f} s")
        for case, _, clabel in CASES:
            print(f"\n== {clabel}")
            print(f"  {'steps':>6} {'tol':>7} {'keep':>4} {'wall s':>7} {'period (s)':>16} {'p2p_t (m)':>13} "
                  f"{'p2p_b (m)':>12} {'p2p_n (m)':>10}  {'fp':>5}  contact (sep/stuck/slide %)  settle drift")
            res = {}
            for s, tol in plan:
                h5 = os.path.join(tmp, f"{case}_{s}_{tol:g}.h5")
                r = run_squeal(squeal, scenes[case], periods, s, tol, keep_for(s), h5, args.repeat)
                os.remove(h5)
                res[(s, tol)] = r
                f = r["full"]
                drift_p = abs(f["period"] - f["period_prev"]) / f["period"] if f["period_prev"] else float("inf")
                jm = int(np.argmax(f["p2p"]))
                drift_a = abs(f["p2p"][jm] - f["p2p_prev"][jm]) / f["p2p"][jm]
                r["drift"] = (drift_p, drift_a)
                c = r["stdout"].get("contact")
                cs = f"{c[0]:5.1f} {c[1]:5.1f} {c[2]:5.1f} ({c[3]})" if c else "-"
                p2p = list(f["p2p"]) + [float("nan")] * (3 - len(f["p2p"]))
                print(f"  {s:6d} {tol:7.0e} {keep_for(s):4d} {r['wall']:7.3f} {f['period']:16.10e} {p2p[0]:13.7e} "
                      f"{p2p[1]:12.6e} {p2p[2]:10.3e}  {r['stdout'].get('fp', float('nan')):5.2f}  {cs:28s}  "
                      f"{drift_p:.1e} / {drift_a:.1e}", flush=True)
                if drift_p > 1e-4 or drift_a > 1e-3:
                    warn(f"{case}, {s} steps/period, tol {tol:g}: the cycle has not settled (period drift "
                         f"{drift_p:.2e}, amplitude drift {drift_a:.2e} between the 60-80 % and 80-100 % windows); "
                         "use more --periods")
            ref = res[(ref_steps, REF_TOL)]
            P_ref = ref["full"]["period"]
            A_ref = float(np.max(ref["full"]["p2p"]))
            # Effect of -transient_keep_every on the reference (the summary is computed from records).
            if not args.no_keep_check and keep_for(ref_steps) > 1:
                h5 = os.path.join(tmp, f"{case}_keep1.h5")
                r1 = run_squeal(squeal, scenes[case], periods, ref_steps, REF_TOL, 1, h5, 1)
                os.remove(h5)
                dP = abs(r1["full"]["period"] - P_ref) / P_ref
                dA = abs(float(np.max(r1["full"]["p2p"])) - A_ref) / A_ref
                print(f"  keep_every check on the reference: keep_every {keep_for(ref_steps)} vs 1 changes the period "
                      f"by {dP:.1e} and the amplitude by {dA:.1e} (relative); wall {ref['wall']:.2f} s vs "
                      f"{r1['wall']:.2f} s")
            for (s, tol), r in sorted(res.items(), key=lambda kv: (kv[0][0], -kv[0][1])):
                f = r["full"]
                p2p = list(f["p2p"]) + [float("nan")] * (3 - len(f["p2p"]))
                rows.append({"case": case, "steps_per_period": s, "fp_tol": tol, "wall_s": r["wall"],
                             "period": f["period"], "p2p_t": p2p[0], "p2p_b": p2p[1], "p2p_n": p2p[2],
                             "err_period": abs(f["period"] - P_ref) / P_ref,
                             "err_amplitude": abs(float(np.max(f["p2p"])) - A_ref) / A_ref,
                             "h": r["stdout"]["h"]})
            # Orders.
            seq = sorted((r for r in rows if r["case"] == case and r["fp_tol"] == REF_TOL),
                         key=lambda r: r["steps_per_period"])
            hs = [r["h"] for r in seq]
            ep, ea = [r["err_period"] for r in seq], [r["err_amplitude"] for r in seq]
            op, oa = orders_vs_ref(hs, ep), orders_vs_ref(hs, ea)
            sp = orders_successive(hs, [r["period"] for r in seq])
            sa = orders_successive(hs, [max(r["p2p_t"], r["p2p_b"], r["p2p_n"]) for r in seq])
            orders[case] = (op, oa, sp, sa)
            print(f"\n  errors against {ref_steps} steps/period, tol 1e-12 (P_ref = {P_ref:.10e} s, "
                  f"max p2p_ref = {A_ref:.8e} m); order = slope of log err vs log h to the next step size;")
            print("  order (diff) = from successive differences q(h) - q(h/2), independent of the reference")
            print(f"  {'steps':>6} {'h (s)':>11} {'wall s':>7} {'err_period':>11} {'order':>6} {'order(diff)':>11} "
                  f"{'err_amplitude':>13} {'order':>6} {'order(diff)':>11}")
            for i, r in enumerate(seq):
                print(f"  {r['steps_per_period']:6d} {r['h']:11.4e} {r['wall_s']:7.3f} {r['err_period']:11.3e} "
                      f"{fmt_order(op[i] if i < len(op) else None)} {fmt_order(sp[i] if i < len(sp) else None):>11} "
                      f"{r['err_amplitude']:13.3e} {fmt_order(oa[i] if i < len(oa) else None)} "
                      f"{fmt_order(sa[i] if i < len(sa) else None):>11}")
            for r in sorted((r for r in rows if r["case"] == case and r["fp_tol"] != REF_TOL),
                            key=lambda r: -r["fp_tol"]):
                print(f"  {r['steps_per_period']:6d} tol {r['fp_tol']:7.0e}      {r['wall_s']:7.3f} "
                      f"{r['err_period']:11.3e} {'':18} {r['err_amplitude']:13.3e}")
            # Richardson estimate of the reference's own error from the last difference and order.
            for name, q, so in (("period", [r["period"] for r in seq], sp),
                                ("amplitude", [max(r["p2p_t"], r["p2p_b"], r["p2p_n"]) for r in seq], sa)):
                p_est = next((p for p in reversed(so) if p is not None and p > 0.3), None)
                if p_est is not None and len(q) >= 2:
                    e_ref = abs(q[-1] - q[-2]) / (2 ** p_est - 1) / abs(q[-1])
                    print(f"  estimated error of the reference itself ({name}, Richardson with order {p_est:.2f}): "
                          f"{e_ref:.2e}")

    with open(csv_path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(CSV_COLUMNS)
        for r in rows:
            w.writerow([r["case"], r["steps_per_period"], f"{r['fp_tol']:g}", f"{r['wall_s']:.4f}",
                        f"{r['period']:.12e}", f"{r['p2p_t']:.10e}", f"{r['p2p_b']:.10e}", f"{r['p2p_n']:.6e}",
                        f"{r['err_period']:.6e}", f"{r['err_amplitude']:.6e}"])
    plot(rows, steps, png_path, f"({periods:g} periods{', quick' if args.quick else ''})", fixed_wall)

    print("\nobserved orders (slope of log err vs log h between successive step sizes; "
          "in brackets: from successive differences)")
    for case, _, clabel in CASES:
        op, oa, sp, sa = orders[case]

        def seq_str(a, b):
            return ", ".join(f"{fmt_order(x).strip()} [{fmt_order(y).strip()}]"
                             for x, y in zip(a, b + [None] * (len(a) - len(b))))
        print(f"  {clabel}\n    period:    {seq_str(op, sp)}\n    amplitude: {seq_str(oa, sa)}")
    print(f"\nwrote {csv_path}\nwrote {png_path}")


if __name__ == "__main__":
    main()
