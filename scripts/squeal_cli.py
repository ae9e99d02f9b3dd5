#!/usr/bin/python3
"""squeal's results on the command line: info, plot, compare, xdmf, steady-state, work-precision.

    python3 scripts/squeal_cli.py SUBCOMMAND ...   (`--help` lists them, `SUBCOMMAND --help` documents each)

The code is the package scripts/squeal (squeal.cli); from scripts/, `python3 -m squeal` is the same.
"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from squeal.cli import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main())
