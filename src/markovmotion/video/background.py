"""The empty scene behind a person, and a check of whether a median background still holds them.

The annealed particle filter's foreground is the difference to a background
(:mod:`~markovmotion.video.annealed_particle_filter`). Without an image of the
empty scene it takes the per-pixel median of frames spread over the video,
which is the scene only where the person covers a pixel in fewer than half of
them: a person who barely moves stays in it (a "ghost"), and the tracker sees
no foreground where they stand.

Given where the person is in each sampled frame (a mask per frame, here drawn
from MediaPipe Pose's 2-D landmarks: :func:`person_masks`), :func:`check_background`
says how much of the person the plain median still holds (the share of their
mean silhouette covered in more than half of the frames) and how much of it is
never seen empty (covered in every frame); :func:`person_background` learns the
background where the person is not: the per-pixel median over the frames in
which the pixel is uncovered (the plain median where it never is).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import cv2
import numpy as np

from markovmotion.video.landmarks import LANDMARKS, MIN_VISIBILITY

if TYPE_CHECKING:
    from markovmotion.video.cameras import CalibratedCamera

#: Limbs drawn as thick lines for a person's mask: pairs of landmark names.
_LIMBS = tuple(
    (f"{s}_{a}", f"{s}_{b}")
    for s in ("left", "right")
    for a, b in (
        ("shoulder", "elbow"),
        ("elbow", "wrist"),
        ("hip", "knee"),
        ("knee", "ankle"),
        ("ankle", "heel"),
        ("heel", "foot_index"),
        ("ankle", "foot_index"),
    )
)
_TORSO = ("left_shoulder", "right_shoulder", "right_hip", "left_hip")
#: Share of the person's mean silhouette the plain median may hold before it is reported.
HELD_LIMIT = 0.2


def person_masks(
    pixels: np.ndarray, visibility: np.ndarray, shape: tuple[int, int], margin: float = 0.25
) -> np.ndarray:
    """(F, H, W) bool: the person of each frame, drawn from (F, 33, 2) landmark pixels: torso
    polygon, limbs and head as lines and discs ``margin`` times the torso's height thick (a
    generous outline: better too much person than a ghost left in the background)."""
    h, w = shape
    idx = {n: i for i, n in enumerate(LANDMARKS)}
    out = np.zeros((len(pixels), h, w), dtype=bool)
    for f in range(len(pixels)):
        p, seen = pixels[f], visibility[f] >= MIN_VISIBILITY * 0.5
        if not np.isfinite(p).all() or seen.sum() < 4:
            continue
        torso = p[[idx[n] for n in _TORSO]]
        size = np.linalg.norm(torso[:2].mean(0) - torso[2:].mean(0))
        thick = max(3, int(round(margin * size)))
        img = np.zeros((h, w), np.uint8)
        cv2.fillConvexPoly(img, np.round(torso).astype(np.int32), 1)
        for a, b in _LIMBS + tuple(zip(_TORSO, _TORSO[1:] + _TORSO[:1], strict=True)):
            pa, pb = np.round(p[idx[a]]).astype(int), np.round(p[idx[b]]).astype(int)
            cv2.line(img, tuple(pa.tolist()), tuple(pb.tolist()), 1, thick)
        head = p[: idx["mouth_right"] + 1]
        centre = np.round(head.mean(0)).astype(int)
        radius = int(round(max(np.ptp(head, axis=0).max(), 0.35 * size)))
        cv2.circle(img, tuple(centre.tolist()), radius, 1, -1)
        out[f] = img.astype(bool)
    return out


@dataclass(frozen=True)
class BackgroundCheck:
    """How much of the person's mean silhouette the plain median holds (``held``, covered in
    more than half the frames) and never sees empty (``unseen``, covered in every frame)."""

    held: float
    unseen: float
    person_area: float

    @property
    def holds_person(self) -> bool:
        return self.held > HELD_LIMIT

    def message(self, camera: str) -> str:
        """One line for the user."""
        if not self.holds_person:
            return f"{camera}: the median background is the empty scene (holds {self.held:.0%})"
        return (
            f"{camera}: the median background still holds the person (an area of "
            f"{self.held:.0%} of their mean silhouette; {self.unseen:.0%} never uncovered): "
            "give an empty-scene image "
            "('background' in cameras.json)"
        )


def background_note(
    cameras: Sequence[tuple[str, BackgroundCheck | None]], why: str = ""
) -> list[str]:
    """The note on the backgrounds of the cameras without an empty-scene image, as one line
    naming them (none without such cameras; it had been a line per camera, four on the real
    video): ``cameras`` holds each one's name and its :class:`BackgroundCheck` of the plain
    median (its background then learnt where the person is not), or None for the plain
    median, not checked (``why``: the reason said, such as MediaPipe not installed)."""
    plain = [name for name, check in cameras if check is None]
    learnt = [(name, check) for name, check in cameras if check is not None]
    parts = []
    if plain:
        parts.append(
            f"{', '.join(plain)}: median background (no empty-scene image), not checked for "
            f"the person{f' ({why})' if why else ''}"
        )
    if learnt:
        parts.append(
            f"{', '.join(name for name, _ in learnt)}: no empty-scene image, so the background "
            "is the median where MediaPipe finds no person"
        )
    if held := [(name, c) for name, c in learnt if c.holds_person]:
        shares = [f"{n} ({c.held:.0%}; {c.unseen:.0%})" for n, c in held]  # the first in words
        n, c = held[0]
        shares[0] = f"{n} ({c.held:.0%} of their mean silhouette; {c.unseen:.0%} never uncovered)"
        parts.append(
            f"the plain median still holds the person in {', '.join(shares)}: give an "
            "empty-scene image ('background' in cameras.json)"
        )
    if empty := [f"{n} (holds {c.held:.0%})" for n, c in learnt if not c.holds_person]:
        parts.append(f"the plain median is the empty scene in {', '.join(empty)}")
    return [f"note: {'; '.join(parts)}"] if parts else []


def check_background(masks: np.ndarray) -> BackgroundCheck:
    """:class:`BackgroundCheck` of the person masks (F, H, W) of the frames a median is over."""
    area = float(masks.sum(axis=(1, 2)).mean())
    if area <= 0:
        return BackgroundCheck(0.0, 0.0, 0.0)
    share = masks.mean(axis=0)
    return BackgroundCheck(
        float((share > 0.5).sum() / area), float((share >= 1.0).sum() / area), area
    )


#: Rows of the frames taken at once by :func:`person_background` (memory: frames x rows x
#: width x 3 x 4 bytes, 50 MB for 31 frames of 1920 pixels).
MEDIAN_ROWS = 64


def person_background(frames: Sequence[np.ndarray], masks: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8: per pixel, the median of the frames in which the person does not cover
    it (``masks`` (N, H, W)); the plain median where they always do.

    Band by band of :data:`MEDIAN_ROWS` rows, each pixel's values sorted with the covered ones
    last, the median read at the middle of the uncovered ones: NumPy's ``nanmedian`` over the
    whole stack took about 15 s and 1 GB a camera at 1088x1920 (a new user's trial)."""
    stack = np.stack(frames)
    out = np.empty(stack.shape[1:], dtype=np.uint8)
    for r in range(0, stack.shape[1], MEDIAN_ROWS):
        band = stack[:, r : r + MEDIAN_ROWS].astype(np.float32)
        hidden = np.broadcast_to(masks[:, r : r + MEDIAN_ROWS, :, None], band.shape)
        seen = (~hidden).sum(axis=0)  # (rows, W, 3)
        ordered = np.sort(np.where(hidden, np.inf, band), axis=0)
        lo = np.take_along_axis(ordered, np.maximum(seen - 1, 0)[None] // 2, axis=0)[0]
        hi = np.take_along_axis(ordered, (seen // 2)[None].clip(max=len(band) - 1), axis=0)[0]
        clean = np.where(seen > 0, 0.5 * (lo + hi), np.median(band, axis=0))
        out[r : r + MEDIAN_ROWS] = np.round(clean).astype(np.uint8)
    return out


def learn_background(
    video: str | os.PathLike[str],
    frames: int = 31,
    camera: CalibratedCamera | None = None,
) -> tuple[np.ndarray, np.ndarray, BackgroundCheck]:
    """The plain median of up to ``frames`` frames spread over ``video`` (``camera``'s:
    undistorted), the background learnt where MediaPipe Pose finds no person
    (:func:`person_background`), and the check of the plain median (:func:`check_background`)."""
    from markovmotion.video.monocular import detect_landmarks
    from markovmotion.video.render import spread_frames

    stack = spread_frames(video, frames, camera)
    lm = detect_landmarks(stack)
    masks = person_masks(lm.pixels, lm.visibility, stack[0].shape[:2])
    plain = np.median(np.stack(stack), axis=0).astype(np.uint8)
    return plain, person_background(stack, masks), check_background(masks)
