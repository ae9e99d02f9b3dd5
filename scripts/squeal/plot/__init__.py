"""Plotting functions of squeal results files, one module per kind; each module's main(argv, prog)
is the command line of scripts/plot_KIND.py and of `squeal_cli.py plot KIND`."""
import importlib

KINDS = {
    "stability": "eigenvalues of /stability in the complex plane",
    "sweep": "stability map of /sweep: growth rate and frequency against mu",
    "energy": "energy estimate of /energy: mean powers against the modal amplitude",
    "transient": "limit cycle of /transient: time histories, phase portrait, contact status",
    "continuation": "limit-cycle branch of /continuation: amplitude and period against mu or V",
    "mesh-modes": "unstable mode shapes of an FE model on one plane of its mesh",
}


def module(kind):
    return importlib.import_module("." + kind.replace("-", "_"), __name__)
