#!/usr/bin/python3
"""Plot the eigenvalues of a squeal linear stability analysis in the complex plane.

    plot_stability.py RESULTS.h5 [-o out.png] [--mirror] [--title TITLE]

The code is squeal.plot.stability (scripts/squeal/plot/stability.py); also `squeal_cli.py plot stability ...`.
"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from squeal.plot.stability import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main())
