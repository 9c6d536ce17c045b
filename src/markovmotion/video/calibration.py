"""Cameras from a Pose2Sim / Anipose calibration file (``Calib.toml``) to ``cameras.json``.

Multi-camera labs calibrate with Pose2Sim or Anipose (aniposelib), which write one TOML
section per camera::

    [cam_01]
    name = "cam_01"
    size = [1088.0, 1920.0]              # width, height of the calibrated images (px)
    matrix = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]
    distortions = [k1, k2, p1, p2]       # OpenCV's model
    rotation = [rx, ry, rz]              # world to camera, a Rodrigues vector (OpenCV)
    translation = [tx, ty, tz]           # world to camera (Pose2Sim: metres)
    fisheye = false

:func:`cameras_from_toml` reads such a file into the project's cameras
(:mod:`markovmotion.video.cameras`): the translation in mm, the world turned from the
calibration's up axis (Pose2Sim's world is Z up) to the project's Y up, the intrinsics scaled
to the size of the videos given (``u' = (u + 1/2) s - 1/2``: pixel centres kept, so a video
shrunk to a quarter keeps its calibration), the lens distortion kept (dimensionless: it does
not scale). Written here because neither Pose2Sim nor aniposelib is a dependency (nor
needed for the reading: Python's ``tomllib`` reads the file; ``cv2.Rodrigues`` turns the
rotation). OpenCV's fisheye model is a different lens model and is refused.

Qualisys systems (the Miqus video cameras of the real video, ``../shared/data/video``) write
a ``.qca.txt`` XML file instead; :func:`cameras_from_qca` reads it as Pose2Sim's
``calib_qca_to_toml`` converts it (so both give the same cameras): the video cameras only
(model "Miqus Video ..." or "none"), in the natural order of their serials; the intrinsics
in the file's sub-pixel units (1/64 px) and relative to the video's field of view; the
lens distortion likewise divided by 64 (Pose2Sim's reading); each camera's ``transform`` its
position (mm) and orientation in the world, whose camera axes are OpenCV's turned half a turn
about x. :func:`calibration_cameras` picks the reader by the file's first characters.
"""

from __future__ import annotations

import os
import tomllib
import xml.etree.ElementTree as ET
from pathlib import Path

import cv2
import numpy as np

from markovmotion.defaults import MAX_CAMERAS
from markovmotion.errors import MotionFormatError
from markovmotion.progress import note
from markovmotion.video.cameras import (
    CAMERAS_FILE,
    CalibratedCamera,
    one_number,
    placement_notes,
    read_distortion,
    read_matrix,
    read_small_text,
    save_cameras,
    valid_camera,
)
from markovmotion.video.render import natural_key, video_fps

#: The calibration's up axis to the project's world (Y up, mm): rows are the project's X,
#: Y, Z in the calibration's axes (a rotation, so handedness is kept).
UP_AXES: dict[str, np.ndarray] = {
    "z": np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]]),  # Pose2Sim, Qualisys: X=x, Y=z, Z=-y
    "y": np.eye(3),
    "-y": np.array([[1.0, 0, 0], [0, -1, 0], [0, 0, -1]]),  # OpenCV's camera-like: Y down
}
#: Metres (Pose2Sim) or millimetres (Anipose with a board measured in mm) to mm.
UNITS: dict[str, float] = {"m": 1000.0, "mm": 1.0}


def _video_size(video: Path) -> tuple[int, int]:
    if not Path(video).is_file():
        raise MotionFormatError(video, "no such video file")
    cap = cv2.VideoCapture(str(video))
    ok, frame = cap.read() if cap.isOpened() else (False, None)
    cap.release()
    if not ok:
        raise MotionFormatError(video, "cannot read a frame of this video")
    return frame.shape[1], frame.shape[0]


