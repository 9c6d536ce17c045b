"""Demo steps of the video system: a handshake rendered by three cameras, person A tracked in
it by annealed particle filtering, the virtual partner of a dual HMM that never saw the take
put back into camera 0's video (dual-HMM paper §3, Fig. 1); and exercise takes rendered as
silhouette video, tracked as contours and learnt by a structured VLMM (VLMM paper §2.1.1,
Fig. 9).

They live here, not in :mod:`markovmotion.demo`, because video sits above the demo in the
layers; ``markovmotion demo`` adds them to the demo's steps (:mod:`markovmotion.cli.demo`).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
from rich.console import Console

from markovmotion.algorithms.vector_quantisation import collapse_repeats, nearest_prototype
from markovmotion.data import MocapIndex
from markovmotion.data.splits import held_out_last
from markovmotion.demo.run import required
from markovmotion.errors import MotionFormatError
from markovmotion.models.hmm.dual import DualHMM
from markovmotion.models.vlmm.behaviour import BehaviourModel
from markovmotion.models.vlmm.structured import StructuredBehaviourModel
from markovmotion.progress import track
from markovmotion.video.composite import respond_in_video
from markovmotion.video.contours import (
    contour_configurations,
    contour_scale,
    contour_strip,
    contour_track,
)
from markovmotion.video.multiview import render_multiview, training_body_model

HANDSHAKE = "handshake"
SECONDS = 2.0  # of the take, at 30 fps: 60 frames tracked

#: The contour step learns the first CONTOUR_SECONDS of CONTOUR_TAKES training takes of one
#: exercise label (500 frames at 25 fps, about 20 s to render and track on one core; the
#: paper learnt 1,000 frames, 40 s of one routine).
CONTOUR_TAKES = 4
CONTOUR_SECONDS = 5.0
#: The synthesized routines: every STRIP_STEP-th of the first STRIP_FRAMES * STRIP_STEP frames.
ROUTINE_SECONDS = 10.0
STRIP_FRAMES = 20
STRIP_STEP = 12
#: How coherent a routine is: the share of its runs of 4 prototypes seen in training, over
#: a routine this long.
COHERENCE_SECONDS = 120.0


def video_partner(out: Path, index: MocapIndex, console: Console) -> list[Path]:
    """A handshake on video: A tracked from 3 cameras, the virtual partner composited in."""
    shakes = required(
        index.pairs(label=[HANDSHAKE], kind="skeleton"), "two-person handshakes (skeletons)", index
    )  # rendered from skeletons
    test = shakes[-1]
    train = [
        p for p in index.pairs(kind="skeleton") if p[0].subject == test[0].subject and p != test
    ]
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
        summary = respond_in_video(model_file, video, composite, body, view=None)
    console.print(
        f"video: handshake {test[0].name} rendered by 3 cameras ({SECONDS:g} s), A tracked at "
        f"{summary['fps']:g} frames/s, B from a dual HMM that never saw the take "
        f"({', '.join(model.labels_)}) composited into camera {summary['view']} (the one that "
        "shows both people most)",
        highlight=False,
    )
    for line in summary["notes"]:
        console.print(line, highlight=False)
    return [composite]


def contour_label(index: MocapIndex) -> str | None:
    """The exercise label of the contour step: the one with the most takes in the index,
    ties broken by the most captured frames (None: no exercise take)."""
    takes: dict[str, tuple[int, int]] = {}
    for e in index.query(category="exercise"):
        n, frames = takes.get(e.label, (0, 0))
        takes[e.label] = (n + 1, frames + e.frames)
    return max(takes, key=takes.__getitem__) if takes else None


def seen_windows(tokens: np.ndarray, runs: list[np.ndarray], length: int) -> float:
    """Fraction of the windows of ``length`` successive prototypes (repeats collapsed) of a
    routine's ``tokens`` that occur somewhere in the training ``runs``."""
    seen = {tuple(r[i : i + length]) for r in runs for i in range(len(r) - length + 1)}
    t = collapse_repeats(np.asarray(tokens))[0]
    windows = [tuple(t[i : i + length]) for i in range(len(t) - length + 1)]
    return sum(w in seen for w in windows) / max(len(windows), 1)


