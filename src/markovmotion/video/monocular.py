"""Monocular 3-D tracking of one person in one calibrated camera: MediaPipe Pose placed by PnP.

The webcam case of the dual-HMM paper's tracker (§3 tracks person A before
the partner answers): one camera, no background, no body model. Per frame:

1. **Landmarks.** MediaPipe Pose (``mediapipe==0.10.21``, the optional extra
   installed by ``scripts/install-camera``; its bundled *full* landmark model, which runs offline) gives
   33 landmarks: 2-D in the image (normalised, with a visibility) and 3-D
   *world* landmarks in metres, centred between the hips, with the body's
   size learnt by the network (not measured).
2. **Body points and markers.** The 33 landmarks map to the project's 19 body
   points (:data:`~markovmotion.features.body_points.BODY_POINTS`) by one
   fixed weight matrix (:data:`LANDMARK_WEIGHTS`): shoulders, elbows, wrists,
   hips, knees and ankles are landmarks; the pelvis and neck are the middles
   of the hips and shoulders; the spine and chest lie a third and two thirds
   of the way from pelvis to neck; the head is the middle of the ears; the
   toe is the foot index. The VLMM paper's 13 markers
   (:data:`~markovmotion.features.body_points.MARKER_POINTS`) are a subset,
   written with the marker names the partner models read
   (:func:`monocular_markers`).
3. **Placement (depth).** The world landmarks are hip-centred: where the
   body stands is unknown. It is the rigid pose ``(R, t)`` that projects the
   world landmarks (mm) onto the 2-D landmarks through the camera's
   intrinsics ``K``: the perspective-n-point problem, solved by
   ``cv2.solvePnP`` (SQPnP, then Levenberg-Marquardt from the previous
   frame's pose) over the landmarks seen with visibility above
   :data:`MIN_VISIBILITY`. Depth is thus resolved by the body's *size*: a
   body of the network's size appears that large at that distance, so an
   error of k % in size is an error of k % in distance along the ray.
4. **Size (scale).** A calibrated camera knows the floor (world ``Y = 0``).
   Scaling the body about the camera centre ``C`` by ``s`` leaves the image
   unchanged, so ``s`` is free; it is chosen so that the lowest foot landmark
   (heel or foot index) rests on the floor: per frame
   ``s_t = (floor - C_y) / (y_t - C_y)`` and the video's scale is the median
   over frames (the person's global size, estimated from the video). A given
   ``stature`` (mm, from the top of the head to the floor) replaces it.

:func:`track_monocular` returns the body points (F, 19, 3) in the world's mm,
per-frame confidence (mean landmark visibility) and timing.
:func:`reference_errors` measures them against a 3-D reference (as the
triangulated MediaPipe keypoints beside the real 4-view video), per joint,
after the rigid alignment of each frame (Kabsch, no scale) and without it.
"""

from __future__ import annotations

import csv
import itertools
import os
import sys
import tempfile
import threading
import time
import warnings
from collections.abc import Iterable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from markovmotion.core.markers import Markers
from markovmotion.errors import MotionFormatError
from markovmotion.features.body_points import (
    BODY_POINTS,
    MARKER_POINTS,
    bone_lengths,
    with_bone_lengths,
)
from markovmotion.progress import track
from markovmotion.video.cameras import CalibratedCamera, lone_video
from markovmotion.video.landmarks import LANDMARKS, MIN_VISIBILITY
from markovmotion.video.left_right import OnlineSides, consistent_sides
from markovmotion.video.render import expected_frames, header_shortfall, read_frames

#: The release whose bundled pose models load offline (the 1.x releases ship none).
MEDIAPIPE_VERSION = "0.10.21"
#: How left and right are labelled (:func:`track_monocular`).
LEFT_RIGHT: tuple[str, ...] = ("mediapipe", "continuity", "facing", "online")
#: Fewest landmarks that place a body (solvePnP needs at least 4; fewer is a guess).
MIN_LANDMARKS = 6
#: The foot landmarks whose lowest rests on the floor.
FEET = ("left_heel", "right_heel", "left_foot_index", "right_foot_index")
#: Height of the top of the head above the middle of the ears (mm), for a given stature.
HEAD_TOP_MM = 120.0


