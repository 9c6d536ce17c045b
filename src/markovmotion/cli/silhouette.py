"""``silhouette``: videos of two-person takes and the silhouette tracker (interaction paper, §2)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import typer

from markovmotion.progress import err_console

app = typer.Typer(
    help="Silhouette videos of the two-person takes (fixed side camera, 25 fps) and the "
    "tracker: background subtraction, one blob per person, 32-point B-spline outlines.",
    no_args_is_help=True,
)


@app.command()
def render(
    out: Path = typer.Option(..., help="Folder for the videos and index.json."),
    data: Path = typer.Option(None, help="Folder with INDEX.csv (default: see README)."),
    label: str = typer.Option("salsa", help="Label of the two-person takes."),
    png: bool = typer.Option(False, "--png", help="PNG frame folders instead of MP4 files."),
    noise: float = typer.Option(4.0, min=0.0, help="Sensor noise (grey levels, std)."),
    max_frames: int = typer.Option(None, min=1, help="Only the first frames of each take."),
) -> None:
    """Render every take as silhouettes; held-out takes also once per person alone."""
    from markovmotion.video.dataset import render_takes

    index = render_takes(data, out, label, "" if png else ".mp4", noise, max_frames)
    err_console.print(f"wrote {index}", highlight=False)


@app.command("track")
def track_(
    video: Path = typer.Argument(..., help="Video file or folder of frames."),
    out: Path = typer.Option(..., help="Track file to write (.npz)."),
    people: int = typer.Option(2, min=1, max=2, help="People in the video."),
) -> None:
    """Track the people of a video: B-spline control points, reference points, heights."""
    from markovmotion.video.tracker import track_video

    result = track_video(video, people)
    result.save(out)
    err_console.print(
        f"wrote {out}: {result.n_frames} frames at {result.fps:g} fps, "
        f"{int(result.found.all(axis=1).sum())} with everyone found, "
        f"{int(result.merged.sum())} with two people cut apart, "
        f"median height {np.median(result.height[result.found]):.0f} px",
        highlight=False,
    )
