"""Cameras started at different times: their offsets measured from the person's landmarks.

Cameras that are not triggered together start recording one after another, and a frame of
one video then shows another moment than the same frame of the next: the triangulation pairs
a wrist in one view with where it was a few frames earlier in another. Pose2Sim
(Pagnon et al. 2022, ``synchronization.py``) measures the offset by cross-correlating the
speeds of the 2-D keypoints in each view. With calibrated cameras a sharper test is at
hand, and it is the one used here: at the right offset every landmark MediaPipe finds in two
views lies on its epipolar line (Hartley and Zisserman, *Multiple View Geometry*, §9.2:
``x1^T F x0 = 0``, ``F = K1^-T [t]_x R K0^-1`` from the two cameras' relative pose). For each
camera and each offset ``L`` within ``max_lag_s``, camera 0's frame ``f`` is paired with the
camera's frame ``f + L``, and the offset scored by the mean distance (px) of the landmarks
seen in both from their epipolar lines, each capped at :data:`CAP_ANGLE` focal lengths (a
landmark put on the other arm counts as an outlier, not as a score). A person who stands
still scores every offset alike; the offset is reported only where it scores clearly
better than none (:data:`MIN_GAIN`), else 0.

``markovmotion video sync DIR`` (:func:`sync_video`) prints the offsets and with ``--write``
records them in the camera file as each camera's ``skip_frames``
(:mod:`markovmotion.video.cameras`), which every reader of the videos then honours.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from markovmotion.video.cameras import CalibratedCamera, lone_video
from markovmotion.video.monocular import MIN_VISIBILITY

if TYPE_CHECKING:
    from markovmotion.video.triangulation import ViewLandmarks

#: Offsets tried: up to this many seconds either way.
MAX_LAG_S = 2.0
#: A landmark's epipolar distance is capped at this many focal lengths (12 px at focal 400).
CAP_ANGLE = 0.03
#: An offset is taken when its score is at most this share of the score without one, and at
#: least :data:`MIN_GAIN_ANGLE` focal lengths lower (a person standing still scores every
#: offset alike; on the real 4-view video, focal 420 px, neighbouring offsets differ by 0.1-0.6
#: px, smoothly). In focal lengths, so that the same video at half its size (every score
#: halved) is judged alike.
MIN_GAIN = 0.9
MIN_GAIN_ANGLE = 0.5 / 420
#: Fewest landmark pairs an offset must be scored on (else it is not tried).
MIN_PAIRS = 200


def fundamental(cam0: CalibratedCamera, cam1: CalibratedCamera) -> np.ndarray:
    """The fundamental matrix (3, 3) taking a pixel of ``cam0`` to its epipolar line in
    ``cam1`` (``x1^T F x0 = 0``)."""
    r = cam1.R @ cam0.R.T
    t = cam1.t - r @ cam0.t
    tx = np.array([[0.0, -t[2], t[1]], [t[2], 0.0, -t[0]], [-t[1], t[0], 0.0]])
    return np.linalg.inv(cam1.K).T @ tx @ r @ np.linalg.inv(cam0.K)


def epipolar_distances(f: np.ndarray, x0: np.ndarray, x1: np.ndarray) -> np.ndarray:
    """Symmetric epipolar distance (px) of pixel pairs ``x0``, ``x1`` (N, 2): the mean of
    ``x1``'s distance from ``F x0``'s line and ``x0``'s from ``F^T x1``'s."""
    h0 = np.c_[x0, np.ones(len(x0))]
    h1 = np.c_[x1, np.ones(len(x1))]
    l1 = h0 @ f.T  # lines in image 1
    l0 = h1 @ f  # lines in image 0
    num = np.abs((h1 * l1).sum(axis=1))
    with np.errstate(invalid="ignore", divide="ignore"):
        d1 = num / np.hypot(l1[:, 0], l1[:, 1])
        d0 = num / np.hypot(l0[:, 0], l0[:, 1])
    return 0.5 * (d0 + d1)


@dataclass
class SyncResult:
    """Per camera: its offset to camera 0 in frames (camera 0's frame ``f`` shows the moment of
    this camera's frame ``f + offset``), the score (px) at that offset and without one, the
    landmark pairs scored, and whether it could be measured (too few landmarks seen in both
    it and camera 0: offset 0, scores NaN); ``best`` and ``best_px``: the offset that scored
    least and its score, which differ from ``offsets`` where it was not clearly better than
    none (:data:`MIN_GAIN`)."""

    names: list[str]
    offsets: np.ndarray
    score_px: np.ndarray
    score_none_px: np.ndarray
    pairs: np.ndarray
    measured: np.ndarray
    best: np.ndarray
    best_px: np.ndarray

    @property
    def in_step(self) -> bool:
        """Every camera measured, and none offset."""
        return bool(self.measured.all()) and not self.offsets.any()

    def skips(self, current: np.ndarray | None = None) -> np.ndarray:
        """Each camera's frames to skip so that all start together, from the ``current``
        skips the offsets were measured with (none are skipped needlessly)."""
        base = np.zeros(len(self.offsets), int) if current is None else np.asarray(current)
        total = base + self.offsets
        return total - total.min()

    def summary(self, fps: float) -> dict:
        """JSON-ready, per camera."""
        return {
            n: {
                "offset_frames": int(o) if m else None,
                "offset_s": round(float(o) / fps, 4) if m else None,
                "epipolar_px": _px(s),
                "epipolar_px_in_step": _px(z),
                "pairs": int(p),
                "best_offset_frames": int(b) if m else None,
                "best_offset_px": _px(bp),
            }
            for n, o, s, z, p, m, b, bp in zip(
                self.names,
                self.offsets,
                self.score_px,
                self.score_none_px,
                self.pairs,
                self.measured,
                self.best,
                self.best_px,
                strict=True,
            )  # fmt: skip
        }


def _px(value: float) -> float | None:
    return round(float(value), 3) if np.isfinite(value) else None


def estimate_offsets(views: ViewLandmarks, fps: float, max_lag_s: float = MAX_LAG_S) -> SyncResult:
    """Each camera's offset to camera 0 (module docstring), from MediaPipe's landmarks in
    every view (:class:`~markovmotion.video.triangulation.ViewLandmarks`)."""
    cams = views.cameras
    v_n, f_n, _ = views.visibility.shape
    seen = (views.visibility >= MIN_VISIBILITY) & np.isfinite(views.pixels).all(axis=-1)
    # every offset scored on most of the clip (an offset over half of it picked wrong ones)
    max_lag = int(min(round(max_lag_s * fps), max(0, f_n // 4)))
    offsets = np.zeros(v_n, int)
    best_lag = np.zeros(v_n, int)
    best_px = np.full(v_n, np.nan)
    best = np.full(v_n, np.nan)
    none = np.full(v_n, np.nan)
    pairs = np.zeros(v_n, int)
    measured = np.zeros(v_n, bool)
    measured[0] = True
    for v in range(1, v_n):
        f = fundamental(cams[0], cams[v])
        focal = 0.5 * (cams[0].focal + cams[v].focal)  # the pair's, in pixels
        cap = CAP_ANGLE * focal
        scores, counts = {}, {}
        for lag in range(-max_lag, max_lag + 1):
            a = slice(max(0, -lag), min(f_n, f_n - lag))  # camera 0's frames
            b = slice(a.start + lag, a.stop + lag)  # the camera's
            both = seen[0, a] & seen[v, b]
            n = int(both.sum())
            if n < MIN_PAIRS:
                continue
            d = epipolar_distances(f, views.pixels[0, a][both], views.pixels[v, b][both])
            scores[lag] = float(np.minimum(np.nan_to_num(d, nan=cap), cap).mean())
            counts[lag] = n
        if 0 not in scores:
            continue
        measured[v] = True
        lag = min(scores, key=scores.get)
        none[v], best[v], pairs[v] = scores[0], scores[lag], counts[lag]
        best_lag[v], best_px[v] = lag, scores[lag]
        gain_px = MIN_GAIN_ANGLE * focal
        if scores[lag] <= MIN_GAIN * scores[0] and scores[0] - scores[lag] >= gain_px:
            offsets[v] = lag
        else:
            best[v], pairs[v] = scores[0], counts[0]
    best[0] = none[0] = best_px[0] = 0.0
    names = [c.name for c in cams]
    return SyncResult(names, offsets, best, none, pairs, measured, best_lag, best_px)


def write_skips(path: str | os.PathLike[str], result: SyncResult) -> Path:
    """Record ``result`` in the camera file at ``path`` (atomically): each camera's
    ``skip_frames`` grows by what aligns it (:meth:`SyncResult.skips`); the rest is kept."""
    from markovmotion.errors import MotionFormatError
    from markovmotion.io.files import atomic_write
    from markovmotion.video.cameras import CAMERAS_FILE, load_cameras

    path = Path(path)
    if path.is_dir():
        path = path / CAMERAS_FILE
    lost = [n for n, m in zip(result.names, result.measured, strict=True) if not m]
    if lost:
        raise MotionFormatError(
            path, f"{', '.join(lost)} could not be measured (too few landmarks seen in it and "
            f"{result.names[0]}): nothing written",
        )  # fmt: skip
    cams, _ = load_cameras(path)
    doc = json.loads(path.read_text(encoding="utf-8"))
    skips = result.skips(np.array([c.skip for c in cams[: len(result.offsets)]]))
    for entry, skip in zip(doc["cameras"], skips, strict=False):
        if skip:
            entry["skip_frames"] = int(skip)
        else:
            entry.pop("skip_frames", None)
    try:
        with atomic_write(path, "w") as fh:
            json.dump(doc, fh, indent=1)
    except OSError as exc:
        raise MotionFormatError(path, f"cannot write the offsets here ({exc.strerror})") from None
    return path


def sync_video(
    video: str | os.PathLike[str],
    cameras: str | os.PathLike[str] | None = None,
    max_lag_s: float = MAX_LAG_S,
    max_frames: int | None = None,
) -> tuple[SyncResult, float, Path, list[str]]:
    """``video sync``: MediaPipe over every camera's video (as ``track --method triangulate``
    reads them: one person, left and right agreed, each camera's ``skip_frames`` honoured),
    each camera's offset to camera 0 (:func:`estimate_offsets`); also the frame rate, the
    camera file, and the notes on them (the camera file's, a video that ended early)."""
    from markovmotion.errors import MotionFormatError
    from markovmotion.video.cameras import CAMERAS_FILE, camera_file, camera_videos, load_cameras
    from markovmotion.video.triangulation import person_views

    where = camera_file(video, cameras)
    where = where / CAMERAS_FILE if where.is_dir() else where
    if lone_video(video):
        raise MotionFormatError(video, "syncing needs the folder of every camera")
    notes: list[str] = []
    cams, doc = load_cameras(where, notes)
    if len(cams) < 2:
        raise MotionFormatError(where, "syncing needs at least 2 cameras")
    fps = float(doc["fps"])
    views = person_views(camera_videos(where, cams), cams, fps, max_frames)
    return estimate_offsets(views.agreed, fps, max_lag_s), fps, where, [*notes, *views.notes]
