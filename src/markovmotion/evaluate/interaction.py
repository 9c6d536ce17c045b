"""The observer study of the dual-HMM paper (§4.2, Tables 1-2): real and generated interactions.

For every two-person take of a test index that fits a dual-HMM model and that
the model did not train on (:func:`~markovmotion.evaluate.hmm.evaluation_pairs`),
two clips: the real take (real A, real B) and a generated one (real A, B from
``model.respond(A)``, standard Viterbi), both at the model's frame rate and cut
to the same frames. Observers see each clip as a point-light display (white
dots on black, both people: :func:`markovmotion.viz.point_light.point_lights`),
name the action among the labels the model was trained on, and may say they
noticed something strange or unusual, with a free comment.

The stimuli folder holds each clip as two anonymously numbered BVH files
(``interaction_NNN_a.bvh``, ``interaction_NNN_b.bvh``) and the manifest
``interaction.json`` (written last): the labels offered and, per clip, its
files, label, kind (``real`` or ``generated``) and the take it comes from.
The same folder may also hold the gait study's ``manifest.csv``.

:func:`summarise_interaction` recomputes, from the answered items, the
identification rate per behaviour for real and generated clips, how many
observers noticed something unusual, and the comments of each clip (the
paper's Tables 1-2), for the results page and ``markovmotion evaluation report``.
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from markovmotion.errors import DataNotFoundError, MarkovMotionError, MotionFormatError
from markovmotion.io import write_motion
from markovmotion.io.files import atomic_write, read_text
from markovmotion.progress import note

if TYPE_CHECKING:
    from markovmotion.evaluate.store import Item
    from markovmotion.models.hmm.dual import DualHMM

INTERACTION = "interaction"
"""The test name of this study in the evaluation database."""
INTERACTION_MANIFEST = "interaction.json"
CLIP_KINDS = ("real", "generated")
OTHER = "dont_know"
"""The answer for "something else / I don't know" (never a correct identification)."""
OTHER_LABEL = "something else / I don't know"
MAX_COMMENT = 2000
"""Longest comment kept, in characters."""
QUESTION = "Which action are these two people performing?"


@dataclass(frozen=True)
class Clip:
    """One two-person point-light clip: A and B files (relative to the stimuli folder)."""

    id: str
    file_a: str
    file_b: str
    label: str
    kind: str
    take: str = ""


@dataclass
class InteractionStimuli:
    """What ``interaction.json`` holds: the labels offered and the clips."""

    labels: list[str]
    clips: list[Clip]
    model: str = ""
    fps: float = 30.0
    left_out: dict[str, list[str]] = field(default_factory=dict)

    def choices(self) -> tuple[str, ...]:
        """The answers offered: the labels, then :data:`OTHER`."""
        return (*self.labels, OTHER)

    def clip(self, clip_id: str) -> Clip | None:
        return next((c for c in self.clips if c.id == clip_id), None)


def choice_labels(labels: Sequence[str]) -> list[tuple[str, str]]:
    """``(value, text shown)`` of each answer: the labels as they are, then "something else"."""
    return [*((label, label) for label in labels), (OTHER, OTHER_LABEL)]


def read_interaction_manifest(folder: str | os.PathLike[str]) -> InteractionStimuli:
    """The clips listed in ``folder/interaction.json``, each file checked to lie inside ``folder``.

    Raises:
        DataNotFoundError: no manifest.
        MotionFormatError: the manifest is not what this module writes (one line naming it).
    """
    root = Path(folder).resolve()
    path = root / INTERACTION_MANIFEST
    if not path.is_file():
        raise DataNotFoundError(f"{path}: no interaction stimuli manifest")
    try:
        data = json.loads(read_text(path))
        labels = [str(v) for v in data["labels"]]
        clips = [
            Clip(
                str(c["id"]),
                str(c["file_a"]),
                str(c["file_b"]),
                str(c["label"]),
                str(c["kind"]),
                str(c.get("take", "")),
            )
            for c in data["clips"]
        ]
        model, fps = str(data.get("model", "")), float(data.get("fps", 30.0))
        left_out = {str(k): [str(f) for f in v] for k, v in dict(data.get("left_out", {})).items()}
    except (ValueError, KeyError, TypeError, AttributeError) as exc:
        raise MotionFormatError(path, f"not an interaction manifest ({exc!r})") from None
    if not isinstance(data["labels"], list) or not isinstance(data["clips"], list):
        raise MotionFormatError(path, "labels and clips must be lists")
    if not labels or any(not label for label in labels) or OTHER in labels:
        raise MotionFormatError(path, "labels: expected a list of action names")
    if not clips:
        raise MotionFormatError(path, "the manifest lists no clips")
    if len({c.id for c in clips}) != len(clips):
        raise MotionFormatError(path, "two clips have the same id")
    for c in clips:
        if c.kind not in CLIP_KINDS:
            raise MotionFormatError(
                path, f"clip {c.id}: kind {c.kind!r} is not one of {CLIP_KINDS}"
            )
        if c.label not in labels:
            raise MotionFormatError(path, f"clip {c.id}: label {c.label!r} is not one offered")
        for file in (c.file_a, c.file_b):
            target = (root / file).resolve()
            if not target.is_relative_to(root) or not target.is_file():
                raise MotionFormatError(path, f"clip {c.id}: {file!r} is not a file inside {root}")
    return InteractionStimuli(labels, clips, model, fps, left_out)


def write_interaction_stimuli(
    folder: str | os.PathLike[str],
    model_path: str | os.PathLike[str],
    test: str | os.PathLike[str] | None = None,
    rng: np.random.Generator | None = None,
    videos: bool = False,
) -> InteractionStimuli:
    """Build the observer study's clips from the dual HMM in ``model_path`` (see the module).

    ``test``: an index (folder or INDEX.csv) to take the two-person takes from
    (default: the model's own held-out takes, as ``dualhmm evaluate``). Takes the
    model trained on, and takes whose person A has another skeleton, are left out
    and listed in the manifest. Clips are numbered in a random order. With ``videos``,
    each clip is also rendered as a point-light MP4 (``interaction_NNN.mp4``, white dots
    on black) for showing outside the browser.

    Raises:
        ModelFormatError: not a dual-HMM model file.
        MarkovMotionError: a partner of markers (clips are skeletons).
        DataNotFoundError: no take fits, or all are training takes or of another skeleton.
    """
    from markovmotion.evaluate.hmm import evaluation_pairs, pairs_that_fit
    from markovmotion.models.hmm.dual import DualHMM

    root = Path(folder)
    if root.exists() and not root.is_dir():
        raise MarkovMotionError(f"{root}: not a folder to write the stimuli into")
    model = DualHMM.load(model_path)
    if model.uses_markers:  # clips are skeletons (BVH) drawn as the 13 points of each body
        raise MarkovMotionError(
            f"{model_path}: a partner of markers; the observer study's clips are skeletons "
            "drawn as point lights: train the partner on skeleton takes (--kind skeleton)"
        )
    index, takes = evaluation_pairs(model, test)
    made: list[tuple[str, str, Any, Any, Any]] = []
    other_skeleton: list[str] = []
    for ea, eb, a, b in pairs_that_fit(model, index, takes.takes, other_skeleton):
        made.append((f"{ea.name}+{eb.name}", ea.label, *_clip_pair(model, a, b)))
    if not made:
        raise DataNotFoundError(
            f"{index.root / 'INDEX.csv'}: every two-person take that fits the model has "
            f"another skeleton for person A: {', '.join(other_skeleton)}"
        )
    labels = list(getattr(model, "labels_", None) or []) or sorted({m[1] for m in made})
    labels += sorted({m[1] for m in made} - set(labels))
    if unshown := [label for label in labels if label not in {m[1] for m in made}]:
        note(
            f"no clip is labelled {', '.join(unshown)} (every such take was learnt): offered "
            "as an answer, but the study cannot measure how it is recognised; hold one out "
            "(dualhmm train --test-trials) or give --test"
        )
    order = (rng or np.random.default_rng()).permutation(2 * len(made))
    root.mkdir(parents=True, exist_ok=True)
    clips: list[Clip] = []
    for i, (take, label, a, b, generated) in enumerate(made):
        if videos:
            from markovmotion.viz import render
            from markovmotion.viz.point_light import point_lights

            # both versions of a take in one view: same camera, same frame size
            shown = [point_lights([a, b]), point_lights([a, generated])]
        for k, (kind, person_b) in enumerate((("real", b), ("generated", generated))):
            cid = f"interaction_{order[2 * i + k] + 1:03d}"
            write_motion(a, root / f"{cid}_a.bvh")
            write_motion(person_b, root / f"{cid}_b.bvh")
            clips.append(Clip(cid, f"{cid}_a.bvh", f"{cid}_b.bvh", label, kind, take))
            if videos:
                render(shown[k], root / f"{cid}.mp4", fps=model.fps, point_light=True, framed=shown)
    clips.sort(key=lambda c: c.id)
    stimuli = InteractionStimuli(
        labels,
        clips,
        Path(model_path).name,
        float(model.fps),
        {
            "left_out_training_files": takes.report()["left_out_training_files"],
            "left_out_other_kind": takes.other_kind,
            "left_out_other_skeleton": other_skeleton,
        },
    )
    with atomic_write(root / INTERACTION_MANIFEST) as fh:
        fh.write(json.dumps(_manifest(stimuli), indent=1))
    return stimuli


def _clip_pair(model: DualHMM, a: Any, b: Any) -> tuple[Any, Any, Any]:
    """A and real B at the model's rate and B generated from A, all cut to the same frames."""
    generated = model.respond(a, "standard")
    a, b = (m if np.isclose(m.fps, model.fps) else m.resample(model.fps) for m in (a, b))
    n = min(a.n_frames, b.n_frames, generated.n_frames)
    return a.trim(0, n), b.trim(0, n), generated.trim(0, n)


def _manifest(s: InteractionStimuli) -> dict[str, Any]:
    return {
        "study": INTERACTION,
        "model": s.model,
        "fps": s.fps,
        "labels": s.labels,
        "clips": [asdict(c) for c in s.clips],
        "left_out": s.left_out,
    }


# ---------------------------------------------------------------- analysis


def _percent(count: int, total: int) -> float | None:
    return 100.0 * count / total if total else None


def _cell(rows: Sequence[Item]) -> dict[str, Any]:
    correct = sum(i.answer == i.style for i in rows)
    unusual = sum(bool(i.unusual) for i in rows)
    return {
        "n": len(rows),
        "correct": correct,
        "rate": _percent(correct, len(rows)),
        "unusual": unusual,
    }


def summarise_interaction(
    items: Sequence[Item], labels: Sequence[str], clips: Sequence[Clip] = ()
) -> dict[str, Any]:
    """The observer study's figures from the answered items (JSON-ready; no answers: rates None).

    ``rates[label][kind]`` and ``overall[kind]``: ``n`` answers, ``correct``
    identifications, ``rate`` (%), ``unusual`` (observers who noticed something
    strange); ``clips``: the same per clip, with its label, kind, take and comments.
    """
    rows = [i for i in items if i.test == INTERACTION and i.answer is not None]
    known = {c.id: c for c in clips}
    ids = sorted({i.file for i in rows} | set(known))
    labels = list(labels) + sorted({i.style for i in rows} - set(labels))
    per_clip = []
    for cid in ids:
        mine = [i for i in rows if i.file == cid]
        clip = known.get(cid)
        per_clip.append(
            {
                "clip": cid,
                "label": clip.label if clip else mine[0].style,
                "kind": clip.kind if clip else mine[0].kind,
                "take": clip.take if clip else "",
                **_cell(mine),
                "comments": [i.comment for i in mine if i.comment],
            }
        )
    return {
        "labels": labels,
        "kinds": list(CLIP_KINDS),
        "observers": len({i.token for i in rows}),
        "answers": len(rows),
        "rates": {
            label: {
                kind: _cell([i for i in rows if i.style == label and i.kind == kind])
                for kind in CLIP_KINDS
            }
            for label in labels
        },
        "overall": {kind: _cell([i for i in rows if i.kind == kind]) for kind in CLIP_KINDS},
        "clips": per_clip,
    }
