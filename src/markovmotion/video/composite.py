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

import cv2
import numpy as np
from threadpoolctl import threadpool_limits

from markovmotion.core.markers import Markers
from markovmotion.core.motion import Motion
from markovmotion.errors import MotionFormatError, SkeletonMismatchError
from markovmotion.features.body_points import BODY_POINTS, body_points
from markovmotion.io.files import check_writable
from markovmotion.video.annealed_particle_filter import (
    AnnealedParticleFilter,
    no_one,
    open_video,
)
from markovmotion.video.body_model import BODY_SHAPE, BodyModel, marker_shape
from markovmotion.video.cameras import (
    CalibratedCamera,
    camera_of_video,
    camera_videos,
    load_cameras,
    lone_video,
    read_camera_file,
)
from markovmotion.video.multiview import track_take
from markovmotion.video.render import BodyShape, read_frames, write_video
from markovmotion.video.shading import CLOTHES, DepthCanvas, capsule_colours


def partner_body(b: Motion | Markers | np.ndarray) -> tuple[np.ndarray, BodyShape, np.ndarray]:
    """What of B is drawn: its points (F, P, 3), their flesh and each primitive's colour. A
    Motion by its 19 body points on :data:`BODY_SHAPE` (an array: those points); Markers (a
    partner learnt from a depth sensor's markers) by :func:`marker_shape`, only the parts its
    markers show (a sensor's 8 upper-body points: trunk, head and arms; no legs are invented)."""
    if isinstance(b, Markers):
        shape, names = marker_shape(b.names)
        return b.positions, shape, capsule_colours(shape, names, CLOTHES["b"])
    points = body_points(b) if isinstance(b, Motion) else np.asarray(b, dtype=float)
    return points, BODY_SHAPE, capsule_colours(BODY_SHAPE, BODY_POINTS, CLOTHES["b"])


def composite_frames(
    frames: Iterator[np.ndarray],
    camera: CalibratedCamera,
    a_points: np.ndarray,
    b: Motion | Markers | np.ndarray,
    caption: str = "",
) -> Iterator[np.ndarray]:
    """``frames`` with B (a Motion, Markers or body points, :func:`partner_body`) drawn shaded
    where it is in front of A's model (A's body points (F, 19, 3) on :data:`BODY_SHAPE`),
    and ``caption`` (say, which model B is) in the top left corner of every frame.

    Stops with A's tracked frames; frames beyond B's motion pass through unchanged.
    """
    b_points, shape, colours = partner_body(b)
    hidden = np.zeros((len(BODY_SHAPE.segments()[0]), 3))
    for t, frame in enumerate(frames):
        if t >= len(a_points):
            return
        if t >= len(b_points) or not np.isfinite(b_points[t]).all():
            yield with_caption(frame, caption)
            continue
        canvas = DepthCanvas(camera.width, camera.height)
        if np.isfinite(a_points[t]).all():  # A not found in this frame: B hides nothing of A
            canvas.body(a_points[t], camera, BODY_SHAPE, hidden, 0)
        canvas.body(b_points[t], camera, shape, colours, 1)
        yield with_caption(canvas.over(frame, only=1), caption)


def partner_caption(model: str | os.PathLike[str]) -> str:
    """What a composite says of its people: B, drawn in red, is the model's answer."""
    return f"red: virtual partner ({Path(model).name})"


def with_caption(frame: np.ndarray, caption: str) -> np.ndarray:
    """``frame`` (RGB) with ``caption`` in white on a dark band at its top left, sized to the
    frame's width (a composite did not say which figure is the virtual partner)."""
    if not caption:
        return frame
    out = np.ascontiguousarray(frame).copy()
    scale = min(0.6, max(0.3, out.shape[1] / 900))  # legible, and small on a large frame
    (w, h), base = cv2.getTextSize(caption, cv2.FONT_HERSHEY_SIMPLEX, scale, 1)
    w = min(w, out.shape[1] - 4)
    out[: h + base + 6, : w + 8] = (out[: h + base + 6, : w + 8] * 0.35).astype(out.dtype)
    cv2.putText(out, caption, (4, h + 3), cv2.FONT_HERSHEY_SIMPLEX, scale, (255, 255, 255), 1,
                cv2.LINE_AA)  # fmt: skip
    return out


