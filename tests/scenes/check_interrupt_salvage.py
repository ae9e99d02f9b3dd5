#!/usr/bin/env python3
"""A second signal keeps the results file readable when it was just flushed (issue 20, item 1).

    check_interrupt_salvage.py PROGRAM DIR [MPIEXEC ARGS...]

Runs PROGRAM (tests/io/interrupt_salvage.cpp) in its two modes and checks: it dies by SIGTERM;
after a flush the file is under its name, readable by the results reader (scripts/squeal/results.py), with /stability's value and the status
"running (complete up to the stability analysis)", and no temporary left; in the middle of a write
the message names the temporary left instead. Then, with a complete results file already at the
name, the salvaged file goes beside it (".failed.h5") and the complete one is untouched.

With MPIEXEC (Open MPI's, which kills its ranks a second after passing SIGTERM on): PROGRAM's
"stuck" mode under it, SIGTERM to mpiexec once the file is flushed; the rank computes on without
a poll, so the watchdog must have moved the file to its name (status "running (complete up to the
stability analysis)") before the kill, said so, and left no temporary; the rank's late poll and
exit after it must leave that file readable.
"""
import glob
import os
import signal
import subprocess
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scripts"))
from squeal.results import Results, status_of  # noqa: E402


def run(prog, path, mode):
    p = subprocess.run([prog, path, mode], capture_output=True, text=True, timeout=60)
    print(f"+ {prog} {path} {mode}: exit {p.returncode}\n{p.stderr}")
    return p


def salvaged(checks, path, d, tag):
    """The file moved to its name as it was at the flush: readable, status and value, no temporary."""
    ok = os.path.exists(path)
    checks.append((ok, f"{tag}: {path} exists"))
    if ok:
        # Under mpiexec the killed rank can still hold HDF5's lock on the file for a moment after
        # mpiexec returns (a fresh-clone CI run, 2026-11-30: errno 11 at the first open): the claim is
        # a readable file once the rank is gone, so the open waits up to 10 s for the lock.
        t0 = time.time()
        while True:
            try:
                with Results(path) as r:
                    status = r.status
                    value = float(r.stability.attrs["value"])
                break
            except BlockingIOError:
                if time.time() - t0 > 10:
                    raise
                time.sleep(0.1)
        if time.time() - t0 > 0.05:
            print(f"{tag}: the file's lock was released {time.time() - t0:.2f} s after the run ended")
        checks.append((status == "running (complete up to the stability analysis)", f"{tag}: status '{status}'"))
        checks.append((value == 42.0, f"{tag}: /stability value {value}"))
    checks.append((not glob.glob(os.path.join(d, ".salvage.h5.part-*")), f"{tag}: no temporary left"))


def main(prog, d, mpiexec):
    os.makedirs(d, exist_ok=True)
    path = os.path.join(d, "salvage.h5")
    for f in glob.glob(os.path.join(d, "*salvage*")):
        os.remove(f)
    checks = []
    p = run(prog, path, "flushed")
    checks.append((p.returncode == -signal.SIGTERM, f"flushed: killed by SIGTERM (exit {p.returncode})"))
    checks.append(("results written so far are in " + path in p.stderr, "flushed: the message names the file"))
    salvaged(checks, path, d, "flushed")

    os.remove(path)
    p = run(prog, path, "writing")
    parts = glob.glob(os.path.join(d, ".salvage.h5.part-*"))
    checks.append((p.returncode == -signal.SIGTERM, f"writing: killed by SIGTERM (exit {p.returncode})"))
    checks.append((not os.path.exists(path), "writing: nothing under the name"))
    checks.append((len(parts) == 1 and parts[0] in p.stderr, "writing: the message names the temporary left"))
    for f in parts:
        os.remove(f)

    # A complete file at the name stays; the salvage goes beside it.
    p = run(prog, path, "complete")
    checks.append((p.returncode == 0, "beside: a complete file written"))
    p = run(prog, path, "flushed")
    failed = os.path.join(d, "salvage.failed.h5")
    s = status_of(path)
    checks.append((s == "complete", "beside: the complete file is untouched"))
    checks.append((os.path.exists(failed) and failed in p.stderr, f"beside: salvaged to {failed}, and said"))

    if mpiexec:
        os.remove(path)
        cmd = mpiexec + ["-n", "1", prog, path, "stuck"]
        print("+ " + " ".join(cmd))
        p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        line = p.stdout.readline()
        t0 = time.time()
        p.send_signal(signal.SIGTERM)
        out, err = p.communicate(timeout=60)
        dt = time.time() - t0
        print(f"{line}{out}--- stderr:\n{err}")
        checks.append((line.strip() == "flushed", f"stuck: the file flushed before the signal ('{line.strip()}')"))
        checks.append((dt < 5, f"stuck: mpiexec ended {dt:.2f} s after SIGTERM"))
        checks.append((p.returncode != 0, f"stuck: mpiexec exit code {p.returncode} (not 0)"))
        checks.append(("results written so far are in " + path in err, "stuck: the watchdog's message names the file"))
        salvaged(checks, path, d, "stuck")

    bad = 0
    for good, what in checks:
        print(("ok:   " if good else "FAIL: ") + what)
        bad += not good
    print("PASS" if not bad else f"{bad} check(s) FAILED")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1], sys.argv[2], sys.argv[3:]))
