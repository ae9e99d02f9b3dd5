"""The command line of squeal's results package:

    python3 scripts/squeal_cli.py SUBCOMMAND ...     (or, from scripts/, python3 -m squeal ...)

  info FILE [--datasets]        status, model, groups and each analysis's verdict on one screen
  plot KIND FILE ... [options]  one of the plots (KIND: see `plot --help`); options as plot_KIND.py
  compare A B [--rtol R]        every dataset and attribute of two results files; exit 1 on a
                                difference beyond the tolerance
  xdmf FILE ...                 scripts/squeal_xdmf.py: modes, cycle, transient on the mesh for ParaView
  steady-state FILE ...         scripts/steady_state.py: statistical steady state of a transient
  work-precision ...            scripts/work_precision.py: transient against shooting, error vs time

`SUBCOMMAND --help` documents each.
"""
import argparse
import os
import sys

import numpy as np

from . import plot as plotpkg
from .results import decode, decoded_attrs, fail, open_results

PROG = os.path.basename(sys.argv[0]) if sys.argv and sys.argv[0] else "squeal_cli.py"
if PROG == "__main__.py":
    PROG = "python3 -m squeal"

# Subcommands handed whole to a script module of scripts/ (its own argparse and --help).
DISPATCH = {
    "xdmf": ("squeal_xdmf", "results on the mesh as XDMF + HDF5 time series (scripts/squeal_xdmf.py)"),
    "steady-state": ("steady_state", "statistical steady state of a transient (scripts/steady_state.py)"),
    "work-precision": ("work_precision", "transient against shooting, error against time (scripts/work_precision.py)"),
}


# --------------------------------------------------------------------------------------------
# info

def _g(x, spec="g"):
    return "?" if x is None else format(x, spec)


def _summary(name, g):
    """One line per analysis group: what it found."""
    a = g.attrs
    if name == "equilibrium":
        n_c = g.dataset("N").shape[0] if "N" in g else 0
        n_a = g.dataset("active").shape[0] if "active" in g else 0
        return f"mu = {_g(a.get('mu'))}; {n_a} of {n_c} contact point(s) closed"
    if name == "stability":
        return f"{g.verdict()} ({g.eigenvalues.shape[0]} eigenvalue(s), complete up to {_g(a.get('complete_up_to'))} Hz)"
    if name == "sweep":
        mu = g.array("mu").ravel() if "mu" in g else np.array([])
        V = g.V if g.V is not None else np.array([])
        crit, fc = g._attr_array("critical_mu", V.size), g._attr_array("coalescence_frequency", V.size)
        where = f"{mu.size} mu in [{mu.min():g}, {mu.max():g}]" if mu.size else "no mu"
        cert = np.asarray(g["critical_certified"]).ravel() if "critical_certified" in g else np.ones(V.size)
        parts = [f"V = {v:g} m/s: " + (f"critical mu {c:.6g} ({f:.2f} Hz{'' if ok else ', not certified'})"
                                       if np.isfinite(c) else "no crossing")
                 for v, c, f, ok in zip(V, crit, fc, cert)]
        failed = int(np.count_nonzero(g["failed"])) if "failed" in g else 0
        return f"{where} x {V.size} V; " + "; ".join(parts) + (f"; {failed} failed point(s)" if failed else "")
    if name == "energy":
        if a.get("stable", 0):
            return "no estimate: no unstable mode in the band"
        if not a.get("found", 0):
            return f"mode {_g(a.get('mode'))}: no balance found" + ("" if "q" in g else " (no amplitude scan)")
        return f"mode {_g(a.get('mode'))}: balance q0 = {_g(a.get('q0'), '.6g')} m, T0 = {_g(a.get('T0'), '.6g')} s"
    if name == "shooting":
        s = (f"converged in {g.iterations} iteration(s): T = {g.period:.9g} s" if g.converged
             else f"NOT converged ({a.get('reason', '?')})")
        if "floquet_verdict" in a:
            s += (f"; Floquet {a['floquet_verdict']} (margin {_g(a.get('floquet_margin'), '.3g')}, "
                  f"error {_g(a.get('floquet_error'), '.2g')})")
        return s
    if name == "transient":
        n = g.dataset("t").shape[0] if "t" in g else 0
        t_end = float(g.dataset("t")[-1]) if n else float("nan")
        s = f"{n} records to t = {t_end:.6g} s, {'complete' if g.complete else 'INCOMPLETE'}"
        if a.get("settled", 0):
            s += f"; settled cycle, period {_g(g.period, '.9g')} s"
        elif "trend" in a:
            s += f"; not settled ({a['trend']})"
        if "fraction_separated" in a:
            s += f"; separated {100 * a['fraction_separated']:.1f} %, stuck {100 * a.get('fraction_stuck', 0):.1f} %"
        return s
    if name == "continuation":
        p = g.array("param") if "param" in g else np.array([])
        s = f"{p.size} point(s), {g.parameter} in [{p.min():g}, {p.max():g}]" if p.size else "no point"
        if "stable" in g and p.size:
            s += f", {int(np.count_nonzero(g['stable']))} stable"
        ev = g.events()
        if ev:
            s += "; events " + ", ".join(f"{t} at {v:.6g}" for t, v in ev)
        if a.get("interrupted", 0):
            s += "; INTERRUPTED"
        return s
    if name == "mesh":
        nodes = g.dataset("x").shape[0] if "x" in g else 0
        cells = ", ".join(f"{g.h5['cells'][k].shape[0]} {k}" for k in g.h5["cells"]) if "cells" in g else "no cells"
        return f"{nodes} nodes, {cells}" + (", partial (reduced model)" if a.get("partial", 0) else "")
    if name == "steady_state":
        return f"{a.get('verdict', '?')} ({a.get('evidence', '')}); RMS {_g(a.get('rms'), '.4e')}"
    return ", ".join(g.keys())


