#!/usr/bin/python3
"""Runs squeal -analyses auto (the command after --) and checks the route it chose (/route) and
what that route wrote: with --route shooting a converged /shooting; with --route steady_state a
/steady_state whose levels and Welch PSD are those numpy computes (scripts/steady_state.py's
levels and welch) on the records it wrote, its RMS inside its own interval, and --verdict among
the allowed ones."""
import argparse
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "..", "scripts"))
from squeal.results import Results  # noqa: E402
import steady_state as ss  # noqa: E402
import scene_run  # noqa: E402


def fail(msg):
    sys.exit(f"check_route: {msg}")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--output", required=True)
    ap.add_argument("--route", choices=["shooting", "steady_state"], required=True)
    ap.add_argument("--verdict", action="append", help="allowed verdicts (steady_state); default any")
    ap.add_argument("--modal", action="store_true", help="check the unstable modes' projection (steady_state)")
    ap.add_argument("--torus", choices=["converged", "tried"],
                    help="a quasi-periodic verdict must go on to the torus (-torus_auto): converged, with its f1 and "
                         "modulation within --ftol Hz of the steady state's two bases; or tried, either way said in /route")
    ap.add_argument("--ftol", type=float, default=1.0)
    ap.add_argument("--reason", help="a text /route's reason must contain")
    ap.add_argument("--max-pre-periods", type=int, help="the pre-periods must stop before this many")
    ap.add_argument("cmd", nargs=argparse.REMAINDER)
    a = ap.parse_args()
    cmd = scene_run.command(a.cmd)
    r = scene_run.run(cmd, "check_route")
    lines = [ln for ln in r.stdout.splitlines() if ln.startswith("route: ")]
    if not lines:
        fail("no 'route:' line printed")
    with Results(a.output) as res:
        g = res.group("route")
        if g is None:
            fail("no /route group")
        route = g.attrs["route"]
        if route != a.route:
            fail(f"route {route}, expected {a.route} ({g.attrs['reason']})")
        if a.reason and a.reason not in str(g.attrs["reason"]):
            fail(f"the route's reason does not say '{a.reason}': {g.attrs['reason']}")
        if a.max_pre_periods is not None and int(g.attrs["pre_periods"]) >= a.max_pre_periods:
            fail(f"{int(g.attrs['pre_periods'])} pre-periods, expected fewer than {a.max_pre_periods} ({g.attrs['reason']})")
        d, tol = float(g.attrs["return_distance"]), float(g.attrs["pre_tol"])
        # A returned flow goes to the statistics when Newton failed from it, or when modes above the
        # band grow faster than the band's (-stab_guard_route; without the attribute: none).
        guarded = route == "steady_state" and int(g.attrs.get("faster_above_band", 0)) > 0
        if (route == "shooting") != (d < tol) and not int(g.attrs["newton_failed"]) and not guarded:
            fail(f"route {route} with return distance {d:.3g} against -shoot_pre_tol {tol:g}")
        if route == "shooting":
            if res.shooting is None or not res.shooting.converged:
                fail("route shooting without a converged /shooting")
            print(f"check_route: shooting, return distance {d:.2e} < {tol:g}, period {res.shooting.period:.7g} s")
            return
        s = res.steady_state
        if s is None:
            fail("route steady_state without /steady_state")
        at = s.attrs
        t, x = s["t"], s["signal"]
        dt = t[1] - t[0]
        if np.max(np.abs(np.diff(t) - dt)) > 1e-9 * dt:
            fail("the analysed records are not uniformly spaced (chunks off one grid)")
        lv = ss.levels(x, int(at["batches"]))
        for k in ("rms", "rms_lo", "rms_hi", "peak"):
            if abs(lv[k] - float(at[k])) > 1e-9 * abs(lv[k]):
                fail(f"{k} {float(at[k]):.9e}, numpy gives {lv[k]:.9e}")
        if not float(at["rms_lo"]) <= float(at["rms"]) <= float(at["rms_hi"]):
            fail("the RMS is outside its own interval")
        f, p = ss.welch(x, dt)
        if len(f) != len(s["psd"]) or np.max(np.abs(p - s["psd"])) > 1e-9 * np.max(p):
            fail("the PSD differs from numpy's Welch on the same records")
        if a.verdict and at["verdict"] not in a.verdict:
            fail(f"verdict {at['verdict']} ({at['evidence']}), expected one of {a.verdict}")
        if len(s["lines"]) == 0:
            fail("no spectral line")
        modal = check_modal(res, s) if a.modal else ""
        if a.torus:
            modal += check_torus(a, res, g, s, lines)
        print(f"check_route: steady_state, return distance {d:.2e} >= {tol:g}; RMS {lv['rms']:.4e} in "
              f"[{lv['rms_lo']:.4e}, {lv['rms_hi']:.4e}] as numpy's; PSD as numpy's; verdict {at['verdict']}{modal}")


