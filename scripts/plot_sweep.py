#!/usr/bin/python3
"""Plot the stability map (friction-coefficient sweep) written by squeal.

    plot_sweep.py RESULTS.h5 [RESULTS2.h5 ...] -o out.png [--label LABEL ...]

The code is squeal.plot.sweep (scripts/squeal/plot/sweep.py); also `squeal_cli.py plot sweep ...`.
"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from squeal.plot.sweep import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main())
