"""What the plotting modules share: the Agg backend, the house style, the output checks."""
import io
import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402,F401

from ..results import fail  # noqa: E402


def house_style(**extra):
    plt.style.use("default")
    plt.rcParams.update({
        "font.size": 10, "legend.fontsize": 8.5,
        "axes.spines.top": False, "axes.spines.right": False,
        "axes.grid": True, "grid.color": "0.88", "grid.linewidth": 0.6, **extra,
    })


def check_out_dir(out):
    out_dir = os.path.dirname(os.path.abspath(out))
    if not os.path.isdir(out_dir):
        fail(f"output directory '{out_dir}' does not exist")


def save_png(fig, out, dpi=None):
    """Save as PNG, quantised to a 256-colour palette when Pillow is there (a third of the size)."""
    try:
        from PIL import Image
    except ImportError:  # pragma: no cover
        fig.savefig(out, dpi=dpi)
        return
    buf = io.BytesIO()
    fig.savefig(buf, dpi=dpi, format="png")
    buf.seek(0)
    with Image.open(buf) as im:
        im.convert("RGB").quantize(colors=256, method=Image.Quantize.MEDIANCUT).save(out, optimize=True)


def save_tight(fig, out, dpi):
    """Save cropped to what is drawn (labels outside the axes included) and free the figure."""
    fig.savefig(out, dpi=dpi, bbox_inches="tight")
    plt.close(fig)
