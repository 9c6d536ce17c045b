"""Which side is which: a front/back flip of the tracked body, told by MediaPipe's left and right.

The annealed particle filter's weighting function (silhouettes and edges) cannot tell a body
facing the camera from the same body turned round with its limbs mirrored: both cover the
same pixels. A flip is then silent (issue 24: the held-out handshake tracked front to back at
confidence 0.74-0.82). MediaPipe Pose tells left from right by the person's appearance (face,
hands, feet). :class:`SideCheck` holds its 2-D landmarks in one camera and, for a tracked
pose, compares the projected left and right shoulders and hips with MediaPipe's: the pose is
**flipped** when swapping left and right fits MediaPipe's landmarks better than keeping them,
by more than :data:`MARGIN` of the landmarks' own left-right distance.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from markovmotion.features.body_points import BODY_POINTS
from markovmotion.video.cameras import CalibratedCamera
from markovmotion.video.monocular import LANDMARKS, MIN_VISIBILITY, detect_landmarks
from markovmotion.video.render import read_frames

#: Left-right pairs compared: (body point, MediaPipe landmark) for each side.
PAIRS: tuple[tuple[str, str], ...] = (("shoulder", "shoulder"), ("hip", "hip"))
#: How much better (a share of the landmarks' left-right distance) the swapped sides must fit.
MARGIN = 0.5
#: Pairs whose landmarks lie closer than this (pixels) say nothing (seen edge on).
MIN_SEPARATION = 6.0


@dataclass
class SideCheck:
    """MediaPipe's 2-D landmarks (F, 33, 2) and visibility (F, 33) in ``camera``."""

    camera: CalibratedCamera
    pixels: np.ndarray
    visibility: np.ndarray

    @classmethod
    def from_video(
        cls, video: str | os.PathLike[str], camera: CalibratedCamera, max_frames: int | None = None
    ) -> SideCheck:
        """MediaPipe Pose over one camera's video (``scripts/install-camera``)."""
        lm = detect_landmarks(read_frames(video), max_frames)
        return cls(camera, lm.pixels, np.where(lm.found[:, None], lm.visibility, 0.0))

    def evidence(self, points: np.ndarray, frame: int) -> float | None:
        """How much better the swapped sides fit than the tracked ones, as a share of the
        landmarks' left-right distance (positive: flipped); None when MediaPipe saw no pair
        well enough in that frame. ``points``: the tracked body points (19, 3) mm."""
        if not 0 <= frame < len(self.pixels):
            return None
        same = swap = sep = 0.0
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
            same += np.linalg.norm(pl - ml) + np.linalg.norm(pr - mr)
            swap += np.linalg.norm(pl - mr) + np.linalg.norm(pr - ml)
            sep += d
        if sep == 0.0:
            return None
        return float((same - swap) / sep)

    def flipped(self, points: np.ndarray, frame: int) -> bool:
        """Whether the tracked body points (19, 3) are turned front to back in ``frame``."""
        e = self.evidence(points, frame)
        return e is not None and e > MARGIN
