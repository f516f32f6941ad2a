"""Figure setup shared by every PNG the package writes: matplotlib's object API on the Agg canvas.

Why not ``pyplot`` and ``tight_layout``: importing ``matplotlib.pyplot`` costs ~0.5 s (its GUI
backend machinery), and ``tight_layout`` draws each figure once more to measure its labels
before ``savefig`` draws it again.  Here a figure is a :class:`matplotlib.figure.Figure` on an
Agg canvas, its margins are fixed in inches (room for two title lines, tick labels and an axis
label) and it is drawn once, when saved.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

__all__ = ["new_figure", "subplots", "set_margins", "save", "legend_outside"]

#: margins [in]: left (tick labels + y label), right, bottom (tick labels + x label), top (two
#: title lines)
MARGINS = {"left": 0.95, "right": 0.2, "bottom": 0.55, "top": 0.6}


def new_figure(figsize: tuple[float, float]):
    """A Figure [in] on an Agg canvas (no pyplot, no display)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize)
    FigureCanvasAgg(fig)
    return fig


def set_margins(fig, *, left: float | None = None, right: float | None = None,
                bottom: float | None = None, top: float | None = None,
                hspace: float = 0.35, wspace: float = 0.3) -> None:
    """Fix the subplot area by margins in inches (defaults: :data:`MARGINS`)."""
    w, h = fig.get_size_inches()
    m = dict(MARGINS)
    m.update({k: v for k, v in (("left", left), ("right", right), ("bottom", bottom),
                                ("top", top)) if v is not None})
    fig.subplots_adjust(left=m["left"] / w, right=1.0 - m["right"] / w, bottom=m["bottom"] / h,
                        top=1.0 - m["top"] / h, hspace=hspace, wspace=wspace)


def subplots(nrows: int = 1, ncols: int = 1, *, figsize: tuple[float, float] = (8, 4),
             margins: dict[str, float] | None = None, hspace: float = 0.35,
             wspace: float = 0.3, **kw: Any):
    """(fig, axes) as ``pyplot.subplots``, on :func:`new_figure`, with fixed margins [in] and
    spacing (fractions of the mean axes height/width)."""
    fig = new_figure(figsize)
    axes = fig.subplots(nrows, ncols, **kw)
    set_margins(fig, hspace=hspace, wspace=wspace, **(margins or {}))
    return fig, axes


def legend_outside(ax, **kw: Any):
    """The legend to the right of the axes, top-aligned: it can cover no data."""
    kw.setdefault("fontsize", 8)
    return ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0, **kw)


#: zlib level of the PNGs: 1 compresses ~3x faster than Pillow's default 6 for files ~15 %
#: larger; the pixels are the same
PNG_COMPRESS_LEVEL = 1


def save(fig, path: str | Path, dpi: int = 110) -> Path:
    """Write the figure as PNG (one draw), whole or not at all
    (:func:`prsm_fmu.atomic.write_atomic`: an interrupted run leaves no half-written file).

    Drawn by ``savefig`` (its settings: dpi, face colour, ...) to raw RGBA pixels and encoded by
    :func:`prsm_fmu.png.encode_rgba` (rows unfiltered: ~2.5x less CPU than Pillow's encoder,
    the same pixels) with matplotlib's ``Software`` entry, as ``savefig`` writes it."""
    import io

    import matplotlib
    import numpy as np

    from .atomic import write_atomic
    from .png import encode_rgba

    raw = io.BytesIO()
    fig.savefig(raw, dpi=dpi, format="rgba")
    # the canvas's size at ``dpi``, as Agg sizes it (whole pixels, truncated)
    w, h = (int(v) for v in np.asarray(fig.get_size_inches(), dtype=float) * dpi)
    pixels = np.frombuffer(raw.getbuffer(), dtype=np.uint8)
    if pixels.size != 4 * w * h:
        raise RuntimeError(f"savefig wrote {pixels.size} bytes of RGBA, not {w} × {h} × 4")
    data = encode_rgba(pixels.reshape(h, w, 4), dpi,
                       {"Software": f"Matplotlib version{matplotlib.__version__}, "
                                    "https://matplotlib.org/"}, PNG_COMPRESS_LEVEL)
    write_atomic(path, [data])
    return Path(path)
