#!/usr/bin/python3
"""Results files are never lost or mixed (issue 9, item 3).

  check_results_io.py interrupt --output F --after REGEX [--signal INT|TERM] [--period T] -- cmd...
      Starts cmd, waits for a stdout line matching REGEX, sends the signal, and checks: exit code
      in 1..127, stderr names the signal, F holds the stability table (unstable period T within
      0.5 %), a partial /transient (complete = 0, >= 2 records, time increasing at a constant
      step), root status "interrupted ...", no temporary file left.
  check_results_io.py steady_interrupt --output F --after REGEX [--signal INT|TERM] -- cmd...
  check_results_io.py sweep_interrupt --output F --after REGEX [--signal INT|TERM] -- cmd...
      The same signal during a sweep (issue 20, item 1): F holds /sweep with the points computed
      (/sweep/failed 0, eigenvalues finite) and the rest marked 2 (not computed), /sweep
      interrupted = 1, no critical mu, status "interrupted ...", stdout says INTERRUPTED.
  check_results_io.py concurrent --output F -- cmdA -- cmdB
      Starts both at once (same -output, different mu; A also runs a transient). Both exit 0;
      F comes whole from one run: /model mu = /equilibrium mu, r_t = mu r_n at every closed point
      (Coulomb sliding), /transient present exactly when mu is A's; no temporary file left.
  check_results_io.py refuse --output F -- cmd...
      F is a text file (a scene); cmd must fail with one "squeal: error:" line naming F and
      "not a squeal results file", and leave F byte for byte unchanged.
  check_results_io.py no_room --output F --limit-mb L --dataset D [--period T] -- cmd...
      Runs cmd under a file size limit of L MiB (SIGXFSZ ignored, as a full disk gives ENOSPC),
      too small for dataset D: exit code 1 (not a crash), one error line naming D, F and the
      limit; F under its name with status "failed ...", the stability table (unstable period T),
      D absent and its group's attribute "incomplete" naming it; no temporary file left.
"""
import glob
import os
import re
import signal
import subprocess
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scripts"))
from squeal.results import Results  # noqa: E402

failures = 0


def ok(cond, msg):
    global failures
    print(("ok:   " if cond else "FAIL: ") + msg)
    if not cond:
        failures += 1
    return cond


def no_temporaries(out):
    d, b = os.path.split(os.path.abspath(out))
    left = glob.glob(os.path.join(d, "." + b + ".part-*"))
    ok(not left, f"no temporary file left beside {b} ({left})")


def signal_after(cmd, out, pattern, which="INT", wait=0.0, within=None):
    """Runs cmd, sends SIGINT (or SIGTERM) `wait` seconds after a stdout line matches `pattern`,
    and checks the clean stop: exit code, the message naming the signal and the results file, and
    (if `within` is given) the stop within that many seconds. Returns the signal's name."""
    if os.path.exists(out):
        os.remove(out)
    sig = signal.SIGTERM if which == "TERM" else signal.SIGINT
    name = "SIGTERM" if sig == signal.SIGTERM else "SIGINT"
    print("+ " + " ".join(cmd))
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, bufsize=1)
    pat = re.compile(pattern)
    seen = []
    for line in p.stdout:
        seen.append(line)
        if pat.search(line):
            break
    time.sleep(wait)
    ok(p.poll() is None, f"still running {wait} s after a line matched /{pattern}/")
    t0 = time.time()
    p.send_signal(sig)
    rest, err = p.communicate(timeout=120)
    dt = time.time() - t0
    print("".join(seen) + rest)
    print("--- stderr:\n" + err)
    print(f"stopped {dt:.2f} s after {name}")
    if within is not None:
        ok(dt <= within, f"stopped {dt:.2f} s after {name} (<= {within} s)")
    signal_after.stderr = err  # for checks of the message's details
    ok(0 < p.returncode < 128, f"exit code {p.returncode} in 1..127 (clean stop, not killed)")
    ok(re.search(r"^squeal: error: interrupted by " + name, err, re.M) is not None, f"stderr says 'interrupted by {name}'")
    ok(out in err, "the message names the results file")
    return name


