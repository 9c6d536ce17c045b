"""Pictures of motion: stick-figure animations and frame strips, line plots."""

from markovmotion.viz.animation import OUTPUT_SUFFIXES, check_output, render, render_frames
from markovmotion.viz.plots import new_figure, save_figure, save_line_plot

__all__ = [
    "OUTPUT_SUFFIXES",
    "check_output",
    "new_figure",
    "render",
    "render_frames",
    "save_figure",
    "save_line_plot",
]
