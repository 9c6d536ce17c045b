"""Demo step of the video system (dual-HMM paper §3, Fig. 1): a handshake rendered by three
cameras, person A tracked in it by annealed particle filtering, the virtual partner of a
dual HMM that never saw the take put back into camera 0's video.

It lives here, not in :mod:`markovmotion.demo`, because video sits above the demo in the
layers; ``markovmotion demo`` adds it to the demo's steps (:mod:`markovmotion.cli.demo`).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

from rich.console import Console

from markovmotion.data import MocapIndex
from markovmotion.models.hmm.dual import DualHMM
from markovmotion.progress import track
from markovmotion.video.composite import respond_in_video
from markovmotion.video.multiview import render_multiview, training_body_model

HANDSHAKE = "handshake"
SECONDS = 2.0  # of the take, at 30 fps: 60 frames tracked


def video_partner(out: Path, index: MocapIndex, console: Console) -> list[Path]:
    """A handshake on video: A tracked from 3 cameras, the virtual partner composited in."""
    shakes = index.pairs(label=[HANDSHAKE])
    if not shakes:
        console.print("no handshake in the index: video demo skipped")
        return []
    test = shakes[-1]
    train = [p for p in index.pairs() if p[0].subject == test[0].subject and p != test]
    if not train:
        console.print("no other take of the handshake's people to learn from: skipped")
        return []
    takes = [index.load_pair(*p) for p in track(train, "loading interaction takes")]
    model = DualHMM().fit(takes, [p[0].label for p in train])
    composite = out / "video-partner.mp4"
    with tempfile.TemporaryDirectory() as tmp:
        model_file = Path(tmp) / "partner.npz"
        model.save(model_file)
        video = Path(tmp) / "video"
        render_multiview(test[0].path, video, views=3, seconds=SECONDS, fps=30.0)
        body = training_body_model(index.root)
        summary = respond_in_video(model_file, video, composite, body)
    console.print(
        f"video: handshake {test[0].name} rendered by 3 cameras ({SECONDS:g} s), A tracked at "
        f"{summary['fps']:g} frames/s, B from a dual HMM that never saw the take "
        f"({', '.join(model.labels_)}) composited into camera 0",
        highlight=False,
    )
    return [composite]