def interrupt(args, cmd):
    out = args["--output"]
    name = signal_after(cmd, out, args["--after"], args.get("--signal", "INT"))
    no_temporaries(out)
    if not ok(os.path.exists(out), f"{out} exists"):
        return
    with Results(out) as r:
        ok(r.status.startswith("interrupted (" + name), f"root status '{r.status}'")
        T = r.stability.unstable_period()
        ref = float(args.get("--period", "0.0109"))
        ok(T is not None and abs(T - ref) / ref < 5e-3, f"stability table: unstable period {T} ~ {ref}")
        if ok("transient/t" in r, "has /transient/t"):
            t = np.asarray(r.transient["t"])
            U = np.asarray(r.transient["U"])
            ok(int(r.transient.attrs["complete"]) == 0, "/transient complete = 0")
            ok(t.size >= 2 and U.shape[0] == t.size, f"{t.size} records, U {U.shape}")
            dt = np.diff(t)
            ok(t.size >= 2 and np.all(dt > 0) and np.ptp(dt) <= 1e-9 * dt.max(), "time increases at a constant step")
            ok(np.all(np.isfinite(U)), "U finite")


def steady_interrupt(args, cmd):
    """SIGINT during the statistical steady state's first chunk: /steady_state holds the statistics
    of the records so far (not empty) and says it was interrupted, and where."""
    out = args["--output"]
    name = signal_after(cmd, out, args["--after"], args.get("--signal", "INT"))
    no_temporaries(out)
    if not ok(os.path.exists(out), f"{out} exists"):
        return
    with Results(out) as r:
        ok(r.status.startswith("interrupted (" + name), f"root status '{r.status}'")
        s = r.steady_state
        if not ok(s is not None, "has /steady_state"):
            return
        note = str(s.attrs.get("interrupted", ""))
        ok(note.startswith("interrupted by " + name + " during chunk 1 "), f"/steady_state interrupted = '{note}'")
        t = np.asarray(s["t"])
        ok(t.size >= 100 and float(s.attrs["rms"]) > 0, f"{t.size} records analysed, RMS {float(s.attrs['rms']):.3e}")
        ok(float(s.attrs["T_ref"]) > 0 and float(s.attrs["periods"]) > 0, "T_ref and periods set")
        ok("mode_rms" in s and np.all(np.asarray(s["mode_rms"]) > 0), "the unstable mode's RMS")


def sweep_interrupt(args, cmd):
    out = args["--output"]
    name = signal_after(cmd, out, args["--after"], args.get("--signal", "INT"))
    no_temporaries(out)
    if not ok(os.path.exists(out), f"{out} exists"):
        return
    with Results(out) as r:
        ok(r.status.startswith("interrupted (" + name), f"root status '{r.status}'")
        if not ok("sweep/failed" in r, "has /sweep/failed"):
            return
        failed = np.asarray(r.sweep["failed"])
        ev = r.sweep.array("eigenvalues")
        done, skipped = int(np.sum(failed == 0)), int(np.sum(failed == 2))
        ok(done >= 20 and skipped > 0 and done + skipped == failed.size,
           f"{done} point(s) computed, {skipped} not computed (2), of {failed.size}; none 'without sliding'")
        ok(np.all(np.isfinite(ev[failed == 0][..., 0][:, 0])), "every computed point has its eigenvalues")
        ok(np.all(np.isnan(ev[failed == 2])), "no eigenvalue at a point not computed")
        ok(int(r.sweep.attrs["interrupted"]) == 1, "/sweep interrupted = 1")
        m = re.search(r"the sweep's points so far \((\d+) of (\d+),", signal_after.stderr)
        ok(m is not None and int(m.group(1)) == failed.size - skipped and int(m.group(2)) == failed.size,
           f"the message counts the points computed ({m.group(0) if m else 'no count in it'})")
        ok(np.all(np.isnan(np.asarray(r.sweep.attrs["critical_mu"], dtype=float))), "no critical mu from a grid with holes")