def cameras_from_toml(
    path: str | os.PathLike[str],
    videos: list[Path],
    up: str = "z",
    units: str = "m",
) -> list[CalibratedCamera]:
    """The cameras of a Pose2Sim / Anipose ``Calib.toml`` (module docstring), one per
    section with a ``matrix``, in the file's order, for ``videos`` (one per camera, same
    order: each camera's intrinsics are scaled to its video's size).

    Raises:
        MotionFormatError: not TOML, a camera without a valid field, a fisheye camera,
            another number of videos than cameras, or a video of another shape than its
            calibrated images."""
    path = Path(path)
    if up not in UP_AXES or units not in UNITS:
        raise ValueError(f"up must be one of {', '.join(UP_AXES)} and units of {', '.join(UNITS)}")
    text = read_small_text(path, "no such calibration file", "calibration file")
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise MotionFormatError(path, f"not a TOML calibration file ({exc})") from None
    sections = [(k, v) for k, v in doc.items() if isinstance(v, dict) and "matrix" in v]
    if not 1 <= len(sections) <= MAX_CAMERAS:
        raise MotionFormatError(
            path, f"{len(sections)} cameras (sections with a matrix): 1 to {MAX_CAMERAS} are read"
        )
    if len(videos) != len(sections):
        raise MotionFormatError(
            path, f"{len(sections)} cameras but {len(videos)} videos: give one video per camera"
        )
    turn = UP_AXES[up]
    out = []
    for (key, sec), video in zip(sections, videos, strict=True):
        name = str(sec.get("name", key))[:64]
        if sec.get("fisheye", False):
            raise MotionFormatError(path, f"[{key}] is a fisheye camera: not supported")
        size = read_matrix(path, f"[{key}] size", sec.get("size"), (2,))
        k = read_matrix(path, f"[{key}] matrix", sec.get("matrix"), (3, 3))
        dist = read_distortion(path, f"[{key}] distortions", sec.get("distortions", []))
        rvec = read_matrix(path, f"[{key}] rotation", sec.get("rotation"), (3,))
        t = read_matrix(path, f"[{key}] translation", sec.get("translation"), (3,)) * UNITS[units]
        r = cv2.Rodrigues(rvec)[0] @ turn.T  # the project's world to the camera
        out.append(_for_video(path, f"[{key}]", name, video, size, k, r, t, dist))
    return out


#: Qualisys camera models with video (:func:`cameras_from_qca`; "none": written by a tool).
QCA_VIDEO_MODELS = ("miqus video", "none")


def _number(path: Path, where: str, attrib: dict, key: str) -> float:
    """A finite number from an XML element's attribute, or one line naming it."""
    try:
        value = float(attrib[key])
    except (KeyError, ValueError):
        raise MotionFormatError(path, f"{where}: no number {key}") from None
    if not np.isfinite(value):
        raise MotionFormatError(path, f"{where}: {key} is not finite")
    return value


