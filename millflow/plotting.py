"""Figures for millflow's reports: the one module that imports matplotlib.

It builds :class:`matplotlib.figure.Figure` objects directly, never through pyplot:
no global figure state, no backend forced on the user's session (``matplotlib.use``
is never called) and nothing that needs a display, so plots are written the same way
in a terminal, a notebook or CI. matplotlib is imported on first use only, so
importing millflow does not load it.
"""
from __future__ import annotations

from pathlib import Path

__all__ = ["figure", "save"]


def figure(nrows: int = 1, ncols: int = 1, *, figsize=(8, 5), **subplots_kw):
    """A new Figure and its axes, as ``pyplot.subplots`` returns them."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize)
    return fig, fig.subplots(nrows, ncols, **subplots_kw)


def save(fig, path, dpi: int = 110, *, margins: dict | None = None) -> Path:
    """Lay out and write ``fig`` to ``path`` (format from the suffix); returns the path.

    ``margins`` (``subplots_adjust`` fractions: left, right, bottom, top, ...) places the
    axes directly; without it ``tight_layout`` measures every label, which costs a full
    extra draw of the figure. PNGs are written with zlib level 1: line plots compress
    nearly as well, several times faster than the default level 6.
    """
    if margins is None:
        fig.tight_layout()
    else:
        fig.subplots_adjust(**margins)
    png = str(path).lower().endswith(".png")
    fig.savefig(path, dpi=dpi, **({"pil_kwargs": {"compress_level": 1}} if png else {}))
    return Path(path)
