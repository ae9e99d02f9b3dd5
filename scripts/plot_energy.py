#!/usr/bin/python3
"""Energy estimate of a squeal results file: mean damping and reaction power against the modal amplitude.

    plot_energy.py RESULTS.h5 [RESULTS2.h5 ...] -o energy.png [--label LABEL ...]

The code is squeal.plot.energy (scripts/squeal/plot/energy.py); also `squeal_cli.py plot energy ...`.
"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from squeal.plot.energy import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main())