def cameras_from_qca(
    path: str | os.PathLike[str], videos: list[Path], up: str = "z"
) -> list[CalibratedCamera]:
    """The video cameras of a Qualisys ``.qca.txt`` calibration (module docstring), in the
    natural order of their serials, for ``videos`` (one per camera, same order; each
    camera's intrinsics scaled to its video's size, as :func:`cameras_from_toml`).

    Raises:
        MotionFormatError: not a Qualisys calibration (or one with a DOCTYPE), a camera
            without a valid field, another number of videos than video cameras, or a video
            of another shape than its field of view."""
    path = Path(path)
    if up not in UP_AXES:
        raise ValueError(f"up must be one of {', '.join(UP_AXES)}")
    text = read_small_text(path, "no such calibration file", "calibration file")
    if "<!DOCTYPE" in text or "<!ENTITY" in text:
        raise MotionFormatError(path, "a calibration file with a DOCTYPE or entities is not read")
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise MotionFormatError(path, f"not a Qualisys calibration file ({exc})") from None
    found = [
        c
        for c in root.findall("cameras/camera")
        if str(c.get("model", "none")).lower().startswith(QCA_VIDEO_MODELS)
    ]
    if not 1 <= len(found) <= MAX_CAMERAS:
        raise MotionFormatError(
            path, f"{len(found)} video cameras (cameras/camera): 1 to {MAX_CAMERAS} are read"
        )
    found.sort(key=lambda c: natural_key(c.get("serial", "")))
    if len(videos) != len(found):
        raise MotionFormatError(
            path, f"{len(found)} video cameras but {len(videos)} videos: give one video per camera"
        )
    turn = UP_AXES[up]
    out = []
    for cam_el, video in zip(found, videos, strict=True):
        name = str(cam_el.get("serial", f"cam{len(out) + 1}"))[:64]
        where = f"camera {name}"
        fov, intr, tr = (cam_el.find(k) for k in ("fov_video", "intrinsic", "transform"))
        if fov is None or intr is None or tr is None:
            raise MotionFormatError(path, f"{where}: needs fov_video, intrinsic and transform")
        left, top, right, bottom = (
            _number(path, f"{where} fov_video", fov.attrib, k)
            for k in ("left", "top", "right", "bottom")
        )
        size = np.array([right - left + 1.0, bottom - top + 1.0])
        fu, fv, cu, cv = (
            _number(path, f"{where} intrinsic", intr.attrib, k) / 64.0
            for k in ("focalLengthU", "focalLengthV", "centerPointU", "centerPointV")
        )
        k = np.array([[fu, 0.0, cu - left], [0.0, fv, cv - top], [0.0, 0.0, 1.0]])
        dist = tuple(
            _number(path, f"{where} intrinsic", intr.attrib, key) / 64.0
            for key in (
                "radialDistortion1", "radialDistortion2", "tangentalDistortion1",
                "tangentalDistortion2",
            )
        )  # fmt: skip
        m = np.array(
            [
                [_number(path, f"{where} transform", tr.attrib, f"r{i}{j}") for j in "123"]
                for i in "123"
            ]
        )
        position = np.array([_number(path, f"{where} transform", tr.attrib, a) for a in "xyz"])
        r = np.diag([1.0, -1.0, -1.0]) @ m  # the world to OpenCV's camera axes
        t = -r @ position
        out.append(_for_video(path, where, name, video, size, k, r @ turn.T, t, dist))
    return out


def _for_video(
    path: Path,
    where: str,
    name: str,
    video: Path,
    size: np.ndarray,
    k: np.ndarray,
    r: np.ndarray,
    t: np.ndarray,
    dist: tuple[float, ...],
) -> CalibratedCamera:
    """A camera calibrated at ``size`` (width, height) made for ``video``: its intrinsics ``k``
    scaled to the video's size (pixel centres kept), checked; one line when the video has
    another shape."""
    width, height = _video_size(video)
    if not (size > 0).all() or abs(width / height - size[0] / size[1]) > 0.01 * width / height:
        raise MotionFormatError(
            video, f"is {width}x{height}; camera {name} was calibrated at "
            f"{size[0]:g}x{size[1]:g} (another shape)",
        )  # fmt: skip
    scale = np.array([width / size[0], height / size[1]])
    if not np.isclose(scale[0], scale[1], rtol=1e-4):
        note(
            f"{video.name} is {width}x{height} and camera {name} was calibrated at "
            f"{size[0]:g}x{size[1]:g}: its intrinsics are scaled by {scale[0]:.4f} across and "
            f"{scale[1]:.4f} down (a video stretched to another shape; if it was cropped "
            "instead, its pixels are off by up to the difference)"
        )
    k = k.copy()
    k[:2, :2] *= scale[:, None]
    k[:2, 2] = (k[:2, 2] + 0.5) * scale - 0.5
    cam = CalibratedCamera(k, r, t, width, height, name, video.name, "", dist)
    valid_camera(path, where, cam)
    return cam


