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
import os
import time
from collections import deque
from dataclasses import dataclass

import numpy as np

from markovmotion.features.body_points import bone_lengths, with_bone_lengths
from markovmotion.video.left_right import OnlineSides
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

#: Frames over which each body segment's median length is taken.
BONE_MEMORY = 300

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


#: MediaPipe graphs a tracker runs, each on every ``graphs``-th frame: two on two cores. One
#: graph's frame takes about 30 ms of one core and MediaPipe lets go of the GIL while it runs:
#: on the real video's camera 0, two graphs in two threads answered 35-50 frames/s against
#: 22-32 for one (2 cores shared with other jobs, load average 2.1-2.9), and tracking every
#: other frame left the landmarks as close to the reference (docs/web.md, the camera partner).
DEFAULT_GRAPHS = min(2, os.cpu_count() or 1)


@dataclass
class FoundLandmarks:
    """MediaPipe's answer for one frame (:meth:`WebcamTracker.landmarks`): the 33 landmarks'
    pixels (x, y), world points (mm, hip-centred) and visibility, the image's (width, height)
    and when the frame's tracking started (``time.perf_counter``)."""

    pixels: np.ndarray
    world: np.ndarray
    visibility: np.ndarray
    size: tuple[int, int]
    started: float


class WebcamTracker:
    """The person in a webcam's frames, one RGB frame at a time (module docstring).

    MediaPipe runs in video mode (each frame's landmarks start from the last frame's), so
    one tracker follows one camera. ``fov``: the camera's horizontal field of view
    (degrees). ``graphs``: MediaPipe graphs, frame ``n`` going to graph ``n % graphs``
    (:data:`DEFAULT_GRAPHS`). ``left_right``: ``"online"`` relabels MediaPipe's left and
    right where they jump between frames, causally
    (:class:`~markovmotion.video.left_right.OnlineSides`; on the real video's four cameras
    it gives what the offline decoder gives), ``"mediapipe"`` keeps its labels. :meth:`track` runs a frame from start to end; a pipeline
    (:mod:`markovmotion.web.camera`) runs :meth:`landmarks` of several frames at once, each
    graph's frames in order, and :meth:`place` of every frame in order. Close it (or use it
    in a ``with``) to free MediaPipe's graphs.

    Raises:
        MotionFormatError: MediaPipe is not installed (``scripts/install-camera``).
    """

    def __init__(
        self, fov: float = DEFAULT_FOV, graphs: int = DEFAULT_GRAPHS, left_right: str = "online"
    ):
        if graphs < 1:
            raise ValueError(f"graphs: at least 1, not {graphs}")
        if left_right not in ("online", "mediapipe"):
            raise ValueError(f"left_right: online or mediapipe, not {left_right!r}")
        self.fov = float(fov)
        self._sides = OnlineSides() if left_right == "online" else None
        self._estimators = []
        try:
            for _ in range(graphs):
                self._estimators.append(pose_estimator())
        except BaseException:
            self.close()
            raise
        self._pose: tuple[np.ndarray, np.ndarray] | None = None
        self._lift: float | None = None  # added to Y so that the floor is at 0
        self._frames = 0
        self._bones: deque[np.ndarray] = deque(maxlen=BONE_MEMORY)

    @property
    def graphs(self) -> int:
        """MediaPipe graphs: frames whose :meth:`landmarks` may run at once."""
        return len(self._estimators)

    def landmarks(self, rgb: np.ndarray, graph: int = 0) -> FoundLandmarks | None:
        """MediaPipe's landmarks of one RGB frame (H, W, 3) uint8 on graph ``graph``, or None
        when no one is found. Graphs run in parallel (MediaPipe lets go of the GIL); one
        graph must be given its frames one at a time and in order."""
        t0 = time.perf_counter()
        got = frame_landmarks(self._estimators[graph], rgb)
        if got is None:
            return None
        return FoundLandmarks(*got, (rgb.shape[1], rgb.shape[0]), t0)

    def place(self, found: FoundLandmarks | None) -> WebcamFrame | None:
        """A frame's landmarks placed in the upright world (module docstring), or None when
        none were found or they cannot be placed; frames must come in order."""
        if found is None:
            if self._sides is not None:
                self._sides.gap()
            return None
        pixels, world, visibility = found.pixels, found.world, found.visibility
        if self._sides is not None:
            pixels, world, visibility, _ = self._sides.step(pixels, world, visibility)
        k = webcam_intrinsics(*found.size, self.fov)
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
            lift = PELVIS_HEIGHT - pts[_HIPS, 1].mean()
            return self._finish(pts, pixels, visibility, found.started, lift)
        return self._finish(pts, pixels, visibility, found.started, self._lift)

    def track(self, rgb: np.ndarray) -> WebcamFrame | None:
        """The person in one RGB frame (H, W, 3) uint8 (the graphs taking the frames in
        turn), or None when no one is found or the landmarks cannot be placed."""
        graph = self._frames % self.graphs
        self._frames += 1
        return self.place(self.landmarks(rgb, graph))

    def _finish(
        self, pts: np.ndarray, pixels: np.ndarray, vis: np.ndarray, t0: float, lift: float
    ) -> WebcamFrame:
        body = to_body_points(pts)
        body[:, 1] += lift
        # each segment at its median length over the last BONE_MEMORY frames (a person's
        # bones do not change; MediaPipe's do, frame to frame)
        self._bones.append(bone_lengths(body[None]))
        lengths = np.r_[np.nan, np.median(np.array(self._bones)[:, 1:], axis=0)]  # 0: pelvis
        body = with_bone_lengths(body[None], lengths)[0]
        return WebcamFrame(body, pixels, vis, float(vis.mean()), time.perf_counter() - t0)

    def close(self) -> None:
        for est in self._estimators:
            est.close()
        self._estimators = []

    def __enter__(self) -> WebcamTracker:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