def info(path, datasets=False):
    with open_results(path) as r:
        print(f"{path}: {r.creator or '(no creator attribute)'}")
        print(f"status: {r.status or '(none)'}")
        m = r.model
        if m:
            bits = [str(m.get("name", "?"))]
            for key, fmt in (("dofs", "{} DOFs"), ("contact_points", "{} contact point(s)"), ("mu", "mu = {:g}"),
                             ("V", "V = {:g} m/s"), ("friction", "friction {}")):
                if key in m:
                    bits.append(fmt.format(m[key]))
            print("model: " + ", ".join(bits))
        groups = r.groups
        print("groups: " + ", ".join("/" + g for g in groups))
        width = max([len(g) for g in groups] + [1])
        for name in groups:
            if name == "model":
                continue
            print(f"  {name:{width}}  {_summary(name, r.group(name))}")
        if datasets:
            print("datasets:")

            def show(name, obj):
                if hasattr(obj, "shape"):
                    print(f"  /{name}  {obj.shape} {obj.dtype}")
            r.h5.visititems(show)
    return 0


# --------------------------------------------------------------------------------------------
# compare

def _objects(h5):
    """{path: object} of every group and dataset of an open file, the root included."""
    out = {"/": h5}
    h5.visititems(lambda name, obj: out.__setitem__("/" + name, obj))
    return out


