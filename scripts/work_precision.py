#!/usr/bin/python3
"""Work-precision study of squeal on the two 3-DOF reference cases: transient vs shooting.

For case 1 (V = 3 m/s, separation/slip) and case 2 (V = 0.75 m/s, stick/slip) this measures the
error of the limit cycle's period and amplitude against the wall time of the run, for the two ways
squeal finds the cycle (both with the theta-method, theta = 0.5, contact fixed point tol 1e-12):

  transient  `squeal -analyses transient`: integrate from the unstable mode until the cycle has
             settled, then read the cycle off the last 20 % of the records. Settings: the steps per
             period (h = T_lin / steps, T_lin the period of the unstable linear mode) and the simulated
             length (-transient_periods, in periods of T_lin):
               h series       125 ... 8000 steps per period at --periods (default 200) periods;
               short h series the same steps at --short-periods (default 25; not in --quick);
               length series  1000 steps per period at 12.5, 25, 50, 100 periods (and --periods);
               fp tolerance   1000 steps per period with -theta_fp_tol 1e-6 and 1e-9 (CSV only: the
                              cycle does not change, so only the timing noise shows).
  shooting   `squeal -analyses shooting -floquet_compute 0`: Newton (SNES) on the initial state and the
             period of one period of the theta-method with -shoot_steps S steps (h = T / S), started
             from the energy estimate. Settings: S = 125 ... 8000 at -shoot_eps1 = -shoot_eps2 = 1e-8,
             and eps = 1e-3, 1e-5 at S = 1000. The Floquet multipliers are switched off for the timing
             runs (they cost 2N extra period integrations and are not part of finding the cycle); one
             extra run at S = 1000, eps 1e-5 with -floquet_compute 1 reports their cost (CSV row with
             floquet = 1, not in the figure).

Quantities. Transient: the settled-cycle period (the /transient period attribute, at full precision)
and the peak-to-peak of U_t over the last 20 % of the records, recomputed from /transient/U exactly as
squeal does (both checked against the stdout summary to the printed digits). Shooting: /shooting/period
and the peak-to-peak of column 0 (U_t) of /shooting/orbit/U (one period, S + 1 samples), checked against
stdout. U_t is the DOF with the largest amplitude in both cases.

Reference for BOTH methods: the finest shooting run (8000 steps per period, eps 1e-8; --quick: 2000).
Shooting and transient at equal h converge to the same discrete cycle; the script checks that with
transient runs at exactly the shooting step (-transient_h = T_shoot(S) / S, 50 periods, every step
recorded; "equal_h" rows, CSV only) and reports the difference between the finest transient and
the finest shooting run.

Timing: time.perf_counter around the subprocess (the whole program: process and MPI start-up,
equilibrium, stability, [energy estimate,] the analysis and the HDF5 output). The plan is run --repeat
times with the passes interleaved (so that a burst of load elsewhere does not hit all repeats of one
run) and the least wall time is kept. The fixed cost common to both methods (a run with -analyses
stability only, repeated through every pass) is measured too. On the 3-DOF cases that fixed cost is
most of the wall time, so every run also passes -log_view :FILE and the script reads the time of the
PETSc log stages that find the cycle ("analysis time": the Transient stage; the Energy + Shooting
stages, the energy estimate being the shooting's initial guess; the Energy stage alone is the CSV
column energy_s); -log_view only writes the log at the end. The speed ratios are given on the total
wall time, on the wall time above the fixed cost and on the analysis time.

Speed ratio at equal accuracy: for a target relative period error (1e-4) and amplitude error (1e-3),
the wall time of the cheapest transient run that reaches it divided by that of the cheapest shooting
run, per case: (a) over the measured runs, (b) interpolated on the log-log curves of each series
(linear in log wall vs log error between the two runs that bracket the target, along the step-size
series only: error vs length or vs tolerance is no power law; the least over the series of a method),
on the wall time, the wall time above the fixed cost and the analysis time; once over all transient
runs and once over the --periods runs only (a transient whose length was not tuned to the case).
Also printed for the tighter targets 1e-5 (period) and 1e-4 (amplitude).

Outputs: the CSV (one row per run; columns in CSV_COLUMNS, `method` transient or shooting, `series`
the series the run belongs to, empty fields where a setting does not apply; shooting rows have
floquet = 0 except the one Floquet-cost run) and work_precision.png (per case: error vs wall time,
error vs analysis time, error vs steps per period). Printed: the tables per case, the observed
orders (slope of log err vs log h to the next step size, and from successive differences,
independent of the reference) for both methods, the equal-h check and the speed ratios.

Usage:
  work_precision.py --squeal PATH [--out-dir DIR] [--csv FILE] [--quick] [--periods P]
                    [--short-periods P] [--repeat R] [--records-per-period N] [--examples DIR]
                    [--no-keep-check] [--no-equal-h]

  full study:  scripts/work_precision.py --squeal build/squeal --out-dir docs/img --csv docs/work_precision.csv
  smoke test:  add --quick (under a minute; reference shooting at 2000 steps, one timing pass)
  cost only:   add --cost (a minute): shooting + Floquet as the scenes run it (1000 steps, eps 1e-5) against
               the shortest transient whose period is within 1e-4 of shooting's at that length and the next
               two (lengths --cost-lengths, 1000 steps per period); prints their period integrations
               (shooting: Newton + Floquet, from squeal's summary line) and, side by side, the whole-run wall
               time, the PETSc time (-log_view "Time (sec)": PetscInitialize to PetscFinalize, without process
               and MPI start-up) and the analysis time (PETSc stages Energy + Shooting, resp. Transient), least
               and median of --repeat interleaved runs (default 7), with the load average before and after.
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

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from squeal.plot.common import save_png  # noqa: E402
from squeal.results import PROG, Results, fail, open_results  # noqa: E402

CASES = (("case1", "case1_separation_slip.yaml", "case 1: V = 3 m/s (separation/slip)"),
         ("case2", "case2_stick_slip.yaml", "case 2: V = 0.75 m/s (stick/slip)"))
FULL_STEPS = (125, 250, 500, 1000, 2000, 4000, 8000)
QUICK_STEPS = (125, 250, 500, 1000, 2000)
TOLS = (1e-6, 1e-9, 1e-12)       # transient contact fixed-point tolerances
TOL_STEPS = 1000                 # the steps per period of the tolerance study
REF_TOL = 1e-12
LEN_STEPS = 1000                 # the steps per period of the length study
FULL_LENGTHS = (12.5, 25.0, 50.0, 100.0)   # simulated lengths (periods) besides --periods
QUICK_LENGTHS = (12.5, 25.0)
SHOOT_EPS = (1e-3, 1e-5, 1e-8)   # -shoot_eps1 = -shoot_eps2
EPS_STEPS = 1000                 # the steps per period of the shooting tolerance study
REF_EPS = 1e-8
FLOQUET_EPS = 1e-5               # the run that measures the cost of the Floquet multipliers
TARGETS = (("err_period", 1e-4), ("err_amplitude", 1e-3))
EXTRA_TARGETS = (("err_period", 1e-5), ("err_amplitude", 1e-4))  # printed only
ERR_KINDS = (("err_period", "period", "#1f77b4"), ("err_amplitude", "amplitude (U_t peak-to-peak)", "#d95f02"))

CSV_COLUMNS = ("method", "case", "series", "steps_per_period", "h", "periods", "fp_tol", "shoot_eps", "floquet",
               "newton_its", "period_integrations", "converged", "wall_s", "analysis_s", "energy_s", "petsc_s",
               "period", "p2p_t", "p2p_b", "p2p_n", "err_period", "err_amplitude")
# The PETSc log stages (-log_view) that make up the cost of finding the cycle with each method.
STAGES = {"transient": ("Transient",), "shooting": ("Energy", "Shooting"), "fixed": ("Equilibrium", "Stability")}
RE_LOG_TOTAL = re.compile(r"^Time \(sec\):\s+([0-9.eE+-]+)", re.M)
RE_LOG_STAGE = re.compile(r"^\s*\d+:\s+([^:]+?):\s+([0-9.eE+-]+)\s", re.M)

RE_PERIOD = re.compile(r"settled cycle period\s+([-+0-9.eE]+)\s*s")
RE_P2P = re.compile(r"peak-to-peak \(m\), last 20 %:\s*(.+)")
RE_STEPS = re.compile(r"transient:\s*(\d+)\s+steps of h =\s*([-+0-9.eE]+)\s*s")
RE_CONTACT = re.compile(r"contact, last 20 %: separated\s*([0-9.]+) %, stuck\s*([0-9.]+) %, "
                        r"sliding\s*([0-9.]+) %(?:\s*\(([^)]*)\))?")
RE_FP = re.compile(r"mean fixed-point passes per step\s+([0-9.eE+-]+)")
RE_SHOOT = re.compile(r"shooting: converged in\s+(\d+)\s+Newton iteration")
RE_SHOOT_FLOWS = re.compile(r"(\d+)\s+period integrations")
RE_SHOOT_PER = re.compile(r"limit cycle period\s+([-+0-9.eE]+)\s*s")
RE_SHOOT_P2P = re.compile(r"^\s*peak-to-peak \(m\):\s*(.+)$", re.M)
RE_SHOOT_REGIME = re.compile(r"regime:\s*(.+)")
RE_SHOOT_PARTS = re.compile(r"(\d+)\s+period integrations \(Newton (\d+), Floquet (\d+)")


def warn(msg):
    print(f"{PROG}: warning: {msg}", file=sys.stderr)


# --------------------------------------------------------------------------------------------
# Transient runs.

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


def read_transient_file(path):
    """Period (attribute) and peak-to-peak amplitudes over the last 20 % of the records (squeal's
    window) at full precision, plus the same over the preceding 20 % for the settling check."""
    if not os.path.isfile(path):
        fail(f"squeal did not write '{path}'")
    with Results(path) as r:
        g = r.require("transient", ("t", "U"))
        t, U = g.array("t"), g.array("U")
        attr_period = float(g.period) if g.period is not None else None
        complete = g.complete
    n = t.size
    if n < 10:
        fail(f"'{path}': only {n} records")
    win = max(n // 5, 2)
    period, p2p = summarise_records(t, U, n - win, n)
    period_prev, p2p_prev = summarise_records(t, U, n - 2 * win, n - win + 1)
    return {"period": attr_period if attr_period else period, "period_records": period, "p2p": p2p,
            "period_prev": period_prev, "p2p_prev": p2p_prev, "records": n, "complete": complete}


def transient_cmd(squeal, scene, periods, steps, tol, keep_every, h5, h=None):
    cmd = [squeal, "-scene", scene, "-analyses", "transient", "-transient_periods", f"{periods:g}",
           "-transient_steps_per_period", str(steps), "-transient_keep_every", str(keep_every),
           "-theta_fp_tol", f"{tol:g}", "-output", h5]
    if h is not None:
        cmd[-2:-2] = ["-transient_h", f"{h:.17g}"]
    return cmd


def analyse_transient(proc, cmd, h5):
    """The cycle of a transient run at full precision (checked against the stdout summary)."""
    s = parse_summary(proc.stdout, cmd)
    if "pass limit hit" in proc.stdout:
        warn(f"the contact fixed point hit its pass limit in {' '.join(cmd)}")
    full = read_transient_file(h5)
    if not full["complete"]:
        warn(f"the run {' '.join(cmd)} is marked incomplete")
    # The full-precision numbers must round to what squeal printed (6 and 5 significant digits).
    if abs(full["period"] - s["period"]) > 0.6e-7 + 1e-12:
        warn(f"period from the file {full['period']:.10g} s does not match stdout {s['period']} s ({' '.join(cmd)})")
    for j, (a, b) in enumerate(zip(full["p2p"], s["p2p"])):
        if abs(a - b) > 0.6e-4 * max(abs(b), 1e-300) and abs(b) > 1e-15:
            warn(f"peak-to-peak of DOF {j} from the file {a:.8g} does not match stdout {b:.4e}")
    drift_p = abs(full["period"] - full["period_prev"]) / full["period"] if full["period_prev"] else float("inf")
    drift_a = abs(full["p2p"][0] - full["p2p_prev"][0]) / full["p2p"][0]
    p2p = list(full["p2p"]) + [float("nan")] * (3 - len(full["p2p"]))
    if int(np.argmax(full["p2p"])) != 0:
        warn(f"U_t is not the largest peak-to-peak in {' '.join(cmd)}")
    return {"period": full["period"], "p2p": p2p[:3], "h": s["h"], "contact": s.get("contact"), "fp": s.get("fp"),
            "drift": (drift_p, drift_a), "records": full["records"], "converged": 1}


# --------------------------------------------------------------------------------------------
# Shooting runs.

def shooting_cmd(squeal, scene, steps, eps, h5, floquet=False):
    return [squeal, "-scene", scene, "-analyses", "shooting", "-shoot_steps", str(steps),
            "-shoot_eps1", f"{eps:g}", "-shoot_eps2", f"{eps:g}", "-floquet_compute", "1" if floquet else "0",
            "-output", h5]


def analyse_shooting(proc, cmd, h5):
    """Period (/shooting/period) and peak-to-peak of the orbit (/shooting/orbit/U, one period)."""
    if not os.path.isfile(h5):
        fail(f"squeal did not write '{h5}' ({' '.join(cmd)})")
    with Results(h5) as r:
        if r.shooting is None:
            fail(f"'{h5}' has no /shooting group ({' '.join(cmd)})")
        g = r.require("shooting", ("period", "orbit/U"))
        converged = g.converged
        reason = str(g.attrs.get("reason", ""))
        period = g.period
        U = g.array("orbit/U")
        its = g.iterations
        ndof = int(r.model.get("dofs", 3))
    if U.ndim != 2:
        fail(f"'{h5}': /shooting/orbit/U has shape {U.shape}")
    if U.shape[1] != ndof and U.shape[0] == ndof:  # stored DOF-major: one row per DOF
        U = U.T
    p2p = U.max(axis=0) - U.min(axis=0)
    if int(np.argmax(p2p)) != 0:
        warn(f"U_t is not the largest peak-to-peak of the orbit in {' '.join(cmd)}")
    m = RE_SHOOT.search(proc.stdout)
    mf = RE_SHOOT_FLOWS.search(proc.stdout)
    integrations = int(mf.group(1)) if mf else -1
    if converged:
        if not m:
            warn(f"no 'shooting: converged' line in the output of {' '.join(cmd)}")
        mp, ma = RE_SHOOT_PER.search(proc.stdout), RE_SHOOT_P2P.search(proc.stdout)
        if mp and abs(period - float(mp.group(1))) > 0.6e-7 + 1e-12:
            warn(f"shooting period from the file {period:.10g} s does not match stdout {mp.group(1)} s")
        if ma:
            for j, b in enumerate(float(x) for x in ma.group(1).split(",") if x.strip()):
                if j < p2p.size and abs(b) > 1e-15 and abs(p2p[j] - b) > 0.6e-4 * abs(b):
                    warn(f"orbit peak-to-peak of DOF {j} from the file {p2p[j]:.8g} does not match stdout {b:.4e}")
    else:
        warn(f"shooting did not converge ({reason}): {' '.join(cmd)}")
    mr = RE_SHOOT_REGIME.search(proc.stdout)
    p2p = list(p2p) + [float("nan")] * (3 - p2p.size)
    return {"period": period, "p2p": p2p[:3], "h": period / (U.shape[0] - 1), "converged": converged,
            "reason": reason, "its": its, "integrations": integrations, "samples": U.shape[0],
            "regime": mr.group(1).strip() if mr else ""}


# --------------------------------------------------------------------------------------------
# Running and timing.

def run_timed(cmd, h5, allow_fail=False):
    """Run squeal once; the wall time of the whole process and the CompletedProcess."""
    if os.path.exists(h5):
        os.remove(h5)
    t0 = time.perf_counter()
    try:
        p = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    except OSError as e:
        fail(f"cannot run '{cmd[0]}': {e}")
    wall = time.perf_counter() - t0
    if p.returncode != 0 and not (allow_fail and "did not converge" in (p.stderr + p.stdout)):
        tail = "\n".join((p.stderr or p.stdout).strip().splitlines()[-15:])
        fail(f"squeal failed (exit {p.returncode}):\n  {' '.join(cmd)}\n{tail}")
    return wall, p


def read_log_view(path):
    """Total PETSc time and the time of each log stage from a -log_view file ({} if there is none)."""
    try:
        with open(path) as fh:
            text = fh.read()
    except OSError:
        return {}
    out = {}
    m = RE_LOG_TOTAL.search(text)
    if m:
        out["total"] = float(m.group(1))
    i = text.find("Summary of Stages")
    if i >= 0:
        block = text[i:text.find("\n\n", i) if text.find("\n\n", i) > 0 else len(text)]
        for name, t in RE_LOG_STAGE.findall(block):
            out[name.strip()] = out.get(name.strip(), 0.0) + float(t)
    return out


def run_job(job, tmp, analyse=True):
    h5, log = os.path.join(tmp, "run.h5"), os.path.join(tmp, "log_view.txt")
    if os.path.exists(log):
        os.remove(log)
    cmd = job["make_cmd"](h5) + ["-log_view", f":{log}"]
    wall, p = run_timed(cmd, h5, allow_fail=job["method"] == "shooting")
    job.setdefault("walls", []).append(wall)
    lv = read_log_view(log)
    stages = [lv[s] for s in STAGES[job["method"]] if s in lv]
    job.setdefault("analysis", []).append(sum(stages) if len(stages) == len(STAGES[job["method"]]) else float("nan"))
    job.setdefault("petsc", []).append(lv.get("total", float("nan")))
    job.setdefault("energy", []).append(lv.get("Energy", float("nan")))
    if analyse and job["method"] != "fixed":
        res = (analyse_transient if job["method"] == "transient" else analyse_shooting)(p, cmd, h5)
        job["res"] = res
    if os.path.exists(h5):
        os.remove(h5)
    return wall


def least(xs):
    xs = [x for x in xs if x == x]
    return min(xs) if xs else float("nan")


# --------------------------------------------------------------------------------------------
# Orders and the cheapest run at a target error.

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


def series_curves(rows, method):
    """The series of a method, each as its rows in the order of increasing cost."""
    if method == "transient":
        defs = (("h", lambda r: r["steps_per_period"]), ("h_short", lambda r: r["steps_per_period"]),
                ("length", lambda r: r["periods"]))
    else:
        defs = (("steps", lambda r: r["steps_per_period"]), ("eps", lambda r: -r["shoot_eps"]))
    out = []
    for name, key in defs:
        rs = sorted((r for r in rows if r["method"] == method and name in r["series"].split("+")), key=key)
        if rs:
            out.append((name, rs))
    return out


def cheapest(rows, method, key, target, wall_of):
    """Cheapest run of a method whose error `key` is <= target: (a) over the measured runs (timed
    runs only: not the equal-h checks nor the Floquet run), (b) interpolated along each step-size
    series, linear in log(wall) vs log(err) between the two runs bracketing the target."""
    timed = [r for r in rows if r["method"] == method and r["timed"] and r["converged"]]
    ok = [r for r in timed if r[key] <= target]
    meas = min(ok, key=wall_of) if ok else None
    best = (wall_of(meas), "measured") if meas else (None, "")
    for name, rs in series_curves(timed, method):
        if name not in ("h", "h_short", "steps"):  # error vs length or tolerance is no power law: measured only
            continue
        for i, r in enumerate(rs):
            if r[key] > target:
                continue
            if i == 0:
                w = wall_of(r)
            else:
                a = rs[i - 1]
                wa, wb = max(wall_of(a), 1e-3), max(wall_of(r), 1e-3)
                if r[key] <= 0 or a[key] <= 0:
                    w = wb
                else:
                    f = (math.log(target) - math.log(a[key])) / (math.log(r[key]) - math.log(a[key]))
                    w = math.exp(math.log(wa) + f * (math.log(wb) - math.log(wa)))
            if best[0] is None or w < best[0]:
                best = (w, f"{name} series")
            break
    return meas, best


def describe(r):
    if r is None:
        return "not reached"
    if r["method"] == "transient":
        tol = "" if r["fp_tol"] == REF_TOL else f", tol {r['fp_tol']:g}"
        return f"{r['steps_per_period']} steps x {r['periods']:g} T{tol}"
    return f"S = {r['steps_per_period']}, eps {r['shoot_eps']:g}"


# --------------------------------------------------------------------------------------------
# Figure.

# (method, series, marker, filled, line style, legend label); colour = error kind.
PLOT_SERIES = (("transient", "h", "o", True, "-", "transient, steps per period varied, {P:g} periods"),
               ("transient", "h_short", "o", False, "--", "transient, steps per period varied, {SP:g} periods"),
               ("transient", "length", "o", False, ":", "transient, {LS} steps/period, length {lengths} periods"),
               ("shooting", "steps", "s", True, "-", "shooting, steps per period varied, eps {REF_EPS:g}"),
               ("shooting", "eps", "s", False, ":", "shooting, {ES} steps/period, eps {eps}"))


def plot(rows, steps, out_png, info):
    from matplotlib.lines import Line2D
    from matplotlib.ticker import FormatStrFormatter, LogLocator, NullFormatter

    fig, axes = plt.subplots(3, 2, figsize=(13.0, 14.6), dpi=90,
                             gridspec_kw={"height_ratios": (1.2, 1.0, 1.0), "hspace": 0.34, "wspace": 0.2})
    used = [(m, s) for m, s, *_ in PLOT_SERIES
            if any(r["method"] == m and s in r["series"].split("+") for r in rows)]
    plotted = [r for r in rows if r["timed"] and r["converged"] and r["floquet"] != 1
               and (r["err_period"] > 0 or r["err_amplitude"] > 0)]
    emin = min(r[k] for r in plotted for k, *_ in ERR_KINDS if r[k] > 0)
    emax = max(r[k] for r in plotted for k, *_ in ERR_KINDS if r[k] > 0)
    xkeys = (("wall_s", "wall time of the whole run (s)", "error vs wall time"),
             ("analysis_s", "analysis time (s): PETSc log stages Transient, resp. Energy + Shooting",
              "error vs analysis time (no start-up, stability, output)"))

    def in_series(r, series):
        return series in r["series"].split("+")

    for col, (case, _, clabel) in enumerate(CASES):
        crow = [r for r in rows if r["case"] == case and r["converged"] and r["floquet"] != 1 and r["timed"]]
        bx = axes[2, col]
        for row, (xkey, xlabel, title) in enumerate(xkeys):
            ax = axes[row, col]
            for method, series, marker, filled, ls, _ in PLOT_SERIES:
                rs = [r for r in crow if r["method"] == method and in_series(r, series)]
                if not rs:
                    continue
                order = {"length": lambda r: r["periods"], "eps": lambda r: -r["shoot_eps"]}.get(
                    series, lambda r: r["steps_per_period"])
                rs.sort(key=order)
                for key, _, colour in ERR_KINDS:
                    pts = [r for r in rs if r[key] > 0 and r[xkey] == r[xkey]]
                    if not pts:
                        continue
                    style = dict(color=colour, marker=marker, ls=ls, lw=1.3 if filled else 1.0,
                                 ms=7 if filled else (5 if series == "length" else 6.5), mfc=colour if filled else "white", mec=colour,
                                 mew=1.2, alpha=0.95, zorder=3 if filled else 2)
                    ax.plot([r[xkey] for r in pts], [r[key] for r in pts], **style)
                    if row == 0 and series in ("h", "h_short", "steps"):
                        bx.plot([r["steps_per_period"] for r in pts], [r[key] for r in pts], **style)
                    # Labels: steps per period of the main series, periods of the length series (period error).
                    if key == "err_period" and series in ("h", "h_short", "steps", "length"):
                        lab = pts if series == "h" else [pts[0], pts[-1]]  # the others: ends only
                        for r in lab:
                            if series == "length" and r["periods"] == info["periods"]:
                                continue
                            txt = f"{r['periods']:g} T" if series == "length" else f"{r['steps_per_period']}"
                            off = {"h": (-5, -11), "h_short": (-5, -11), "steps": (5, 4), "length": (6, -3)}[series]
                            ax.annotate(txt, (r[xkey], r[key]), textcoords="offset points", xytext=off,
                                        ha="right" if off[0] < 0 else "left", fontsize=7.5,
                                        color="0.15" if series in ("h", "steps") else "0.45")
            xs = [r[xkey] for r in crow if r[xkey] == r[xkey]] + ([info["fixed_wall"]] if row == 0 else [])
            for key, _, colour in ERR_KINDS:
                ax.axhline(dict(TARGETS)[key], color=colour, ls=(0, (6, 3)), lw=0.9, alpha=0.6, zorder=1)
            if row == 0:
                ax.axvline(info["fixed_wall"], color="0.45", ls="-.", lw=1.0, zorder=1)
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_xlim(min(xs) / 1.12, max(xs) * 1.15)
            ax.set_ylim(emin / 3, emax * 3)
            if max(xs) / min(xs) < 30:
                subs = (1.0, 1.2, 1.5, 2.0, 2.5, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0) if max(xs) / min(xs) < 4 else \
                    (1.0, 1.5, 2.0, 3.0, 4.0, 5.0, 7.0)
                ax.xaxis.set_major_locator(LogLocator(base=10, subs=subs))
                ax.xaxis.set_major_formatter(FormatStrFormatter("%g"))
            ax.xaxis.set_minor_formatter(NullFormatter())
            ax.set_xlabel(xlabel)
            ax.set_ylabel("relative error vs the reference")
            ax.grid(True, which="major", alpha=0.3)
            ax.grid(True, which="minor", axis="y", alpha=0.12)
            ax.set_title(f"({'abcdef'[2 * row + col]}) {clabel if row == 0 else clabel.split(':')[0]}: {title}",
                         loc="left", fontsize=11)
            # Speed ratios in the corner.
            lab = "total" if row == 0 else "analysis"
            lines = [f"transient / shooting {'wall' if row == 0 else 'analysis'} time at equal accuracy",
                     f"(interpolated; in brackets: {info['periods']:g}-period transients only):"]
            for key, target in TARGETS:
                sr, sp = info["ratios"][case][key], info["ratios_p"][case][key]
                what = "period" if key == "err_period" else "amplitude"
                val = f"{sr[lab]:.2g}" if sr[lab] else "not reached"
                valp = f"{sp[lab]:.2g}" if sp[lab] else "not reached"
                lines.append(f"  {what} error {target:g}: {val}  ({valp})")
            ax.text(0.985, 0.98, "\n".join(lines), transform=ax.transAxes, ha="right", va="top", fontsize=8,
                    bbox=dict(boxstyle="round,pad=0.35", fc="white", ec="0.7", alpha=0.92), zorder=5)
        # Bottom: error vs steps per period.
        for key, _, colour in ERR_KINDS:
            bx.axhline(dict(TARGETS)[key], color=colour, ls=(0, (6, 3)), lw=0.9, alpha=0.6, zorder=1)
        S = np.array([min(steps), max(steps) / 2], dtype=float)
        first = [r[k] for r in crow for k, *_ in ERR_KINDS if r["steps_per_period"] == min(steps) and r[k] > 0]
        anchor = 2.0 * max(first) if first else 1e-3
        for p, lsg in ((1, ":"), (2, "-.")):
            bx.plot(S, anchor * (S / S[0]) ** (-p), color="0.4", ls=lsg, lw=1.0)
            bx.annotate(f"order {p}", (S[-1], anchor * (S[-1] / S[0]) ** (-p)), fontsize=8, color="0.3",
                        textcoords="offset points", xytext=(4, -2))
        bx.set_xscale("log", base=2)
        bx.set_yscale("log")
        bx.set_xticks(list(steps))
        bx.set_xticklabels([str(s) for s in steps], fontsize=8)
        bx.xaxis.set_minor_formatter(NullFormatter())
        bx.set_ylim(emin / 3, emax * 3)
        bx.set_xlabel("steps per period  (transient: h = T_lin / steps; shooting: h = T / S)")
        bx.set_ylabel("relative error vs the reference")
        bx.grid(True, which="both", alpha=0.25)
        bx.set_title(f"({'ef'[col]}) {clabel.split(':')[0]}: error vs steps per period (same runs)",
                     loc="left", fontsize=11)
    fmt = dict(P=info["periods"], SP=info["short_periods"] or 0, LS=LEN_STEPS, ES=EPS_STEPS, REF_EPS=REF_EPS,
               lengths=", ".join(f"{x:g}" for x in info["lengths"]),
               eps=", ".join(f"{e:g}" for e in SHOOT_EPS))
    handles = []
    for method, series, marker, filled, ls, label in PLOT_SERIES:
        if (method, series) in used:
            handles.append(Line2D([], [], color="0.25", marker=marker, ls=ls, mfc="0.25" if filled else "white",
                                  mec="0.25", ms=6.5, lw=1.2, label=label.format(**fmt)))
    handles += [Line2D([], [], color=c, lw=2.5, label=f"{lab} error") for _, lab, c in ERR_KINDS]
    handles += [Line2D([], [], color="0.4", ls=(0, (6, 3)), lw=0.9,
                       label="targets: period 1e-4 (blue), amplitude 1e-3 (orange)"),
                Line2D([], [], color="0.45", ls="-.", lw=1.0,
                       label=f"fixed cost of a run: -analyses stability only ({info['fixed_wall']:.2f} s)")]
    fig.legend(handles=handles, loc="lower center", ncol=2, fontsize=8.5, frameon=False,
               bbox_to_anchor=(0.5, 0.0), columnspacing=2.5)
    fig.suptitle("squeal, 3-DOF cases: work-precision of the transient vs shooting (theta = 0.5)" + info["title_extra"],
                 x=0.06, ha="left", fontsize=12.5, fontweight="bold")
    fig.text(0.06, 0.948, f"reference for both methods: shooting, {info['ref_steps']} steps/period, eps {REF_EPS:g}. "
             "Shooting runs with -floquet_compute 0 (no Floquet multipliers). Wall time = whole program, least of "
             f"{info['repeat']} interleaved run(s).\nPoint labels (on the period error): steps per period (transient: "
             "below left; shooting: above right; grey: ends of the other series), simulated periods (length series).", fontsize=8.5, color="0.25", va="top")
    fig.subplots_adjust(left=0.065, right=0.985, bottom=0.105, top=0.915)
    save_png(fig, out_png)


# --------------------------------------------------------------------------------------------

def fmt_num(x, spec):
    return "" if x is None else format(x, spec)


def load_average():
    try:
        with open("/proc/loadavg") as fh:
            return " ".join(fh.read().split()[:3])
    except OSError:
        return "?"


def cost_study(squeal, scenes, repeat, keep, lengths, tol=1e-4):
    """Shooting + Floquet against the shortest transient that settles to its period to `tol`."""
    def stages(log, names):
        lv = read_log_view(log)
        return sum(lv[n] for n in names) if all(n in lv for n in names) else float("nan")

    print(f"load average {load_average()}")
    out = {}
    with tempfile.TemporaryDirectory(prefix="squeal_cost_") as tmp:
        h5, log = os.path.join(tmp, "run.h5"), os.path.join(tmp, "log.txt")
        snap = os.path.join(tmp, "squeal")  # a private copy: a rebuild during the study cannot mix two builds
        shutil.copy2(squeal, snap)
        squeal = snap
        for case, _, clabel in CASES:
            shoot = [squeal, "-scene", scenes[case], "-analyses", "shooting", "-floquet_compute", "1", "-output", h5]
            _, p = run_timed(shoot, h5)
            with open_results(h5) as r:
                T_s = r.require("shooting", ("period",)).period
            m = RE_SHOOT_PARTS.search(p.stdout)
            if not m:
                fail(f"no 'period integrations (Newton n, Floquet m)' in the output of {' '.join(shoot)}")
            parts = tuple(int(x) for x in m.groups())
            # Transients of increasing length until the period stays within tol of shooting's for 3 lengths.
            errs, best = [], None
            for L in lengths:
                cmd = transient_cmd(squeal, scenes[case], L, 1000, REF_TOL, keep, h5)
                _, p = run_timed(cmd, h5)
                with open_results(h5) as r:
                    T_t = float(r.require("transient").attrs.get("period", float("nan")))
                errs.append((L, abs(T_t - T_s) / T_s))
                ok = [e <= tol for _, e in errs[-3:]]
                if len(ok) == 3 and all(ok):
                    best = errs[-3][0]
                    break
            print(f"\n== {clabel}: shooting T = {T_s:.10e} s; transient period error by length: "
                  + ", ".join(f"{L:g} T: {e:.1e}" for L, e in errs))
            if best is None:
                warn(f"{case}: no transient length in {lengths[0]:g}..{lengths[-1]:g} periods settles to {tol:g}")
                continue
            jobs = {"shooting": (shoot, ("Energy", "Shooting")),
                    "transient": (transient_cmd(squeal, scenes[case], best, 1000, REF_TOL, keep, h5), ("Transient",))}
            t = {k: {"wall": [], "stage": [], "petsc": []} for k in jobs}
            for _ in range(repeat):  # interleaved: a burst of load elsewhere hits both
                for k, (cmd, names) in jobs.items():
                    if os.path.exists(log):
                        os.remove(log)
                    w, _ = run_timed(cmd + ["-log_view", f":{log}"], h5)
                    t[k]["wall"].append(w)
                    t[k]["stage"].append(stages(log, names))
                    t[k]["petsc"].append(read_log_view(log).get("total", float("nan")))
            med = lambda xs: float(np.median(xs))  # noqa: E731
            print(f"  {'':34} {'period integrations':>27} {'wall s (least / median)':>24} {'PETSc ms (least / median)':>26} "
                  f"{'analysis ms (least / median)':>29}")
            for k, label, integ in (("shooting", "shooting + Floquet (1000 steps)", f"{parts[0]} (Newton {parts[1]} + Floquet {parts[2]})"),
                                    ("transient", f"transient, {best:g} periods (1000 steps)", f"{best:g}")):
                w, a, pt = t[k]["wall"], t[k]["stage"], t[k]["petsc"]
                print(f"  {label:34} {integ:>27} {min(w):15.3f} / {med(w):.3f} {1e3 * least(pt):15.1f} / {1e3 * med(pt):6.1f} "
                      f"{1e3 * least(a):18.1f} / {1e3 * med(a):.1f}")
            rw = min(t["transient"]["wall"]) / min(t["shooting"]["wall"])
            ra = least(t["transient"]["stage"]) / least(t["shooting"]["stage"])
            rp = least(t["transient"]["petsc"]) / least(t["shooting"]["petsc"])
            print(f"  transient / shooting: wall {rw:.2f} (medians {med(t['transient']['wall']) / med(t['shooting']['wall']):.2f}), "
                  f"PETSc (PetscInitialize to PetscFinalize) {rp:.2f}, analysis {ra:.2f}; {repeat} interleaved runs each")
            out[case] = (parts, best, rw, ra)
    print(f"\nload average {load_average()}")
    return out


def main(argv=None, prog=PROG):
    ap = argparse.ArgumentParser(prog=prog, description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--squeal", required=True, help="path of the squeal executable")
    ap.add_argument("--out-dir", default=".", help="directory of work_precision.png (and of the CSV unless --csv)")
    ap.add_argument("--csv", default=None, help="CSV path (default OUT_DIR/work_precision.csv)")
    ap.add_argument("--quick", action="store_true",
                    help="smoke test: 125 ... 2000 steps per period (reference: shooting at 2000), 50 periods, "
                         "no short h series, one timing pass")
    ap.add_argument("--periods", type=float, default=None,
                    help="simulated length of the transient h series in periods of the linear mode "
                         "(default 200, quick 50)")
    ap.add_argument("--short-periods", type=float, default=None,
                    help="length of the second (short) transient h series (default 25; quick: none; 0: none)")
    ap.add_argument("--repeat", type=int, default=None,
                    help="timing passes over the whole plan, the least wall time is kept (default 3, quick 1)")
    ap.add_argument("--records-per-period", type=int, default=500,
                    help="transient: -transient_keep_every = max(1, steps_per_period // N) (default 500)")
    ap.add_argument("--examples", default=os.path.join(HERE, "..", "examples", "three_dof"),
                    help="directory of the case YAML files (default: ../examples/three_dof next to this script)")
    ap.add_argument("--no-keep-check", action="store_true",
                    help="skip the rerun of the finest transient with -transient_keep_every 1")
    ap.add_argument("--no-equal-h", action="store_true",
                    help="skip the transient runs at exactly the step of the shooting runs")
    ap.add_argument("--cost", action="store_true",
                    help="only shooting + Floquet against the shortest transient that settles to its period (see above)")
    ap.add_argument("--cost-lengths", default="10:60",
                    help="--cost: transient lengths tried, in periods of the linear mode, FIRST:LAST by 1 (default 10:60)")
    args = ap.parse_args(argv)

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
    short = args.short_periods if args.short_periods is not None else (0.0 if args.quick else 25.0)
    short = short if 0 < short < periods else None
    lengths = tuple(L for L in (QUICK_LENGTHS if args.quick else FULL_LENGTHS) if L < periods) + (periods,)
    repeat = max(1, args.repeat if args.repeat else (1 if args.quick else 3))
    ref_steps = steps[-1]
    if periods <= 0:
        fail("--periods must be > 0")

    def keep_for(s):
        return max(1, s // args.records_per_period)

    if args.cost:
        try:
            a, b = (int(x) for x in args.cost_lengths.split(":"))
        except ValueError:
            fail(f"--cost-lengths '{args.cost_lengths}': expected FIRST:LAST (whole periods)")
        cost_study(squeal, scenes, max(1, args.repeat or 7), keep_for(1000), [float(L) for L in range(a, b + 1)])
        return

    print(f"squeal: {squeal} (the study runs a private copy of it)")
    print(f"transient: steps per period {', '.join(map(str, steps))} at {periods:g} periods"
          + (f" and at {short:g} periods" if short else "")
          + f"; {LEN_STEPS} steps per period at {', '.join(f'{x:g}' for x in lengths)} periods; "
          f"fixed-point tol {', '.join(f'{t:g}' for t in TOLS)} at {TOL_STEPS} steps ({periods:g} periods); "
          f"keep_every = steps // {args.records_per_period}")
    print(f"shooting (-floquet_compute 0): steps per period {', '.join(map(str, steps))} at eps {REF_EPS:g}; "
          f"eps {', '.join(f'{e:g}' for e in SHOOT_EPS)} at {EPS_STEPS} steps; one run with -floquet_compute 1 "
          f"({EPS_STEPS} steps, eps {FLOQUET_EPS:g})")
    print(f"reference for both methods: shooting, {ref_steps} steps per period, eps {REF_EPS:g}; "
          f"wall time = least of {repeat} interleaved pass(es)")

    # ---- the plan
    jobs = []
    for case, _, _ in CASES:
        tr = []
        for s in steps:
            tr.append((s, periods, REF_TOL))
        if short:
            tr += [(s, short, REF_TOL) for s in steps]
        tr += [(LEN_STEPS, L, REF_TOL) for L in lengths]
        tr += [(TOL_STEPS, periods, tol) for tol in TOLS]
        for s, P, tol in dict.fromkeys(tr):
            jobs.append({"method": "transient", "case": case, "steps": s, "periods": P, "tol": tol,
                         "keep": keep_for(s),
                         "make_cmd": (lambda h5, sc=scenes[case], P=P, s=s, tol=tol:
                                      transient_cmd(None, sc, P, s, tol, keep_for(s), h5))})
        sh = [(s, REF_EPS, False) for s in steps] + [(EPS_STEPS, e, False) for e in SHOOT_EPS]
        sh.append((EPS_STEPS, FLOQUET_EPS, True))
        for s, e, fl in dict.fromkeys(sh):
            jobs.append({"method": "shooting", "case": case, "steps": s, "eps": e, "floquet": fl,
                         "make_cmd": (lambda h5, sc=scenes[case], s=s, e=e, fl=fl:
                                      shooting_cmd(None, sc, s, e, h5, fl))})
    fixed_job = {"method": "fixed", "make_cmd": (lambda h5, sc=scenes[CASES[0][0]]:
                                                 [None, "-scene", sc, "-analyses", "stability", "-output", h5])}

    rows = []
    t_start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="squeal_wp_") as tmp:
        # Run a private copy, so that a rebuild of the executable during the study cannot mix two builds.
        snap = os.path.join(tmp, "squeal")
        try:
            shutil.copy2(squeal, snap)
        except OSError as e:
            fail(f"cannot copy '{squeal}' to '{snap}': {e}")
        import hashlib
        with open(snap, "rb") as fh:
            digest = hashlib.sha256(fh.read()).hexdigest()[:16]
        print(f"executable copied: modified {time.strftime('%Y-%m-%d %H:%M:%S', time.localtime(os.path.getmtime(squeal)))}"
              f", sha256 {digest}...")
        for j in jobs + [fixed_job]:
            mk = j["make_cmd"]
            j["make_cmd"] = (lambda h5, mk=mk: [snap] + mk(h5)[1:])

        # ---- timing passes (pass 1 also reads the results)
        for it in range(repeat):
            t0 = time.perf_counter()
            nfixed = 0
            for k, j in enumerate(jobs):
                if k % 8 == 0:  # the fixed-cost run, spread through the pass
                    run_job(fixed_job, tmp, analyse=False)
                    nfixed += 1
                w = run_job(j, tmp, analyse=(it == 0))
                if it == 0:
                    r = j["res"]
                    what = (f"{j['steps']:5d} steps x {j['periods']:g} T, tol {j['tol']:g}"
                            if j["method"] == "transient" else
                            f"S = {j['steps']:5d}, eps {j['eps']:g}{', Floquet' if j['floquet'] else ''}")
                    print(f"  pass 1: {j['case']} {j['method']:9s} {what:32s} {w:6.3f} s (analysis "
                          f"{j['analysis'][-1]:.3f} s)  period {r['period']:.9e} s  p2p_t {r['p2p'][0]:.7e} m",
                          flush=True)
            print(f"pass {it + 1}/{repeat}: {len(jobs) + nfixed} runs in "
                  f"{time.perf_counter() - t0:.1f} s", flush=True)
        fixed_wall = min(fixed_job["walls"])
        print(f"fixed cost of a run (-analyses stability only: start-up, equilibrium, stability, output; least of "
              f"{len(fixed_job['walls'])}): {fixed_wall:.3f} s wall (median {np.median(fixed_job['walls']):.3f} s, "
              f"max {max(fixed_job['walls']):.3f} s), of which PETSc {least(fixed_job['petsc']):.3f} s, equilibrium "
              f"+ stability stages {least(fixed_job['analysis']) * 1e3:.1f} ms")
        if any(not (x == x) for j in jobs for x in j["analysis"]):
            warn("some runs had no PETSc log stage times (-log_view): analysis_s is nan there")

        # ---- rows of the timed runs, errors against the reference shooting run
        def series_of(j):
            if j["method"] == "shooting":
                ser = (["steps"] if j["eps"] == REF_EPS and not j["floquet"] else []) + \
                      (["eps"] if j["steps"] == EPS_STEPS and not j["floquet"] else []) + \
                      (["floquet"] if j["floquet"] else [])
            else:
                ser = (["h"] if j["periods"] == periods and j["tol"] == REF_TOL else []) + \
                      (["h_short"] if short and j["periods"] == short and j["tol"] == REF_TOL else []) + \
                      (["length"] if j["steps"] == LEN_STEPS and j["tol"] == REF_TOL else []) + \
                      (["fp_tol"] if j["steps"] == TOL_STEPS and j["periods"] == periods else [])
            return "+".join(ser)

        for j in jobs:
            r = j["res"]
            rows.append({"method": j["method"], "case": j["case"], "series": series_of(j),
                         "steps_per_period": j["steps"], "h": r["h"],
                         "periods": j.get("periods"), "fp_tol": j.get("tol"),
                         "shoot_eps": j.get("eps"),
                         "floquet": (int(j["floquet"]) if j["method"] == "shooting" else None),
                         "newton_its": r.get("its"), "period_integrations": r.get("integrations"),
                         "converged": r["converged"], "wall_s": min(j["walls"]), "walls": j["walls"],
                         "analysis_s": least(j["analysis"]), "petsc_s": least(j["petsc"]),
                         "energy_s": least(j["energy"]) if j["method"] == "shooting" else float("nan"),
                         "period": r["period"], "p2p_t": r["p2p"][0], "p2p_b": r["p2p"][1], "p2p_n": r["p2p"][2],
                         "timed": True, "res": r, "keep": j.get("keep")})
        refs = {}
        for case, _, _ in CASES:
            ref = next((r for r in rows if r["case"] == case and r["method"] == "shooting" and r["floquet"] == 0
                        and r["steps_per_period"] == ref_steps and r["shoot_eps"] == REF_EPS), None)
            if ref is None or not ref["converged"]:
                fail(f"{case}: the reference shooting run ({ref_steps} steps, eps {REF_EPS:g}) did not converge")
            refs[case] = (ref["period"], ref["p2p_t"])

        # ---- equal-h check: transient at exactly the step of each shooting run. Every step is recorded
        # (keep_every 1): at h = T / S the cycle is commensurate with the step, so recording every k-th
        # step would sample the same phases in every cycle and miss the peaks (-7e-6 in p2p_t at k = 4).
        # 50 periods (the cycles have settled after 25) keep the files small.
        eq_periods = min(periods, 50.0)
        if not args.no_equal_h:
            for case, _, _ in CASES:
                for s in steps:
                    sr = next(r for r in rows if r["case"] == case and r["method"] == "shooting" and r["floquet"] == 0
                              and r["steps_per_period"] == s and r["shoot_eps"] == REF_EPS)
                    if not sr["converged"]:
                        continue
                    h = sr["period"] / s
                    h5 = os.path.join(tmp, "eqh.h5")
                    cmd = transient_cmd(snap, scenes[case], eq_periods, s, REF_TOL, 1, h5, h=h)
                    w, p = run_timed(cmd, h5)
                    r = analyse_transient(p, cmd, h5)
                    os.remove(h5)
                    rows.append({"method": "transient", "case": case, "series": "equal_h", "steps_per_period": s,
                                 "h": r["h"], "periods": eq_periods, "fp_tol": REF_TOL, "shoot_eps": None,
                                 "floquet": None, "newton_its": None, "period_integrations": None, "converged": 1,
                                 "wall_s": w, "walls": [w], "analysis_s": float("nan"), "petsc_s": float("nan"),
                                 "energy_s": float("nan"), "period": r["period"], "p2p_t": r["p2p"][0],
                                 "p2p_b": r["p2p"][1], "p2p_n": r["p2p"][2], "timed": False, "res": r,
                                 "h_shoot": h, "shoot_row": sr, "keep": 1})
        # ---- effect of -transient_keep_every on the finest transient
        keep_check = {}
        if not args.no_keep_check and keep_for(ref_steps) > 1:
            for case, _, _ in CASES:
                h5 = os.path.join(tmp, "keep1.h5")
                cmd = transient_cmd(snap, scenes[case], periods, ref_steps, REF_TOL, 1, h5)
                w, p = run_timed(cmd, h5)
                keep_check[case] = (analyse_transient(p, cmd, h5), w)
                os.remove(h5)

    for r in rows:
        P_ref, A_ref = refs[r["case"]]
        r["err_period"] = abs(r["period"] - P_ref) / P_ref
        r["err_amplitude"] = abs(r["p2p_t"] - A_ref) / A_ref

    # ---- report per case
    ratios, ratios_p, orders, summary = {}, {}, {}, {}
    for case, _, clabel in CASES:
        P_ref, A_ref = refs[case]
        crow = [r for r in rows if r["case"] == case]
        print(f"\n== {clabel}\nreference: shooting {ref_steps} steps/period, eps {REF_EPS:g}: period {P_ref:.12e} s, "
              f"p2p_t {A_ref:.10e} m")
        print(f"  transient {'series':>15} {'steps':>5} {'periods':>7} {'tol':>6} {'keep':>4} {'wall s':>7} "
              f"{'anal s':>7} "
              f"{'period (s)':>16} {'p2p_t (m)':>15} {'err_period':>10} {'err_ampl':>9}  {'fp':>4}  "
              f"{'contact sep/stuck/slide %':26s} settle drift P / A")
        tr = sorted((r for r in crow if r["method"] == "transient" and r["timed"]),
                    key=lambda r: (r["periods"] != periods, -r["periods"], r["steps_per_period"], -r["fp_tol"]))
        for r in tr:
            res = r["res"]
            c = res.get("contact")
            cs = f"{c[0]:5.1f} {c[1]:5.1f} {c[2]:5.1f} {c[3][:10]}" if c else "-"
            dp, da = res["drift"]
            print(f"  {'':9} {r['series']:>15} {r['steps_per_period']:5d} {r['periods']:7g} {r['fp_tol']:6.0e} "
                  f"{r['keep']:4d} {r['wall_s']:7.3f} {r['analysis_s']:7.4f} {r['period']:16.10e} {r['p2p_t']:15.9e} "
                  f"{r['err_period']:10.2e} "
                  f"{r['err_amplitude']:9.2e}  {res.get('fp') or float('nan'):4.2f}  {cs:26s} {dp:.1e} / {da:.1e}")
            if (dp > 1e-4 or da > 1e-3) and "length" not in r["series"].split("+"):
                warn(f"{case}, transient {r['steps_per_period']} steps x {r['periods']:g} periods: the cycle has not "
                     f"settled (drift {dp:.1e} / {da:.1e} between the 60-80 % and 80-100 % windows)")
        print(f"  shooting  {'S':>5} {'eps':>6} {'Floquet':>7} {'Newton':>6} {'flows':>5} {'wall s':>7} "
              f"{'anal s':>7} {'energy':>6} "
              f"{'period (s)':>16} {'p2p_t (m)':>15} {'err_period':>10} {'err_ampl':>9}  regime")
        sh = sorted((r for r in crow if r["method"] == "shooting"),
                    key=lambda r: (r["floquet"], r["shoot_eps"] != REF_EPS, r["steps_per_period"], -r["shoot_eps"]))
        for r in sh:
            conv = "" if r["converged"] else f"  NOT CONVERGED ({r['res']['reason']})"
            print(f"  {'':9} {r['steps_per_period']:5d} {r['shoot_eps']:6.0e} {'yes' if r['floquet'] else 'no':>7} "
                  f"{r['newton_its']:6d} {r['period_integrations']:5d} {r['wall_s']:7.3f} {r['analysis_s']:7.4f} "
                  f"{r['energy_s']:6.4f} "
                  f"{r['period']:16.10e} "
                  f"{r['p2p_t']:15.9e} {r['err_period']:10.2e} {r['err_amplitude']:9.2e}  {r['res']['regime']}{conv}")
        fl = next((r for r in sh if r["floquet"] == 1), None)
        nf = next((r for r in sh if r["floquet"] == 0 and r["steps_per_period"] == EPS_STEPS
                   and r["shoot_eps"] == FLOQUET_EPS), None)
        if fl and nf:
            print(f"  cost of the Floquet multipliers ({EPS_STEPS} steps, eps {FLOQUET_EPS:g}): "
                  f"{fl['wall_s'] - nf['wall_s']:+.3f} s wall ({fl['wall_s']:.3f} s vs {nf['wall_s']:.3f} s), "
                  f"{fl['analysis_s'] - nf['analysis_s']:+.4f} s analysis ({fl['analysis_s']:.4f} s vs "
                  f"{nf['analysis_s']:.4f} s); "
                  f"period integrations reported {fl['period_integrations']} vs {nf['period_integrations']}")

        # Orders.
        orders[case] = {}
        print("\n  errors against the reference; order = slope of log err vs log h to the next step size; "
              "order(diff) = from successive differences q(h) - q(h/2), independent of the reference")
        for name, sel in ((f"transient, {periods:g} periods", lambda r: r["method"] == "transient" and r["timed"]
                           and "h" in r["series"].split("+")),
                          (f"transient, {short:g} periods" if short else "", lambda r: short and r["method"] ==
                           "transient" and r["timed"] and "h_short" in r["series"].split("+")),
                          (f"shooting, eps {REF_EPS:g}", lambda r: r["method"] == "shooting"
                           and "steps" in r["series"].split("+"))):
            seq = sorted((r for r in crow if sel(r)), key=lambda r: r["steps_per_period"])
            if len(seq) < 2:
                continue
            hs = [r["h"] for r in seq]
            ep, ea = [r["err_period"] for r in seq], [r["err_amplitude"] for r in seq]
            op, oa = orders_vs_ref(hs, ep), orders_vs_ref(hs, ea)
            sp = orders_successive(hs, [r["period"] for r in seq])
            sa = orders_successive(hs, [r["p2p_t"] for r in seq])
            orders[case][name] = (op, oa, sp, sa)
            print(f"  {name}:\n  {'steps':>6} {'h (s)':>11} {'wall s':>7} {'anal s':>7} {'err_period':>11} "
                  f"{'order':>6} "
                  f"{'order(diff)':>11} {'err_amplitude':>13} {'order':>6} {'order(diff)':>11}")
            for i, r in enumerate(seq):
                print(f"  {r['steps_per_period']:6d} {r['h']:11.4e} {r['wall_s']:7.3f} {r['analysis_s']:7.4f} "
                      f"{r['err_period']:11.3e} "
                      f"{fmt_order(op[i] if i < len(op) else None)} {fmt_order(sp[i] if i < len(sp) else None):>11} "
                      f"{r['err_amplitude']:13.3e} {fmt_order(oa[i] if i < len(oa) else None)} "
                      f"{fmt_order(sa[i] if i < len(sa) else None):>11}")
            if name.startswith("shooting"):
                for qn, q, so in (("period", [r["period"] for r in seq], sp),
                                  ("amplitude", [r["p2p_t"] for r in seq], sa)):
                    p_est = next((p for p in reversed(so) if p is not None and p > 0.3), None)
                    if p_est is not None:
                        e_ref = abs(q[-1] - q[-2]) / (2 ** p_est - 1) / abs(q[-1])
                        print(f"  estimated error of the reference itself vs h -> 0 ({qn}, Richardson with order "
                              f"{p_est:.2f}): {e_ref:.2e}")

        # Finest transient vs finest shooting.
        fin = [r for r in crow if r["method"] == "transient" and r["timed"] and r["steps_per_period"] == ref_steps
               and r["fp_tol"] == REF_TOL]
        summary[case] = {"finest": []}
        for r in sorted(fin, key=lambda r: -r["periods"]):
            print(f"  finest transient ({ref_steps} steps x {r['periods']:g} periods) vs finest shooting: period "
                  f"{r['err_period']:.2e}, amplitude {r['err_amplitude']:.2e} (relative difference)")
            summary[case]["finest"].append((r["periods"], r["err_period"], r["err_amplitude"]))
        if case in keep_check:
            r1, w1 = keep_check[case]
            r0 = next(r for r in fin if r["periods"] == periods)
            print(f"  keep_every check on the finest transient: keep_every {keep_for(ref_steps)} vs 1 changes the "
                  f"period by {abs(r1['period'] - r0['period']) / r0['period']:.1e} and the amplitude by "
                  f"{abs(r1['p2p'][0] - r0['p2p_t']) / r0['p2p_t']:.1e} (relative)")
        eq = sorted((r for r in crow if r["series"] == "equal_h"), key=lambda r: r["steps_per_period"])
        if eq:
            print(f"  equal-h check: transient ({eq_periods:g} periods, every step recorded) at h = T_shoot(S) / S vs "
                  "shooting at S (relative differences); for comparison the shooting error at S")
            print(f"  {'S':>6} {'h (s)':>11} {'d period':>9} {'d p2p_t':>9} {'err_P shoot':>11} {'err_A shoot':>11}")
            for r in eq:
                s = r["shoot_row"]
                dP = abs(r["period"] - s["period"]) / s["period"]
                dA = abs(r["p2p_t"] - s["p2p_t"]) / s["p2p_t"]
                r["d_period"], r["d_amplitude"] = dP, dA
                print(f"  {r['steps_per_period']:6d} {r['h']:11.4e} {dP:9.1e} {dA:9.1e} {s['err_period']:11.2e} "
                      f"{s['err_amplitude']:11.2e}")
            summary[case]["equal_h"] = [(r["steps_per_period"], r["d_period"], r["d_amplitude"]) for r in eq]

        # Speed ratio at equal accuracy.
        ratios[case], ratios_p[case] = {}, {}
        measures = (("total", lambda r: r["wall_s"]), ("net", lambda r: r["wall_s"] - fixed_wall),
                    ("analysis", lambda r: r["analysis_s"]))
        pools = (("all runs", lambda r: True),
                 (f"{periods:g} T only", lambda r: r["method"] == "shooting" or "h" in r["series"].split("+")))
        print("\n  speed ratio at equal accuracy = time of the cheapest transient run reaching the target / that of the "
              "cheapest shooting run;\n  interpolated on the step-size series (in brackets: over the measured runs "
              f"only); wall = whole run, net = wall - fixed cost {fixed_wall:.3f} s, analysis = PETSc stages")
        print(f"    {'target':18} {'transient runs':14} {'wall':>12} {'net':>12} {'analysis':>12}   "
              "cheapest measured (wall): transient | shooting")
        for key, target in TARGETS + EXTRA_TARGETS:
            for pool, keep in pools:
                prow = [r for r in crow if keep(r)]
                out, cells = {}, []
                for label, wall_of in measures:
                    mt, (it_, _) = cheapest(prow, "transient", key, target, wall_of)
                    ms, (is_, _) = cheapest(prow, "shooting", key, target, wall_of)
                    out[label] = it_ / is_ if (it_ and is_ and is_ > 0) else None
                    meas = wall_of(mt) / wall_of(ms) if (mt and ms and wall_of(ms) > 0) else None
                    cells.append(f"{fmt_num(out[label], '.2f') or '-':>5} [{fmt_num(meas, '.2f') or '-':>4}]")
                    if label == "total":
                        wt = f" {mt['wall_s']:.3f} s" if mt else ""
                        ws = f" {ms['wall_s']:.3f} s" if ms else ""
                        who = f"{describe(mt)}{wt} | {describe(ms)}{ws}"
                if (key, target) in TARGETS:
                    (ratios if pool == "all runs" else ratios_p)[case][key] = out
                what = f"{'period' if key == 'err_period' else 'amplitude'} {target:g}"
                print(f"    {what:18} {pool:14} {cells[0]:>12} {cells[1]:>12} {cells[2]:>12}   {who}")

    # ---- CSV and figure
    with open(csv_path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(CSV_COLUMNS)
        for r in rows:
            w.writerow([r["method"], r["case"], r["series"], r["steps_per_period"], f"{r['h']:.6e}",
                        fmt_num(r["periods"], "g"), fmt_num(r["fp_tol"], "g"), fmt_num(r["shoot_eps"], "g"),
                        fmt_num(r["floquet"], "d"), fmt_num(r["newton_its"], "d"),
                        fmt_num(r["period_integrations"], "d"), r["converged"], f"{r['wall_s']:.4f}",
                        "" if r["analysis_s"] != r["analysis_s"] else f"{r['analysis_s']:.5f}",
                        "" if r["energy_s"] != r["energy_s"] else f"{r['energy_s']:.5f}",
                        "" if r["petsc_s"] != r["petsc_s"] else f"{r['petsc_s']:.5f}",
                        f"{r['period']:.12e}", f"{r['p2p_t']:.10e}", f"{r['p2p_b']:.10e}", f"{r['p2p_n']:.6e}",
                        f"{r['err_period']:.6e}", f"{r['err_amplitude']:.6e}"])
    plot(rows, steps, png_path, {"periods": periods, "short_periods": short, "lengths": lengths,
                                 "fixed_wall": fixed_wall, "ratios": ratios, "ratios_p": ratios_p, "ref_steps": ref_steps, "repeat": repeat,
                                 "title_extra": " [quick]" if args.quick else ""})

    print("\nobserved orders (slope of log err vs log h between successive step sizes; "
          "in brackets: from successive differences)")
    for case, _, clabel in CASES:
        print(f"  {clabel}")
        for name, (op, oa, sp, sa) in orders[case].items():
            def seq_str(a, b):
                return ", ".join(f"{fmt_order(x).strip()} [{fmt_order(y).strip()}]"
                                 for x, y in zip(a, b + [None] * (len(a) - len(b))))
            print(f"    {name}\n      period:    {seq_str(op, sp)}\n      amplitude: {seq_str(oa, sa)}")
    print(f"\ntotal time of the study {time.perf_counter() - t_start:.0f} s\nwrote {csv_path}\nwrote {png_path}")


if __name__ == "__main__":
    main()
