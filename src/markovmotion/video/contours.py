"""Contour sequences of one person from silhouette video: the VLMM paper's data set 1 (§2.1.1).

An exercise take (motion capture of one person) is rendered as a silhouette
video from a fixed side camera (:func:`markovmotion.video.render.render_frames`)
and tracked (:func:`markovmotion.video.tracker.track_video`): per frame a
closed uniform cubic B-spline with 32 control points and the reference point
at the top of the head, in pixels. The configuration C of a frame (eq. 1) is
the control points relative to the reference point, divided by a fixed scale
``s`` (pixels) and shifted so the head sits at (0.5, 0.35):

    C = (x_1 - r_x, y_1 - r_y, ..., x_n - r_x, y_n - r_y) / s + (0.5, 0.35, ..., 0.5, 0.35),

clipped to [0, 1]^2n. ``s`` is twice the person's height in pixels over the
training takes (:func:`contour_scale`; the 95th percentile of the tracked
heights, as the tracker loses limbs in some frames, which lowers the median),
fixed once for a model, so a body
of that height spans half the unit square: outstretched arms and legs (within
one height either side of the head, 1.3 heights below it, 0.7 above: raised
arms) stay inside it. Contours where limbs were lost are kept as tracked. The behaviour model then augments C with lambda dC (eq. 2).

:func:`exercise_contours` renders and tracks the takes of an index (category
``exercise``), caching videos and tracks in a folder; :func:`contour_strip`
draws a synthesized routine as filled contours (paper Fig. 9) and
:func:`contour_extrapolation` predictions at selected instants (Fig. 7);
:func:`evaluate_contours` measures E_T (eq. 9, Figs. 4 and 10).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from markovmotion.data.index import Entry, MocapIndex
from markovmotion.data.splits import held_out_last
from markovmotion.errors import DataNotFoundError, MotionFormatError
from markovmotion.evaluate.vlmm import (
    FIRST_ORDER,
    ConfigurationSpace,
    HorizonCurve,
    ZeroVelocity,
    evaluate_horizon,
)
from markovmotion.features.joint_shape import person_from_motion
from markovmotion.io.files import atomic_path
from markovmotion.models.vlmm.behaviour import BehaviourModel
from markovmotion.models.vlmm.structured import StructuredBehaviourModel
from markovmotion.progress import track
from markovmotion.video.bspline import evaluate_closed_bspline
from markovmotion.video.dataset import FPS, tracked
from markovmotion.video.render import empty_frames, render_frames, side_camera, write_video
from markovmotion.video.tracker import SilhouetteTrack, track_video
from markovmotion.viz.plots import ordinal

#: Where the head reference point sits in the unit square (x, y; y down).
HEAD_AT = (0.5, 0.35)
#: The fixed scale is this many times the person's height in pixels.
HEIGHTS_PER_UNIT = 2.0
#: The person's height is this percentile of the tracked heights.
HEIGHT_PERCENTILE = 95.0
#: Frames of the empty scene a clip's background is learnt from (a static plate needs few).
PLATE_FRAMES = 15


def contour_scale(tracks: Sequence[SilhouetteTrack], person: int = 0) -> float:
    """The fixed scale s (pixels) of :func:`contour_configurations`: HEIGHTS_PER_UNIT times
    the HEIGHT_PERCENTILE-th percentile of the found person's height over ``tracks``
    (the training takes)."""
    heights = np.concatenate([t.height[t.found[:, person], person] for t in tracks])
    if not len(heights):
        raise ValueError("contour scale: the person is never found in the training tracks")
    return float(HEIGHTS_PER_UNIT * np.percentile(heights, HEIGHT_PERCENTILE))


def contour_configurations(track: SilhouetteTrack, scale: float, person: int = 0) -> np.ndarray:
    """(F, 2n) configurations C in [0, 1]^2n of a tracked person (§2.1.1, eq. 1).

    Control points relative to the head reference point, divided by ``scale``
    (:func:`contour_scale`) and shifted to :data:`HEAD_AT`; frames where the person
    was lost repeat the nearest found one (:meth:`SilhouetteTrack.filled`).
    """
    if not scale > 0:
        raise ValueError(f"contour scale must be positive, got {scale}")
    t = track.filled()
    rel = (t.control[:, person] - t.reference[:, person, None, :]) / scale + np.asarray(HEAD_AT)
    return np.clip(rel, 0.0, 1.0).reshape(len(rel), -1)


def configuration_control(configs: np.ndarray, scale: float) -> np.ndarray:
    """(F, n, 2) control points in pixels relative to the head for configurations (F, 2n):
    :func:`contour_configurations` undone (but for the clipping)."""
    c = np.asarray(configs, dtype=float)
    return (c.reshape(len(c), -1, 2) - np.asarray(HEAD_AT)) * scale


# ------------------------------------------------------------------ takes
@dataclass
class ContourTakes:
    """Tracked exercise takes: training and held-out tracks, their entries, the scale, and
    the takes left out (a skeleton without the renderer's joints)."""

    train: list[SilhouetteTrack]
    test: list[SilhouetteTrack]
    train_entries: list[Entry]
    test_entries: list[Entry]
    scale: float = field(default=0.0)
    left_out: list[Entry] = field(default_factory=list)

    def configurations(self, split: str = "train") -> list[np.ndarray]:
        """Contour configurations (F, 64) of the ``split`` takes at the training scale."""
        tracks = self.train if split == "train" else self.test
        return [contour_configurations(t, self.scale) for t in tracks]


def take_name(entry: Entry) -> str:
    """A file name for an entry's video: its file name without suffixes."""
    return Path(entry.file).name.split(".")[0]


def contour_track(
    index: MocapIndex,
    entry: Entry,
    cache: str | os.PathLike[str],
    seconds: float | None = None,
    noise: float = 4.0,
) -> SilhouetteTrack:
    """The silhouette track of one take seen alone from a side camera (first ``seconds``).

    The video (``<cache>/<name>.mp4``) and its track (``.track.npz`` beside it) are
    written once and reused (:func:`markovmotion.video.dataset.tracked`). A whole take's
    background is learnt from its own frames; a clip's (``seconds``) from a video of the
    empty scene (``<cache>/empty-scene.mp4``, :data:`PLATE_FRAMES` frames, written once):
    in a few seconds a dancer hardly leaves her spot, and the median of the clip's own
    frames would keep her in the background.
    """
    cache = Path(cache)
    cache.mkdir(parents=True, exist_ok=True)
    tag = "" if seconds is None else f".{seconds:g}s"
    video = cache / f"{take_name(entry)}{tag}.mp4"
    stored = video.parent / f"{video.name}.track.npz"
    if stored.is_file():
        return tracked(video, 1)
    motion = index.load_motion(entry).resample(FPS)
    plate = None
    if seconds is not None:
        motion = motion.trim(0, int(round(seconds * FPS)))
        plate = cache / "empty-scene.mp4"
        if not plate.is_file():
            write_video(empty_frames(PLATE_FRAMES, noise=noise), plate, FPS)
    person = person_from_motion(motion)
    write_video(render_frames([person], side_camera([person]), noise), video, FPS)
    result = track_video(video, 1, background=plate)
    result.save(stored)
    return result


def exercise_contours(
    data: str | os.PathLike[str] | None,
    cache: str | os.PathLike[str],
    category: str = "exercise",
    labels: Sequence[str] | None = None,
    hold_out: bool = True,
    seconds: float | None = None,
    scale: float | None = None,
) -> ContourTakes:
    """Render and track the takes of ``category`` (and ``labels``) of an index, one person
    each, the last take of each label held out when ``hold_out``; ``scale`` defaults to
    :func:`contour_scale` of the training tracks.

    Raises:
        DataNotFoundError: no such take.
    """
    index = MocapIndex.load(data)
    entries = index.query(category=category, label=labels or None)
    if not entries:
        raise DataNotFoundError(f"no {category} takes in {index.root / 'INDEX.csv'}")
    train, test = held_out_last(entries) if hold_out else (list(entries), [])
    out = ContourTakes([], [], [], [])
    for e in track([*train, *test], "contour takes"):
        try:
            t = contour_track(index, e, cache, seconds)
        except MotionFormatError:  # a skeleton the silhouette renderer cannot draw
            out.left_out.append(e)
            continue
        split = "test" if e in test else "train"
        getattr(out, split).append(t)
        getattr(out, f"{split}_entries").append(e)
    if not out.train:
        raise DataNotFoundError(
            f"no {category} take of {index.root / 'INDEX.csv'} has a skeleton the silhouette "
            "renderer draws"
        )
    out.scale = scale if scale is not None else contour_scale(out.train)
    return out


# ------------------------------------------------------------------ figures
def contour_strip(
    sequences: Sequence[np.ndarray],
    path: str | os.PathLike[str],
    frames: int = 10,
    step: int = 10,
    cell: int = 96,
    titles: Sequence[str] = (),
    box: tuple[float, float, float, float] = (0.15, 0.15, 0.85, 0.85),
    fps: float | None = None,
    heading: str = "",
) -> Path:
    """A PNG of filled contours (paper Fig. 9): one row per sequence of configurations
    (F, 2n), every ``step``-th frame of the first ``frames * step``, the closed
    B-spline sampled (:func:`evaluate_closed_bspline`) and filled, the part ``box``
    (x0, y0, x1, y1) of the unit square filling each cell; with ``fps``, each cell's time
    under it and the spacing in the ``heading`` line above the rows (a strip without them
    did not say which seconds of a routine it shows); written atomically."""
    lo, span = np.asarray(box[:2]), np.asarray(box[2:]) - np.asarray(box[:2])
    rows = []
    for configs in sequences:
        row = np.full((cell, cell * frames), 255, np.uint8)
        for k, t in enumerate(range(0, min(len(configs), frames * step), step)):
            ctrl = np.asarray(configs[t], dtype=float).reshape(-1, 2)
            curve = (evaluate_closed_bspline(ctrl, 256) - lo) / span * cell + [k * cell, 0]
            cv2.fillPoly(row, [np.round(curve * 4).astype(np.int32)], 0, cv2.LINE_AA, shift=2)
            if fps:
                cv2.putText(row, f"{t / fps:.1f} s", (k * cell + 4, cell - 5),
                            cv2.FONT_HERSHEY_SIMPLEX, 0.35, 110, 1, cv2.LINE_AA)  # fmt: skip
        rows.append(row)
    if fps and not heading:
        span = min(frames * step, max(len(c) for c in sequences)) / fps
        which = "every frame" if step == 1 else f"every {ordinal(step)} frame"
        heading = f"{which} ({step / fps:.2g} s apart) of the first {span:.3g} s"
    head_h = 20 if heading else 0
    label_h = 18 if titles else 0
    img = np.full((head_h + len(rows) * (cell + label_h), cell * frames), 255, np.uint8)
    if heading:
        cv2.putText(img, heading, (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.45, 0, 1, cv2.LINE_AA)
    for i, row in enumerate(rows):
        y = head_h + i * (cell + label_h)
        if i < len(titles):
            cv2.putText(img, titles[i], (4, y + 14), cv2.FONT_HERSHEY_SIMPLEX, 0.45, 0, 1)
        img[y + label_h : y + label_h + cell] = row
    path = Path(path)
    with atomic_path(path) as tmp:
        if not cv2.imwrite(str(tmp), img):
            raise OSError(f"{path}: could not write the PNG")
    return path


def contour_extrapolation(
    model: BehaviourModel | StructuredBehaviourModel,
    configs: np.ndarray,
    instants: Sequence[int],
    path: str | os.PathLike[str],
    recent: int = 8,
    ahead: int = 12,
    cell: int = 160,
    box: tuple[float, float, float, float] = (0.15, 0.15, 0.85, 0.85),
) -> Path:
    """A PNG of maximum likelihood extrapolation at selected instants (paper Fig. 7): per
    instant t, the last ``recent`` observed contours filled in greys (the lightest the
    current one, t) and the first ``ahead`` predicted frames (:meth:`BehaviourModel.predict`
    from ``configs[: t + 1]``) as red outlines; written atomically."""
    lo, span = np.asarray(box[:2]), np.asarray(box[2:]) - np.asarray(box[:2])
    img = np.full((cell, cell * len(instants), 3), 255, np.uint8)

    def curve(c: np.ndarray, k: int) -> np.ndarray:
        pts = (evaluate_closed_bspline(c.reshape(-1, 2), 256) - lo) / span * cell + [k * cell, 0]
        return np.round(pts * 4).astype(np.int32)

    for k, t in enumerate(instants):
        if not 1 <= t < len(configs):
            raise ValueError(f"instant {t} is outside the sequence (1..{len(configs) - 1})")
        pred = model.predict(configs[: t + 1], ahead / model.fps)[t + 1 : t + 1 + ahead]
        past = configs[max(0, t - recent + 1) : t + 1]
        for i, c in enumerate(past):  # oldest darkest
            grey = int(200 * (i + 1) / len(past))
            cv2.fillPoly(img, [curve(c, k)], (grey, grey, grey), cv2.LINE_AA, shift=2)
        for c in pred:
            cv2.polylines(img, [curve(c, k)], True, (0, 0, 220), 1, cv2.LINE_AA, shift=2)
    path = Path(path)
    with atomic_path(path) as tmp:
        if not cv2.imwrite(str(tmp), img):
            raise OSError(f"{path}: could not write the PNG")
    return path


# ------------------------------------------------------------------ evaluation
class ContourPixels:
    """A contour predictor measured in pixels: eq. 9 on the control points, the
    configurations undone (eq. 4, then :func:`configuration_control` at ``scale``)."""

    def __init__(self, predictor: Any, model: BehaviourModel, scale: float):
        self.predictor, self.model, self.scale = predictor, model, scale

    def prepare(self, features: np.ndarray) -> Any:
        return self.predictor.prepare(features)

    def predict_configurations(self, features, prepared, frames, horizon, n_samples, rng):
        return self.predictor.predict_configurations(
            features, prepared, frames, horizon, n_samples, rng
        )

    def configuration_positions(self, configs: np.ndarray) -> np.ndarray:
        return self.model.configuration_positions(configs) * self.scale


def evaluate_contours(
    model: BehaviourModel | StructuredBehaviourModel,
    sequences: Sequence[np.ndarray],
    scale: float,
    samples: int = 50,
    horizon: float = 3.0,
    stride: int = 1,
    seed: int = 0,
    space: str = "configuration",
) -> dict[str, HorizonCurve]:
    """E_T (eq. 9) of a contour model on contour configurations (F, 2n), against a
    first-order Markov model over the same prototypes and zero velocity (and for a
    structured model, its prototype VLMM as ``vlmm`` and itself as ``structured``).

    ``space``: ``"configuration"`` (C in [0, 1]^2n scaled by eq. 4, as
    :class:`~markovmotion.evaluate.vlmm.ConfigurationSpace`) or ``"pixels"`` (mean
    control-point distance, :class:`ContourPixels`).
    """
    if space not in ("configuration", "pixels"):
        raise ValueError(f"space must be configuration or pixels, got {space!r}")
    base = model.prototype_model_ if isinstance(model, StructuredBehaviourModel) else model
    feats = base.observe(sequences)
    predictors: dict[str, Any] = {
        "vlmm": base,
        "first_order": base.with_vlmm(*FIRST_ORDER),
        "zero_velocity": ZeroVelocity(base),
    }
    if model is not base:
        predictors["structured"] = model
    frames = int(round(horizon * base.fps))
    curves = {}
    for name, p in predictors.items():
        measured = (
            ConfigurationSpace(p) if space == "configuration" else ContourPixels(p, base, scale)
        )
        curves[name] = evaluate_horizon(
            measured, feats, frames, base.fps, samples, stride, seed=seed, name=name
        )
    return curves


# ------------------------------------------------------------------ training on an index
def fit_contours(
    model: BehaviourModel | StructuredBehaviourModel,
    data: str | os.PathLike[str] | None,
    cache: str | os.PathLike[str],
    category: str = "exercise",
    labels: Sequence[str] | None = None,
    hold_out: bool = True,
) -> ContourTakes:
    """Fit a ``configuration="contour"`` model (or a structured model over one) on the
    rendered and tracked takes of an index (:func:`exercise_contours`), at the video's
    frame rate.

    Records on the model ``contour_scale_`` (pixels), ``category_``, ``labels_``,
    ``held_out_files_`` and, in ``train_files_``, the INDEX.csv names of the takes.
    """
    base = model.prototype_model if isinstance(model, StructuredBehaviourModel) else model
    if base is None or not base.is_contour:
        raise ValueError("fit_contours needs a model with configuration='contour'")
    takes = exercise_contours(data, cache, category, labels, hold_out)
    base.fps = takes.train[0].fps
    model.fit(takes.configurations("train"))
    for rec, entry in zip(model.train_files_, takes.train_entries, strict=True):
        rec["file"] = entry.file
    model.contour_scale_ = takes.scale
    model.category_ = category
    model.labels_ = sorted({e.label for e in takes.train_entries})
    model.held_out_files_ = [e.file for e in takes.test_entries]
    return takes


def held_out_contours(
    model: BehaviourModel | StructuredBehaviourModel,
    data: str | os.PathLike[str] | None,
    cache: str | os.PathLike[str],
) -> tuple[list[np.ndarray], list[Entry]]:
    """Contour configurations (at the model's scale) of the takes the model held out.

    Raises:
        DataNotFoundError: the model held out no take, or the index lacks them.
    """
    from markovmotion.evaluate.takes import evaluation_index

    index = evaluation_index(model, data)  # without --test, the index it was trained on
    wanted = list(getattr(model, "held_out_files_", []))
    entries = [e for e in index.query(category=model.category_) if e.file in wanted]
    if not entries:
        raise DataNotFoundError(
            f"the contour model held out no take found in {index.root / 'INDEX.csv'}"
        )
    tracks = [contour_track(index, e, cache) for e in track(entries, "contour takes")]
    return [contour_configurations(t, model.contour_scale_) for t in tracks], entries
