"""Which side is which: a front/back flip of the tracked body, told by MediaPipe's left and right.

The annealed particle filter's weighting function (silhouettes and edges) cannot tell a body
facing the camera from the same body turned round with its limbs mirrored: both cover the
same pixels. A flip is then silent (issue 24: the held-out handshake tracked front to back at
confidence 0.74-0.82). MediaPipe Pose tells left from right by the person's appearance (face,
hands, feet). :class:`SideCheck` holds its 2-D landmarks in the cameras and, for a tracked
pose, compares the projected left and right shoulders and hips with MediaPipe's: the pose is
**flipped** when swapping left and right fits MediaPipe's landmarks better than keeping them,
by more than :data:`MARGIN` of the landmarks' own left-right distance, pooled over the
cameras. On the real 4-view video, MediaPipe alone in camera 1 (a second person stands
behind the man) swaps the sides in 47 of 100 frames of a track the other three cameras find
right way round: one camera is not enough.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from markovmotion.features.body_points import BODY_POINTS
from markovmotion.video.cameras import CalibratedCamera
from markovmotion.video.monocular import LANDMARKS, MIN_VISIBILITY
from markovmotion.video.triangulation import ViewLandmarks

#: Left-right pairs compared: (body point, MediaPipe landmark) for each side.
PAIRS: tuple[tuple[str, str], ...] = (("shoulder", "shoulder"), ("hip", "hip"))
#: How much better (a share of the landmarks' left-right distance) the swapped sides must fit.
MARGIN = 0.5
#: Pairs whose landmarks lie closer than this (pixels) say nothing (seen edge on).
MIN_SEPARATION = 6.0


@dataclass
class SideView:
    """MediaPipe's 2-D landmarks (F, 33, 2) and visibility (F, 33) in one ``camera``."""

    camera: CalibratedCamera
    pixels: np.ndarray
    visibility: np.ndarray

    def distances(self, points: np.ndarray, frame: int) -> tuple[float, float, float]:
        """Pixel distances of the tracked left and right shoulders and hips (``points``, the
        body points (19, 3) mm) to MediaPipe's same sides and to its other sides, and the
        landmarks' left-right distance, summed over the pairs seen well in ``frame``."""
        same = swap = sep = 0.0
        if not 0 <= frame < len(self.pixels):
            return same, swap, sep
        for point, landmark in PAIRS:
            lm = [LANDMARKS.index(f"{s}_{landmark}") for s in ("left", "right")]
            if (self.visibility[frame, lm] < MIN_VISIBILITY).any():
                continue
            ml, mr = self.pixels[frame, lm]
            d = float(np.linalg.norm(ml - mr))
            if d < MIN_SEPARATION:
                continue
            bp = [BODY_POINTS.index(f"{s}_{point}") for s in ("left", "right")]
            (pl, pr), _ = self.camera.project(points[bp])
            same += float(np.linalg.norm(pl - ml) + np.linalg.norm(pr - mr))
            swap += float(np.linalg.norm(pl - mr) + np.linalg.norm(pr - ml))
            sep += d
        return same, swap, sep


@dataclass
class SideCheck:
    """MediaPipe's left and right in one or more cameras (:class:`SideView`), pooled: one
    camera whose MediaPipe confuses the sides (another person behind, a view edge on) is
    outweighed by the others."""

    views: list[SideView]

    @classmethod
    def from_landmarks(cls, views: ViewLandmarks) -> SideCheck:
        """The check of MediaPipe's landmarks already found in every camera (the detection
        the guide of :mod:`~markovmotion.video.triangulation` uses too: run once)."""
        return cls(
            [
                SideView(camera, views.pixels[k], views.visibility[k])
                for k, camera in enumerate(views.cameras)
            ]
        )

    @classmethod
    def from_videos(
        cls,
        videos: list[str | os.PathLike[str]],
        cameras: list[CalibratedCamera],
        max_frames: int | None = None,
    ) -> SideCheck:
        """MediaPipe Pose over each camera's video (``scripts/install-camera``)."""
        return cls.from_landmarks(ViewLandmarks.from_videos(videos, cameras, max_frames))

    def evidence(self, points: np.ndarray, frame: int) -> float | None:
        """How much better the swapped sides fit than the tracked ones, summed over the views
        and divided by the landmarks' left-right distances (positive: flipped); None when no
        view saw a pair well enough in that frame."""
        same, swap, sep = (
            sum(v) for v in zip(*(w.distances(points, frame) for w in self.views), strict=True)
        )
        if sep == 0.0:
            return None
        return float((same - swap) / sep)

    def flipped(self, points: np.ndarray, frame: int) -> bool:
        """Whether the tracked body points (19, 3) are turned front to back in ``frame``."""
        e = self.evidence(points, frame)
        return e is not None and e > MARGIN


