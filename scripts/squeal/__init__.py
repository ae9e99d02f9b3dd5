"""squeal's results package: read a results file (squeal.results), draw it (squeal.plot), and the
command line `python3 scripts/squeal_cli.py` / `python3 -m squeal` (squeal.cli): info, plot,
compare, xdmf, steady-state, work-precision. Needs scripts/ on sys.path; no install step."""
from .results import Group, Results, decode, fail, open_results

__all__ = ["Group", "Results", "decode", "fail", "open_results"]