def _weights() -> np.ndarray:
    """(19, 33) rows of landmark weights, one per body point (see the module's docstring)."""
    idx = {n: i for i, n in enumerate(LANDMARKS)}
    mid = {
        "pelvis": {"left_hip": 0.5, "right_hip": 0.5},
        "neck": {"left_shoulder": 0.5, "right_shoulder": 0.5},
        "head": {"left_ear": 0.5, "right_ear": 0.5},
    }
    mid["spine"] = {
        k: v * w for part, w in (("pelvis", 2 / 3), ("neck", 1 / 3)) for k, v in mid[part].items()
    }
    mid["chest"] = {
        k: v * w for part, w in (("pelvis", 1 / 3), ("neck", 2 / 3)) for k, v in mid[part].items()
    }
    out = np.zeros((len(BODY_POINTS), len(LANDMARKS)))
    for p, point in enumerate(BODY_POINTS):
        if point in mid:
            for name, w in mid[point].items():
                out[p, idx[name]] += w
        else:
            out[p, idx[point.replace("_toe", "_foot_index")]] = 1.0
    return out


#: (19, 33): body points = LANDMARK_WEIGHTS @ landmarks (every row sums to 1).
LANDMARK_WEIGHTS: np.ndarray = _weights()


def to_body_points(landmarks: np.ndarray) -> np.ndarray:
    """(..., 19, 3) body points of (..., 33, 3) MediaPipe landmarks."""
    return np.einsum("pl,...lc->...pc", LANDMARK_WEIGHTS, landmarks)


#: MediaPipe's start-up lines (its C++ logging, at the graph's creation and its first found
#: person): benign, and held back by :func:`native_start_up_lines_held`.
START_UP_LINES = (
    "Created TensorFlow Lite XNNPACK delegate",
    "All log messages before absl::InitializeLog",
    "inference_feedback_manager.cc",
    "landmark_projection_calculator.cc",
    "gl_context",
    "GPU suport",
)
_STDERR_HELD = threading.Lock()


@contextmanager
def native_start_up_lines_held() -> Iterator[None]:
    """Hold what is written to file descriptor 2 in the block, then pass on every line except
    MediaPipe's start-up lines (:data:`START_UP_LINES`).

    Written here because nothing else reaches those lines: MediaPipe's C++ logging (absl)
    writes them to the descriptor directly, and neither Python's logging nor the
    environment variables ``GLOG_minloglevel`` / ``TF_CPP_MIN_LOG_LEVEL`` silence them
    (google-ai-edge/mediapipe#5737). One block at a time in the process (a lock), so two
    graphs started in two threads cannot leave the descriptor pointing at the wrong file.
    Nothing else is lost: other lines written meanwhile, Python's too, come out after it."""
    with _STDERR_HELD, tempfile.TemporaryFile() as held:
        sys.stderr.flush()
        saved = os.dup(2)
        os.dup2(held.fileno(), 2)
        try:
            yield
        finally:
            sys.stderr.flush()
            os.dup2(saved, 2)
            os.close(saved)
            held.seek(0)
            for line in held.read().decode("utf-8", "replace").splitlines(keepends=True):
                if not any(known in line for known in START_UP_LINES):
                    sys.stderr.write(line)
            sys.stderr.flush()


class QuietPose:
    """MediaPipe Pose whose start-up lines are held back (:func:`native_start_up_lines_held`):
    at its creation, and in each frame until it has found a person the first time (the last
    start-up line is written then). Afterwards frames go straight through."""

    def __init__(self, make):
        with native_start_up_lines_held():
            self._pose = make()
            # the graph opens its models in its own threads after make() returns, and
            # TensorFlow Lite says so then: one blank frame waits for them, inside the block
            self._pose.process(np.zeros((64, 64, 3), dtype=np.uint8))
        self._starting = True

    def process(self, rgb: np.ndarray):
        if not self._starting:
            return self._pose.process(rgb)
        with native_start_up_lines_held():
            res = self._pose.process(rgb)
        self._starting = res.pose_landmarks is None
        return res

    def close(self) -> None:
        self._pose.close()

    def __enter__(self) -> QuietPose:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def mediapipe_installed() -> bool:
    """Whether MediaPipe can be imported (``scripts/install-camera``), without importing it."""
    import importlib.util

    return importlib.util.find_spec("mediapipe") is not None


def pose_estimator(static: bool = False) -> QuietPose:
    """MediaPipe Pose with its bundled full landmark model (offline), its start-up lines held
    back (:class:`QuietPose`), or a one-line error.

    Raises:
        MotionFormatError: mediapipe is not installed (``scripts/install-camera``).
    """
    try:
        from mediapipe.python.solutions import pose
    except ImportError:
        raise MotionFormatError(
            "MediaPipe Pose (--method monocular or triangulate, --guide, --sides)",
            f"needs MediaPipe {MEDIAPIPE_VERSION}: run scripts/install-camera (pip install --no-deps mediapipe=={MEDIAPIPE_VERSION} absl-py attrs flatbuffers 'protobuf>=4.25.3,<5')",
        ) from None
    return QuietPose(
        lambda: pose.Pose(
            static_image_mode=static,
            model_complexity=1,
            smooth_landmarks=True,
            min_detection_confidence=0.5,
            min_tracking_confidence=0.5,
        )
    )


