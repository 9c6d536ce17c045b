"""The webcam front end: one person in one uncalibrated camera, frame by frame.

The live partner's input from a camera (the dual-HMM paper's §3 system, with
the browser's webcam for the tracked person A). Each frame goes through the
monocular front end (:mod:`markovmotion.video.monocular`): MediaPipe Pose's
33 landmarks, placed by PnP of its world landmarks onto its 2-D ones
(:func:`~markovmotion.video.monocular.place_frame`), mapped to the 19 body
points (:func:`~markovmotion.video.monocular.to_body_points`).

A webcam has no calibration, so:

* **intrinsics** are those of an ideal pinhole with the image's size and an
  assumed horizontal field of view (:data:`DEFAULT_FOV`, 60°, typical of
  laptop webcams; the page lets the user give another). An error of k % in
  the focal length is an error of k % in A's distance, which moves A along
  the camera's axis but changes neither A's pose nor the partner's answer
  (the partner reads A's body-centred pose and travel);
* **the world** is the camera's frame turned upright: X to the image's right,
  Y up, Z from the person towards the camera (the camera is assumed level);
* **depth** is the body's size as MediaPipe learnt it (PnP puts a body of that
  size where it looks that large);
* **the floor** (Y = 0) is under the lowest foot landmark seen (heel or foot
  index, visibility at least :data:`~markovmotion.video.monocular.MIN_VISIBILITY`),
  smoothed over frames; until a foot is seen, the pelvis stands
  :data:`PELVIS_HEIGHT` mm above it.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from markovmotion.video.monocular import (
    FEET,
    LANDMARKS,
    MIN_VISIBILITY,
    frame_landmarks,
    place_frame,
    pose_estimator,
    to_body_points,
)

#: Horizontal field of view (degrees) assumed for a webcam without calibration.
DEFAULT_FOV = 60.0
#: Where the pelvis stands above the floor (mm) until a foot is seen.
PELVIS_HEIGHT = 950.0
#: Weight of a new frame's floor in the running floor (an exponential average).
FLOOR_RATE = 0.2
#: Camera frame (x right, y down, z forward) to the upright world (X right, Y up, Z back).
CAMERA_TO_WORLD = np.array([1.0, -1.0, -1.0])

_FEET = [LANDMARKS.index(n) for n in FEET]
_HIPS = [LANDMARKS.index("left_hip"), LANDMARKS.index("right_hip")]


def webcam_intrinsics(width: int, height: int, fov: float = DEFAULT_FOV) -> np.ndarray:
    """(3, 3) pinhole intrinsics of a ``width`` x ``height`` image whose horizontal field of
    view is ``fov`` degrees (square pixels, principal point at the centre; OpenCV's pixel
    centres at integer coordinates)."""
    f = (width / 2.0) / math.tan(math.radians(fov) / 2.0)
    return np.array([[f, 0.0, (width - 1) / 2.0], [0.0, f, (height - 1) / 2.0], [0.0, 0.0, 1.0]])


@dataclass
class WebcamFrame:
    """One tracked frame: the 19 body points (mm, the upright world, floor at Y = 0), the 33
    landmarks' pixels (x, y) and visibility, the confidence (mean visibility) and the time
    the frame took (s)."""

    points: np.ndarray
    pixels: np.ndarray
    visibility: np.ndarray
    confidence: float
    seconds: float


class WebcamTracker:
    """The person in a webcam's frames, one RGB frame at a time (module docstring).

    MediaPipe runs in video mode (each frame's landmarks start from the last frame's), so
    one tracker follows one camera. ``fov``: the camera's horizontal field of view
    (degrees). Close it (or use it in a ``with``) to free MediaPipe's graph.

    Raises:
        MotionFormatError: MediaPipe is not installed (``scripts/install-camera``).
    """

    def __init__(self, fov: float = DEFAULT_FOV):
        self.fov = float(fov)
        self._estimator = pose_estimator()
        self._pose: tuple[np.ndarray, np.ndarray] | None = None
        self._lift: float | None = None  # added to Y so that the floor is at 0

    def track(self, rgb: np.ndarray) -> WebcamFrame | None:
        """The person in one RGB frame (H, W, 3) uint8, or None when no one is found or the
        landmarks cannot be placed."""
        t0 = time.perf_counter()
        got = frame_landmarks(self._estimator, rgb)
        if got is None:
            return None
        pixels, world, visibility = got
        k = webcam_intrinsics(rgb.shape[1], rgb.shape[0], self.fov)
        placed = place_frame(world, pixels, visibility, k, self._pose)
        if placed is None:
            self._pose = None
            return None
        cam, self._pose = placed
        pts = cam * CAMERA_TO_WORLD
        feet = [f for f in _FEET if visibility[f] >= MIN_VISIBILITY]
        if feet:
            lift = -float(pts[feet, 1].min())
            self._lift = (
                lift if self._lift is None else self._lift + FLOOR_RATE * (lift - self._lift)
            )
        elif self._lift is None:
            return self._finish(pts, pixels, visibility, t0, PELVIS_HEIGHT - pts[_HIPS, 1].mean())
        return self._finish(pts, pixels, visibility, t0, self._lift)

    def _finish(
        self, pts: np.ndarray, pixels: np.ndarray, vis: np.ndarray, t0: float, lift: float
    ) -> WebcamFrame:
        body = to_body_points(pts)
        body[:, 1] += lift
        return WebcamFrame(body, pixels, vis, float(vis.mean()), time.perf_counter() - t0)

    def close(self) -> None:
        self._estimator.close()

    def __enter__(self) -> WebcamTracker:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