def _blocks(a, b, size=1 << 22):
    """The two datasets in matching blocks along the first axis (a whole transient need not fit twice)."""
    if a.ndim == 0 or a.size <= size:
        yield 0, a[()], b[()]
        return
    step = max(1, size // max(1, a.size // a.shape[0]))
    for i in range(0, a.shape[0], step):
        yield i, a[i:i + step], b[i:i + step]


def _numeric_diff(x, y, rtol, atol):
    """(count beyond tolerance, largest |x - y|, largest relative difference, first flat index beyond)."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    both_nan = np.isnan(x) & np.isnan(y)
    same = (x == y) | both_nan  # equal infinities too
    with np.errstate(invalid="ignore", over="ignore"):
        d = np.where(same, 0.0, np.abs(x - y))
        d = np.where(np.isnan(d), np.inf, d)  # NaN against a number
        scale = np.maximum(np.abs(x), np.abs(y))
        rel = np.where(d == 0, 0.0, d / np.where(scale > 0, scale, np.inf))
        rel = np.where(np.isnan(rel), np.inf, rel)
    bad = d > atol + rtol * np.where(np.isfinite(scale), scale, 0.0)
    first = int(np.flatnonzero(bad.ravel())[0]) if bad.any() else -1
    return int(bad.sum()), float(d.max()) if d.size else 0.0, float(rel.max()) if rel.size else 0.0, first


def _values_differ(u, v, rtol, atol):
    """None when u and v agree (attributes: small arrays or scalars), else a short description."""
    u, v = decode(u), decode(v)
    au, av = np.asarray(u), np.asarray(v)
    if au.dtype.kind in "biuf" and av.dtype.kind in "biuf":
        if au.shape != av.shape:
            return f"shape {au.shape} vs {av.shape}"
        n, dmax, rmax, _ = _numeric_diff(au, av, rtol, atol)
        return None if n == 0 else f"{u!r} vs {v!r} (relative difference {rmax:.2e})"
    return None if str(u) == str(v) and au.shape == av.shape else f"{u!r} vs {v!r}"


def compare(path_a, path_b, rtol, atol, quiet=False):
    diffs, inexact, count = [], 0, 0
    with open_results(path_a) as ra, open_results(path_b) as rb:
        oa, ob = _objects(ra.h5), _objects(rb.h5)
        for p in sorted(set(oa) | set(ob)):
            if p not in ob:
                diffs.append(f"{p}: only in A")
                continue
            if p not in oa:
                diffs.append(f"{p}: only in B")
                continue
            a, b = oa[p], ob[p]
            count += 1
            ka, kb = hasattr(a, "shape"), hasattr(b, "shape")
            if ka != kb:
                diffs.append(f"{p}: a {'dataset' if ka else 'group'} in A, a {'dataset' if kb else 'group'} in B")
                continue
            aa, ab = decoded_attrs(a), decoded_attrs(b)
            for k in sorted(set(aa) | set(ab)):
                where = f"{p} attribute {k}"
                if k not in ab or k not in aa:
                    diffs.append(f"{where}: only in {'A' if k in aa else 'B'}")
                    continue
                count += 1
                d = _values_differ(aa[k], ab[k], rtol, atol)
                if d:
                    diffs.append(f"{where}: {d}")
            if not ka:
                continue
            if a.shape != b.shape:
                diffs.append(f"{p}: shape {a.shape} vs {b.shape}")
                continue
            if a.dtype.kind in "biuf" and b.dtype.kind in "biuf":
                n_bad, dmax, rmax, first = 0, 0.0, 0.0, -1
                for off, x, y in _blocks(a, b):
                    n, dm, rm, f = _numeric_diff(x, y, rtol, atol)
                    if f >= 0 and first < 0:
                        first = off * (x.size // max(1, x.shape[0] if x.ndim else 1)) + f
                    n_bad, dmax, rmax = n_bad + n, max(dmax, dm), max(rmax, rm)
                if n_bad:
                    at = np.unravel_index(first, a.shape) if a.ndim else ()
                    diffs.append(f"{p}: {n_bad} of {a.size} value(s) differ beyond the tolerance; largest |A - B| "
                                 f"{dmax:.3e}, largest relative {rmax:.3e}; first at {tuple(int(i) for i in at)}: "
                                 f"{a[at] if a.ndim else a[()]!r} vs {b[at] if b.ndim else b[()]!r}")
                elif dmax > 0:
                    inexact += 1
            else:
                d = _values_differ(a[()], b[()], rtol, atol) if a.size < 100000 else (
                    None if np.array_equal(a[()], b[()]) else "contents differ")
                if d:
                    diffs.append(f"{p}: {d}")
    for d in diffs:
        print(d)
    if not quiet or diffs:
        print(f"compare: {count} objects and attributes in both files; {len(diffs)} difference(s) beyond "
              f"rtol {rtol:g}, atol {atol:g}; {inexact} dataset(s) differ within the tolerance")
    return 1 if diffs else 0


# --------------------------------------------------------------------------------------------

def _plot(argv):
    if not argv or argv[0] in ("-h", "--help") or argv[0] not in plotpkg.KINDS:
        width = max(len(k) for k in plotpkg.KINDS)
        text = (f"usage: {PROG} plot KIND RESULTS.h5 ... [options]\n\nKIND (`{PROG} plot KIND --help` for its "
                "options; the same command line as scripts/plot_KIND.py):\n"
                + "\n".join(f"  {k:{width}}  {h}" for k, h in plotpkg.KINDS.items()))
        if argv and argv[0] not in ("-h", "--help"):
            print(text, file=sys.stderr)
            fail(f"unknown plot kind '{argv[0]}'")
        print(text)
        return 0 if argv else 2
    return plotpkg.module(argv[0]).main(argv[1:], prog=f"{PROG} plot {argv[0]}") or 0


def parser():
    ap = argparse.ArgumentParser(prog=PROG, description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", metavar="SUBCOMMAND")
    p = sub.add_parser("info", help="status, model, groups and verdicts of a results file",
                       description="One screen on a squeal results file: the root status, the model, which groups "
                                   "it holds and, per analysis, what it found (the stability verdict, critical mu, "
                                   "energy balance, shooting convergence and Floquet verdict, settled test, branch).")
    p.add_argument("file", metavar="FILE.h5")
    p.add_argument("--datasets", action="store_true", help="also list every dataset with its shape and type")
    p = sub.add_parser("compare", help="every dataset and attribute of two results files",
                       description="Compares every group, dataset and attribute of two results files (the root's "
                                   "status and creator included) and lists what is only in one, what has another "
                                   "shape, and what differs beyond the tolerance |A - B| <= atol + rtol max(|A|, |B|) "
                                   "(NaN equals NaN). Exit 0: the same within the tolerance; 1: a difference.")
    p.add_argument("a", metavar="A.h5")
    p.add_argument("b", metavar="B.h5")
    p.add_argument("--rtol", type=float, default=1e-9, help="relative tolerance (default 1e-9; 0: exact)")
    p.add_argument("--atol", type=float, default=0.0, help="absolute tolerance (default 0)")
    p.add_argument("-q", "--quiet", action="store_true", help="print nothing when the files agree")
    sub.add_parser("plot", add_help=False, help="KIND FILE ...: one of the plots (`plot --help` lists the kinds)")
    for name, (_, text) in DISPATCH.items():
        sub.add_parser(name, add_help=False, help=text + "; same options")
    return ap


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    if argv and argv[0] == "plot":
        return _plot(argv[1:])
    if argv and argv[0] in DISPATCH:
        import importlib
        sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
        mod = importlib.import_module(DISPATCH[argv[0]][0])
        kw = {"prog": f"{PROG} {argv[0]}"} if "prog" in mod.main.__code__.co_varnames else {}
        return mod.main(argv[1:], **kw) or 0
    a = parser().parse_args(argv)
    if a.cmd == "info":
        return info(a.file, a.datasets)
    if a.cmd == "compare":
        return compare(a.a, a.b, a.rtol, a.atol, a.quiet)
    parser().print_help()
    return 2


if __name__ == "__main__":
    sys.exit(main())