def concurrent(args, cmds):
    out = args["--output"]
    if os.path.exists(out):
        os.remove(out)
    procs = []
    for c in cmds:
        print("+ " + " ".join(c))
        procs.append(subprocess.Popen(c, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True))
    outs = [p.communicate(timeout=300)[0] for p in procs]
    for i, (p, o) in enumerate(zip(procs, outs)):
        print(f"--- run {'AB'[i]} (exit {p.returncode}):\n{o}")
        ok(p.returncode == 0, f"run {'AB'[i]} exit code 0")
    no_temporaries(out)
    mu_a = float(cmds[0][cmds[0].index("-contact_mu") + 1])
    mu_b = float(cmds[1][cmds[1].index("-contact_mu") + 1])
    with Results(out) as res:
        ok(res.status == "complete", f"status '{res.status}'")
        mu = float(res.model["mu"])
        ok(mu in (mu_a, mu_b), f"/model mu = {mu} is one run's ({mu_a} or {mu_b})")
        ok(float(res.equilibrium.attrs["mu"]) == mu, "/equilibrium mu = /model mu")
        r = np.asarray(res.equilibrium["r"])
        closed = r[:, 2] > 0
        ok(closed.any() and np.allclose(r[closed, 0], mu * r[closed, 2], rtol=1e-12), "r_t = mu r_n at the closed points")
        ok(("transient" in res) == (mu == mu_a), "/transient present exactly when the file is run A's")
        print(f"the file is run {'A' if mu == mu_a else 'B'}'s")


def refuse(args, cmd):
    out = args["--output"]
    text = "# a scene file, not results\nmodel:\n  type: three_dof\n"
    with open(out, "w") as fh:
        fh.write(text)
    print("+ " + " ".join(cmd))
    p = subprocess.run(cmd, capture_output=True, text=True)
    print(p.stdout + "\n--- stderr:\n" + p.stderr)
    ok(0 < p.returncode < 128, f"exit code {p.returncode} in 1..127")
    lines = [l for l in p.stderr.splitlines() if l.startswith("squeal: error:")]
    ok(len(lines) == 1 and "not a squeal results file" in lines[0] and out in lines[0],
       "one error line naming the file and 'not a squeal results file'")
    with open(out) as fh:
        ok(fh.read() == text, f"{out} unchanged")
    no_temporaries(out)


def no_room(args, cmd):
    import resource

    out, dataset = args["--output"], args["--dataset"]
    limit = int(float(args["--limit-mb"]) * 1048576)
    if os.path.exists(out):
        os.remove(out)

    def limited():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write past the limit then fails with EFBIG
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    print("+ " + " ".join(cmd))
    p = subprocess.run(cmd, capture_output=True, text=True, preexec_fn=limited)
    print(p.stdout[-2000:] + "\n--- stderr:\n" + p.stderr)
    ok(p.returncode == 1, f"exit code {p.returncode} is 1 (a crash reads 139 or 134)")
    lines = [l for l in p.stderr.splitlines() if l.startswith("squeal: error:")]
    ok(len(lines) == 1 and dataset in lines[0] and out in lines[0] and "ulimit -f" in lines[0],
       f"one error line naming {dataset}, the file and the limit")
    no_temporaries(out)
    if not ok(os.path.exists(out), f"{out} exists"):
        return
    with Results(out) as r:
        ok(r.status.startswith("failed"), f"root status '{r.status}'")
        T = r.stability.unstable_period()
        ref = float(args.get("--period", "0.0109"))
        ok(T is not None and abs(T - ref) / ref < 5e-3, f"stability table: unstable period {T} ~ {ref}")
        group, name = dataset.rsplit("/", 1)
        g = r.group(group.strip("/"))
        if not ok(g is not None, f"{group} exists"):
            return
        ok(name not in g, f"{dataset} absent")
        note = g.attrs.get("incomplete", "")
        ok(dataset in note and "no room" in note, f"{group} says it is incomplete: '{note}'")


def main():
    argv = sys.argv[1:]
    mode, argv = argv[0], argv[1:]
    k = argv.index("--")
    opts, rest = argv[:k], argv[k + 1:]
    args = dict(zip(opts[::2], opts[1::2]))
    if mode == "interrupt":
        interrupt(args, rest)
    elif mode == "steady_interrupt":
        steady_interrupt(args, rest)
    elif mode == "sweep_interrupt":
        sweep_interrupt(args, rest)
    elif mode == "concurrent":
        k = rest.index("--")
        concurrent(args, [rest[:k], rest[k + 1:]])
    elif mode == "refuse":
        refuse(args, rest)
    elif mode == "no_room":
        no_room(args, rest)
    else:
        sys.exit(__doc__)
    print("PASS" if failures == 0 else f"{failures} check(s) FAILED")
    sys.exit(1 if failures else 0)


if __name__ == "__main__":
    main()
