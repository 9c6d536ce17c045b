"""Demo step: routines synthesized by VLMMs of CMU dance and martial arts."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from rich.console import Console

from markovmotion.data import MocapIndex
from markovmotion.demo.run import required
from markovmotion.io import write_motion

#: The paper's configuration for synthesis (rotations, lambda 10, no join): the routine
#: is joint rotations as captured, with no inverse kinematics (docs/vlmm.md).
PAPER = {"configuration": "rotations", "lam": 10.0, "join": 0.0}


def demo_step(out: Path, index: MocapIndex, console: Console) -> list[Path]:
    """Routines synthesized by VLMMs of CMU dance and martial arts (VLMM paper Figs. 3, 6, 9)."""
    from markovmotion.data.splits import held_out_last
    from markovmotion.models.vlmm.behaviour import BehaviourModel, load_motions
    from markovmotion.models.vlmm.structured import StructuredBehaviourModel
    from markovmotion.viz import render
    from markovmotion.viz.plots import new_figure, save_figure

    entries = required(
        index.query(category="exercise", label=("indian_dance", "martial_arts")),
        "exercise takes labelled indian_dance or martial_arts, at least 2", index, 2,
    )  # fmt: skip
    train, _ = held_out_last(entries)
    train = [e for label in ("indian_dance", "martial_arts") for e in train if e.label == label][:8]
    motions, _ = load_motions(index, train, 30.0)
    base = BehaviourModel(n_prototypes=80, max_memory=5, **PAPER)
    model = StructuredBehaviourModel(base, max_memory=4).fit(motions)
    vlmm = model.prototype_model_.vlmm_
    console.print(
        f"VLMM over {len(model.prototype_model_.prototypes_)} prototypes of {len(motions)} takes: "
        f"{vlmm.n_states} states (N = 5); structured model: {len(model.keys_)} key prototypes, "
        f"{model.n_atomic_behaviours} atomic behaviours, {len(model.template_probs_)} templates"
    )
    rng = np.random.default_rng(0)
    routine = model.generate(15.0, rng)
    bvh, gif = out / "vlmm-routine.bvh", out / "vlmm-routine.gif"
    write_motion(routine, bvh)
    render(routine, gif, title="Structured VLMM: a synthesized routine (15 s)")
    strip = out / "vlmm-key-memory.png"
    render(
        [model.with_key_memory(n).generate(12.0, np.random.default_rng(1)) for n in (1, 4)],
        strip,
        side_by_side=True,
        names=["key memory N = 1", "key memory N = 4"],
        strip_frames=8,
        title="Synthesized routines, first-order versus N = 4 key VLMM (paper Fig. 9)",
    )
    fig, ax = new_figure()
    for k, n in enumerate((5, 20)):
        hist = model.prototype_model_.with_vlmm(n, 1e-4).vlmm_.memory_length_histogram()
        ax.bar(np.arange(len(hist)) + 0.4 * k - 0.2, hist, width=0.4, label=f"N = {n}")
    ax.set_xlabel("memory length")
    ax.set_ylabel("number of states")
    ax.set_title("States of the prototype VLMM by memory length (paper Fig. 3)")
    ax.legend()
    hist_png = save_figure(fig, out / "vlmm-memory-lengths.png")
    return [bvh, gif, strip, hist_png]