@dataclass
class Landmarks:
    """MediaPipe's answer for a video: per frame (F, 33) pixels (x, y), world points (mm,
    hip-centred, Y down as MediaPipe's) and visibility; ``found`` (F,) where a person was seen."""

    pixels: np.ndarray
    world: np.ndarray
    visibility: np.ndarray
    found: np.ndarray
    seconds: float = 0.0


#: MediaPipe sees a smaller frame enlarged so that its longer side is this many pixels
#: (:func:`frame_landmarks`). Chosen by leaving one kind of motion out among 320 (as they
#: are), 480, 640, 960 and 1280 px on the 11 rendered held-out kinds (320x240, 3 views,
#: ``track --method triangulate``): every fold chose 960, 58.9 mm against 61.3 as they are
#: (1280: 59.9, 640: 60.7, 480: 60.5). On the real video (272x480) it also helps a little
#: (triangulated 78.5 mm against 79.5; monocular 112.7 against 114.4 after alignment), and
#: MediaPipe is faster, not slower, on the enlarged frames (about 12 ms a frame against 20
#: on the real camera 0): on a small frame its tracking loses the person's box and runs its
#: detector again more often. Our own measure; docs/video.md.
MEDIAPIPE_SIDE = 960


def frame_landmarks(
    estimator: QuietPose, rgb: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """One RGB frame through a :func:`pose_estimator`: (33, 2) pixels, (33, 3) world points
    (mm, hip-centred, Y down as MediaPipe's) and (33,) visibility; None when no person.

    A frame whose longer side is under :data:`MEDIAPIPE_SIDE` is shown to MediaPipe
    enlarged to it (bicubic); its landmarks are MediaPipe's normalised image coordinates,
    so they come back in the frame's own pixels."""
    h, w = rgb.shape[:2]
    scale = MEDIAPIPE_SIDE / max(h, w)
    if scale > 1.0:
        size = (round(w * scale), round(h * scale))
        rgb = cv2.resize(rgb, size, interpolation=cv2.INTER_CUBIC)
    res = estimator.process(np.ascontiguousarray(rgb))
    if res.pose_landmarks is None or res.pose_world_landmarks is None:
        return None
    lm = res.pose_landmarks.landmark
    wl = res.pose_world_landmarks.landmark
    return (
        np.array([(p.x * w - 0.5, p.y * h - 0.5) for p in lm]),
        np.array([(p.x, p.y, p.z) for p in wl]) * 1000.0,
        np.array([p.visibility for p in lm]),
    )


def detect_landmarks(
    frames: Iterable[np.ndarray],
    max_frames: int | None = None,
    description: str | None = None,
    total: int | None = None,
) -> Landmarks:
    """MediaPipe Pose landmarks of RGB frames, in video mode (tracking between frames); with
    a ``description``, a progress bar (of ``total`` frames, if known)."""
    pixels, world, vis, found = [], [], [], []
    t0 = time.perf_counter()
    frames = itertools.islice(frames, max_frames)  # the bar's loop then always ends
    if description is not None:
        frames = track(frames, description, total)
    with pose_estimator() as est:
        for img in frames:
            got = frame_landmarks(est, img)
            found.append(got is not None)
            if got is None:
                got = (
                    np.full((len(LANDMARKS), 2), np.nan),
                    np.full((len(LANDMARKS), 3), np.nan),
                    np.zeros(len(LANDMARKS)),
                )
            for out, value in zip((pixels, world, vis), got, strict=True):
                out.append(value)
    if not found:
        raise MotionFormatError("video", "no frames in this video")
    return Landmarks(
        np.array(pixels), np.array(world), np.array(vis), np.array(found), time.perf_counter() - t0
    )


def place_frame(
    world: np.ndarray,
    pixels: np.ndarray,
    visibility: np.ndarray,
    k: np.ndarray,
    previous: tuple[np.ndarray, np.ndarray] | None = None,
    snap: bool = True,
) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray]] | None:
    """One frame's (33, 3) landmarks in the camera's frame (mm) by PnP of its world landmarks
    (33, 3) onto its 2-D ones (33, 2) through intrinsics ``k`` (module docstring, step 3),
    and the pose ``(rvec, tvec)`` found (to start the next frame's from); None when too few
    landmarks are seen or the body lands behind the camera. ``previous``: the last frame's
    pose, kept if it reprojects better than this frame's own SQPnP solution."""
    use = visibility >= MIN_VISIBILITY
    if use.sum() < MIN_LANDMARKS:
        return None
    obj = np.ascontiguousarray(world[use], dtype=np.float64)
    img = np.ascontiguousarray(pixels[use], dtype=np.float64)
    ok, r, t = cv2.solvePnP(obj, img, k, None, flags=cv2.SOLVEPNP_SQPNP)
    if not ok:
        return None
    # refine from this solution (or last frame's, if that one reprojects better)
    if previous is not None:
        cands = [(r, t), (previous[0].copy(), previous[1].copy())]
        errs = [
            np.linalg.norm(cv2.projectPoints(obj, a, b, k, None)[0][:, 0] - img, axis=1).mean()
            for a, b in cands
        ]
        r, t = cands[int(np.argmin(errs))]
    ok, r, t = cv2.solvePnP(obj, img, k, None, r, t, True, cv2.SOLVEPNP_ITERATIVE)
    if not ok or t[2, 0] <= 0:
        return None
    out = world @ cv2.Rodrigues(r)[0].T + t[:, 0]
    if snap:  # each landmark onto its ray through its 2-D landmark, at its depth
        ray = np.c_[pixels, np.ones(len(pixels))] @ np.linalg.inv(k).T
        out = ray * out[:, 2:3]
    return out, (r, t)


