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
from typing import TypeVar

import numpy as np
from rich.console import Console
from rich.table import Table

from markovmotion.data import MocapIndex
from markovmotion.data.index import Entry, shared_roots
from markovmotion.data.kinds import largest_group
from markovmotion.errors import DataNotFoundError, MarkovMotionError
from markovmotion.features import PCA, JointPositions
from markovmotion.io import write_motion
from markovmotion.io.files import base_suffix
from markovmotion.progress import note, track
from markovmotion.viz import render, render_frames, save_line_plot

Step = Callable[[Path, MocapIndex, Console], list[Path]]
T = TypeVar("T")

WALK = "cmu/asfamc/02/02_01.amc.gz"  # CMU subject 2, trial 1: a straight walk


def _cmu_training_set(index: MocapIndex) -> list[Entry]:
    """CMU walks and exercise takes sharing the walk's skeleton (the ASF/AMC subjects); in
    a collection without them, its skeleton walks and exercise takes (the largest group of
    one skeleton is kept when they are read)."""
    fmt = base_suffix(WALK)
    cmu = [
        e
        for e in index.query(source="cmu", category=("walk", "exercise"))
        if base_suffix(e.file) == fmt
    ]
    return cmu or [e for e in index.query(category=("walk", "exercise")) if e.kind == "skeleton"]


def required(items: Sequence[T], what: str, index: MocapIndex, least: int = 1) -> Sequence[T]:
    """``items`` if there are at least ``least``, else the one line of a demo step whose
    takes ``index`` does not hold (:class:`DataNotFoundError`: the step is skipped on a
    user's own collection, :func:`run_demo`)."""
    if len(items) < least:
        raise DataNotFoundError(f"{what}: {len(items)} in {index.root / 'INDEX.csv'}")
    return items


def _walk_entry(index: MocapIndex) -> Entry:
    """:data:`WALK` where the index has it (the shared collection), else its first walk
    (a user's own collection)."""
    if (shared := next((e for e in index if e.file == WALK), None)) is not None:
        return shared
    walks = [e for e in index.query(category="walk") if e.kind == "skeleton"]
    if not walks:
        raise DataNotFoundError(f"no skeleton take of category walk in {index.root / 'INDEX.csv'}")
    return walks[0]


def captured_walk(out: Path, index: MocapIndex, console: Console) -> list[Path]:
    """A captured walk as BVH, an animated GIF and a strip of frames."""
    entry = _walk_entry(index)
    walk = index.load_motion(entry)
    console.print(
        f"captured walk {entry.file}: {walk.n_frames} frames at {walk.fps:g} fps "
        f"({walk.duration:.1f} s, {walk.skeleton.n_joints} joints)"
    )
    bvh, gif, png = out / "walk.bvh", out / "walk.gif", out / "walk-frames.png"
    write_motion(walk, bvh)
    title = (
        "CMU subject 02, trial 01: walk (captured)"
        if entry.file == WALK
        else f"{Path(entry.file).name}: walk (captured)"
    )
    render(walk, gif, title=title)
    render_frames(walk, np.linspace(0, walk.n_frames - 1, 6).astype(int), png, title=title)
    return [bvh, gif, png]


def pca_energy(out: Path, index: MocapIndex, console: Console) -> list[Path]:
    """Energy kept by PCA of body-centred joint positions (CMU walks and exercise)."""
    entries = _cmu_training_set(index)
    if not entries:
        raise DataNotFoundError(f"no skeleton walk or exercise take in {index.root / 'INDEX.csv'}")
    motions = [index.load_motion(e) for e in track(entries, "loading walks and exercise")]
    best, _ = largest_group(motions, [e.file for e in entries])
    motions = [motions[i] for i in best]
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
        title=f"PCA of body-centred joint positions: {len(motions)} takes, {n_frames} frames",
        hlines={"95 % energy": 0.95},
        vlines={f"chosen K = {k}": k},
    )
    return [path]


