"""Calibrated pinhole cameras of a multi-view video, and the ``cameras.json`` that stores them.

A camera maps world points (mm, Y up) to pixels (x right, y down, pixel
centres at integer coordinates) by ``x_cam = R X + t`` and
``u = fx x/z + cx``, ``v = fy y/z + cy`` (OpenCV's convention). A camera with
lens distortion (``distortion``: OpenCV's coefficients k1 k2 p1 p2 [k3 ...],
4, 5, 8, 12 or 14 of them) has its frames undistorted as they are read
(:meth:`CalibratedCamera.undistorter`), so everything after sees that pinhole
camera. ``cameras.json`` lies beside the videos::

    {"units": "mm", "fps": 30.0,
     "cameras": [{"name": "cam0", "video": "cam0.mp4", "width": 320, "height": 240,
                  "K": [[fx, 0, cx], [0, fy, cy], [0, 0, 1]],
                  "R": [[...], [...], [...]], "t": [tx, ty, tz],
                  "distortion": [0, 0, 0, 0, 0]}, ...]}

``units`` is the unit of ``t``: "mm" (the default), "cm" or "m"; ``R`` and ``t`` take
world points to the camera (not the camera's pose in the world: such a file is recognised,
:func:`convention_problem`). ``video`` is relative to the file (or, when the command is
given the videos' folder apart from the file, to that folder first); so is the optional
``background``, an image of the empty scene (else the tracker estimates it from the video). The optional
``skip_frames`` of a camera is how many frames of its video come before the cameras'
shared first frame (cameras started one after another; ``markovmotion video sync``
measures and writes it); every reader of the video with its camera skips them. Without
``fps`` the rate the videos' own headers agree on is taken, and said. Any real video with such a file is read
the same way as the rendered ones; a malformed file is one error naming the
file and the field.
"""

from __future__ import annotations

import copy
import difflib
import functools
import json
import math
import os
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np

from markovmotion.defaults import MAX_CAMERAS
from markovmotion.errors import MotionFormatError
from markovmotion.io import MOTION_SUFFIXES
from markovmotion.io.files import atomic_write, base_suffix
from markovmotion.progress import say
from markovmotion.video.render import FRAME_SUFFIXES, missing_frames_note

CAMERAS_FILE = "cameras.json"
MAX_SIDE = 4096
MAX_JSON_BYTES = 1_000_000
#: How many lens distortion coefficients OpenCV takes (k1 k2 p1 p2 [k3 [k4 k5 k6 [s1-s4 [tx ty]]]]).
DISTORTION_LENGTHS = (4, 5, 8, 12, 14)
#: Largest magnitude of a distortion coefficient accepted (real lenses: well under 10).
MAX_DISTORTION = 1000.0
#: Most frames a camera's video may skip to start with the others (``skip_frames``).
MAX_SKIP = 1_000_000


