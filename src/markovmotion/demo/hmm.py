"""Demo step of the dual-HMM paper: a virtual salsa partner responding to a held-out dancer."""

from __future__ import annotations

from pathlib import Path

from rich.console import Console

from markovmotion.data import MocapIndex
from markovmotion.data.splits import held_out_pairs
from markovmotion.demo.scene import partner_scene
from markovmotion.evaluate.hmm import evaluate_pair, plot_pair
from markovmotion.models.hmm.dual import DualHMM
from markovmotion.progress import track

LABEL = "salsa"
TRAIN_TAKES = 4  # a minute at most: four takes, 16 states


def demo_step(out: Path, index: MocapIndex, console: Console) -> list[Path]:
    """Virtual partner (dual HMM, windowed Viterbi): a held-out salsa dancer and the generated partner."""
    pairs = index.pairs(label=LABEL)
    train, held_out = held_out_pairs(pairs)
    train, test = train[:TRAIN_TAKES], held_out[-1]
    takes = [index.load_pair(a, b) for a, b in track(train, "loading salsa takes")]
    model = DualHMM(n_states=16, n_iter=20).fit(takes)
    console.print(
        f"dual HMM: {len(takes)} salsa takes, {len(model.train_a_)} frames at {model.fps:g} fps, "
        f"N={model.n_states}, PCA dims A={model.train_a_.shape[1]} B={model.train_b_.shape[1]}"
    )
    a, b = index.load_pair(*test)
    a, b = a.resample(model.fps), b.resample(model.fps)
    virtual = model.respond(a, "windowed")
    result = evaluate_pair(model, a, b, f"{test[0].name}+{test[1].name}", LABEL)
    errors = {k: result.errors[k].mean() for k in ("standard", "windowed", "mean_pose")}
    console.print(
        f"held-out take {result.name}: windowed {errors['windowed']:.0f} mm, standard "
        f"{errors['standard']:.0f} mm, mean-pose baseline {errors['mean_pose']:.0f} mm "
        f"(lag {model.window - 1} frames)"
    )
    written = partner_scene(
        a,
        b,
        virtual,
        out / "partner-virtual.bvh",
        out / "partner.gif",
        "virtual partner",
        f"salsa {test[0].trial}: real and virtual partner (windowed Viterbi)",
        max_seconds=10.0,
    )
    return [*written, plot_pair(result, out / "partner-error.png")]
