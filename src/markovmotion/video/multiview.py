"""Multi-view video of motion capture with ground truth, and 3-D tracking of it (dual-HMM paper, §3).

:func:`render_multiview` renders a take as the person the tracker sees: the
body model's flesh (:data:`~markovmotion.video.body_model.BODY_SHAPE`) on
the take's body points, seen by 1 to 6 calibrated cameras spaced around the
capture volume (Deutscher et al. used three), over a static textured
background with sensor noise; person A alone (B masked) or both. It writes
one video per camera and ``cameras.json``.

:func:`collection_body_model` learns the body model from every skeleton take of the
collection, retargeted onto the template (the default, :func:`default_body_model`);
:func:`training_body_model` from the training handshake and pull takes alone;
:func:`track_take` tracks a multi-view video and, given the true motion, measures the
error over the body points.
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Iterator, Sequence
from pathlib import Path

import cv2
import numpy as np

from markovmotion.core.motion import GROUND, Motion
from markovmotion.data.index import MocapIndex, listed_entry, read_listed_motion
from markovmotion.data.splits import held_out_pairs
from markovmotion.defaults import TRACK_METHODS
from markovmotion.errors import DataNotFoundError, MotionFormatError
from markovmotion.features.body_points import BODY_POINTS, body_points
from markovmotion.io.files import atomic_path
from markovmotion.limits import MAX_FRAMES
from markovmotion.video.annealed_particle_filter import TrackResult, track_video
from markovmotion.video.body_model import BODY_SHAPE, BodyModel, local_rotvecs
from markovmotion.video.cameras import CalibratedCamera, ring_of_cameras, save_cameras
from markovmotion.video.render import background, write_video
from markovmotion.video.retarget import Template
from markovmotion.video.shading import CLOTHES, DepthCanvas, capsule_colours

#: Labels of the two-person takes the interaction body model learns from; person A of the
#: first training take of them is the template of every body model.
BODY_LABELS = ("handshake", "pull")
#: The body models ``track --body-model`` builds: from every skeleton take of the collection
#: (retargeted), or from the training takes of :data:`BODY_LABELS` alone (the template's own).
BODY_MODELS = ("collection", "interaction")
#: At most this many frames of each label (at :data:`~markovmotion.video.retarget.RETARGET_FPS`)
#: go into the collection's body model, so that hours of walks do not outweigh a dance.
LABEL_FRAMES = 1000


def shaded_frames(
    people: list[np.ndarray],
    camera: CalibratedCamera,
    bg: np.ndarray,
    noise: float = 4.0,
    seed: int = 0,
) -> Iterator[np.ndarray]:
    """RGB frames of people (each (F, 19, 3) body points, mm) shaded over ``bg``, with noise."""
    rng = np.random.default_rng(seed)
    colours = [capsule_colours(BODY_SHAPE, BODY_POINTS, CLOTHES[k]) for k in ("a", "b")]
    for t in range(len(people[0])):
        canvas = DepthCanvas(camera.width, camera.height)
        for k, p in enumerate(people):
            canvas.body(p[t], camera, BODY_SHAPE, colours[k % 2], k)
        img = canvas.over(bg).astype(np.float32)
        img += rng.normal(0.0, noise, img.shape).astype(np.float32)
        yield np.clip(img, 0, 255).round().astype(np.uint8)


def load_take(path: str | os.PathLike[str], people: str = "a") -> tuple[Motion, Motion | None]:
    """Person A of a take and, for ``people="both"``, its partner (from the collection's index)."""
    path = Path(path)
    entry = listed_entry(path)
    if people == "both":
        if entry is None or not entry.partner_file:
            raise DataNotFoundError(f"{path}: no partner listed for this file in INDEX.csv")
        index = MocapIndex.load()
        return index.load_pair(entry, index.find(entry.partner_file))
    return read_listed_motion(path), None


def render_multiview(
    take: str | os.PathLike[str],
    out: str | os.PathLike[str],
    views: int = 3,
    seconds: float | None = None,
    fps: float | None = None,
    people: str = "a",
    size: tuple[int, int] = (320, 240),
    noise: float = 4.0,
    seed: int = 0,
    start: float = 0.0,
) -> Path:
    """Render ``take`` (a BVH/ASF-AMC file) into ``out``: ``camK.mp4`` per camera and
    ``cameras.json``; returns the path of ``cameras.json``."""
    a, b = load_take(take, people)
    fps = fps or a.fps
    if not np.isclose(fps, a.fps):
        a = a.resample(fps)
        b = b.resample(fps) if b is not None else None
    first = int(round(start * fps))
    stop = None if seconds is None else first + max(1, int(round(seconds * fps)))
    a = a.trim(first, stop)
    b = b.trim(first, stop) if b is not None else None
    if a.n_frames < 1:
        raise MotionFormatError(take, f"no frames from {start:g} s")
    if a.n_frames > MAX_FRAMES.value:
        raise MotionFormatError(take, f"more than {MAX_FRAMES.value:g} frames")
    bodies = [a] + ([b] if b is not None else [])
    pts = [body_points(m) for m in bodies]
    pelvis = np.concatenate([p[:, 0] for p in pts])
    centre = pelvis.mean(axis=0)
    reach = np.linalg.norm((pelvis - centre)[:, GROUND], axis=1).max()
    # camera 0 sees A from the side of its mean heading, at 45 degrees
    heading = float(np.median(a.heading())) if a.n_frames else 0.0
    cams = ring_of_cameras(
        centre,
        radius=2800.0 + 1.3 * reach,
        views=views,
        size=size,
        first_azimuth=heading + math.pi / 4,
    )
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    for k, cam in enumerate(cams):
        bg = background((cam.width, cam.height), seed + 7 * k)
        write_video(shaded_frames(pts, cam, bg, noise, seed + 7 * k), out / cam.video, fps)
        with atomic_path(out / cam.background) as tmp:
            cv2.imwrite(str(tmp), cv2.cvtColor(bg, cv2.COLOR_RGB2BGR))
    return save_cameras(
        cams,
        out / "cameras.json",
        fps,
        source=Path(take).name,
        rendered=True,
        start_frame=first,
        people=people,
    )


def training_body_model(
    data: str | os.PathLike[str] | None = None,
    labels: tuple[str, ...] = BODY_LABELS,
    include_held_out: bool = False,
    max_dof: int = 28,
) -> BodyModel:
    """The body model learnt from both people of the collection's training takes of ``labels``
    (its skeleton: person A's of the first take): skeleton takes only, markers takes of
    the labels left out without a word (the tracker's body model is not a model of them)."""
    index = MocapIndex.load(data)
    pairs = index.pairs(label=list(labels))
    if not any(a.kind == "skeleton" for a, _ in pairs):
        raise DataNotFoundError(
            f"no skeleton two-person takes labelled {', '.join(labels)} in {index.root} "
            "for the body model"
        )
    # skeleton takes only, by design: no note about the markers takes left out (the user
    # asked for a tracker, not for a model of these takes)
    pairs = [p for p in pairs if p[0].kind == "skeleton"]
    train, test = held_out_pairs(pairs)
    motions = []
    for a, b in train + (test if include_held_out else []):
        ma, mb = index.load_pair(a, b)
        motions += [ma.resample(30.0), mb.resample(30.0)]
    return BodyModel.fit(motions, max_dof=max_dof)


def collection_body_model(
    data: str | os.PathLike[str] | None = None,
    leave_out: Sequence[str] = (),
    max_dof: int = 28,
    label_frames: int = LABEL_FRAMES,
) -> BodyModel:
    """The body model learnt from every skeleton take of the collection (BVH and ASF/AMC, any
    skeleton whose body points are found), retargeted onto the template
    (:mod:`~markovmotion.video.retarget`): its principal axes and joint ranges cover what the
    collection's people do, not only the handshakes and pulls. The takes:
    :func:`collection_takes`; the axes chosen backward, the limits without the
    :data:`LIMIT_TAIL` at each end, the speeds from the takes at the retargeting's full rate
    (:meth:`BodyModel.fit_rotvecs`), the standing height the template's own.

    Raises:
        DataNotFoundError: no skeleton take is left.
    """
    from markovmotion.video.retarget import RETARGET_FPS

    template, takes = collection_takes(data, leave_out, label_frames)
    body = BodyModel.fit_rotvecs(
        template.skeleton, takes, max_dof=max_dof, tail=LIMIT_TAIL, speed_fps=0.99 * RETARGET_FPS
    )
    return dataclasses.replace(body, height=template.height)


def collection_takes(
    data: str | os.PathLike[str] | None = None,
    leave_out: Sequence[str] = (),
    label_frames: int = LABEL_FRAMES,
) -> tuple[Template, list[tuple[np.ndarray, np.ndarray, float]]]:
    """The template and every skeleton take of the collection as its poses: per take (or run
    of frames) local rotation vectors (F, J, 3), root positions (F, 3) and frame rate.

    The template is person A of the first training take of :data:`BODY_LABELS` (else the
    first take left); its own takes of those labels give the IK's pose prior and enter with
    their own rotations. Left out: the held-out two-person takes of every label
    (:func:`~markovmotion.data.splits.held_out_pairs`, the split the tracker's benchmarks
    render), the labels in ``leave_out``, takes whose body points are not all found (a
    note names them), and retargeted frames with a joint beyond :data:`HALF_TURN`. Each
    label gives at most ``label_frames`` frames, every ``round(fps / RETARGET_FPS) * k``-th
    frame of its takes with ``k`` as small as allows. Retargeted takes are cached
    (:func:`~markovmotion.video.retarget.retarget_file`).
    """
    from markovmotion.errors import SkeletonMismatchError
    from markovmotion.progress import note, track
    from markovmotion.video.retarget import RETARGET_FPS, Template, retarget_file

    index = MocapIndex.load(data)
    _, test = held_out_pairs(index.pairs(kind="skeleton"))
    unseen = {e.file for pair in test for e in pair}
    entries = [
        e for e in index.query(kind="skeleton") if e.label not in leave_out and e.file not in unseen
    ]
    if not entries:
        raise DataNotFoundError(f"no skeleton takes in {index.root} for the body model")
    own = [e for a, b in index.pairs(label=list(BODY_LABELS), kind="skeleton") for e in (a, b)]
    own = [e for e in own if e in entries] or entries[:1]
    stride = {e.file: max(1, round(e.fps / RETARGET_FPS)) for e in entries}
    per_label: dict[str, float] = {}
    for e in entries:
        per_label[e.label] = per_label.get(e.label, 0.0) + e.frames / stride[e.file]
    for e in entries:
        stride[e.file] *= max(1, math.ceil(per_label[e.label] / label_frames))
    template_motions = [index.load_motion(e) for e in own]
    template = Template.fit(template_motions)
    sk = template.skeleton
    takes, done, skipped = [], set(), []
    for e, m in zip(own, template_motions, strict=True):
        if m.skeleton.same_topology(sk):
            s = stride[e.file]
            takes.append((local_rotvecs(m)[::s], m.translations[::s, 0], m.fps / s))
            done.add(e.file)
    rest = [e for e in entries if e.file not in done]
    for e in track(rest, "retargeting takes to the body model", total=len(rest)):
        try:
            rv, root, _ = retarget_file(template, e.path, e.read, stride[e.file])
        except SkeletonMismatchError:
            skipped.append(e.file)
            continue
        # a joint near a half turn: a wrong basin of the IK (no elbow or knee bends 160
        # degrees), where rotation vectors also wrap; such frames are left out
        sane = (np.linalg.norm(rv[:, template.free[1:]], axis=-1) < HALF_TURN).all(axis=1)
        for run in _runs(sane):
            takes.append((rv[run], root[run], e.fps / stride[e.file]))
    if skipped:
        note(f"body model: {len(skipped)} takes without every body point left out: "
             f"{', '.join(skipped[:6])}")  # fmt: skip
    return template, takes


#: The collection's joint limits leave out this share of frames at each end of every
#: coefficient's range (:meth:`BodyModel.fit_rotvecs`).
LIMIT_TAIL = 0.005
#: Retargeted frames with a joint's rotation (rad) beyond this are left out (160 degrees).
HALF_TURN = np.radians(160.0)


def _runs(mask: np.ndarray) -> list[slice]:
    """Slices of the runs of True in ``mask`` (two frames or more)."""
    edges = np.flatnonzero(np.diff(np.r_[0, mask.astype(np.int8), 0]))
    return [slice(a, b) for a, b in zip(edges[::2], edges[1::2], strict=True) if b - a >= 2]


def default_body_model(
    data: str | os.PathLike[str] | None = None, which: str = "interaction"
) -> BodyModel:
    """The body model ``track`` and ``respond --video`` use (:data:`BODY_MODELS`)."""
    if which == "interaction":
        return training_body_model(data)
    return collection_body_model(data)


def tracking_errors(tracked: Motion, truth: Motion) -> dict:
    """MPJPE (mm) over the body points, per point, per frame, of a tracked motion vs the truth."""
    return points_errors(body_points(tracked), tracked.fps, truth)


def points_errors(points: np.ndarray, fps: float, truth: Motion) -> dict:
    """MPJPE (mm) of tracked body points (F, 19, 3) at ``fps`` against the truth's, per point and
    per frame (a point not tracked, NaN, left out; None where nothing is left)."""
    if not np.isclose(fps, truth.fps):
        truth = truth.resample(fps)
    n = min(len(points), truth.n_frames)
    err = np.linalg.norm(points[:n] - body_points(truth)[:n], axis=-1)  # (F, 19)

    def mm(values: np.ndarray) -> float | None:
        values = values[np.isfinite(values)]
        return round(float(values.mean()), 1) if values.size else None

    return {
        "mpjpe_mm": mm(err.ravel()),
        "per_joint_mm": {p: mm(e) for p, e in zip(BODY_POINTS, err.T, strict=True)},
        "per_frame_mm": [mm(e) for e in err],
        "frames_compared": n,
    }


def check_truth(
    truth: str | os.PathLike[str],
    video: str | os.PathLike[str],
    cameras: str | os.PathLike[str] | None = None,
) -> str | None:
    """``track --truth``, before any tracking: a motion file (BVH or ASF/AMC), else one line
    (:class:`MotionFormatError`); and a note when the camera file names another take as the
    one ``video render`` rendered (its ``source``): measured against the wrong take, the
    error is only a large number."""
    from markovmotion.io import MOTION_SUFFIXES
    from markovmotion.io.files import base_suffix
    from markovmotion.video.cameras import camera_file, load_cameras

    truth = Path(truth)
    if not truth.is_file():
        raise MotionFormatError(truth, "no such file (--truth)")
    if base_suffix(truth) not in MOTION_SUFFIXES:
        raise MotionFormatError(truth, "--truth is the rendered take's motion (BVH or ASF/AMC)")
    _, doc = load_cameras(camera_file(video, cameras))
    source = doc.get("source")
    if isinstance(source, str) and base_suffix(source) in MOTION_SUFFIXES:
        if Path(source).name != truth.name:
            return f"note: this video was rendered from {source}, not from {truth.name} (--truth)"
    return None


def truth_errors(
    points: np.ndarray,
    fps: float,
    truth: str | os.PathLike[str],
    video: str | os.PathLike[str],
    cameras: str | os.PathLike[str] | None = None,
) -> dict:
    """``track --truth``: tracked body points (F, 19, 3) at ``fps`` against a rendered take's
    capture (:func:`points_errors`), aligned by the ``start_frame`` ``video render`` wrote in
    the camera file (and the first camera's ``skip_frames``: the track starts there)."""
    from markovmotion.video.cameras import camera_file, load_cameras

    cams, doc = load_cameras(camera_file(video, cameras))
    start = doc.get("start_frame", 0)
    start = (start if isinstance(start, int) else 0) + cams[0].skip
    true = read_listed_motion(truth)
    if not np.isclose(true.fps, fps):
        true = true.resample(fps)
    return points_errors(points, fps, true.trim(start))


#: ``--guide``: ``auto`` (the default) is ``mediapipe`` for real video, ``none`` for rendered.
GUIDES = ("auto", "none", "mediapipe")


#: What one view leaves the particle filter, in one note: ``track``'s own note on one view
#: and ``--guide auto``'s had both been printed, each offering ``--method monocular``.
ONE_VIEW_NOTE = (
    "note: one view: the particle filter follows the image alone (MediaPipe's guide "
    "triangulates, which needs two views), its depth and mirror ambiguous (hundreds of mm off, "
    "docs/video.md); for one camera, --method monocular"
)


def resolve_guide(guide: str, doc: dict, views: int = 2) -> tuple[bool, str | None]:
    """Whether MediaPipe guides the particle filter, for ``--guide``, a camera file's
    document ``doc`` and the number of ``views`` tracked; and a note to print when ``auto``
    cannot guide real video.

    ``auto`` guides real people's video: on the real 4-view video the guide takes the error
    from 144-245 mm (images alone, by seed and background) to 111-114 mm, at its native
    1088x1920 from 221.7 to 111.3 mm (docs/video.md). It leaves ``video render``'s video alone
    (:func:`~markovmotion.video.cameras.is_rendered`): its people are capsules, which MediaPipe
    misreads (a held-out pull 57.3 mm unguided, 154.1 guided). Without MediaPipe installed it
    tracks by the images and says so. The guide is MediaPipe's landmarks triangulated, so one
    view gives it nothing: ``auto`` then says so (:data:`ONE_VIEW_NOTE`, which says the rest
    one view leaves the filter), ``mediapipe`` is refused.

    Raises:
        ValueError: an unknown ``guide``, or ``mediapipe`` for one view."""
    from markovmotion.video.cameras import is_rendered
    from markovmotion.video.monocular import mediapipe_installed

    if guide not in GUIDES:
        raise ValueError(f"guide must be one of {', '.join(GUIDES)}, got {guide!r}")
    if guide == "mediapipe" and views < 2:
        raise ValueError(
            "guide mediapipe triangulates MediaPipe's landmarks, which needs at least 2 views; "
            "for one camera, --method monocular"
        )
    if guide != "auto":
        return guide == "mediapipe", None
    if is_rendered(doc):
        return False, None
    if views < 2:
        return False, ONE_VIEW_NOTE
    if not mediapipe_installed():
        return False, (
            "note: MediaPipe is not installed (scripts/install-camera), so the particle filter "
            "follows the images alone; on real people its guide halves the error (docs/video.md)"
        )
    return True, None


def resolve_method(
    method: str, views: int, filter_asked: bool = False, command: str = "track"
) -> tuple[str, str | None]:
    """``--method`` resolved for the number of ``views`` tracked, with the note to print
    when ``auto`` chose; ``filter_asked``: the particle filter was asked for, by what it
    alone gives or reads (``--out A.bvh``, ``--particles``, ``--guide``, ``--realtime``...);
    ``command``: ``track`` or ``respond`` (``dualhmm respond --video``), whose note says how
    that command asks for the filter (respond's ``--out`` is the composite, never a BVH).

    ``auto`` is the most accurate tracker measured for what is asked (docs/video.md): with
    MediaPipe installed (``scripts/install-camera``), ``triangulate`` for two views or more
    (the real 4-view video 78.5 mm from its reference against the guided particle filter's
    112.4; 11 rendered kinds of motion 58.9 mm against 88.6; about 15-25 frames/s against
    about 3) and ``monocular`` for one (the particle filter is 438.6 mm on one view, mirrored
    poses; MediaPipe alone 112.7 after rigid alignment). The particle filter (``apf``) is kept for what it alone gives:
    a skeleton on the body model (BVH), the live tracker of ``--realtime``, its own options,
    and video without MediaPipe installed (said by :func:`resolve_guide`'s note)."""
    from markovmotion.video.monocular import mediapipe_installed

    if method not in TRACK_METHODS:
        raise ValueError(f"method must be one of {', '.join(TRACK_METHODS)}, got {method!r}")
    if method != "auto":
        return method, None
    if filter_asked or not mediapipe_installed():
        return "apf", None
    chosen = "triangulate" if views >= 2 else "monocular"
    views_said = f"{views} views" if views >= 2 else "one view"
    filter_said = (
        "the particle filter: --method apf, or --realtime"
        if command == "respond"
        else "the particle filter's skeleton: --method apf or a .bvh --out"
    )
    return (
        chosen,
        f"note: --method auto chose {chosen} (MediaPipe Pose, {views_said}); {filter_said}",
    )


#: Share of frames whose search started again above which the track is said to be doubtful.
RESTARTS_NOTED = 0.2


def restarts_note(recoveries: int, frames: int, guided: bool = False) -> list[str]:
    """One note when the filter started its search again (its best particle fitted the views
    badly) in more than :data:`RESTARTS_NOTED` of the ``frames``: such a track is mostly
    wrong (a rendered two-person video unguided: 71 restarts in 90 frames, 1750 mm from the
    capture, without a word; the real video with a median background: 76 in 100, 379 mm);
    the docs' good tracks restart in no frame or a few. ``guided``: the filter already
    followed MediaPipe, so the note offers the triangulation and naming the person."""
    if frames == 0 or recoveries <= RESTARTS_NOTED * frames:
        return []
    then = (
        "--method triangulate, or --person CAMERA:U,V to name the person"
        if guided
        else "--guide mediapipe or --method triangulate follow the person MediaPipe finds"
    )
    return [
        f"note: the filter started its search again in {recoveries} of {frames} frames (the "
        "views fitted badly): the track is likely wrong (someone else or a second person in "
        f"view, a background that holds the person, a wrong calibration); {then}"
    ]


def track_take(
    video: str | os.PathLike[str],
    body: BodyModel,
    cameras: str | os.PathLike[str] | None = None,
    truth: str | os.PathLike[str] | None = None,
    particles: int = 200,
    layers: int = 10,
    views: int | None = None,
    max_frames: int | None = None,
    seed: int = 0,
    start: str | os.PathLike[str] | None = None,
    learn_background: bool = True,
    sides: bool = False,
    guide: bool = False,
    left_right: str = "views",
    person: str | None = None,
    size_from_views: bool = False,
) -> tuple[Motion, TrackResult, dict]:
    """Track a multi-view video; A's motion, the raw result, and a JSON-ready summary.

    With ``truth`` (the take's BVH), the summary has ``mpjpe_mm`` and per-joint
    errors, the truth aligned by the ``start_frame`` the renderer recorded. ``start``
    (a motion of the body model's skeleton) gives the first frame's pose instead of
    the coarse search. ``sides``: catch front/back flips with MediaPipe
    (:func:`~markovmotion.video.annealed_particle_filter.track_video`); the summary then has
    ``flips`` (frames searched again) and ``left_flipped`` (frames left flipped).
    ``guide``: MediaPipe in every view guides the filter; the summary then has
    ``guide_seconds`` (MediaPipe's time, not in ``fps``), ``guide_seen`` (the share of views
    and frames with landmarks to pull towards) and ``fps_with_guide``; ``left_right``: how
    MediaPipe's left and right are made consistent across the views first
    (:data:`~markovmotion.video.triangulation.LEFT_RIGHT`); ``person`` (``CAMERA:U,V``): of
    several people, the guide follows the one at that pixel; ``size_from_views``: the body's
    segments measured from MediaPipe's landmarks of every view first (the summary's
    ``body_size``; the motion is on the skeleton so scaled).
    """
    from markovmotion.video.cameras import read_camera_file

    cameras = read_camera_file(video, cameras)  # once: the tracker and --truth take it so
    first = None
    if start is not None:  # the first frame's pose, on the body model's skeleton
        first = body.states_of(read_listed_motion(start).trim(0, 1))[0]
    result = track_video(
        video, body, cameras, particles, layers, views, max_frames, seed, first, learn_background,
        sides, guide, left_right, person, size_from_views,
    )  # fmt: skip
    motion = (result.body or body).motion(result.states, result.fps, name=Path(video).name)
    summary = {
        "method": "apf",  # which tracker, as track_triangulated_video's summary says
        "frames": len(result.states),
        "fps": round(len(result.states) / max(result.seconds, 1e-9), 2),
        "fps_cpu": round(len(result.states) / max(result.cpu_seconds, 1e-9), 2),
        "video_fps": result.fps,
        "views": result.views,
        "particles": particles,
        "layers": layers,
        "dof": body.n_dof,
        "recoveries": result.recoveries,
        **({"flips": result.flips, "left_flipped": result.flipped} if sides else {}),
        **(
            {
                "guide": "mediapipe",
                "guide_seconds": round(result.guide_seconds, 1),
                "guide_seen": round(result.guide_seen or 0.0, 3),
                "views_of_someone_else": result.guide_someone_else,
                **result.guide_whom,
                "fps_with_guide": round(
                    len(result.states) / max(result.seconds + result.guide_seconds, 1e-9), 2
                ),
            }
            if guide
            else {}
        ),
        "confidence": [round(float(c), 3) for c in result.confidence],
        "ended_early": result.ended_early,
        "background": result.background_notes,
        "notes": [
            *result.video_notes,
            *restarts_note(result.recoveries, len(result.states), guide),
        ],
    }
    if truth is not None:
        summary.update(truth_errors(body_points(motion), result.fps, truth, video, cameras))
    return motion, result, summary