#: A frame shows B when at least this share of B's points project inside the image (in
#: front of the camera); a camera that shows B in fewer than :data:`SHOWN_FRAMES` of the
#: frames gets a note naming the camera that shows B most (:func:`framing_notes`).
SHOWN_POINTS = 0.75
SHOWN_FRAMES = 0.9


def shown_share(camera: CalibratedCamera, points: np.ndarray) -> float:
    """The share of frames (F, P, 3) in which ``camera`` sees at least :data:`SHOWN_POINTS`
    of the points inside its image, in front of it (frames with no known point left out)."""
    pts = np.asarray(points, dtype=float)
    known = np.isfinite(pts).all(axis=-1)
    pts = np.where(known[..., None], pts, 0.0)
    uv, _ = camera.project(pts)
    depth = pts @ camera.R[2] + camera.t[2]  # project's depth is clamped: behind is not told
    inside = (
        known & (depth > 0)
        & (uv[..., 0] >= 0) & (uv[..., 0] < camera.width)
        & (uv[..., 1] >= 0) & (uv[..., 1] < camera.height)
    )  # fmt: skip
    frames = known.any(axis=1)
    if not frames.any():
        return 1.0
    share = inside.sum(axis=1)[frames] / known.sum(axis=1)[frames]
    return float(np.mean(share >= SHOWN_POINTS))


def framing_notes(cameras: list[CalibratedCamera], view: int, b: Motion | Markers) -> list[str]:
    """A note when camera ``view`` leaves B (the generated partner) out of its image in more
    than a tenth of the frames, naming the camera that shows B most: a partner standing
    where a partner would can be beside the camera's field (the demo's 320x240 video cut B
    at the left edge in 53 of 60 frames), and the composite then shows no answer."""
    points = partner_body(b)[0]
    shares = [shown_share(c, points) for c in cameras]
    if shares[view] >= SHOWN_FRAMES:
        return []
    best = int(np.argmax(shares))
    better = (
        f"; camera {best} ({cameras[best].name}) shows B whole in {shares[best]:.0%}: --view {best}"
        if best != view and shares[best] > shares[view]
        else ""
    )
    return [
        f"note: the partner is partly outside camera {view} ({cameras[view].name})'s image in "
        f"{1 - shares[view]:.0%} of the frames{better}"
    ]