def vlmm_contours(out: Path, index: MocapIndex, console: Console) -> list[Path]:
    """Contour routines at memory N = 1 and 4, key and prototype (VLMM paper Fig. 9).

    A structured VLMM of tracked silhouette contours; rows for its key memory and for its
    prototype VLMM's memory."""
    label = contour_label(index)
    train, _ = held_out_last(
        required(
            index.query(category="exercise", label=label),
            f"exercise takes labelled {label}, at least 2"
            if label
            else "exercise takes, at least 2",
            index,
            2,
        )
    )
    cache = out / "contour-cache"  # videos and tracks, reused by the next run
    tracks = []
    for e in train:
        if len(tracks) == CONTOUR_TAKES:
            break
        try:
            tracks.append(contour_track(index, e, cache, CONTOUR_SECONDS))
        except MotionFormatError:  # a skeleton the silhouette renderer cannot draw
            continue
    if not tracks:
        console.print("no exercise take the silhouette renderer draws: contour demo skipped")
        return []
    configs = [contour_configurations(t, contour_scale(tracks)) for t in tracks]
    # The paper's contour settings (lambda 10, 5 key prototypes, key memory N = 4, epsilon
    # 1e-4) but 50 prototypes, not 71: the paper had 14 frames per prototype (1,000 frames),
    # 71 here would leave 7; 50 keep 10.
    base = BehaviourModel(
        n_prototypes=50, max_memory=4, lam=10.0, configuration="contour", fps=tracks[0].fps
    )
    model = StructuredBehaviourModel(base, max_memory=4, n_keys=5).fit(configs)
    runs = [
        collapse_repeats(nearest_prototype(f, model.prototype_model_.prototypes_))[0]
        for f in model.prototype_model_.observe(configs)
    ]
    routines, vlmm_routines, seen, seen_vlmm = [], [], [], []
    for n in (1, 4):
        key_model = model.with_key_memory(n)
        routines.append(key_model.generate(ROUTINE_SECONDS, np.random.default_rng(0)))
        long_run = key_model.generate_tokens(COHERENCE_SECONDS, np.random.default_rng(0))
        seen.append(seen_windows(long_run, runs, 4))
        prototype_model = model.prototype_model_.with_vlmm(n, model.epsilon)
        vlmm_routines.append(prototype_model.generate(ROUTINE_SECONDS, np.random.default_rng(0)))
        long_run = prototype_model.generate_tokens(COHERENCE_SECONDS, np.random.default_rng(0))
        seen_vlmm.append(seen_windows(long_run, runs, 4))
    console.print(
        f"contours: the first {CONTOUR_SECONDS:g} s of {len(tracks)} {label} takes tracked "
        f"({sum(len(c) for c in configs)} frames); {len(model.keys_)} key prototypes, "
        f"{model.n_atomic_behaviours} atomic behaviours; runs of 4 prototypes seen in training, "
        f"N = 1 / N = 4: {seen[0]:.0%} / {seen[1]:.0%} with the key memory (the strip), "
        f"{seen_vlmm[0]:.0%} / {seen_vlmm[1]:.0%} with the prototype VLMM's memory",
        highlight=False,
    )
    # both memories side by side: the key memory (the paper's Fig. 9) and the prototype
    # VLMM's, where on a few seconds of video the difference shows
    path = contour_strip(
        [*routines, *vlmm_routines],
        out / "vlmm-contours-key-memory.png",
        frames=STRIP_FRAMES,
        step=STRIP_STEP,
        titles=[
            *(
                f"structured model, key memory N = {n} ({s:.0%} of its runs of 4 seen in training)"
                for n, s in zip((1, 4), seen, strict=True)
            ),
            *(
                f"prototype VLMM, memory N = {n} ({s:.0%} of its runs of 4 seen in training)"
                for n, s in zip((1, 4), seen_vlmm, strict=True)
            ),
        ],
        fps=model.fps,
    )
    return [path]
