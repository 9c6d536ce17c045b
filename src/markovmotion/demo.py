"""The main job: from the CMU motion capture to motion files, animations and plots.

``run_demo`` runs :data:`STEPS` in order. A step is a function
``step(out, index, console) -> list[Path]`` that writes its outputs into
``out`` and returns their paths; its docstring's first line describes it in
the summary. A model adds its part of the demo by appending a step.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from markovmotion.data import MocapIndex
from markovmotion.data.index import Entry
from markovmotion.features import PCA, JointPositions
from markovmotion.io import write_motion
from markovmotion.io.files import base_suffix
from markovmotion.progress import track
from markovmotion.viz import render, render_frames, save_line_plot

Step = Callable[[Path, MocapIndex, Console], list[Path]]

WALK = "cmu/asfamc/02/02_01.amc.gz"  # CMU subject 2, trial 1: a straight walk


def _cmu_training_set(index: MocapIndex) -> list[Entry]:
    """CMU walks and exercise takes sharing the walk's skeleton (the ASF/AMC subjects)."""
    fmt = base_suffix(WALK)
    return [
        e
        for e in index.query(source="cmu", category=("walk", "exercise"))
        if base_suffix(e.file) == fmt
    ]


def captured_walk(out: Path, index: MocapIndex, console: Console) -> list[Path]:
    """A captured CMU walk as BVH, an animated GIF and a strip of frames."""
    walk = index.load_motion(index.find(WALK))
    console.print(
        f"captured walk {WALK}: {walk.n_frames} frames at {walk.fps:g} fps "
        f"({walk.duration:.1f} s, {walk.skeleton.n_joints} joints)"
    )
    bvh, gif, png = out / "walk.bvh", out / "walk.gif", out / "walk-frames.png"
    write_motion(walk, bvh)
    title = "CMU subject 02, trial 01: walk (captured)"
    render(walk, gif, title=title)
    render_frames(walk, np.linspace(0, walk.n_frames - 1, 6).astype(int), png, title=title)
    return [bvh, gif, png]


def pca_energy(out: Path, index: MocapIndex, console: Console) -> list[Path]:
    """Energy kept by PCA of body-centred joint positions (CMU walks and exercise)."""
    entries = _cmu_training_set(index)
    motions = [index.load_motion(e) for e in track(entries, "loading CMU walks and exercise")]
    n_frames = sum(m.n_frames for m in motions)
    features = JointPositions().fit_transform(motions)
    pca = PCA(energy=0.95).fit(features)
    cumulative = np.cumsum(pca.explained_variance_ratio_)
    k = pca.n_components_
    shown = min(len(cumulative), max(3 * k, 20))
    console.print(
        f"PCA of {features[0].shape[1]}-D joint positions over {len(motions)} takes "
        f"({n_frames} frames): {k} components keep {cumulative[k - 1]:.1%} of the energy"
    )
    path = save_line_plot(
        out / "pca-energy.png",
        np.arange(1, shown + 1),
        {"cumulative explained variance": cumulative[:shown]},
        xlabel="number of principal components K",
        ylabel="fraction of variance (energy) kept",
        title=f"PCA of body-centred joint positions: {len(motions)} CMU takes, {n_frames} frames",
        hlines={"95 % energy": 0.95},
        vlines={f"chosen K = {k}": k},
    )
    return [path]


STEPS: list[Step] = [captured_walk, pca_energy]


def run_demo(out: Path, data: Path | None = None, steps: Sequence[Step] | None = None) -> None:
    """Run the demo ``steps`` (default :data:`STEPS`) on the data in ``data``, writing to ``out``."""
    console = Console()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    index = MocapIndex.load(data)
    console.print(f"[bold]markovmotion demo[/]: data {index.root}, outputs in {out}")
    table = Table(title="written", show_lines=False)
    table.add_column("step")
    table.add_column("file")
    table.add_column("size", justify="right")
    table.add_column("time", justify="right")
    for step in STEPS if steps is None else steps:
        start = time.perf_counter()
        paths = step(out, index, console)
        seconds = time.perf_counter() - start
        what = (step.__doc__ or step.__name__).strip().splitlines()[0]
        for n, p in enumerate(paths):
            size = f"{p.stat().st_size / 1024:.0f} KiB"
            table.add_row(
                what if n == 0 else "", str(p), size, f"{seconds:.1f} s" if n == 0 else ""
            )
    console.print(table)