def calibration_cameras(
    path: str | os.PathLike[str], videos: list[Path], up: str = "z", units: str = "m"
) -> list[CalibratedCamera]:
    """The cameras of a calibration file: a Qualisys ``.qca.txt`` (XML: :func:`cameras_from_qca`,
    its own units, mm) or a Pose2Sim / Anipose TOML (:func:`cameras_from_toml`)."""
    head = read_small_text(Path(path), "no such calibration file", "calibration file")[:200]
    if head.lstrip().startswith("<") or Path(path).name.lower().endswith((".qca.txt", ".qca")):
        return cameras_from_qca(path, videos, up)
    return cameras_from_toml(path, videos, up, units)


def check_order(
    names: list[str], videos: list[Path], calibration: str | os.PathLike[str] = "calibration"
) -> None:
    """Refuse videos given in another order than the calibration's cameras, when both are
    numbered alike (each camera's name and each video's file name hold one number, the same
    numbers on both sides, in another order: ``cam02.mp4`` given for ``int_cam01_img``):
    each camera would be paired with another camera's video, and every 3-D point would be
    wrong without a word. Names that do not say (serials, other numbers) are not checked.

    Raises:
        MotionFormatError: the order that matches, in one line."""
    cams = [one_number(n) for n in names]
    vids = [one_number(Path(v).stem) for v in videos]
    if None in cams or None in vids or len(set(cams)) != len(cams) or sorted(cams) != sorted(vids):
        return
    if cams != vids:
        by_number = {n: Path(v).name for n, v in zip(vids, videos, strict=True)}
        raise MotionFormatError(
            calibration,
            "the videos are in another order than its cameras ("
            + ", ".join(names)
            + "): give them as "
            + " ".join(by_number[n] for n in cams),
        )


def check_placement(cameras: list, up: str, units: str) -> None:
    """Notes when the cameras' places look like a wrong ``--units`` (the widest pair of
    cameras closer than a person's width, or further than 100 m, apart) or ``--up`` (a
    camera below the floor, world Y = 0; :func:`~markovmotion.video.cameras.placement_notes`):
    a file in metres read as mm put the cameras a few mm from one another, and a Z-up file
    read as Y-up laid the person on their side, both tracked at confidence 0.93 without a
    word."""
    for line in placement_notes(
        cameras, f"read with --units {units}", "is that the calibration's unit?",
        f", up read as --up {up}", "is that the calibration's up axis?",
    ):  # fmt: skip
        note(line)


def import_calibration(
    calibration: str | os.PathLike[str],
    videos: list[Path],
    out: str | os.PathLike[str] | None = None,
    fps: float | None = None,
    up: str = "z",
    units: str = "m",
    force: bool = False,
) -> Path:
    """``video cameras``: write ``cameras.json`` for ``videos`` from ``calibration`` (a
    Pose2Sim / Anipose TOML or a Qualisys ``.qca.txt``, :func:`calibration_cameras`) beside
    the videos (or at ``out``),
    at ``fps`` (default: the first video's rate). The videos must share one folder. An
    existing camera file is replaced only with ``force``."""
    if not videos:
        raise MotionFormatError(calibration, "no videos given: one per camera, in its order")
    folders = {Path(os.path.abspath(v)).parent for v in videos}  # links not followed
    if len(folders) != 1:
        raise MotionFormatError(
            videos[0], "the videos must be in one folder (cameras.json names them)"
        )
    cameras = calibration_cameras(calibration, videos, up, units)
    check_order([c.name for c in cameras], videos, calibration)
    check_placement(cameras, up, units)
    rate = fps if fps is not None else video_fps(videos[0], 0.0)
    if not rate > 0:
        raise MotionFormatError(videos[0], "no frame rate in this video: give --fps")
    target = Path(out) if out is not None else folders.pop() / CAMERAS_FILE
    if target.exists() and not force:
        raise MotionFormatError(target, "exists: give --force to replace it (or --out)")
    return save_cameras(cameras, target, rate, source=str(Path(calibration).name), up=up)
