"""Shared by the plotting scripts: open a squeal results file and one analysis group, or exit
with a one-line message that says what is missing and how to produce it."""
import contextlib
import os
import sys

try:
    import h5py
except ImportError:  # pragma: no cover
    sys.exit("squeal scripts: error: the h5py module is required (apt-get install python3-h5py)")

PROG = os.path.basename(sys.argv[0]) if sys.argv and sys.argv[0] else "squeal"


def fail(msg):
    print(f"{PROG}: error: {msg}", file=sys.stderr)
    sys.exit(1)


@contextlib.contextmanager
def analysis_group(path, group, required=(), analysis=None):
    """Yields (file, group) of `path`; fails clearly if the file, the group or a dataset is missing."""
    if not os.path.isfile(path):
        fail(f"results file '{path}' not found")
    try:
        f = h5py.File(path, "r")
    except OSError as e:
        fail(f"cannot open '{path}' as HDF5: {e}")
    with f:
        if group not in f or not isinstance(f[group], h5py.Group):
            fail(f"'{path}' has no /{group} group (run squeal with -analyses {analysis or group})")
        g = f[group]
        for name in required:
            if name not in g:
                fail(f"'{path}': /{group}/{name} is missing")
        yield f, g
