#!/usr/bin/python3
"""The statistical steady state of a transient that has no periodic orbit (docs/steady-state.md).

    steady_state.py RESULTS.h5 [--dof K] [--rtol 0.05] [--batches 20] [--write] [--plot OUT.png]

From squeal's /transient records it answers what a cycle cannot when the motion is irregular:
  start-up   dropped by MSER (White 1997) on the signal's power per period of its strongest line:
             the cut minimises the standard error of the mean power of what remains (at most half);
  levels     RMS and peak about the mean of the signal DOF (the transient's signal_dof, or --dof)
             and of the total normal reaction, with a 95 % confidence interval of the RMS from
             batch means (--batches, Student t); "converged" when its half-width is below --rtol;
  spectrum   Welch PSD (Hann, 50 % overlap, 8 segments), its lines (peaks 100x above the median
             floor), refined by a least-squares fit of sinusoids to the signal (frequencies by
             Gauss-Newton), each named as a harmonic or an integer combination of the base lines;
  modes      the share of each linear unstable mode (/stability/modes) in the motion: RMS of its
             modal coordinate from a least-squares projection of U(t) - mean on Re phi, Im phi;
  verdict    periodic (every line a harmonic of one base), quasi-periodic (two or more
             incommensurate bases explain the lines) or broadband (lines carry less than half of
             the power), with the evidence; unresolved, in place of the first two, when at the
             record's resolution more than a quarter of the band would be named by chance.
--write stores it as /steady_state in RESULTS.h5; --plot draws the signal and the PSD.
The functions are importable (tests/scenes/test_steady_state.py checks them on exact signals).
"""
import argparse
import math
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from squeal.results import Results  # noqa: E402

T975 = {5: 2.571, 10: 2.228, 15: 2.131, 19: 2.093, 20: 2.086, 30: 2.042, 40: 2.021, 60: 2.000, 120: 1.980}


def t975(dof):
    """Two-sided 95 % Student t quantile (tabulated, conservative between the entries)."""
    keys = sorted(T975)
    for k in keys:
        if dof <= k:
            return T975[k]
    return 1.96


