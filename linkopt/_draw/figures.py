"""Figures drawn without pyplot, so that linkopt never changes the user's backend.

Every figure linkopt writes is a :class:`matplotlib.figure.Figure` with its own Agg
canvas: nothing registers it with pyplot (so nothing needs closing, and a notebook's
figures are not shown twice), and ``matplotlib.use`` is never called (a user's
interactive backend keeps working after linkopt draws).
"""

from __future__ import annotations

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure


def figure(**kwargs) -> Figure:
    """A new figure on its own Agg canvas (``Figure``'s keyword arguments)."""
    fig = Figure(**kwargs)
    FigureCanvasAgg(fig)
    return fig


def subplots(*args, figsize=None, dpi=None, constrained_layout=None, **kwargs):
    """``(figure, axes)`` as ``pyplot.subplots`` gives them, without pyplot."""
    fig = figure(figsize=figsize, dpi=dpi, constrained_layout=constrained_layout)
    return fig, fig.subplots(*args, **kwargs)
