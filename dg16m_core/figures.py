"""Figures without pyplot: one way to make a matplotlib figure and write it as PNG.

Library code never calls ``matplotlib.use`` or touches pyplot's global state: figures are
:class:`matplotlib.figure.Figure` objects on their own Agg canvas (no display, no GL), saved
atomically. Used by the pictures of objects and grasps, the dataset statistics, the benchmark
report and trial replays.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from dg16m_core.atomic import atomic_path


def new_figure(width: float, height: float, *, dpi: float | None = None) -> Figure:
    """A figure of ``width`` x ``height`` inches on its own Agg canvas (``fig.canvas``)."""
    fig = Figure(figsize=(width, height), dpi=dpi)
    FigureCanvasAgg(fig)
    return fig


def save_png(fig: Figure, path: str | os.PathLike[str], *, dpi: float, **savefig: Any) -> Path:
    """Write ``fig`` to ``path`` as PNG at ``dpi``, atomically (temporary file + rename).

    ``savefig`` holds further keyword arguments of :meth:`~matplotlib.figure.Figure.savefig`
    (e.g. ``bbox_inches="tight"``, ``facecolor="white"``).
    """
    out = Path(path)
    with atomic_path(out) as tmp:
        fig.savefig(tmp, format="png", dpi=dpi, **savefig)
    return out