def mser_cut(x, batch=5):
    """Index at which the start-up ends: MSER-5 on the local power (x - mean)^2."""
    n = len(x) // batch
    if n < 4:
        return 0
    p = ((x[: n * batch] - x.mean()) ** 2).reshape(n, batch).mean(axis=1)
    best, cut = np.inf, 0
    for d in range(n // 2 + 1):
        y = p[d:]
        s = y.var() / (len(y) - 1) if len(y) > 1 else np.inf
        if s < best:
            best, cut = s, d
    return cut * batch


def levels(x, batches=20):
    """RMS about the mean, peak, and the 95 % interval of the RMS from batch means of x^2."""
    y = x - x.mean()
    rms = math.sqrt(np.mean(y * y))
    nb = min(batches, len(y) // 2)
    b = (y[: (len(y) // nb) * nb] ** 2).reshape(nb, -1).mean(axis=1)
    half = t975(nb - 1) * b.std(ddof=1) / math.sqrt(nb)
    lo, hi = math.sqrt(max(b.mean() - half, 0.0)), math.sqrt(b.mean() + half)
    return dict(rms=rms, peak=float(np.abs(y).max()), rms_lo=lo, rms_hi=hi, rel_halfwidth=(hi - lo) / (2 * rms) if rms else 0.0)


def welch(x, dt, segments=8):
    """One-sided PSD by Welch's method (Hann window, 50 % overlap)."""
    n = len(x)
    L = max(16, 2 * n // (segments + 1))
    step = L // 2
    w = np.hanning(L)
    scale = 1.0 / (np.sum(w * w) / dt)
    acc, k = 0.0, 0
    for s in range(0, n - L + 1, step):
        seg = x[s:s + L] - x[s:s + L].mean()
        acc = acc + np.abs(np.fft.rfft(seg * w)) ** 2
        k += 1
    psd = acc * scale / k
    psd[1:-1] *= 2
    return np.fft.rfftfreq(L, dt), psd


def refine_peaks(x, dt, f0, width):
    """Each rough frequency to within a small fraction of 1/record: the largest value of the whole
    record's Hann-windowed spectrum (4x zero-padded) within +-width, by parabolic interpolation of
    its logarithm. Gauss-Newton on the sinusoids needs this start (a phase error below ~1 rad
    over the record)."""
    y = (x - x.mean()) * np.hanning(len(x))
    n = 4 * len(x)
    X = np.abs(np.fft.rfft(y, n))
    fr = np.fft.rfftfreq(n, dt)
    out = []
    for g in f0:
        lo, hi = np.searchsorted(fr, g - width), np.searchsorted(fr, g + width)
        i = lo + int(np.argmax(X[lo:hi + 1]))
        if 0 < i < len(X) - 1:
            a, b, c = np.log(X[i - 1:i + 2] + 1e-300)
            i = i + 0.5 * (a - c) / (a - 2 * b + c)
        out.append(i * (fr[1] - fr[0]))
    return out


def fit_lines(x, t, f0, iters=8):
    """Least-squares sinusoids at frequencies refined by Gauss-Newton: (f, amplitude) per line."""
    f = np.array(refine_peaks(x, t[1] - t[0], f0, 1.5 / ((t[1] - t[0]) * max(16, 2 * len(x) // 9))), dtype=float)
    y = x - x.mean()
    tt = t - t[0]
    for _ in range(iters):
        C = np.cos(2 * np.pi * np.outer(tt, f))
        S = np.sin(2 * np.pi * np.outer(tt, f))
        ab, *_ = np.linalg.lstsq(np.hstack([C, S]), y, rcond=None)
        a, b = ab[: len(f)], ab[len(f):]
        r = y - C @ a - S @ b
        J = 2 * np.pi * tt[:, None] * (-a * S + b * C)
        df, *_ = np.linalg.lstsq(J, r, rcond=None)
        f += df
        if np.all(np.abs(df) <= 1e-13 * np.abs(f)):
            break
    C = np.cos(2 * np.pi * np.outer(tt, f))
    S = np.sin(2 * np.pi * np.outer(tt, f))
    ab, *_ = np.linalg.lstsq(np.hstack([C, S]), y, rcond=None)
    amp = np.hypot(ab[: len(f)], ab[len(f):])
    return f, amp


def find_lines(freq, psd, floor_factor=100.0, max_lines=8):
    """Local maxima of the PSD at least floor_factor above its median: (bin, frequency) list."""
    floor = np.median(psd[1:]) if len(psd) > 1 else 0.0
    peaks = [i for i in range(1, len(psd) - 1) if psd[i] >= psd[i - 1] and psd[i] > psd[i + 1] and psd[i] > floor_factor * floor]
    peaks.sort(key=lambda i: -psd[i])
    return peaks[:max_lines], floor


def classify(f, amp, power_in_lines, total_power, df_res):
    """Names each line from the base frequencies and returns (verdict, bases, names, evidence)."""
    if len(f) == 0 or power_in_lines < 0.5 * total_power:
        share = power_in_lines / total_power if total_power else 0.0
        return "broadband", [], [], f"lines carry {share:.0%} of the power (< 50 %)"
    order = np.argsort(-amp)
    # The base: the strongest line, or the lowest line of which it is a harmonic (a wave whose second
    # harmonic is the stronger is periodic in the lower one, not a second base at half the first).
    f1, top = f[order[0]], f[order[0]]
    for i in order:
        k = round(top / f[i])
        if f[i] < f1 and k >= 2 and abs(top - k * f[i]) <= max(3 * df_res, 1e-9 * top):
            f1 = f[i]
    bases = [f1]
    names = {}

    def name_of(g, bases):
        tol = max(3 * df_res, 1e-9 * g)
        rng = range(-4, 5)
        if len(bases) == 1:
            k = round(g / bases[0])
            return f"{k} f1" if k >= 1 and abs(g - k * bases[0]) <= tol else None
        best = None
        for m in rng:
            for n in rng:
                if (m, n) == (0, 0):
                    continue
                if abs(g - (m * bases[0] + n * bases[1])) <= tol and (best is None or abs(m) + abs(n) < best[0]):
                    best = (abs(m) + abs(n), f"{m} f1 {'+' if n >= 0 else '-'} {abs(n)} f2")
        return best[1] if best else None

    for i in order:
        nm = name_of(f[i], bases)
        if nm is None and len(bases) == 1:
            bases.append(f[i])
            nm = name_of(f[i], bases)
        names[i] = nm if nm else "unexplained"
    names = [names[i] for i in range(len(f))]
    if len(bases) == 1:
        verdict, evidence = "periodic", f"every line a harmonic of f1 = {bases[0]:.6g} Hz"
    else:
        ratio = bases[1] / bases[0]
        unexplained = sum(1 for n in names if n == "unexplained")
        verdict = "quasi-periodic" if unexplained == 0 else "broadband"
        evidence = f"two bases f1 = {bases[0]:.6g} Hz, f2 = {bases[1]:.6g} Hz (ratio {ratio:.6f}), {unexplained} line(s) unexplained"
    # Names given by chance: with a short record's tolerance most of the band is some name (unexplained
    # lines stay evidence: a wider tolerance could only name more).
    chance = naming_chance(f, bases, df_res)
    if verdict != "broadband" and len(f) > len(bases) and chance > MAX_NAMING_CHANCE:
        tol = max(3 * df_res, 0.0)
        verdict = "unresolved"
        evidence += (f"; but at the record's resolution (+-{tol:.3g} Hz) {100 * chance:.0f} % of the band would be named "
                     "by chance: run on (-steady_max_periods)")
    return verdict, bases, names, evidence


MAX_NAMING_CHANCE = 0.25


def naming_chance(f, bases, df_res):
    """The share of (0, F] (F the highest line) within the naming tolerance of a name."""
    F, tol = max(f), 3 * df_res
    if len(bases) == 1:
        return min(1.0, 2 * tol / bases[0])
    names = sum(1 for m in range(-4, 5) for n in range(-4, 5) if 0 < m * bases[0] + n * bases[1] <= F + tol)
    return min(1.0, names * 2 * tol / F)


def dominant_period_records(x):
    """Records per period of the strongest spectral line of the whole record (at least 5)."""
    X = np.abs(np.fft.rfft((x - x.mean()) * np.hanning(len(x))))
    k = int(np.argmax(X[1:])) + 1
    return max(5, int(round(len(x) / k)))


def analyse(x, t, batches=20, rtol=0.05):
    """Everything above for one signal x(t) (uniform t)."""
    # MSER on the power of whole periods: within a period the power swings with the phase.
    cut = mser_cut(x, dominant_period_records(x))
    xs, ts = x[cut:], t[cut:]
    dt = ts[1] - ts[0]
    lv = levels(xs, batches)
    freq, psd = welch(xs, dt)
    peaks, floor = find_lines(freq, psd)
    df_res = freq[1] - freq[0]
    f, amp = fit_lines(xs, ts, [freq[i] for i in peaks]) if peaks else (np.array([]), np.array([]))
    total = float(np.sum(psd) * df_res)
    in_lines = float(np.sum(amp ** 2) / 2)
    # Names to within 3 resolutions of the whole record, not of the 4.5x coarser Welch segments
    # (on the small pad at V = 10 m/s those called 12 958 Hz the third harmonic of 4 203 Hz).
    verdict, bases, names, evidence = classify(f, amp, in_lines, total, 1.0 / (len(xs) * dt))
    return dict(cut=cut, t_cut=float(t[cut]), levels=lv, converged=lv["rel_halfwidth"] <= rtol, freq=freq, psd=psd,
                lines=f, amplitudes=amp, names=names, bases=bases, verdict=verdict, evidence=evidence)


def main(argv=None, prog=None):
    import h5py
    ap = argparse.ArgumentParser(prog=prog, description=__doc__.split("\n")[0])
    ap.add_argument("results")
    ap.add_argument("--dof", type=int)
    ap.add_argument("--rtol", type=float, default=0.05)
    ap.add_argument("--batches", type=int, default=20)
    ap.add_argument("--write", action="store_true")
    ap.add_argument("--plot")
    a = ap.parse_args(argv)
    with Results(a.results) as r:
        if "transient/U" not in r:
            sys.exit(f"steady_state.py: error: '{a.results}' has no /transient records (run -analyses transient)")
        g = r.transient
        t = g["t"]
        dof = a.dof if a.dof is not None else int(g.attrs.get("signal_dof", 0))
        x = g.dataset("U")[:, dof]
        rn = g.dataset("R")[:, :, 2].sum(axis=1) if "R" in g else None
        modes = None
        st = r.stability
        if st is not None and "modes/re" in st and st.unstable.size:
            idx = st.unstable
            modes = (idx, st["modes/re"][:, idx], st["modes/im"][:, idx], st.frequency[idx])
            U = g["U"]
    res = analyse(x, t, a.batches, a.rtol)
    lv = res["levels"]
    print(f"steady state of DOF {dof}: start-up dropped before t = {res['t_cut']:.6g} s (MSER on the power per period, record {res['cut']} of {len(t)})")
    print(f"  RMS {lv['rms']:.4e} (95 % interval {lv['rms_lo']:.4e} to {lv['rms_hi']:.4e}, half-width {lv['rel_halfwidth']:.1%}: "
          f"{'converged' if res['converged'] else 'NOT converged: run longer (-transient_periods)'}), peak {lv['peak']:.4e}")
    for fl, am, nm in sorted(zip(res["lines"], res["amplitudes"], res["names"]), key=lambda z: -z[1]):
        print(f"  line {fl:14.6f} Hz  amplitude {am:.4e}  {nm}")
    print(f"  verdict: {res['verdict']} ({res['evidence']})")
    rn_res = None
    if rn is not None:
        rn_res = levels(rn[res["cut"]:] , a.batches)
        print(f"  total normal reaction: mean {rn[res['cut']:].mean():.6g} N, RMS about it {rn_res['rms']:.4e} N, peak {rn_res['peak']:.4e} N")
    shares = None
    if modes is not None:
        idx, re, im, fr = modes
        B = np.hstack([re, im])
        Y = (U[res["cut"]:] - U[res["cut"]:].mean(axis=0)).T
        q, *_ = np.linalg.lstsq(B, Y, rcond=None)
        k = len(idx)
        rmsq = np.sqrt(np.mean(q[:k] ** 2 + q[k:] ** 2, axis=1))
        resid = np.linalg.norm(Y - B @ q) / max(np.linalg.norm(Y), 1e-300)
        shares = rmsq
        for m, fm, r in zip(idx, fr, rmsq):
            print(f"  unstable mode {m} ({fm:.2f} Hz): modal RMS {r:.4e}")
        print(f"  the unstable modes explain {1 - resid ** 2:.1%} of the motion's variance")
    if a.write:
        with h5py.File(a.results, "a") as f:
            if "steady_state" in f:
                del f["steady_state"]
            s = f.create_group("steady_state")
            s.attrs.update(dict(dof=dof, t_cut=res["t_cut"], rms=lv["rms"], rms_lo=lv["rms_lo"], rms_hi=lv["rms_hi"],
                                peak=lv["peak"], converged=int(res["converged"]), verdict=res["verdict"], evidence=res["evidence"],
                                method="MSER start-up cut on the power per period; batch-means 95 % interval; Welch PSD (Hann, 50 % overlap); "
                                       "lines refined by least-squares sinusoids"))
            s["psd_frequency"], s["psd"] = res["freq"], res["psd"]
            s["lines"], s["line_amplitudes"] = res["lines"], res["amplitudes"]
            s["line_names"] = np.array(res["names"], dtype=h5py.string_dtype())
            if shares is not None:
                s["mode_rms"] = shares
        print(f"  written to {a.results}:/steady_state")
    if a.plot:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        fig, ax = plt.subplots(2, 1, figsize=(8, 6))
        ax[0].plot(t, x, lw=0.5)
        ax[0].axvline(res["t_cut"], color="r", ls="--", label="start-up cut")
        ax[0].set_xlabel("t (s)")
        ax[0].set_ylabel(f"U[{dof}]")
        ax[0].legend()
        ax[1].semilogy(res["freq"], res["psd"])
        for fl in res["lines"]:
            ax[1].axvline(fl, color="r", lw=0.5)
        ax[1].set_xlabel("f (Hz)")
        ax[1].set_ylabel("PSD")
        ax[1].set_title(f"{res['verdict']}: {res['evidence']}", fontsize=8)
        fig.tight_layout()
        fig.savefig(a.plot, dpi=110)
        print(f"  plot: {a.plot}")


if __name__ == "__main__":
    main()