def check_torus(a, res, g, s, lines):
    """-analyses auto after a quasi-periodic steady state: the route line and /route say whether the
    torus converged; converged, /torus's f1 and modulation (the distance of f2 to the nearest multiple
    of f1) agree with the spectrum's two bases, the lines named 1 f1 (or 1 f1 + 0 f2) and 0 f1 + 1 f2."""
    at = s.attrs
    verdict = at["verdict"]
    tor = g.attrs.get("torus", "")
    if verdict != "quasi-periodic":
        if tor.startswith("converged") or tor.startswith("not converged"):
            fail(f"verdict {verdict} but /route torus = {tor}")
        return f"; no torus ({tor})"
    if not int(at["converged"]):
        if not tor.startswith("not attempted"):
            fail(f"statistics not converged, yet /route torus = '{tor}'")
        return f"; no torus ({tor})"
    said = [ln for ln in lines if ln.startswith("route: torus: ")]
    if tor not in ("converged", "not converged") or not said:
        fail(f"quasi-periodic verdict: /route torus = '{tor}', route lines {lines}")
    if tor == "not converged":
        if a.torus == "converged":
            fail(f"the torus did not converge: {g.attrs['torus_reason']}")
        if "statistical steady state above stands" not in said[0]:
            fail(f"a torus that did not converge must leave the statistics standing: {said[0]}")
        return "; torus tried, not converged (the statistics stand)"
    names = [n.strip() for n in str(at["line_names"]).split(";")]
    fl = np.asarray(s["lines"])
    # The first base is named before the second exists ("1 f1"), or after it ("1 f1 + 0 f2").
    b1 = [f for f, n in zip(fl, names) if n in ("1 f1", "1 f1 + 0 f2")]
    b2 = [f for f, n in zip(fl, names) if n == "0 f1 + 1 f2"]
    if len(b1) != 1 or len(b2) != 1:
        fail(f"no lines named the two bases in {names}")
    b1, b2 = b1[0], b2[0]
    t = res.group("torus").attrs
    if not int(t["converged"]) or not float(t["residual"]) < 1e-6:
        fail(f"/route says converged, /torus converged {int(t['converged'])}, residual {float(t['residual']):.3e}")
    f1, fm = float(t["f1"]), float(t["f_modulation"])
    r = (b2 / b1) % 1.0
    bm = b1 * min(r, 1 - r)
    if abs(f1 - b1) > a.ftol or abs(fm - bm) > a.ftol:
        fail(f"torus f1 {f1:.4f} Hz, modulation {fm:.4f} Hz; the bases give {b1:.4f} and {bm:.4f} (+- {a.ftol:g})")
    return f"; torus converged: f1 {f1:.3f} Hz (base {b1:.3f}), modulation {fm:.3f} Hz (bases {bm:.3f})"


def check_modal(res, s):
    """The unstable modes' share against numpy on the modal coordinates the run wrote: their RMS,
    each mode's part |Re(phi_j q_j)|^2 over the motion's variance (the shapes from /stability), the
    modes those of /stability's unstable list, the coordinates' window mean zero, the
    signal DOF's fitted part no larger than the signal."""
    at = s.attrs
    st = res.stability
    if "mode_rms" not in s:
        fail(f"no /steady_state/mode_rms ({at.get('modes_note', 'no note')})")
    idx = np.asarray(s["mode_index"], dtype=int)
    if list(idx) != list(st.unstable):
        fail(f"modes {list(idx)} projected on, /stability's unstable ones are {list(st.unstable)}")
    if np.max(np.abs(np.asarray(s["mode_frequency"]) - st.frequency[idx])) > 1e-9 * np.max(st.frequency[idx]):
        fail("mode_frequency differs from /stability's")
    q = np.asarray(s["modal_coordinates"])
    k = len(idx)
    t = np.asarray(s["t"])
    if q.ndim != 2 or q.shape[1] != 2 * k or not 2 <= q.shape[0] <= len(t):
        fail(f"modal_coordinates of shape {q.shape}, expected (<= {len(t)}, {2 * k})")
    # The window: the last q.shape[0] of the analysed records, starting at modes_t_from.
    if abs(t[len(t) - q.shape[0]] - float(at["modes_t_from"])) > 1e-9 * abs(t[-1]):
        fail(f"the modal window starts at t = {float(at['modes_t_from'])}, its records at {t[len(t) - q.shape[0]]}")
    if np.max(np.abs(q.mean(axis=0))) > 1e-9 * np.max(np.abs(q)):
        fail("the modal coordinates' mean over the window is not zero")
    a, b = q[:, 0::2], q[:, 1::2]
    rms = np.sqrt(np.mean(a ** 2 + b ** 2, axis=0))
    if np.max(np.abs(rms - s["mode_rms"])) > 1e-9 * np.max(rms):
        fail(f"mode_rms {np.asarray(s['mode_rms'])}, numpy gives {rms}")
    var = float(at["modes_variance"])
    share = []
    for j, m in enumerate(idx):
        phi = st.mode(m)
        part = np.outer(a[:, j], phi.real) + np.outer(b[:, j], phi.imag)  # Re(phi (a - i b))
        share.append(np.mean(np.sum(part ** 2, axis=1)) / var)
    share = np.array(share)
    if np.max(np.abs(share - s["mode_share"])) > 1e-8 * max(np.max(share), 1e-300):
        fail(f"mode_share {np.asarray(s['mode_share'])}, numpy gives {share}")
    ex = float(at["modes_explained"])
    if not 0 <= ex <= 1 or abs(ex + float(at["modes_residual"]) - 1) > 1e-12:
        fail(f"modes_explained {ex}, modes_residual {float(at['modes_residual'])}")
    # The fitted part at the signal DOF over the same records: a least-squares fit of all DOFs
    # cannot put more variance on one DOF than the whole motion has.
    dof = int(at["dof"])
    fit = sum(a[:, j] * st.mode(m).real[dof] + b[:, j] * st.mode(m).imag[dof] for j, m in enumerate(idx))
    if np.mean(fit ** 2) > var * (1 + 1e-9):
        fail("the fitted part at the signal DOF exceeds the motion's variance")
    return "; modal " + ", ".join(f"mode {m} {f:.0f} Hz RMS {r:.3e} share {sh:.1%}" for m, f, r, sh in
                                  zip(idx, np.asarray(s["mode_frequency"]), rms, share)) + f", explained {ex:.1%} (as numpy's)"


if __name__ == "__main__":
    main()