# -- one camera's own left and right, made consistent over the video ---------------------------

#: Left-right landmark groups relabelled together (MediaPipe's partial swaps: one limb
#: segment at a time), each decoded on its own.
SIDE_GROUPS: tuple[tuple[str, ...], ...] = (
    ("eye_inner", "eye", "eye_outer", "ear", "mouth", "shoulder"),
    ("elbow",),
    ("wrist", "pinky", "index", "thumb"),
    ("hip",),
    ("knee",),
    ("ankle", "heel", "foot_index"),
)
#: Cost of a change of labelling between two frames, in torso lengths of 2-D motion: a pair
#: of landmarks must jump across at least a quarter torso (each of the two moving it) before
#: relabelling it is worth a switch; closer pairs hardly matter to the body's placement.
SWITCH_COST = 0.5
#: Cost per frame of the swapped labelling (torso lengths): the tie-break that keeps
#: MediaPipe's own labels wherever continuity does not decide, and, of the two labellings
#: that continuity cannot tell apart (all flipped), the one that swaps fewer frames.
SWAPPED_COST = 0.01
#: Each group's parent (an index into :data:`SIDE_GROUPS`, decoded first), whose same side
#: a group's landmarks should lie nearer to in MediaPipe's 3-D world points.
PARENTS: tuple[int | None, ...] = (None, 0, 1, 0, 3, 4)
#: Cost per frame (torso lengths) of a labelling whose landmarks lie nearer the parent's
#: other side, at full evidence (the distances' difference at least the parent's width).
ATTACH_COST = 0.1


def _pairs(stem: str) -> tuple[int, int]:
    names = ("mouth_left", "mouth_right") if stem == "mouth" else (f"left_{stem}", f"right_{stem}")
    return LANDMARKS.index(names[0]), LANDMARKS.index(names[1])


def continuity_costs(
    pixels: np.ndarray, visibility: np.ndarray, pairs: list[tuple[int, int]]
) -> np.ndarray:
    """(F, 2) cost of frame t's labelling relative to frame t-1's: column 0 the same
    labelling, column 1 the other one; the landmarks' 2-D motion (pixels, weighted by both
    frames' visibility) in torso lengths (median shoulder-to-hip distance). Row 0 and rows
    next to a frame without a person are 0 (no continuity across a gap)."""
    li, ri = (np.array(x) for x in zip(*pairs, strict=True))
    sh = [LANDMARKS.index(f"{s}_shoulder") for s in ("left", "right")]
    hp = [LANDMARKS.index(f"{s}_hip") for s in ("left", "right")]
    torso = np.linalg.norm(pixels[:, sh].mean(1) - pixels[:, hp].mean(1), axis=1)
    scale = float(np.nanmedian(torso)) if np.isfinite(torso).any() else 1.0
    out = np.zeros((len(pixels), 2))
    for t in range(1, len(pixels)):
        a, b = pixels[t - 1], pixels[t]
        w = np.minimum(visibility[t - 1], visibility[t])
        same = w[li] * np.linalg.norm(b[li] - a[li], axis=1) + w[ri] * np.linalg.norm(
            b[ri] - a[ri], axis=1
        )
        swap = w[li] * np.linalg.norm(b[li] - a[ri], axis=1) + w[ri] * np.linalg.norm(
            b[ri] - a[li], axis=1
        )
        if np.isfinite(same).all() and np.isfinite(swap).all():
            out[t] = same.sum() / max(scale, 1e-9), swap.sum() / max(scale, 1e-9)
    return out


