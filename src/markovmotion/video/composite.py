"""Video in, video out: track person A, generate the partner B, draw B into the video (dual-HMM
paper, §3 and Fig. 1).

:func:`respond_in_video` tracks A by annealed particle filtering
(:mod:`markovmotion.video.annealed_particle_filter`), asks the dual HMM for
B's response to the tracked motion (:meth:`DualHMM.respond`, public API
only), and renders B shaded with the same camera over the original frames.
A pixel of B is drawn only where B's surface is nearer the camera than A's
tracked body model, so A's arm in front of B hides B and B in front of A
hides A.
"""

from __future__ import annotations

import os
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from markovmotion.core.motion import Motion
from markovmotion.errors import MotionFormatError
from markovmotion.features.body_points import BODY_POINTS, body_points
from markovmotion.video.body_model import BODY_SHAPE, BodyModel
from markovmotion.video.cameras import CalibratedCamera, camera_videos, load_cameras
from markovmotion.video.multiview import track_take
from markovmotion.video.render import read_frames, write_video
from markovmotion.video.shading import CLOTHES, DepthCanvas, capsule_colours


def composite_frames(
    frames: Iterator[np.ndarray],
    camera: CalibratedCamera,
    a_points: np.ndarray,
    b_points: np.ndarray,
) -> Iterator[np.ndarray]:
    """``frames`` with B (body points (F, 19, 3)) drawn shaded where it is in front of A's model.

    Stops with A's tracked frames; frames beyond B's motion pass through unchanged.
    """
    colours = capsule_colours(BODY_SHAPE, BODY_POINTS, CLOTHES["b"])
    hidden = np.zeros((len(BODY_SHAPE.segments()[0]), 3))
    for t, frame in enumerate(frames):
        if t >= len(a_points):
            return
        if t >= len(b_points) or not np.isfinite(b_points[t]).all():
            yield frame
            continue
        canvas = DepthCanvas(camera.width, camera.height)
        canvas.body(a_points[t], camera, BODY_SHAPE, hidden, 0)
        canvas.body(b_points[t], camera, BODY_SHAPE, colours, 1)
        yield canvas.over(frame, only=1)


def respond_in_video(
    model: str | os.PathLike[str],
    video: str | os.PathLike[str],
    out: str | os.PathLike[str],
    body: BodyModel,
    cameras: str | os.PathLike[str] | None = None,
    view: int = 0,
    particles: int = 200,
    layers: int = 10,
    max_frames: int | None = None,
    method: str = "windowed",
) -> dict:
    """Track A in ``video`` (a folder with ``cameras.json`` or one camera's video file with
    ``cameras``), generate B with the dual HMM ``model``, write the composite of camera ``view``
    to ``out`` (``.mp4``, or a folder of PNG frames). Returns a summary."""
    from markovmotion.models.hmm.dual import DualHMM

    dual = DualHMM.load(model)
    where = Path(cameras) if cameras is not None else Path(video)
    cams, _ = load_cameras(where)
    if not 0 <= view < len(cams):
        raise MotionFormatError(where, f"no camera {view}: the file has {len(cams)}")
    start = time.perf_counter()
    a, result, summary = track_take(video, body, cameras, None, particles, layers, None, max_frames)
    tracked = time.perf_counter() - start
    b = _respond(dual, a, method)
    video_path = Path(video) if Path(video).is_file() else camera_videos(where, cams)[view]
    frames = read_frames(video_path)
    written = write_video(
        composite_frames(frames, cams[view], body_points(a), body_points(b)), out, result.fps
    )
    summary.update(
        {
            "tracking_seconds": round(tracked, 2),
            "partner_frames": b.n_frames,
            "out": str(written),
            "view": view,
        }
    )
    return summary


def _respond(dual, a: Motion, method: str) -> Motion:
    """B's response at the video's rate (the model works at its own)."""
    b = dual.respond(a, method)
    return b.resample(a.fps) if not np.isclose(b.fps, a.fps) else b
