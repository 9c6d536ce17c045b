"""Demo step of the gait paper: an average walk adapted to a style, beside a real walk of that style."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from rich.console import Console

from markovmotion.data import MocapIndex
from markovmotion.data.splits import held_out_every
from markovmotion.data.walks import gait_entries
from markovmotion.demo.run import required
from markovmotion.features.gait import align_walk, detect_steps
from markovmotion.io import write_motion
from markovmotion.models.gait.synthesizer import GaitSynthesizer
from markovmotion.progress import track
from markovmotion.viz import render, render_frames

STYLE = "elderly"
AVERAGE_WALKS = 8
ADAPTATION_STEPS = 12


def demo_step(out: Path, index: MocapIndex, console: Console) -> list[Path]:
    """Stylistic gait (HSMM): an average walk adapted to an elderly style from 12 steps, beside a real one."""
    normal_train, _ = held_out_every(
        required(gait_entries(index, "normal"), "walks labelled normal, at least 2", index, 2)
    )
    style_train, style_test = held_out_every(
        required(gait_entries(index, STYLE), f"walks labelled {STYLE}, at least 2", index, 2)
    )
    normal = [
        index.load_motion(e) for e in track(normal_train[:AVERAGE_WALKS], "loading neutral walks")
    ]
    average = GaitSynthesizer(n_iter=5).fit(normal)
    h = average.hsmm_
    console.print(
        f"average walk: {len(normal)} neutral Bandai walks, {average.n_steps_} steps cut at heel "
        f"strikes; {len(h.means_)} output and {len(h.dur_means_)} duration densities after "
        "context clustering"
    )
    style_walks = [index.load_motion(e) for e in style_train[:1]]
    styled = average.adapt(style_walks, STYLE, ADAPTATION_STEPS)
    console.print(
        f"adapted to '{STYLE}' (CSMAPLR + MAP) from {styled.n_steps_} steps of {style_walks[0].name}"
    )
    synthesized = styled.generate(12)
    synthesized.name = f"synthesized {STYLE} walk (adapted model)"
    real = align_walk(index.load_motion(style_test[0]))
    steps = detect_steps(real)
    real = real.trim(int(steps.boundaries[0]), int(steps.boundaries[-1]) + 1)
    real.name = f"real {STYLE} walk ({style_test[0].name}, held out)"
    bvh_synth = out / f"gait-{STYLE}-synthesized.bvh"
    bvh_real = out / f"gait-{STYLE}-real.bvh"
    write_motion(synthesized, bvh_synth)
    write_motion(real, bvh_real)
    title = f"'{STYLE}' walk: synthesized from 12 adaptation steps (blue), captured (red)"
    pair = [synthesized, real]
    names = [synthesized.name, real.name]
    gif = render(
        pair,
        out / f"gait-{STYLE}.gif",
        side_by_side=True,
        max_seconds=6.0,
        title=title,
        names=names,
    )
    frames = np.linspace(0, min(m.n_frames for m in pair) - 1, 6).astype(int)
    png = render_frames(
        pair, frames, out / f"gait-{STYLE}-frames.png", side_by_side=True, title=title, names=names
    )
    return [bvh_synth, bvh_real, gif, png]
