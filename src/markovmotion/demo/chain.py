"""Demo step of the interaction paper: a behaviour chain answers a held-out dancer online."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from rich.console import Console

from markovmotion.data import MocapIndex
from markovmotion.data.splits import held_out_pairs
from markovmotion.demo.run import required
from markovmotion.demo.scene import partner_scene
from markovmotion.evaluate.chain import pose_error_mm
from markovmotion.features.joint_shape import person_from_motion
from markovmotion.models.chain.partner import VirtualPartner
from markovmotion.models.online import run
from markovmotion.progress import track

LABEL = "salsa"
TRAIN_TAKES = 4  # about ten seconds: four takes, 40 + 40 prototypes, two passes each
SECONDS = 20.0  # of the held-out take answered
HYPOTHESES = 100


def demo_step(out: Path, index: MocapIndex, console: Console) -> list[Path]:
    """Virtual partner (behaviour chain, CONDENSATION, online): a held-out salsa dancer answered."""
    pairs = required(index.pairs(label=LABEL), "two-person salsa takes, at least 2", index, 2)
    train, held_out = held_out_pairs(pairs)
    pairs = [index.load_pair(a, b) for a, b in track(train[:TRAIN_TAKES], "loading salsa takes")]
    model = VirtualPartner(n_epochs=2).fit(pairs)
    ch = model.chain_
    console.print(
        f"behaviour chain: {len(pairs)} salsa takes at {model.fps_:g} fps, "
        f"{len(ch.state_prototypes_)} state and {len(ch.behaviour_prototypes_)} behaviour "
        "prototypes"
    )
    test = held_out[-1]
    a, b = (m.resample(model.fps_) for m in index.load_pair(*test))
    n = min(a.n_frames, int(SECONDS * model.fps_))
    a, b = a.trim(0, n), b.trim(0, n)
    partner = model.partner(n_hypotheses=HYPOTHESES)
    virtual = run(partner, a)
    real_a, real_b = person_from_motion(a), person_from_motion(b)
    online = pose_error_mm(model, person_from_motion(virtual), real_b)
    baseline = pose_error_mm(model, model.mean_partner(real_a, np.zeros(n, int)), real_b)
    console.print(
        f"held-out take {test[0].name}+{test[1].name} ({n / model.fps_:.0f} s): online partner "
        f"{online:.0f} mm, mean-shape baseline {baseline:.0f} mm (pose error; lag "
        f"{partner.lag} frames)"
    )
    return partner_scene(
        a,
        b,
        virtual,
        out / "chain-partner.bvh",
        out / "chain-partner.gif",
        "behaviour chain",
        f"salsa {test[0].trial}: real and virtual partner (behaviour chain)",
        max_seconds=8.0,
    )