def respond_in_video(
    model: str | os.PathLike[str],
    video: str | os.PathLike[str],
    out: str | os.PathLike[str],
    body: BodyModel,
    cameras: str | os.PathLike[str] | None = None,
    view: int | None = 0,
    particles: int = 200,
    layers: int = 10,
    max_frames: int | None = None,
    method: str = "windowed",
    live: bool = False,
    guide: bool = False,
    person: str | None = None,
) -> dict:
    """Track A in ``video`` (a folder with ``cameras.json`` or one camera's video file with
    ``cameras``), generate B with the dual HMM ``model``, write the composite of camera ``view``
    (None: the camera that shows A and B whole in the most frames, :func:`shown_share`; not
    live) to ``out`` (``.mp4``, or a folder of PNG frames). Returns a summary. ``live``: frame by
    frame at the video's rate, through the online partner (:func:`_respond_live`).
    ``guide``: MediaPipe guides the tracking of A (:func:`track_take`; not live), following
    the ``person`` at a pixel (``CAMERA:U,V``) if several are in view. A camera without an
    empty-scene image gets the background ``track`` learns (``--background learn``)."""
    if live and guide:
        raise ValueError("the MediaPipe guide runs over the whole video: not live")
    if live:
        if view is None:
            raise ValueError("live, the camera to draw into is given (view)")
        return _respond_live(model, video, out, body, cameras, view, particles, layers, max_frames)
    dual = _load_partner_model(model)
    check_writable(out)  # before the tracking, not after
    where = cameras = read_camera_file(video, cameras)  # once: the tracker takes it so
    single = lone_video(video)
    cams, _ = load_cameras(where, paired=not single)
    if single:  # one camera's video: that camera
        view = camera_of_video(cams, video)
    if view is not None and not 0 <= view < len(cams):
        raise MotionFormatError(where, f"no camera {view}: the file has {len(cams)}")
    start = time.perf_counter()
    a, result, summary = track_take(
        video, body, cameras, None, particles, layers, None, max_frames, guide=guide,
        person=person,
    )  # fmt: skip
    tracked = time.perf_counter() - start
    if guide:  # whom MediaPipe followed, when it may not be the one meant
        from markovmotion.video.triangulation import whom_notes

        summary["notes"] = summary["notes"] + whom_notes(summary, named=person is not None)
    b = _respond(dual, a, method)
    if view is None:  # the camera that shows both people whole most often
        both = np.concatenate([body_points(a), partner_body(b)[0][: a.n_frames]], axis=1)
        view = int(np.argmax([shown_share(c, both) for c in cams]))
    video_path = Path(video) if single else camera_videos(where, cams)[view]
    frames = read_frames(video_path, cams[view])
    shown = composite_frames(frames, cams[view], body_points(a), b, partner_caption(model))
    written = write_video(shown, out, result.fps)
    summary["notes"] = summary["notes"] + framing_notes(cams, view, b)
    summary.update(
        {
            "tracking_seconds": round(tracked, 2),
            "partner_frames": b.n_frames,
            "out": str(written),
            "view": view,
        }
    )
    return summary


def respond_mediapipe(
    model: str | os.PathLike[str],
    video: str | os.PathLike[str],
    out: str | os.PathLike[str],
    cameras: str | os.PathLike[str] | None = None,
    view: int = 0,
    max_frames: int | None = None,
    method: str = "windowed",
    tracker: str = "monocular",
    person: str | None = None,
) -> dict:
    """:func:`respond_in_video` with A tracked by MediaPipe Pose: ``tracker="monocular"``, in
    camera ``view`` alone (:mod:`markovmotion.video.monocular`: placed by PnP, sized by the
    floor), or ``"triangulate"``, in every camera, triangulated
    (:func:`~markovmotion.video.triangulation.track_triangulated_video`, following ``person``
    if given) and composited into camera ``view``. A's 19 body points go to the dual HMM as a
    Motion of them (:func:`~markovmotion.features.body_points.points_motion`), and B is hidden
    where the body model's capsules on A's points are nearer the camera. Frames where no
    person is found are missing observations for the partner."""
    from markovmotion.features.body_points import points_motion

    if tracker not in ("monocular", "triangulate"):
        raise ValueError(f"tracker must be monocular or triangulate, got {tracker!r}")
    dual = _load_partner_model(model)
    check_writable(out)  # before the tracking, not after
    where = cameras = read_camera_file(video, cameras)  # once: the triangulation takes it so
    cams, doc = load_cameras(where, paired=tracker == "triangulate" and not lone_video(video))
    if lone_video(video):  # one camera's video
        if tracker == "triangulate":
            raise MotionFormatError(video, "--method triangulate needs the folder of every camera")
        view = camera_of_video(cams, video)
        path = Path(video)
    elif not 0 <= view < len(cams):
        raise MotionFormatError(where, f"no camera {view}: the file has {len(cams)}")
    else:
        path = camera_videos(where, cams)[view]
    start = time.perf_counter()
    extra: dict = {}
    if tracker == "monocular":
        from markovmotion.video.monocular import MONOCULAR_SMOOTHING_S, track_monocular

        tr = track_monocular(
            path, cams[view], float(doc["fps"]), max_frames, smooth_s=MONOCULAR_SMOOTHING_S
        )
        if not tr.placed.any():
            raise MotionFormatError(path, "no person found in this video")
        extra = {"views": 1, "scale": round(tr.scale, 4), "notes": tr.notes}
    else:
        from markovmotion.video.triangulation import track_triangulated_video, whom_notes

        tr, found = track_triangulated_video(video, cameras, max_frames, person=person)
        extra = {
            "views": found["views"],
            "smoothing_s": found["smoothing_s"],
            "notes": found["notes"] + whom_notes(found, named=person is not None),
        }
    tracked = time.perf_counter() - start
    a = points_motion(tr.points, tr.fps, path.name)
    b = _respond(dual, a, method)
    written = write_video(
        composite_frames(
            read_frames(path, cams[view]), cams[view], tr.points, b, partner_caption(model)
        ),
        out,
        tr.fps,
    )
    n = len(tr.points)
    return {
        "method": tracker,
        "frames": n,
        "frames_placed": int(tr.placed.sum()),
        "fps": round(n / max(tracked, 1e-9), 2),
        "tracking_seconds": round(tracked, 2),
        "partner_frames": b.n_frames,
        "out": str(written),
        "view": view,
        "camera": cams[view].name,
        **extra,
        "notes": extra["notes"] + framing_notes(cams, view, b),
    }


