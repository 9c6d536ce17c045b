"""Line plots saved atomically as PNG (energy curves, error-versus-horizon curves)."""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from markovmotion.errors import MarkovMotionError
from markovmotion.io.files import atomic_write

FIGURE_SUFFIXES = (".png", ".svg", ".pdf")


def ordinal(n: int) -> str:
    """2nd, 3rd, 11th, 12th, 21st ... (figure captions: "every 2nd frame")."""
    tail = "th" if 10 <= n % 100 <= 20 else {1: "st", 2: "nd", 3: "rd"}.get(n % 10, "th")
    return f"{n}{tail}"


def new_figure(width: float = 6.4, height: float = 4.2) -> tuple[Figure, Axes]:
    """A figure (not managed by pyplot) and its single axes."""
    fig = Figure(figsize=(width, height), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    return fig, fig.add_subplot()


def check_suffix(path: str | os.PathLike[str], accepted: tuple[str, ...], what: str) -> str:
    """The suffix of ``path``, or a :class:`MarkovMotionError` naming the ``accepted`` ones."""
    suffix = Path(path).suffix.lower()
    if suffix not in accepted:
        raise MarkovMotionError(
            f"{path}: unknown {what} format {suffix or '(no suffix)'!r}; "
            f"use one of {', '.join(accepted)}"
        )
    return suffix


def check_figure_output(path: str | os.PathLike[str]) -> str:
    """The image format of ``path`` (``png``, ``svg``, ``pdf``), else a MarkovMotionError."""
    return check_suffix(path, FIGURE_SUFFIXES, "image").lstrip(".")


def save_figure(fig: Figure, path: str | os.PathLike[str], dpi: int = 120) -> Path:
    """Write ``fig`` atomically; the format follows the suffix (``.png``, ``.svg``, ``.pdf``)."""
    image_format = check_figure_output(path)
    path = Path(path)
    with atomic_write(path, "wb") as fh:
        fig.savefig(fh, format=image_format, dpi=dpi)
    return path


def save_line_plot(
    path: str | os.PathLike[str],
    x: np.ndarray,
    series: Mapping[str, np.ndarray],
    *,
    xlabel: str,
    ylabel: str,
    title: str = "",
    hlines: Mapping[str, float] | None = None,
    vlines: Mapping[str, float] | None = None,
    logy: bool = False,
    marker: str | None = "o",
) -> Path:
    """One line per entry of ``series`` against ``x``, with labelled reference lines.

    ``hlines`` / ``vlines`` map a legend label to a y / x value drawn dashed
    (a threshold, a chosen number of components). Returns the path written.
    """
    fig, ax = new_figure()
    x = np.asarray(x)
    for label, y in series.items():
        ax.plot(x, np.asarray(y), marker=marker, ms=3.5, lw=1.6, label=label)
    for i, (label, y) in enumerate((hlines or {}).items()):
        ax.axhline(y, color=f"C{i + 3}", ls="--", lw=1.2, label=label)
    for i, (label, v) in enumerate((vlines or {}).items()):
        ax.axvline(v, color=f"C{i + 6}", ls=":", lw=1.4, label=label)
    if logy:
        ax.set_yscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    if title:
        ax.set_title(title)
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=9)
    return save_figure(fig, path)
