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
from markovmotion.video.landmarks import LANDMARKS, MIN_VISIBILITY
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
