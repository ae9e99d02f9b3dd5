#!/usr/bin/python3
"""Plot the limit-cycle branch (continuation in mu or V) written by squeal.

    plot_continuation.py RESULTS.h5 [RESULTS2.h5 ...] -o out.png [--label LABEL ...]

The code is squeal.plot.continuation (scripts/squeal/plot/continuation.py); also `squeal_cli.py plot continuation ...`.
"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from squeal.plot.continuation import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main())