def place_body(
    landmarks: Landmarks, camera: CalibratedCamera, snap: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    """(F, 33, 3) landmarks in the camera's frame (mm) by PnP of the world landmarks onto the
    2-D ones (see the module's docstring, step 3; :func:`place_frame`), and (F,) whether each
    frame was placed."""
    n = len(landmarks.found)
    out = np.full((n, len(LANDMARKS), 3), np.nan)
    placed = np.zeros(n, dtype=bool)
    pose = None
    k = camera.K.astype(np.float64)
    for f in range(n):
        if not landmarks.found[f]:
            continue
        got = place_frame(
            landmarks.world[f], landmarks.pixels[f], landmarks.visibility[f], k, pose, snap
        )
        if got is not None:
            out[f], pose = got
            placed[f] = True
    return out, placed


def to_world(points_cam: np.ndarray, camera: CalibratedCamera) -> np.ndarray:
    """Camera-frame points (..., 3) in world coordinates (mm, Y up)."""
    return (points_cam - camera.t) @ camera.R


def _lowest(heights: np.ndarray) -> np.ndarray:
    """(F,) the least finite value of each row of (F, K); NaN for a row with none (a frame
    without the person), without NumPy's all-NaN warning."""
    low = np.where(np.isfinite(heights), heights, np.inf).min(axis=1)
    return np.where(np.isfinite(low), low, np.nan)


def floor_scale(world: np.ndarray, camera: CalibratedCamera, floor: float = 0.0) -> float:
    """The scale about the camera centre that puts the lowest foot landmark on the floor
    (median over frames; 1 if the camera is below the feet or no foot is seen)."""
    feet = [LANDMARKS.index(n) for n in FEET]
    low = _lowest(world[:, feet, 1])  # (F,) lowest foot
    cy = camera.centre[1]
    ok = np.isfinite(low) & (np.abs(low - cy) > 1.0) & (np.sign(floor - cy) == np.sign(low - cy))
    if not ok.any():
        return 1.0
    return float(np.median((floor - cy) / (low[ok] - cy)))


def stature_scale(world: np.ndarray, stature: float) -> float:
    """The scale that makes the head's top ``stature`` mm above the lowest foot (median)."""
    feet = [LANDMARKS.index(n) for n in FEET]
    ears = [LANDMARKS.index("left_ear"), LANDMARKS.index("right_ear")]
    height = world[:, ears, 1].mean(axis=1) + HEAD_TOP_MM - _lowest(world[:, feet, 1])
    height = height[np.isfinite(height) & (height > 100.0)]
    if not len(height):
        return 1.0
    return float(stature / np.percentile(height, 90))  # the most upright frames


#: Sigma (s) of the Gaussian that smooths a whole video's monocular track over time: chosen
#: by leaving one kind of motion out over 11 rendered kinds (3 cameras each, 30 fps), among
#: 0-100 ms, by the rigidly aligned error against the capture (``python3
#: benchmarks/monocular_smoothing.py``; every fold chose 67 ms: 113.1 to 110.8 mm on
#: the kind left out); one camera leaves no view out to choose it on the video itself.
MONOCULAR_SMOOTHING_S = 1 / 15


@dataclass
class MonocularTrack:
    """Body points (F, 19, 3) mm in the world (NaN where no person), confidence (F,) (mean
    landmark visibility, 0 where none), the scale applied, frame rate and timing."""

    points: np.ndarray
    confidence: np.ndarray
    scale: float
    fps: float
    seconds: float
    landmarks: Landmarks = field(repr=False)
    landmarks_world: np.ndarray = field(repr=False)
    #: One line when the video gave fewer frames than its header counts (damaged?).
    notes: list[str] = field(default_factory=list)

    @property
    def placed(self) -> np.ndarray:
        return np.isfinite(self.points).all(axis=(1, 2))


def finished_points(
    points: np.ndarray, fps: float, smooth_s: float = 0.0, constant_bones: bool = True
) -> np.ndarray:
    """A whole video's body points (F, 19, 3) smoothed over time by a Gaussian of sigma
    ``smooth_s`` (s; :func:`~markovmotion.features.smoothing.smooth_gaps`), then, with
    ``constant_bones``, each segment given its median length
    (:func:`~markovmotion.features.body_points.with_bone_lengths`; after the smoothing, so the
    lengths stay exact)."""
    if smooth_s > 0:
        from markovmotion.features.smoothing import smooth_gaps

        points = smooth_gaps(points, smooth_s * fps)
    if constant_bones:
        points = with_bone_lengths(points, bone_lengths(points))
    return points


def track_monocular(
    video: str | os.PathLike[str],
    camera: CalibratedCamera,
    fps: float,
    max_frames: int | None = None,
    stature: float | None = None,
    floor: float | None = 0.0,
    snap: bool = True,
    left_right: str = "continuity",
    constant_bones: bool = True,
    smooth_s: float = 0.0,
) -> MonocularTrack:
    """Track the person of one camera's video in 3-D (module docstring): body points in the
    world's mm, scaled so the feet rest on ``floor`` (None: MediaPipe's size), or so the
    person is ``stature`` mm tall if given. ``left_right`` (:data:`LEFT_RIGHT`): MediaPipe's
    own left and right, or made consistent over the video
    (:func:`~markovmotion.video.left_right.consistent_sides`), with the prior that the person
    faces the camera for ``"facing"``. ``constant_bones``: each segment of the body points
    given its median length over the video
    (:func:`~markovmotion.features.body_points.with_bone_lengths`). ``smooth_s``: the points
    first smoothed over time by a Gaussian of that sigma (s; offline, the whole video:
    :func:`finished_points`; ``track --method monocular`` uses
    :data:`MONOCULAR_SMOOTHING_S`)."""
    if left_right not in LEFT_RIGHT:
        raise ValueError(f"left_right must be one of {', '.join(LEFT_RIGHT)}, got {left_right!r}")
    t0 = time.perf_counter()
    frames = read_frames(video, camera)  # a camera with lens distortion: its pinhole image
    first = next(frames)
    if first.shape[:2] != (camera.height, camera.width):
        raise MotionFormatError(
            video,
            f"camera {camera.name} is {camera.width}x{camera.height} but its video is "
            f"{first.shape[1]}x{first.shape[0]}",
        )

    lm = detect_landmarks(
        itertools.chain([first], frames),
        max_frames,
        f"MediaPipe {camera.name}",
        expected_frames([video], max_frames, [camera]),
    )
    if left_right == "online":
        pixels, world_lm, vis = online_sides(lm)
        lm = Landmarks(pixels, world_lm, vis, lm.found, lm.seconds)
    elif left_right != "mediapipe":
        pixels, world_lm, vis, _ = consistent_sides(
            lm.pixels, lm.world, lm.visibility, faces_camera=left_right == "facing"
        )
        lm = Landmarks(pixels, world_lm, vis, lm.found, lm.seconds)
    cam_pts, placed = place_body(lm, camera, snap)
    world = to_world(cam_pts, camera)
    if stature is not None:
        scale = stature_scale(world, stature)
    elif floor is not None:
        scale = floor_scale(world, camera, floor)
    else:
        scale = 1.0
    world = camera.centre + scale * (world - camera.centre)
    conf = np.where(placed, np.where(lm.found[:, None], lm.visibility, 0.0).mean(axis=1), 0.0)
    points = finished_points(to_body_points(world), fps, smooth_s, constant_bones)
    n = len(lm.found)
    short = header_shortfall(video, n, camera, max_frames)
    notes = [f"note: {Path(video).name} ended after {n} frames{short}"] if short else []
    return MonocularTrack(points, conf, scale, fps, time.perf_counter() - t0, lm, world, notes)


def online_sides(lm: Landmarks) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The landmarks' left and right relabelled frame by frame as the camera page does
    (:class:`~markovmotion.video.left_right.OnlineSides`: causal, no look-ahead)."""
    sides = OnlineSides()
    pixels, world, vis = lm.pixels.copy(), lm.world.copy(), lm.visibility.copy()
    for t in range(len(pixels)):
        if lm.found[t]:
            pixels[t], world[t], vis[t], _ = sides.step(pixels[t], world[t], vis[t])
        else:
            sides.gap()
    return pixels, world, vis


def monocular_markers(points: np.ndarray, fps: float, name: str = "monocular") -> Markers:
    """The VLMM paper's 13 markers (named as the virtual suit's first 13, ``HEAD_FRONT``,
    ``L_SHOULDER`` ...) at the body points of (F, 19, 3) ``points``; NaN where none."""
    from markovmotion.features.markers import virtual_marker_names

    names = virtual_marker_names(13)
    side = {"L": "left", "R": "right"}
    order = []
    for n in names:
        if n == "HEAD_FRONT":
            order.append(BODY_POINTS.index("head"))
        else:
            s, part = n.split("_", 1)
            order.append(BODY_POINTS.index(f"{side[s]}_{part.lower()}"))
    assert sorted(BODY_POINTS[i] for i in order) == sorted(MARKER_POINTS)
    return Markers(names, points[:, order], fps, name)


# ----------------------------------------------------------------------------- measurement
#: The joints a MediaPipe-triangulated reference has, in the project's body-point names.
REFERENCE_JOINTS: tuple[str, ...] = tuple(
    f"{s}_{p}"
    for s in ("left", "right")
    for p in ("shoulder", "elbow", "wrist", "hip", "knee", "ankle")
)


#: Joints a frame needs known for the rigidly aligned error (:func:`reference_errors`).
ALIGNED_JOINTS = 4


def read_reference(path: str | os.PathLike[str]) -> tuple[np.ndarray, np.ndarray]:
    """Frames (F,) and (F, 12, 3) positions (mm) of :data:`REFERENCE_JOINTS` from a CSV with
    columns ``frame`` and ``<joint>_x``, ``_y``, ``_z`` (empty or NaN where unknown)."""
    path = Path(path)
    try:
        with path.open(newline="", encoding="utf-8") as fh:
            rows = list(csv.DictReader(fh))
    except (OSError, UnicodeDecodeError) as exc:
        raise MotionFormatError(path, f"cannot read the reference ({exc})") from None
    cols = [f"{j}_{a}" for j in REFERENCE_JOINTS for a in "xyz"]
    if not rows or any(c not in rows[0] for c in ["frame", *cols]):
        raise MotionFormatError(
            path, f"a reference needs the columns frame, {', '.join(cols[:3])} ..."
        )
    try:
        frames = np.array([int(r["frame"]) for r in rows])
        pos = np.array([[float(r[c] or "nan") for c in cols] for r in rows])
    except ValueError as exc:
        raise MotionFormatError(path, f"not a number ({exc})") from None
    return frames, pos.reshape(len(rows), len(REFERENCE_JOINTS), 3)


def kabsch_align(moving: np.ndarray, fixed: np.ndarray) -> np.ndarray:
    """(F, P, 3) ``moving`` rotated and translated per frame onto ``fixed`` (least squares,
    no scale: the Kabsch algorithm), over the points finite in both."""
    out = np.full_like(moving, np.nan)
    for f in range(len(moving)):
        ok = np.isfinite(moving[f]).all(1) & np.isfinite(fixed[f]).all(1)
        if ok.sum() < 3:
            continue
        a, b = moving[f, ok], fixed[f, ok]
        ma, mb = a.mean(0), b.mean(0)
        u, _, vt = np.linalg.svd((a - ma).T @ (b - mb))
        d = np.sign(np.linalg.det(u @ vt))
        rot = u @ np.diag([1.0, 1.0, d]) @ vt
        out[f] = (moving[f] - ma) @ rot + mb
    return out


def reference_errors(
    points: np.ndarray,
    reference: str | os.PathLike[str],
    joints: Sequence[str] = BODY_POINTS,
    first_frame: int = 0,
) -> dict:
    """Mean error (mm) of (F, P, 3) tracked ``points`` (named ``joints``) against a reference
    CSV (:func:`read_reference`): over its 12 joints, per joint, with and without each frame's
    rigid alignment (on the joints known in both). Every joint known in both counts, also in
    a frame where another is unknown (a triangulation from two views misses single joints:
    leaving out the whole frame dropped 13 of 40); frames with none are counted as
    ``frames_missing``, unknown joints of the others as ``joints_missing``. The reference's
    frames are numbered in the first camera's video; ``first_frame``: the video frame that is
    the track's first (the camera's ``skip_frames``)."""
    return _errors(points, read_reference(reference), joints, first_frame)


def _errors(
    points: np.ndarray,
    read: tuple[np.ndarray, np.ndarray],
    joints: Sequence[str] = BODY_POINTS,
    first_frame: int = 0,
) -> dict:
    """:func:`reference_errors` of a reference already read (:func:`read_reference`)."""
    frames, ref = read
    frames = frames - first_frame
    keep = (frames >= 0) & (frames < len(points))
    frames, ref = frames[keep], ref[keep]
    idx = [list(joints).index(j) for j in REFERENCE_JOINTS]
    mine = points[frames][:, idx]
    known = np.isfinite(mine).all(axis=2)  # (F, 12)
    ok = known.any(axis=1)
    mine = np.where(known[..., None], mine, np.nan)[ok]
    raw = np.linalg.norm(mine - ref[ok], axis=-1)  # NaN where either is unknown
    # a rigid alignment needs points to align by: frames with fewer than ALIGNED_JOINTS known
    # are left out of the aligned errors (counted as frames_aligned), not fitted exactly
    aligned = np.linalg.norm(kabsch_align(mine, ref[ok]) - ref[ok], axis=-1)
    aligned[known[ok].sum(axis=1) < ALIGNED_JOINTS] = np.nan

    def mean(err: np.ndarray) -> float | None:  # None, not NaN, where nothing is known (JSON)
        finite = err[np.isfinite(err)]
        return round(float(finite.mean()), 1) if len(finite) else None

    def table(err: np.ndarray) -> dict:
        return {j: mean(e) for j, e in zip(REFERENCE_JOINTS, err.T, strict=True)}

    return {
        "frames_compared": int(ok.sum()),
        "frames_missing": int((~ok).sum()),
        "joints_missing": int((~known[ok]).sum()),
        "frames_aligned": int(np.isfinite(aligned).any(axis=1).sum()),
        "mean_mm": mean(raw),
        "aligned_mean_mm": mean(aligned),
        "per_joint_mm": table(raw),
        "aligned_per_joint_mm": table(aligned),
    }


def reference_note(
    reference: str | os.PathLike[str],
    frames: int,
    fps: float,
    first_frame: int = 0,
    max_frames: int | None = None,
    cut_short: bool = False,
) -> str | None:
    """One line when a reference's rows (from the track's first frame, ``first_frame`` of
    the first camera's video, on) are not as many as the track's ``frames`` at ``fps``:
    :func:`reference_errors` pairs them frame by frame, which is right only for a reference
    of the same video at its rate (a 60 fps reference against a 30 fps re-encoding was
    264.7 mm off without a word). A video that ends early looks the same as a reference at
    another rate, so the rate is offered as an "if", not asserted (a trial's video cut to 40
    frames had been told to give a 150 fps reference at the video's rate), and not at all
    when ``cut_short`` (one view's video ended before the others and cut the track: the
    particle filter said so; a camera cut to 70 frames had been offered an 85.7 fps
    reference). None when they match, or when the track was cut by ``max_frames`` and the
    reference goes on."""
    rows = read_reference(reference)[0]
    return _note(reference, rows, frames, fps, first_frame, max_frames, cut_short)


def _note(
    reference: str | os.PathLike[str],
    rows: np.ndarray,
    frames: int,
    fps: float,
    first_frame: int,
    max_frames: int | None,
    cut_short: bool = False,
) -> str | None:
    """:func:`reference_note` of a reference whose frame numbers (``rows``) are read."""
    n = int((rows >= first_frame).sum())
    cut = max_frames is not None and frames >= max_frames
    if n == frames or (cut and n > frames):
        return None
    left = (
        f"its last {n - frames} rows with none"
        if n > frames
        else f"the track's last {frames - n} with none"
    )
    line = (
        f"note: the reference {Path(reference).name} has {n} rows and the track {frames} "
        f"frames: row k is compared with frame k, {left}"
    )
    if not cut and not cut_short and frames > 0 and abs(n / frames - 1.0) > 0.1:
        # a video cut short and a reference at another rate look alike here: both are said
        line += (
            f"; if both span the same time, the reference is at {fps * n / frames:.3g} fps and "
            f"the video at {fps:g}: give a reference at the video's rate"
        )
    return line


#: A person shorter than this in the image (px, MediaPipe's landmarks' median extent
#: top to bottom) gets a note: on the real video at half size (80-95 px) one camera was
#: 336 mm from the reference against 148 at full size (160-190 px).
SMALL_PERSON_PX = 120.0


def person_pixels(pixels: np.ndarray) -> float | None:
    """The person's median height in the image (px) over the frames MediaPipe found them
    in: the extent of the (F, 33, 2) landmark ``pixels`` top to bottom (None: none found)."""
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        extent = np.nanmax(pixels[..., 1], axis=1) - np.nanmin(pixels[..., 1], axis=1)
        tall = float(np.nanmedian(extent))
    return tall if np.isfinite(tall) else None


def small_person_note(tall: float | None, camera: str) -> list[str]:
    """One note when the person stands under :data:`SMALL_PERSON_PX` tall in ``camera``."""
    if tall is None or tall >= SMALL_PERSON_PX:
        return []
    return [
        f"note: the person is {tall:.0f} px tall in {camera}'s image: MediaPipe's landmarks, "
        f"and the depth one camera takes from them, are coarse below about "
        f"{SMALL_PERSON_PX:.0f} px (a larger video, or the person nearer the camera)"
    ]


def reference_report(
    points: np.ndarray,
    reference: str | os.PathLike[str],
    fps: float,
    first_frame: int = 0,
    max_frames: int | None = None,
    cut_short: bool = False,
) -> tuple[dict, str | None]:
    """A track's (F, 19, 3) body ``points`` against a reference CSV, read once: its errors
    (:func:`reference_errors`) and the note of :func:`reference_note` (None when the rows and
    the track's frames pair up; ``cut_short``: a view's video ended first and cut the track),
    as every tracker's summary reports them."""
    read = read_reference(reference)
    note = _note(reference, read[0], len(points), fps, first_frame, max_frames, cut_short)
    return _errors(points, read, BODY_POINTS, first_frame), note


def track_monocular_video(
    video: str | os.PathLike[str],
    cameras: str | os.PathLike[str] | None = None,
    max_frames: int | None = None,
    stature: float | None = None,
    reference: str | os.PathLike[str] | None = None,
    left_right: str = "continuity",
    smooth: float | None = None,
) -> tuple[MonocularTrack, dict]:
    """Track one camera's video (a folder with ``cameras.json``: its first camera; a video
    file: the camera naming it, see :func:`~markovmotion.video.cameras.camera_of_video`);
    the track and a JSON-ready summary (with ``reference``, its errors). ``smooth``: the
    track's smoothing over time (s, a Gaussian's sigma; None: :data:`MONOCULAR_SMOOTHING_S`)."""
    from markovmotion.video.cameras import (
        camera_file,
        camera_of_video,
        camera_videos,
        load_cameras,
    )

    where = camera_file(video, cameras)
    notes: list[str] = []
    cams, doc = load_cameras(where, notes, paired=False)  # one view: others' rates noted
    if lone_video(video):
        cam, path = cams[camera_of_video(cams, video, notes)], Path(video)
    else:
        cam, path = cams[0], camera_videos(where, cams[:1])[0]
    sigma = MONOCULAR_SMOOTHING_S if smooth is None else smooth
    tr = track_monocular(
        path, cam, float(doc["fps"]), max_frames, stature, left_right=left_right, smooth_s=sigma
    )
    if not tr.placed.any():  # as the other methods stop (an empty scene, the wrong video)
        raise MotionFormatError(path, "no person found in this video (no frame placed)")
    tall = person_pixels(tr.landmarks.pixels)
    n = len(tr.points)
    summary = {
        "method": "monocular",
        "camera": cam.name,
        "frames": n,
        "frames_placed": int(tr.placed.sum()),
        "fps": round(n / max(tr.seconds, 1e-9), 2),
        "video_fps": tr.fps,
        "scale": round(tr.scale, 4),
        "left_right": left_right,
        "smoothing_s": round(sigma, 4),
        "smoothing_chosen_by": "fixed: chosen on rendered kinds" if smooth is None else "--smooth",
        "person_px": None if tall is None else round(tall, 1),
        "notes": [*notes, *tr.notes, *small_person_note(tall, cam.name)],
        "confidence": [round(float(c), 3) for c in tr.confidence],
    }
    if reference is not None:
        errors, said = reference_report(tr.points, reference, tr.fps, cams[0].skip, max_frames)
        # flat, as before, and under "reference" as the particle filter's summary has them
        summary.update(errors, reference=errors)
        summary["notes"] += [said] if said else []
    return tr, summary