def _respond_live(
    model, video, out, body: BodyModel, cameras, view: int, particles: int, layers: int,
    max_frames: int | None,
) -> dict:  # fmt: skip
    """:func:`_track_live` with BLAS on one thread, as the whole video's tracking
    (:func:`~markovmotion.video.annealed_particle_filter.track_features`)."""
    with threadpool_limits(1, user_api="blas"):
        return _track_live(model, video, out, body, cameras, view, particles, layers, max_frames)


def _track_live(
    model, video, out, body: BodyModel, cameras, view: int, particles: int, layers: int,
    max_frames: int | None,
) -> dict:  # fmt: skip
    """:func:`respond_in_video` live: frames arrive at the video's rate, each tracked and
    handed to the dual HMM's online partner as it comes.

    A frame is decoded only when the tracker is ready for it (no queue); a frame
    whose successor is already due is skipped (counted; the partner is told, and
    the tracker widens its search by the frames it missed). B's frames come
    ``lag`` frames late, as the windowed Viterbi decides them; the composite is
    written at the end, B drawn over the frames it answers. The first frame's
    search for the person (and the partner's first step) happen before the
    clock starts. A video at a whole multiple k of the model's rate (60 fps for a
    30 fps partner): the partner sees every k-th frame, and B is resampled to the
    video's rate to be drawn.
    """
    from markovmotion.models.online import concatenate

    dual = _load_partner_model(model)
    check_writable(out)  # before the tracking, not after
    mv = open_video(video, cameras, None, max_frames)  # before the clock
    if lone_video(video):
        view = 0
    if not 0 <= view < len(mv.cameras):
        raise MotionFormatError(mv.source, f"no camera {view}: the video has {len(mv.cameras)}")
    partner = dual.partner()
    every = int(round(mv.fps / partner.fps))  # the partner sees every k-th video frame
    if every < 1 or not np.isclose(mv.fps, every * partner.fps):
        raise MotionFormatError(
            mv.source,
            f"live tracking needs the video at the model's {partner.fps:g} fps or a whole "
            f"multiple of it, not {mv.fps:g}: train the partner with --fps {mv.fps:g}, or leave "
            "out --realtime",
        )
    apf = AnnealedParticleFilter(body, mv.cameras, particles, layers, fps=mv.fps)
    period = 1.0 / mv.fps
    states: list[np.ndarray | None] = []
    b_frames, times = [], []
    skipped, gap = 0, 1
    first = next(mv.frames, None)
    if first is None:
        raise MotionFormatError(mv.source, "no frames in this video")
    # before the clock starts: the tracker's initial search and the partner's first step
    feats = mv.features_of(first, 0)
    x, _ = apf.step(feats)
    empty = [no_one(feats)]  # per tracked frame, as track_features has it
    dual.partner().step(body.motion(x[None], partner.fps))  # loads compiled kernels
    states.append(x)
    if (b := partner.step(body.motion(x[None], partner.fps))) is not None:
        b_frames.append(b)
    start = time.perf_counter() - period
    for i, frames in enumerate(mv.frames, start=1):
        due = start + i * period
        now = time.perf_counter()
        if now < due:
            time.sleep(due - now)
        tick = time.perf_counter()
        seen = i % every == 0  # a frame at the partner's rate
        if tick > due + period:  # the next frame is already here: drop this one
            skipped += 1
            gap += 1
            states.append(None)
            b = partner.skip() if seen else None
        else:
            feats = mv.features_of(frames, i)
            x, _ = apf.step(feats, gap)
            empty.append(no_one(feats))
            gap = 1
            states.append(x)
            b = partner.step(body.motion(x[None], partner.fps)) if seen else None
            times.append(time.perf_counter() - tick)
        if b is not None:
            b_frames.append(b)
    b_frames.extend(partner.finish())
    if not states or all(s is None for s in states):
        raise MotionFormatError(mv.source, "no frames tracked")
    if all(empty):  # as the whole video's tracking says it (it had answered no one)
        raise MotionFormatError(
            mv.source, "no person found in this video (no foreground in any view of any "
            f"frame tracked, {len(empty)} of {len(states)})",
        )  # fmt: skip
    if n := sum(empty):
        mv.video_notes.append(
            f"note: no one in any view in {n} of the {len(empty)} frames tracked: their poses "
            "are guesses, and the partner answered them"
        )
    filled = _fill_forward(states)
    a = body.motion(filled, mv.fps)
    b = at_video_rate(concatenate(b_frames, partner.fps), mv.fps, len(states))
    frames = read_frames(mv.videos[view], mv.cameras[view])  # decoded again: none kept
    written = write_video(
        composite_frames(frames, mv.cameras[view], body_points(a), b, partner_caption(model)),
        out,
        mv.fps,
    )
    ms = np.array(times or [0.0]) * 1e3
    return {
        "frames": len(states),
        "tracked": len(states) - skipped,
        "skipped": skipped,
        "latency_ms_median": round(float(np.median(ms)), 1),
        "latency_ms_p99": round(float(np.percentile(ms, 99)), 1),
        "lag_frames": int(partner.lag),
        "views": len(mv.cameras),
        "partner_frames": b.n_frames,
        "out": str(written),
        "view": view,
        "background": mv.background_notes,
        "notes": mv.video_notes + framing_notes(mv.cameras, view, b),
    }