@dataclass(frozen=True)
class CalibratedCamera:
    """Intrinsics ``K`` (3, 3), rotation ``R`` (3, 3) world to camera, translation ``t`` (3,) mm."""

    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    width: int
    height: int
    name: str = "cam"
    video: str = ""
    background: str = ""
    #: OpenCV's lens distortion coefficients (k1 k2 p1 p2 [k3 ...]); () or zeros: none.
    distortion: tuple[float, ...] = ()
    #: Frames of its video before the cameras' shared first frame (``skip_frames``; cameras
    #: started at different times: ``markovmotion video sync`` measures it).
    skip: int = 0

    def undistorter(self) -> Callable[[np.ndarray], np.ndarray] | None:
        """None without lens distortion; else a function that makes a frame of this camera
        (H, W, C) the image of its pinhole model (same ``K``): OpenCV's undistortion maps
        (``cv2.initUndistortRectifyMap``), made once, applied by ``cv2.remap`` (bilinear)."""
        if not any(self.distortion):
            return None
        maps = cv2.initUndistortRectifyMap(
            self.K, np.asarray(self.distortion, float), None, self.K,
            (self.width, self.height), cv2.CV_16SC2,
        )  # fmt: skip
        return lambda image: cv2.remap(
            image, *maps, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE
        )

    @property
    def focal(self) -> float:
        """Mean focal length in pixels (the scale of a ball's radius at depth z: focal * r / z)."""
        return float(0.5 * (self.K[0, 0] + self.K[1, 1]))

    @property
    def centre(self) -> np.ndarray:
        """Optical centre in world coordinates (mm)."""
        return -self.R.T @ self.t

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixel coordinates (..., 2) and depths (...) in mm of world points (..., 3)."""
        cam = np.asarray(points, dtype=float) @ self.R.T + self.t
        z = np.maximum(cam[..., 2], 1.0)
        u = self.K[0, 0] * cam[..., 0] / z + self.K[0, 2]
        v = self.K[1, 1] * cam[..., 1] / z + self.K[1, 2]
        return np.stack([u, v], axis=-1), z

    def ray(self, pixel: np.ndarray) -> np.ndarray:
        """Unit direction in world coordinates of the ray through ``pixel`` (2,)."""
        d = np.array(
            [
                (pixel[0] - self.K[0, 2]) / self.K[0, 0],
                (pixel[1] - self.K[1, 2]) / self.K[1, 1],
                1.0,
            ]
        )
        d = self.R.T @ d
        return d / np.linalg.norm(d)

    def to_dict(self) -> dict:
        return {
            "name": self.name,
            "video": self.video,
            "width": self.width,
            "height": self.height,
            "K": self.K.tolist(),
            "R": self.R.tolist(),
            "t": self.t.tolist(),
            "distortion": [float(d) for d in self.distortion] or [0.0] * 5,
            **({"background": self.background} if self.background else {}),
            **({"skip_frames": self.skip} if self.skip else {}),
        }


def look_at(
    position: np.ndarray,
    target: np.ndarray,
    width: int,
    height: int,
    focal: float,
    name: str = "cam",
    video: str = "",
) -> CalibratedCamera:
    """A camera at ``position`` (mm) looking at ``target``, upright (world Y up is image up)."""
    position, target = np.asarray(position, float), np.asarray(target, float)
    z = target - position
    z /= np.linalg.norm(z)
    x = np.cross(z, [0.0, 1.0, 0.0])  # image right
    x /= np.linalg.norm(x)
    y = np.cross(z, x)  # image down
    r = np.stack([x, y, z])
    k = np.array([[focal, 0, width / 2], [0, focal, height / 2], [0, 0, 1.0]])
    return CalibratedCamera(k, r, -r @ position, int(width), int(height), name, video)


def ring_of_cameras(
    centre: np.ndarray,
    radius: float,
    views: int = 3,
    size: tuple[int, int] = (320, 240),
    height: float = 1800.0,
    first_azimuth: float = 0.0,
    fov_degrees: float = 50.0,
) -> list[CalibratedCamera]:
    """``views`` cameras evenly spaced around ``centre`` (mm) at ``radius``, looking at it from
    ``height`` (Deutscher et al.'s set-up: three cameras around the capture volume)."""
    width, h = size
    focal = 0.5 * width / math.tan(math.radians(fov_degrees) / 2)
    centre = np.asarray(centre, float)
    target = np.array([centre[0], 900.0, centre[2]])
    out = []
    for k in range(views):
        a = first_azimuth + 2 * math.pi * k / views
        pos = np.array([centre[0] + radius * math.sin(a), height, centre[2] + radius * math.cos(a)])
        cam = look_at(pos, target, width, h, focal, f"cam{k}", f"cam{k}.mp4")
        out.append(replace(cam, background=f"cam{k}_background.png"))
    return out


def is_rendered(doc: dict) -> bool:
    """Whether a camera file's video was made by ``video render`` (its people are the body
    model's capsules, not people): ``"rendered": true``, or, in a file written before that key,
    a motion file as its ``source`` (the take rendered; ``video cameras`` names a calibration
    there)."""
    if doc.get("rendered") is True:
        return True
    source = doc.get("source")
    return isinstance(source, str) and base_suffix(Path(source)) in MOTION_SUFFIXES


def save_cameras(
    cameras: list[CalibratedCamera], path: str | os.PathLike[str], fps: float, **extra
) -> Path:
    """Write ``cameras.json`` (atomically); ``extra`` keys (e.g. the source take) are kept."""
    doc = {"units": "mm", "fps": float(fps), **extra, "cameras": [c.to_dict() for c in cameras]}
    path = Path(path)
    with atomic_write(path) as f:
        f.write(json.dumps(doc, indent=1))
    return path


def read_matrix(path: Path, where: str, value: object, shape: tuple[int, ...]) -> np.ndarray:
    """``value`` as finite numbers of ``shape``, else one line naming ``path`` and ``where``."""
    try:
        a = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise MotionFormatError(path, f"{where} must be numbers of shape {shape}") from None
    if a.shape != shape or not np.isfinite(a).all():
        raise MotionFormatError(path, f"{where} must be finite numbers of shape {shape}")
    return a


def read_small_text(path: Path, missing: str, what: str) -> str:
    """The text (UTF-8) of a camera or calibration file, at most :data:`MAX_JSON_BYTES`;
    else a one-line :class:`MotionFormatError` (``missing``: when there is no such file)."""
    if not path.is_file():
        raise MotionFormatError(path, missing)
    if path.stat().st_size > MAX_JSON_BYTES:
        raise MotionFormatError(path, f"{what} larger than {MAX_JSON_BYTES} bytes")
    try:
        return path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise MotionFormatError(path, f"not a text {what} ({exc})") from None


def valid_camera(path: Path, where: str, camera: CalibratedCamera) -> None:
    """Raise a one-line :class:`MotionFormatError` naming ``path`` and ``where`` unless
    ``camera`` has a size of 16 to :data:`MAX_SIDE` pixels, positive focal lengths (``K``'s
    last row 0 0 1) and a rotation ``R``."""
    if not all(16 <= v <= MAX_SIDE for v in (camera.width, camera.height)):
        raise MotionFormatError(path, f"{where}: width and height must be 16 to {MAX_SIDE}")
    k, r = camera.K, camera.R
    if not (k[0, 0] > 0 and k[1, 1] > 0) or not np.allclose(k[2], [0, 0, 1]):
        raise MotionFormatError(path, f"{where}.K: focal lengths must be positive, last row 0 0 1")
    if not np.allclose(r @ r.T, np.eye(3), atol=1e-4):
        raise MotionFormatError(path, f"{where}.R is not a rotation matrix")
    if np.linalg.det(r) < 0:
        raise MotionFormatError(
            path, f"{where}.R is not a rotation matrix (a reflection: determinant -1)"
        )


def read_distortion(path: Path, where: str, value: object) -> tuple[float, ...]:
    """OpenCV's distortion coefficients of a camera, () when all are 0 (none)."""
    if isinstance(value, list) and not value:
        return ()
    if not isinstance(value, list) or len(value) not in DISTORTION_LENGTHS:
        raise MotionFormatError(
            path, f"{where} must be a list of {', '.join(map(str, DISTORTION_LENGTHS))} numbers"
        )
    a = read_matrix(path, where, value, (len(value),))
    if np.abs(a).max() > MAX_DISTORTION:
        raise MotionFormatError(path, f"{where}: coefficients beyond {MAX_DISTORTION:g}")
    return tuple(a.tolist()) if a.any() else ()


#: Suffixes of video files, which a folder of one camera's image frames does not hold
#: (:func:`frames_folder`).
VIDEO_SUFFIXES = (
    ".mp4", ".m4v", ".mov", ".avi", ".mkv", ".webm", ".mpg", ".mpeg", ".wmv", ".flv", ".ts",
    ".mts", ".y4m", ".ogv",
)  # fmt: skip


def frames_folder(folder: str | os.PathLike[str]) -> bool:
    """Whether ``folder`` is one camera's video as a folder of image frames: it holds PNG or
    JPEG images, and no ``cameras.json``, subfolder or video file (the folder of every
    camera holds those, beside its background images)."""
    folder = Path(folder)
    if not folder.is_dir() or (folder / CAMERAS_FILE).exists():
        return False
    entries = list(folder.iterdir())
    if any(p.is_dir() or p.suffix.lower() in VIDEO_SUFFIXES for p in entries):
        return False
    return any(p.suffix.lower() in FRAME_SUFFIXES for p in entries)


def lone_video(video: str | os.PathLike[str]) -> bool:
    """Whether ``--video`` names one camera's video: a file (not the folder of every camera,
    nor their ``cameras.json``), or a folder of its image frames (:func:`frames_folder`;
    such a folder had been taken for the folder of every camera, and camera 0's video
    tracked in its place)."""
    video = Path(video)
    if video.is_dir():
        return frames_folder(video)
    return video.is_file() and video.suffix.lower() != ".json"


class CameraFile(type(Path())):  # type: ignore[misc]  # PosixPath or WindowsPath
    """The path of a camera file given apart from the folder of its videos (``--video DIR
    --cameras OTHER/cameras.json``), with that folder as ``videos``: :func:`camera_videos`
    looks there first, then beside the file. A path, so that every reader passes it on as
    it did the file's own path (the videos had been looked for beside the file alone)."""

    #: The folder ``--video`` named (None on a path made from this one: its parent, ...).
    videos: Path | None = None
    #: The file as read once (:func:`read_camera_file`), which :func:`load_cameras` takes
    #: rather than reading it again (None: read it).
    reading: CameraReading | None = None


def video_folders(path: str | os.PathLike[str]) -> list[Path]:
    """Where the videos of the camera file ``path`` are looked for, in order: the folder a
    :class:`CameraFile` carries, then the file's own folder (the folder ``path`` if one)."""
    own = Path(path) if Path(path).is_dir() else Path(path).parent
    given = getattr(path, "videos", None)
    if given is not None and Path(given).resolve() != own.resolve():
        return [Path(given), own]
    return [own]


def camera_file(video: str | os.PathLike[str], cameras: str | os.PathLike[str] | None) -> Path:
    """The camera file of a video: ``cameras`` if given (with the folder ``video``, if one,
    as where its videos are looked for first: :class:`CameraFile`); else ``cameras.json``
    in the folder ``video`` or beside the video file ``video``.

    Raises:
        MotionFormatError: ``video`` does not exist (named, rather than its camera file).
    """
    video = Path(video)
    if not video.exists():
        raise MotionFormatError(video, "no such video file or folder")
    if isinstance(cameras, CameraFile) and cameras.reading is not None:
        return cameras  # read already (read_camera_file), with where its videos are
    if cameras is not None:
        if not video.is_dir() or lone_video(video):
            return Path(cameras)
        found = CameraFile(cameras)
        found.videos = video
        return found
    if lone_video(video):
        return video.parent / CAMERAS_FILE
    return video


def camera_of_video(
    cameras: list[CalibratedCamera], video: str | os.PathLike[str], notes: list[str] | None = None
) -> int:
    """Which camera a lone video (a file, or a folder of image frames: :func:`lone_video`)
    is: the one naming it, else the first (said in a note, :func:`say`, when there are
    several: a video of another camera tracked through the first's calibration is far off at
    full confidence)."""
    name = Path(video).name
    found = next((k for k, c in enumerate(cameras) if Path(c.video).name == name), None)
    if found is None and Path(video).is_file():  # a README given as --video: that, not a note
        capture = cv2.VideoCapture(str(video))
        readable = capture.isOpened() and capture.read()[0]
        capture.release()
        if not readable:
            raise MotionFormatError(video, "cannot read this video")
    if found is None and len(cameras) > 1:
        listed = ", ".join(Path(c.video).name for c in cameras)
        say(
            [
                f"note: {name} is not a video the camera file names ({listed}): taken as the "
                f"first camera's, {Path(cameras[0].video).name}; name it so in the camera "
                "file if it is another camera's"
            ],
            notes,
            Path(video).resolve(),
        )
    return 0 if found is None else found


def load_cameras(
    path: str | os.PathLike[str], notes: list[str] | None = None, paired: bool = True
) -> tuple[list[CalibratedCamera], dict]:
    """Cameras of ``cameras.json`` (or of the folder holding it) and the whole document,
    whose ``fps`` is the file's or, without one, the rate the videos' own headers agree on;
    each camera's ``t`` in mm whatever the file's ``units`` (:func:`read_cameras`; a path
    from :func:`read_camera_file` is not read again).

    What may be wrong with a file that reads (keys it does not know, a video's header giving
    another rate, no ``fps``, a principal point far from the image's middle, cameras
    placed as if in another unit or below the floor, R and t that look like the cameras'
    poses) is said in notes, printed once per command (:func:`say`: a command may take its
    camera file more than once) and added to ``notes`` if given, for a summary's ``notes``.

    Raises:
        MotionFormatError: what :func:`read_cameras` raises; and with ``paired`` (a command
            that reads the views together; one that reads one camera's video is told in a
            note), videos at rates of their own.
    """
    reading = path.reading if isinstance(path, CameraFile) else None
    reading = reading or read_cameras(path)
    if paired and reading.unpaired:
        raise MotionFormatError(reading.file, reading.unpaired)
    say(reading.notes, notes, reading.file.resolve())
    return list(reading.cameras), copy.deepcopy(reading.doc)


@dataclass(frozen=True)
class CameraReading:
    """A camera file as :func:`read_cameras` read it: its cameras, its document (``fps``
    filled in), the notes on it, and why its views cannot be read together (their videos'
    own frame rates disagree; None: they can), which only a reader of every view refuses."""

    file: Path
    cameras: tuple[CalibratedCamera, ...]
    doc: dict
    notes: tuple[str, ...]
    unpaired: str | None = None


def read_camera_file(
    video: str | os.PathLike[str], cameras: str | os.PathLike[str] | None = None
) -> CameraFile:
    """The camera file of ``video`` (:func:`camera_file`) read once, as a path to it that
    carries what was read (:class:`CameraReading`): given to a reader as its camera file,
    :func:`camera_file` and :func:`load_cameras` take that rather than reading and checking
    the file again (a ``track`` command had read it up to four times: its method's choice,
    the tracker, ``--truth``). Its notes are said when a reader takes it.

    Raises:
        MotionFormatError: ``video`` does not exist, or what :func:`read_cameras` raises."""
    where = camera_file(video, cameras)
    if isinstance(where, CameraFile) and where.reading is not None:
        return where
    out = CameraFile(where)
    out.videos = getattr(where, "videos", None)
    out.reading = read_cameras(where)
    return out


def read_cameras(path: str | os.PathLike[str]) -> CameraReading:
    """Read and check the camera file ``path`` (or the folder holding it) once, for
    :func:`load_cameras`: only the notes on keys it does not know are said here (before an
    error they may explain); the others when a reader takes the file.

    Raises:
        MotionFormatError: no such file, not JSON (a calibration file given instead is
            named as one), another ``units`` than mm, cm or m, or a camera without valid
            size, intrinsics, an orthonormal rotation, a translation, or with distortion
            coefficients OpenCV does not take; no ``fps`` and no rate the videos agree
            on; R and t that are surely the cameras' poses.
    """
    folders = video_folders(path)
    path = Path(path)
    if path.is_dir():
        path = path / CAMERAS_FILE
    text = read_small_text(path, "no camera file (cameras.json) for this video", "camera file")
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise MotionFormatError(path, _not_json(path, text, exc)) from None
    cams = doc.get("cameras") if isinstance(doc, dict) else None
    if not isinstance(cams, list) or not 1 <= len(cams) <= MAX_CAMERAS:
        given = f", not {len(cams)}" if isinstance(cams, list) else ""
        raise MotionFormatError(
            path, f"'cameras' must be a list of 1 to {MAX_CAMERAS} cameras{given}"
        )
    lines = unknown_key_notes(path, doc)
    say(lines, None, path.resolve())  # a typo'd key before its error
    fps = doc.get("fps")
    if fps is not None and (
        isinstance(fps, bool) or not isinstance(fps, (int, float)) or not (0 < fps <= 1000)
    ):
        raise MotionFormatError(path, "'fps' must be a number above 0 and at most 1000")
    units = doc.get("units", "mm")
    if not isinstance(units, str) or units not in CAMERA_UNITS:
        raise MotionFormatError(
            path, f'\'units\' is {json.dumps(units)}: give "mm" (the default), "cm" or "m"'
        )
    out = []
    for i, c in enumerate(cams):
        where = f"cameras[{i}]"
        if not isinstance(c, dict):
            raise MotionFormatError(path, f"{where} must be an object")
        w, h = (_side(path, where, c, key) for key in ("width", "height"))
        k = read_matrix(path, f"{where}.K", c.get("K"), (3, 3))
        r = read_matrix(path, f"{where}.R", c.get("R"), (3, 3))
        t = read_matrix(path, f"{where}.t", c.get("t"), (3,)) * CAMERA_UNITS[units]
        dist = read_distortion(path, f"{where}.distortion", c.get("distortion", []))
        video = c.get("video", "")
        if not isinstance(video, str) or len(video) > 255:
            raise MotionFormatError(path, f"{where}.video must be a file name")
        bg = c.get("background", "")
        if not isinstance(bg, str) or len(bg) > 255:
            raise MotionFormatError(path, f"{where}.background must be a file name")
        name = c.get("name", f"cam{i}")
        skip = c.get("skip_frames", 0)
        if isinstance(skip, bool) or not isinstance(skip, int) or not 0 <= skip <= MAX_SKIP:
            raise MotionFormatError(
                path, f"{where}.skip_frames must be a whole number 0 to {MAX_SKIP}"
            )
        out.append(CalibratedCamera(k, r, t, w, h, str(name)[:64], video, bg, dist, skip))
        valid_camera(path, where, out[-1])
    _check_own_videos(path, out)
    problem, unambiguous = convention_problem(out)
    if problem and unambiguous:
        raise MotionFormatError(path, problem)
    lines += [f"note: {path.name}: {problem}"] if problem else []
    unpaired = None
    if fps is None:
        fps = _rate_of_videos(path, folders, out, lines)
    else:
        rated, unpaired = _rate_notes(folders, out, float(fps))
        lines += rated
    doc["fps"] = float(fps)
    lines += centre_notes(out) + _numbering_gap_notes(folders, out)
    if not problem:  # cameras the wrong way round are placed anywhere
        said = f'its "units": "{units}"' if "units" in doc else 'no "units"'
        placed = placement_notes(out, f"t read in {units}: {said}", "is that the unit of its t?",
                                 "", "is its world Y up?")  # fmt: skip
        lines += [f"note: {path.name}: {line}" for line in placed] + _twin_notes(path, out)
    lines += _numbering_notes(path, out)
    return CameraReading(path, tuple(out), doc, tuple(lines), unpaired)


#: The ``units`` a camera file's ``t`` may be in, and each one's millimetres.
CAMERA_UNITS: dict[str, float] = {"mm": 1.0, "cm": 10.0, "m": 1000.0}
#: The keys a camera file's top level and each of its cameras may hold (``video render``
#: and ``video cameras`` write ``source``, ``rendered``, ``start_frame``, ``people``, ``up``).
TOP_KEYS = ("units", "fps", "cameras", "source", "rendered", "start_frame", "people", "up")
CAMERA_KEYS = (
    "name", "video", "width", "height", "K", "R", "t", "distortion", "background",
    "skip_frames",
)  # fmt: skip


def _side(path: Path, where: str, camera: dict, key: str) -> int:
    """A camera's ``width`` or ``height``: a whole number, also as a float (Pose2Sim writes
    ``1088.0``); one line when it is missing or not whole (the range: :func:`valid_camera`)."""
    value = camera.get(key)
    if value is None:
        raise MotionFormatError(path, f"{where} has no {key} (its images' size in pixels)")
    if isinstance(value, float) and value.is_integer():
        value = int(value)
    if isinstance(value, bool) or not isinstance(value, int):
        raise MotionFormatError(
            path, f"{where}.{key} must be a whole number of pixels, 16 to {MAX_SIDE}"
        )
    return value


def _not_json(path: Path, text: str, exc: json.JSONDecodeError) -> str:
    """Why a camera file is not JSON: a Pose2Sim / Anipose TOML or a Qualisys calibration
    given in its place (``--cameras Calib.toml``) is named, with the command that converts
    it; anything else gets the JSON error."""
    head = text.lstrip()[:200]
    name = path.name.lower()
    if name.endswith((".qca.txt", ".qca")) or head.startswith("<"):
        kind = "a Qualisys calibration (.qca.txt)"
    elif name.endswith(".toml") or (head.startswith("[") and "matrix" in text):
        kind = "a Pose2Sim / Anipose calibration (TOML)"
    else:
        return f"not a JSON camera file ({exc})"
    return (
        f"is {kind}, not a camera file (cameras.json): convert it with `markovmotion video "
        f"cameras {path.name} VIDEO...` (one video per camera, in its order)"
    )


def unknown_key_notes(path: Path, doc: dict) -> list[str]:
    """One note naming the keys of a camera file that nothing reads, with the known ones:
    a lens under ``"distorsion"`` or a plate under ``"backgroud"`` had been dropped without
    a word (79.5 mm for 74.5, the background learnt)."""
    found: dict[str, list[str]] = {}
    for key in doc:
        if key not in TOP_KEYS:
            found.setdefault(key, []).append("top level")
    for i, c in enumerate(doc["cameras"]):
        for key in c if isinstance(c, dict) else ():
            if key not in CAMERA_KEYS:
                found.setdefault(key, []).append(f"cameras[{i}]")
    if not found:
        return []
    listed = []
    for key, where in found.items():
        known = TOP_KEYS if where == ["top level"] else CAMERA_KEYS
        near = difflib.get_close_matches(key, known, n=1, cutoff=0.75)
        more = ", ..." if len(where) > 3 else ""
        hint = f' (meant "{near[0]}"?)' if near else ""
        listed.append(f'"{key}" in {", ".join(where[:3])}{more}{hint}')
    return [
        f"note: {path.name}: unknown keys, ignored: {'; '.join(listed)}. Known: "
        f"{', '.join(TOP_KEYS)}; per camera {', '.join(CAMERA_KEYS)}"
    ]


def capture_centre(cameras: Sequence[CalibratedCamera]) -> np.ndarray | None:
    """The point (3,) mm nearest every camera's optical axis (least squares): where the
    cameras are aimed, the middle of the capture volume; None when the axes are (nearly)
    parallel."""
    a, b = np.zeros((3, 3)), np.zeros(3)
    for c in cameras:
        m = np.eye(3) - np.outer(c.R[2], c.R[2])  # R's third row: the optical axis
        a += m
        b += m @ c.centre
    if np.linalg.cond(a) > 1e6:
        return None
    return np.linalg.solve(a, b)


def _aimed(cameras: Sequence[CalibratedCamera]) -> int:
    """How many cameras have the point they are aimed at (:func:`capture_centre`) in front, within
    about 60 degrees of their axis (0 without such a point)."""
    point = capture_centre(cameras)
    if point is None:
        return 0
    aimed = 0
    for c in cameras:
        ahead = c.R @ point + c.t
        aimed += bool(ahead[2] > 0.5 * np.linalg.norm(ahead))
    return aimed


def convention_problem(cameras: Sequence[CalibratedCamera]) -> tuple[str, bool]:
    """What to say of cameras whose ``R`` and ``t`` look like their poses in the world
    (camera to world) rather than world to camera, and whether it is unambiguous: with each
    inverted (``R^T``, ``-R^T t``) the point their optical axes meet lies ahead of every
    one, as given it does not (unambiguous: ahead of at most half of them). The real video's
    cameras so inverted had been "no person found" (triangulation) or tracked 2800 mm from
    the reference at exit 0. ("", False) for cameras that look right, or for one camera."""
    n = len(cameras)
    if n < 2:
        return "", False
    given = _aimed(cameras)
    inverted = _aimed([replace(c, R=c.R.T, t=-c.R.T @ c.t) for c in cameras])
    if not given < inverted == n:
        return "", False
    return (
        f"R and t look like camera-to-world (the point the cameras' axes meet lies ahead "
        f"of {given} of the {n} cameras; with R and t inverted, of {inverted}): cameras.json "
        "wants world-to-camera (x_cam = R x_world + t)",
        given <= n / 2,
    )


#: Cameras that see a person from this close to one another (mm, the widest pair) or this
#: far are more likely in another unit than said (:func:`placement`).
CAMERA_SPREAD_MM = (200.0, 100_000.0)


def placement(cameras: Sequence[CalibratedCamera]) -> tuple[float | None, list[str]]:
    """How far apart the widest pair of cameras stand (mm) when that is outside
    :data:`CAMERA_SPREAD_MM` (else None), and the cameras below the floor (world Y < 0):
    what a wrong unit or up axis looks like (a file in metres read as mm put the cameras a
    few mm from one another)."""
    centres = np.array([c.centre for c in cameras])
    spread = max((float(np.linalg.norm(a - b)) for a in centres for b in centres), default=0.0)
    low, high = CAMERA_SPREAD_MM
    odd = spread if len(cameras) > 1 and not low <= spread <= high else None
    return odd, [c.name for c, x in zip(cameras, centres, strict=True) if x[1] < 0]


def placement_notes(
    cameras: Sequence[CalibratedCamera],
    units_read: str,
    unit_asked: str,
    up_read: str,
    up_asked: str,
) -> list[str]:
    """:func:`placement` as notes (without the ``note:`` prefix), for a camera file read by
    every command and for a calibration ``video cameras`` converts: ``units_read`` and
    ``up_read`` say how ``t`` and the up axis were read, ``unit_asked`` and ``up_asked`` what
    to check (a hand-written file in metres had been read as mm without a word)."""
    spread, below = placement(cameras)
    out = []
    if spread is not None:
        out.append(
            f"the cameras stand at most {spread:.0f} mm from one another ({units_read}): "
            f"{unit_asked}"
        )
    if below:
        out.append(f"{', '.join(below)} below the floor (world Y = 0{up_read}): {up_asked}")
    return out


def _twin_notes(path: Path, cameras: Sequence[CalibratedCamera]) -> list[str]:
    """A note naming cameras with the same R and t: a camera copied and not edited (one
    view counted twice, no depth from it)."""
    twins = [
        f"{a.name} and {b.name}"
        for i, a in enumerate(cameras)
        for b in cameras[i + 1 :]
        if np.allclose(a.R, b.R, atol=1e-6) and np.linalg.norm(a.centre - b.centre) < 1.0
    ]
    return (
        [f"note: {path.name}: {'; '.join(twins)} are one camera (the same R and t)"]
        if twins
        else []
    )


def _check_own_videos(path: Path, cameras: Sequence[CalibratedCamera]) -> None:
    """Refuse two cameras naming the same video (a camera copied and its video not edited):
    one view would be tracked through two calibrations, and the camera whose video it is not
    gave nothing but disagreement, without a word but a note on that view."""
    seen: dict[str, CalibratedCamera] = {}
    for c in cameras:
        if not c.video:
            continue  # named by camera_videos
        key = os.path.normpath(c.video)
        if key in seen:
            raise MotionFormatError(
                path,
                f"cameras {seen[key].name} and {c.name} both name the video {c.video}: "
                "each camera needs its own",
            )
        seen[key] = c


def one_number(text: str) -> int | None:
    """The one whole number in ``text`` (``int_cam02_img`` gives 2), else None."""
    found = re.findall(r"\d+", text)
    return int(found[0]) if len(found) == 1 else None


def _numbering_notes(path: Path, cameras: Sequence[CalibratedCamera]) -> list[str]:
    """A note when every camera's name and its video's file name hold one number, and the
    videos' numbers are not the cameras' (nor the cameras' shifted by one constant, as 1-based
    names over 0-based videos): ``cam2`` with ``cam1.mp4``, as a user who dropped a camera
    and renumbered its videos made it, each camera then paired with another's video (the
    check ``video cameras`` makes of its videos' order, :func:`~markovmotion.video.
    calibration.check_order`). A note, not an error: a camera file pairs each camera with
    its video by hand, and a user who found two videos swapped puts them right so."""
    names = [one_number(c.name) for c in cameras]
    videos = [one_number(Path(c.video).stem) for c in cameras]
    if len(cameras) < 2 or None in names or None in videos or len(set(names)) < len(names):
        return []
    if len({v - n for n, v in zip(names, videos, strict=True)}) == 1:
        return []
    odd = [
        f"{c.name} with {Path(c.video).name}"
        for c, n, v in zip(cameras, names, videos, strict=True)
        if n != v
    ]
    return [
        f"note: {path.name}: the cameras' numbers are not their videos' ({', '.join(odd)}): "
        "is each video its camera's? (each camera is tracked with the video it names)"
    ]


@functools.lru_cache(maxsize=64)
def _header_rate(video: str, mtime_ns: int) -> float:
    """A video file's own frame rate from its header (0 when unknown), read once per file
    version."""
    cap = cv2.VideoCapture(video)
    own = cap.get(cv2.CAP_PROP_FPS) if cap.isOpened() else 0.0
    cap.release()
    return float(own) if own and own > 0 else 0.0


def _find(folders: Sequence[Path], name: str) -> Path | None:
    """The file or folder ``name`` in the first of ``folders`` that has it (None: none)."""
    return next((f / name for f in folders if (f / name).exists()), None)


def _header_rates(folders: Sequence[Path], cameras: list[CalibratedCamera]) -> dict[str, float]:
    """The own frame rate of each camera's video file found (in ``folders``,
    :func:`video_folders`) whose header gives one, by the video's name (an image folder has
    none; a missing video is left to :func:`camera_videos` to name)."""
    out = {}
    for c in cameras:
        video = _find(folders, c.video) if c.video else None
        if video is not None and video.is_file():
            own = _header_rate(str(video.resolve()), video.stat().st_mtime_ns)
            if own > 0:
                out[video.name] = own
    return out


def _same_rate(a: float, b: float) -> bool:
    """Whether two frame rates are one (within 1 % of ``b``)."""
    return abs(a - b) <= 0.01 * b


def _rate_notes(
    folders: Sequence[Path], cameras: list[CalibratedCamera], fps: float
) -> tuple[list[str], str | None]:
    """A note for each camera's video whose own frame rate is not the camera file's ``fps``,
    which is the one used: a video re-encoded at 30 fps under a file saying 60 was tracked at
    twice its speed, and paired with a reference frame by frame, without a word. And, when
    the videos' own rates disagree (one camera's video re-encoded at 30 fps among others at
    60), why the views cannot be read together (None: they can): they are paired frame by
    frame, so no ``fps`` of the file is right for all of them (the note had advised setting
    it); the odd videos, their rates and the others' rate, to resample them to
    (:func:`load_cameras` refuses it for a command that reads every view)."""
    known = _header_rates(folders, cameras)
    rates = list(known.values())
    problem = None
    if any(not _same_rate(r, rates[0]) for r in rates):
        # the others' rate: the one most videos have (of as many, the file's)
        groups = [[r for r in rates if _same_rate(r, q)] for q in rates]
        usual = max(groups, key=lambda g: (len(g), _same_rate(g[0], fps)))[0]
        odd = [f"{name} is {r:g} fps" for name, r in known.items() if not _same_rate(r, usual)]
        whose, it = ("its", "it") if len(odd) == 1 else ("their", "them")
        problem = (
            f"{', '.join(odd)} by {whose} own header, the other views {usual:g}: resample "
            f"{it} to {usual:g} (the views are paired frame by frame)"
        )
    notes = [
        f"note: {name} is {own:g} fps by its own header, the camera file says {fps:g}: "
        "the camera file's rate is used (set its fps if the video's is right)"
        for name, own in known.items()
        if not _same_rate(own, fps)
    ]
    return notes, problem


def _rate_of_videos(
    path: Path, folders: Sequence[Path], cameras: list[CalibratedCamera], notes: list[str]
) -> float:
    """The frame rate of a camera file without ``fps``: the one its videos' own headers agree
    on (within 1 %), said in ``notes``. It had been 25 without a word: the real 60 fps video
    was then tracked and smoothed at 25.

    Raises:
        MotionFormatError: no video gives a rate (image folders), or they disagree."""
    known = _header_rates(folders, cameras)
    if not known:
        raise MotionFormatError(
            path, 'no "fps" (frames per second), and no video\'s header gives one: add "fps"'
        )
    first = next(iter(known.values()))
    if any(not _same_rate(r, first) for r in known.values()):
        listed = ", ".join(f"{name} {r:g}" for name, r in known.items())
        raise MotionFormatError(
            path,
            f'no "fps" (frames per second), and the videos\' headers disagree ({listed}): '
            'add "fps"',
        )
    names = ", ".join(known)
    notes.append(
        f'note: {path.name} gives no "fps": {first:g} fps taken from the videos\' own '
        f'headers ({names}); add "fps" to it if that is not the rate they were filmed at'
    )
    return first


def _numbering_gap_notes(folders: Sequence[Path], cameras: list[CalibratedCamera]) -> list[str]:
    """A note for each camera whose video is a folder of frames with numbers missing from
    their numbering (:func:`~markovmotion.video.render.missing_frames_note`)."""
    out = []
    for c in cameras:
        video = _find(folders, c.video) if c.video else None
        if video is not None and video.is_dir():
            said = missing_frames_note(c.name, video)
            out += [said] if said else []
    return out


#: A principal point further from the image's middle than this share of its width or
#: height (0.25: outside the middle half) is said (:func:`centre_notes`).
CENTRE_SHARE = 0.25


def centre_notes(cameras: Sequence[CalibratedCamera]) -> list[str]:
    """A note for each camera whose principal point ``(cx, cy)`` lies outside the middle
    half of its image (:data:`CENTRE_SHARE`): intrinsics left at another image size, as a
    video resized to half without its ``K``, put every point far off (a new user's trial:
    973 mm from the reference, the videos blamed). Not an error: a lens shifted off the
    sensor's middle is real, if rare this far."""
    out = []
    for c in cameras:
        cx, cy = float(c.K[0, 2]), float(c.K[1, 2])
        u, v = (cx + 0.5) / c.width, (cy + 0.5) / c.height  # pixel centres at integers
        if not (CENTRE_SHARE <= u <= 1 - CENTRE_SHARE and CENTRE_SHARE <= v <= 1 - CENTRE_SHARE):
            out.append(
                f"note: {c.name}'s principal point ({cx:.1f}, {cy:.1f}) lies outside the middle "
                f"of its {c.width}x{c.height} image: was its K made for another image size? "
                "(a video resized by s needs fx, fy, cx + 0.5 and cy + 0.5 times s; "
                "`video cameras` scales them)"
            )
    return out


def camera_videos(
    path: str | os.PathLike[str], cameras: list[CalibratedCamera], what: str = "video"
) -> list[Path | None]:
    """The ``video`` (or ``background``) file of each camera, relative to the folder
    ``--video`` named if it was given apart from the camera file (:class:`CameraFile`),
    else to ``cameras.json``'s folder (None for a camera without a background image)."""
    folders = video_folders(path)
    out: list[Path | None] = []
    for c in cameras:
        name = getattr(c, what)
        if not name:
            if what != "video":
                out.append(None)
                continue
            raise MotionFormatError(folders[-1] / CAMERAS_FILE, f"camera {c.name} names no video")
        found = _find(folders, name)
        if found is None:
            if len(folders) == 1:
                raise MotionFormatError(
                    (folders[0] / name).resolve(), f"no {what} for camera {c.name}"
                )
            raise MotionFormatError(
                (folders[0] / name).resolve(),
                f"no {what} for camera {c.name}, here nor beside the camera file "
                f"({(folders[1] / name).resolve()})",
            )
        v = found.resolve()
        if not (v.is_file() or v.is_dir()):  # a device or a pipe would never end
            raise MotionFormatError(v, f"the {what} of camera {c.name} is not a regular file")
        out.append(v)
    return out
