"""``render``: stick-figure animation (GIF, MP4) or frame strip (PNG) of motion files."""

from __future__ import annotations

from pathlib import Path

import typer
from rich.console import Console

from markovmotion.cli.options import ranged
from markovmotion.data.index import read_listed


def render(
    inputs: list[Path] = typer.Argument(
        ..., help="Motion files (BVH, ASF/AMC) or C3D marker files.", metavar="IN..."
    ),
    out: Path = typer.Option(..., "--out", "-o", help="Output .gif, .mp4 or .png (frame strip)."),
    side_by_side: bool = typer.Option(
        False, "--side-by-side", help="One panel per input instead of one shared scene."
    ),
    fps: float = ranged("fps", 15.0, min=0.1, help="Frames per second of the animation."),
    max_seconds: float = ranged(
        "seconds", None, min=0.01, help="Render at most this many seconds."
    ),
    data_fps: float = ranged(
        "fps", None, min=0.01, help="True frame rate of the inputs, overriding the files'."
    ),
    title: str = ranged("title", None, help="Text above the picture."),
) -> None:
    """Draw motions as stick figures, in one scene (two partners) or side by side."""
    from markovmotion.viz import check_output, render

    check_output(out)
    items = []
    for path in inputs:
        items.append(read_listed(path, data_fps or None))
    render(items, out, side_by_side=side_by_side, fps=fps, max_seconds=max_seconds, title=title)
    Console(stderr=True).print(f"wrote {out}")


def register(app: typer.Typer) -> None:
    app.command()(render)