def _load_partner_model(model: str | os.PathLike[str]):
    """The dual HMM of ``model``; one trained on markers answers with markers, drawn by the
    body parts they name (:func:`partner_body`), so they must name at least two."""
    from markovmotion.models.hmm.dual import DualHMM

    dual = DualHMM.load(model)
    if getattr(dual, "uses_markers", False):
        try:
            marker_shape(dual.marker_names_b_)
        except SkeletonMismatchError as err:
            raise SkeletonMismatchError(f"{model}: {err}") from None
    return dual


def _fill_forward(states: list[np.ndarray | None]) -> np.ndarray:
    """States with each missing one replaced by the last known (the first known at the start)."""
    first = next(s for s in states if s is not None)
    out, last = [], first
    for s in states:
        last = s if s is not None else last
        out.append(last)
    return np.array(out)


def _respond(dual, a: Motion, method: str) -> Motion | Markers:
    """B's response at the video's rate (the model works at its own)."""
    return at_video_rate(dual.respond(a, method), a.fps, a.n_frames)


def at_video_rate(b: Motion | Markers, fps: float, frames: int) -> Motion | Markers:
    """B resampled to the video's rate with a frame for each of the video's ``frames``: at the
    model's rate B ends up to a video frame early (100 frames at 60 fps are 50 at 30, which
    span 99 at 60), so its last frame is held to the end."""
    from markovmotion.models.online import concatenate

    if not np.isclose(b.fps, fps):
        b = b.resample(fps)
    if b.n_frames >= frames:
        return b
    last = b.trim(b.n_frames - 1, b.n_frames)
    return concatenate([b] + [last] * (frames - b.n_frames), fps)
