"""What the scene checkers share: the command after "--" and running it with its output echoed
(ctest shows it on failure), a non-zero exit being the checker's failure."""
import subprocess
import sys


def command(remainder):
    """The command of an argparse REMAINDER argument, without its leading "--"."""
    return remainder[1:] if remainder and remainder[0] == "--" else remainder


def run(cmd, tool):
    """Runs cmd, echoes its stdout and stderr; exits naming `tool` when it fails."""
    r = subprocess.run(cmd, capture_output=True, text=True)
    sys.stdout.write(r.stdout)
    sys.stderr.write(r.stderr)
    if r.returncode != 0:
        sys.exit(f"{tool}: {' '.join(cmd[:3])} ... exited with {r.returncode}")
    return r
