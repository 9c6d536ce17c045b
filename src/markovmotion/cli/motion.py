"""``info`` and ``convert``: look at a motion file, turn one into BVH."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import typer
from rich.console import Console
from rich.table import Table

from markovmotion.cli.options import ranged
from markovmotion.cli.tables import print_table
from markovmotion.data.index import read_listed, read_listed_motion
from markovmotion.io import write_motion
from markovmotion.io.files import base_suffix


def info(
    file: Path = typer.Argument(..., help="BVH, ASF/AMC or C3D file."),
    fps: float = ranged(
        "fps",
        None,
        help="True frame rate (default: INDEX.csv's for a file of the collection, else the file's).",
    ),
) -> None:
    """Describe a motion file: skeleton, frames, frame rate, extent."""
    console = Console()
    if base_suffix(file) == ".c3d":
        markers = read_listed(file, fps)
        console.print(markers.summary())
        return
    motion = read_listed_motion(file, fps=fps)
    sk = motion.skeleton
    pos = motion.positions(compiled=False)  # one call: not worth importing numba
    extent = pos.reshape(-1, 3).max(0) - pos.reshape(-1, 3).min(0)
    console.print(f"[bold]{file}[/]", highlight=False)
    table = Table(show_header=False)
    table.add_row("frames", str(motion.n_frames))
    table.add_row("frame rate", f"{motion.fps:g} fps")
    table.add_row("duration", f"{motion.duration:.2f} s")
    table.add_row("joints", f"{sk.n_joints} ({int(sk.end_site.sum())} end sites)")
    table.add_row("channels", str(sk.n_channels))
    table.add_row("pelvis", sk.names[sk.body_root])
    table.add_row("extent (mm)", " x ".join(f"{v:.0f}" for v in extent))
    table.add_row("height (mm)", f"{np.ptp(pos[0, :, 1]):.0f} in frame 0")
    print_table(table, console)


def convert(
    src: Path = typer.Argument(..., help="Input motion (BVH or ASF/AMC)."),
    dst: Path = typer.Argument(..., help="Output .bvh or .bvh.gz."),
    fps: float = ranged(
        "fps",
        None,
        help="True frame rate of the input (default: INDEX.csv's for a file of the collection, else the file's).",
    ),
    resample: float = ranged("fps", None, help="Resample to this frame rate before writing."),
) -> None:
    """Convert a motion to BVH (optionally at another frame rate)."""
    motion = read_listed_motion(src, fps=fps)
    if resample:
        motion = motion.resample(resample)
    write_motion(motion, dst)
    Console(stderr=True).print(f"wrote {dst} ({motion.n_frames} frames at {motion.fps:g} fps)")


def register(app: typer.Typer) -> None:
    app.command()(info)
    app.command()(convert)
