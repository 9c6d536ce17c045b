"""``demo``: the main job, from real data to motion, animation and plot."""

from __future__ import annotations

from pathlib import Path

import typer


def demo(
    out: Path = typer.Option(Path("demo-out"), help="Folder for the outputs."),
    data: Path = typer.Option(
        None,
        help="Folder with INDEX.csv (default: see README); on your own, each step runs on the "
        "takes it finds there and the others are skipped, said at the end.",
    ),
) -> None:
    """One model of each family on the CMU and Bandai data: motion (BVH), animations (GIF), plots (PNG)."""
    from markovmotion.demo import run_demo
    from markovmotion.demo.run import STEPS
    from markovmotion.video.demo import video_partner, vlmm_contours

    run_demo(out, data, [*STEPS, vlmm_contours, video_partner])


def register(app: typer.Typer) -> None:
    app.command()(demo)