def dual_hmm_partner(out: Path, index: MocapIndex, console: Console) -> list[Path]:
    """A virtual salsa partner generated by a dual HMM (windowed Viterbi) beside the real one."""
    from markovmotion.demo.hmm import demo_step

    return demo_step(out, index, console)


def dual_hmm_handshake(out: Path, index: MocapIndex, console: Console) -> list[Path]:
    """A virtual partner shaking hands (dual HMM on the two-person CMU interactions)."""
    from markovmotion.demo.hmm import handshake_step

    return handshake_step(out, index, console)


def dual_hmm_new_people(out: Path, index: MocapIndex, console: Console) -> list[Path]:
    """A virtual partner shaking hands with a pair of people it never saw (markers)."""
    from markovmotion.demo.hmm import new_people_step

    return new_people_step(out, index, console)


def vlmm_routine(out: Path, index: MocapIndex, console: Console) -> list[Path]:
    """Routines synthesized by VLMMs of CMU dance and martial arts (VLMM paper Figs. 3, 9)."""
    from markovmotion.demo.vlmm import demo_step

    return demo_step(out, index, console)


def stylized_walk(out: Path, index: MocapIndex, console: Console) -> list[Path]:
    """An average walk adapted to a style (HSMM), synthesized beside a real walk of that style."""
    from markovmotion.demo.gait import demo_step

    return demo_step(out, index, console)


def chain_partner(out: Path, index: MocapIndex, console: Console) -> list[Path]:
    """A virtual salsa partner answered online by a behaviour chain (CONDENSATION)."""
    from markovmotion.demo.chain import demo_step

    return demo_step(out, index, console)


STEPS: list[Step] = [
    captured_walk,
    pca_energy,
    dual_hmm_partner,
    dual_hmm_handshake,
    dual_hmm_new_people,
    chain_partner,
    vlmm_routine,
    stylized_walk,
]


def run_demo(out: Path, data: Path | None = None, steps: Sequence[Step] | None = None) -> None:
    """Run the demo ``steps`` (default :data:`STEPS`) on the data in ``data``, writing to ``out``.

    On the shared collection (``data`` None) every step must run. On a user's own index a
    step whose takes are not there (or not of one skeleton) is skipped, and the skipped
    steps are said after the table, each with why; none running is one line
    (:class:`DataNotFoundError`)."""
    console = Console(soft_wrap=True)  # a log file keeps whole lines
    out = Path(out)
    index = MocapIndex.load(data)  # no data: one line, and no empty output folder left
    out.mkdir(parents=True, exist_ok=True)
    console.print(f"[bold]markovmotion demo[/]: data {index.root}, outputs in {out}")
    table = Table(title=f"written to {out}", show_lines=False)
    table.add_column("step")
    table.add_column("file", no_wrap=True)
    table.add_column("size", justify="right")
    table.add_column("time", justify="right")
    skipped: list[str] = []
    shared = index.root.resolve() in shared_roots()  # not a user's, wherever it is given
    for step in STEPS if steps is None else steps:
        start = time.perf_counter()
        what = (step.__doc__ or step.__name__).strip().splitlines()[0]
        try:
            paths = step(out, index, console)
        except MarkovMotionError as exc:  # takes missing, or not of one skeleton
            if shared:  # the shared collection holds every step's takes
                raise
            skipped.append(f"{what} ({exc})")  # said after the table
            continue
        seconds = time.perf_counter() - start
        for n, p in enumerate(paths):
            size = f"{p.stat().st_size / 1024:.0f} KiB"
            table.add_row(
                what if n == 0 else "", p.name, size, f"{seconds:.1f} s" if n == 0 else ""
            )
    if skipped and len(skipped) == len(STEPS if steps is None else steps):
        if not any(out.iterdir()):
            out.rmdir()  # nothing written: no empty folder left
        raise DataNotFoundError(
            f"no step of the demo found the takes it needs in {index.root / 'INDEX.csv'} "
            f"(the first: {skipped[0]})"
        )
    console.print(table)
    for line in skipped:  # after the table, where a user looks last
        note(f"skipped on {index.root / 'INDEX.csv'}: {line}")
