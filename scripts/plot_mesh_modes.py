#!/usr/bin/python3
"""Unstable mode shapes of an FE model, seen on one plane of its mesh (e.g. a disc's face).

    plot_mesh_modes.py RESULTS.h5 --plane-z Z [--modes 2 | --cycle K] [--r-hole R] -o modes.png

The code is squeal.plot.mesh_modes (scripts/squeal/plot/mesh_modes.py); also `squeal_cli.py plot mesh-modes ...`.
"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from squeal.plot.mesh_modes import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main())
