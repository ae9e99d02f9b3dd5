#!/usr/bin/env python3
"""A signal inside a solver's own loop (an eigensolve, a reduction) is obeyed (issue 20, item 1).

    check_interrupt_anywhere.py --output F --after REGEX [--wait S] [--signal INT|TERM] [--within S]
                                [--where REGEX] [--results interrupted|absent] [--to-rank K] -- cmd...

Starts cmd, waits for a stdout line matching REGEX and S more seconds (inside the long solve),
sends the signal and checks: the run stops within --within seconds (default 3: Open MPI's mpiexec
itself takes one second to pass SIGTERM on), exit code in 1..127, stderr says
"interrupted by SIG... during" (followed by a match of --where, if given: the place the signal
must be obeyed at), and F exists with the root status "interrupted (SIG...". With --to-rank K (cmd
an Open MPI mpiexec) the signal goes to rank K's process alone, as a user's kill or a batch system
may send it, and the other ranks must learn it in their polls. With --results absent
(a signal while the model is built, e.g. during its reduction, before any analysis opens F): no F
is left behind instead.
"""
import os
import re
import signal
import subprocess
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scripts"))
from squeal.results import status_of  # noqa: E402


def rank_pid(launcher, rank):
    """The pid of the launcher's child with OMPI_COMM_WORLD_RANK = rank."""
    kids = []
    for task in os.listdir(f"/proc/{launcher}/task"):
        with open(f"/proc/{launcher}/task/{task}/children") as f:
            kids += [int(k) for k in f.read().split()]
    for k in kids:
        with open(f"/proc/{k}/environ", "rb") as f:
            env = dict(e.split(b"=", 1) for e in f.read().split(b"\0") if b"=" in e)
        if env.get(b"OMPI_COMM_WORLD_RANK") == rank.encode():
            return k
    raise SystemExit(f"no child of {launcher} is rank {rank}")


def main(argv):
    cut = argv.index("--")
    opts, cmd = argv[:cut], argv[cut + 1:]
    args = dict(zip(opts[0::2], opts[1::2]))
    out, pattern = args["--output"], re.compile(args["--after"])
    wait, within = float(args.get("--wait", "1")), float(args.get("--within", "3"))
    where = args.get("--where", "")
    absent = args.get("--results", "interrupted") == "absent"
    sig = signal.SIGTERM if args.get("--signal", "TERM") == "TERM" else signal.SIGINT
    name = "SIGTERM" if sig == signal.SIGTERM else "SIGINT"
    if os.path.exists(out):
        os.remove(out)
    print("+ " + " ".join(cmd))
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, bufsize=1)
    seen = []
    for line in p.stdout:
        seen.append(line)
        if pattern.search(line):
            break
    time.sleep(wait)
    running = p.poll() is None
    t0 = time.time()
    if "--to-rank" in args:
        pid = rank_pid(p.pid, args["--to-rank"])
        print(f"signalling rank {args['--to-rank']} alone (pid {pid})")
        os.kill(pid, sig)
    else:
        p.send_signal(sig)
    rest, err = p.communicate(timeout=120)
    dt = time.time() - t0
    print("".join(seen) + rest)
    print("--- stderr:\n" + err)
    checks = [
        (running, f"still running {wait} s after /{pattern.pattern}/"),
        (dt <= within, f"stopped {dt:.2f} s after {name} (<= {within} s)"),
        (0 < p.returncode < 128, f"exit code {p.returncode} in 1..127"),
        (re.search(r"^squeal: error: interrupted by " + name + " during " + where, err, re.M) is not None,
         f"stderr says 'interrupted by {name} during {where}'"),
    ]
    if absent:
        checks.append((not os.path.exists(out), f"no {out} left behind"))
    elif os.path.exists(out):
        s = status_of(out)
        checks.append((s.startswith("interrupted (" + name), f"root status '{s}'"))
    else:
        checks.append((False, f"{out} exists"))
    if not absent:
        checks.append((out in err, "the message names the results file"))
    bad = 0
    for good, what in checks:
        print(("ok:   " if good else "FAIL: ") + what)
        bad += not good
    print("PASS" if not bad else f"{bad} check(s) FAILED")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