def labelling_cost(labels: np.ndarray, continuity: np.ndarray) -> float:
    """Total cost of a labelling (F,) (0 kept, 1 swapped) given :func:`continuity_costs`."""
    labels = np.asarray(labels, dtype=int)
    change = labels[1:] != labels[:-1]
    return float(
        continuity[1:][np.arange(len(change)), change.astype(int)].sum()
        + SWITCH_COST * change.sum()
        + SWAPPED_COST * labels.sum()
    )


def attachment_costs(world: np.ndarray, pairs, parent) -> np.ndarray:
    """(F, 2) cost of keeping or swapping a group's pairs (3-D world points (F, 33, 3))
    given its parent's pairs as labelled: :data:`ATTACH_COST` times how much nearer each
    landmark lies to the parent's other side than to its own, over the parent's width,
    clipped to [0, 1]."""
    (li, ri), (pl, pr) = pairs[0], parent[0]
    own = np.linalg.norm(world[:, li] - world[:, pl], axis=1) + np.linalg.norm(
        world[:, ri] - world[:, pr], axis=1
    )
    other = np.linalg.norm(world[:, li] - world[:, pr], axis=1) + np.linalg.norm(
        world[:, ri] - world[:, pl], axis=1
    )
    width = np.linalg.norm(world[:, pl] - world[:, pr], axis=1)
    e = np.nan_to_num(np.clip((other - own) / np.maximum(width, 1e-9), -1.0, 1.0))
    return ATTACH_COST * np.c_[np.maximum(-e, 0.0), np.maximum(e, 0.0)]


def decode_labels(continuity: np.ndarray, unary: np.ndarray | None = None) -> np.ndarray:
    """The labelling (F,) of least :func:`labelling_cost`, by Viterbi over the pairs of
    consecutive labels: the state at t is (label t-1, label t), so the cost that depends on
    both is a per-state cost and the transitions ((a, b) to (b, c)) are fixed (Rabiner
    eqs. 32-35 in log space, :func:`~markovmotion.algorithms.hmm_recursions.viterbi`)."""
    from markovmotion.algorithms.hmm_recursions import viterbi

    n = len(continuity)
    prev, cur = np.array([0, 0, 1, 1]), np.array([0, 1, 0, 1])
    change = (prev != cur).astype(int)
    cost = continuity[:, change] + SWITCH_COST * change + SWAPPED_COST * cur
    cost[0] = SWAPPED_COST * cur
    if unary is not None:
        cost += unary[:, cur]
    start = np.where(change == 0, 0.0, -np.inf)
    trans = np.where(cur[:, None] == prev[None, :], 0.0, -np.inf)
    path, _ = viterbi(start, trans, -cost)
    return cur[path][:n]


def consistent_sides(
    pixels: np.ndarray, world: np.ndarray, visibility: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One camera's MediaPipe landmarks (F, 33, 2) pixels, (F, 33, 3) world points and
    (F, 33) visibility with left and right made consistent over the whole video, each of
    :data:`SIDE_GROUPS` relabelled by :func:`decode_labels` (offline: it needs every frame),
    and (F, len(SIDE_GROUPS)) which groups were swapped back. A second person behind the
    one tracked makes MediaPipe swap his sides for tens of frames, sometimes only some limbs
    (issue 24, camera 1 of the real video): each swap is a jump in 2-D that continuity sees."""
    pixels, world, visibility = pixels.copy(), world.copy(), visibility.copy()
    swapped = np.zeros((len(pixels), len(SIDE_GROUPS)), dtype=bool)
    for g, stems in enumerate(SIDE_GROUPS):
        pairs = [_pairs(s) for s in stems]
        up = PARENTS[g]
        unary = (
            None
            if up is None
            else attachment_costs(world, pairs, [_pairs(x) for x in SIDE_GROUPS[up]])
        )
        labels = decode_labels(continuity_costs(pixels, visibility, pairs), unary).astype(bool)
        swapped[:, g] = labels
        li, ri = (list(x) for x in zip(*pairs, strict=True))
        rows = np.nonzero(labels)[0]
        for arr in (pixels, world, visibility):
            arr[np.ix_(rows, li + ri)] = arr[np.ix_(rows, ri + li)]
    return pixels, world, visibility, swapped
