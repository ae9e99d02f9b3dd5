#!/usr/bin/python3
"""Plot a squeal transient (limit cycle) from one results file.

    plot_transient.py RESULTS.h5 -o out.png [--last-periods 5] [--dofs 0,1,2] [--phase-dof 0] [--point 0] [--title TITLE] [--dpi 100]

The code is squeal.plot.transient (scripts/squeal/plot/transient.py); also `squeal_cli.py plot transient ...`.
"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from squeal.plot.transient import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main())
