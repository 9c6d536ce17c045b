"""Video of motion capture: filled body silhouettes seen by a fixed side camera (interaction paper, §2).

There is no video of the shared two-person takes, so it is made from the
capture: each person is a union of capsules (limbs, torso, neck), a ball for
the head and one per hand, projected through a pinhole camera standing beside
the dance floor at a fixed position for the whole take, onto a static
textured background, with Gaussian sensor noise in every frame. The camera
looks at the middle of the take, across the main line between the partners,
so that they are seen side by side as in the paper's Figure 1.

Frames go to an MP4 file (H.264) or a folder of PNG files, at 25 fps as in the
paper. :func:`read_frames` reads either back.
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import cv2
import numpy as np

from markovmotion.core.motion import GROUND
from markovmotion.errors import MotionFormatError
from markovmotion.features.joint_shape import MAJOR_JOINTS, Person
from markovmotion.io.files import atomic_path

if TYPE_CHECKING:
    from markovmotion.video.cameras import CalibratedCamera

#: Capsules of the body between joints of :data:`MAJOR_JOINTS`, radius in mm.
CAPSULES = (
    ("hip", "abdomen", 125),
    ("abdomen", "chest", 130),
    ("chest", "neck", 110),
    ("neck", "head", 50),
    ("chest", "rShldr", 65),
    ("chest", "lShldr", 65),
    ("rShldr", "rForeArm", 50),
    ("lShldr", "lForeArm", 50),
    ("rForeArm", "rHand", 40),
    ("lForeArm", "lHand", 40),
    ("hip", "rThigh", 100),
    ("hip", "lThigh", 100),
    ("rThigh", "rShin", 75),
    ("lThigh", "lShin", 75),
    ("rShin", "rFoot", 55),
    ("lShin", "lFoot", 55),
    ("rFoot", "rFoot_end", 40),
    ("lFoot", "lFoot_end", 40),
)
HEAD_RADIUS = 105.0
HAND_RADIUS = 45.0
FRAME_SIZE = (640, 480)
PEOPLE_COLOURS = ((70, 50, 130), (40, 95, 60))  # RGB
SHIFT = 4  # sub-pixel bits for OpenCV drawing


@dataclass(frozen=True)
class Camera:
    """A pinhole camera looking horizontally along ``forward`` (mm, Y up; pixels, y down)."""

    position: np.ndarray
    forward: np.ndarray
    focal: float = 700.0
    width: int = FRAME_SIZE[0]
    height: int = FRAME_SIZE[1]

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixel coordinates (..., 2) and depths (...) in mm of world points (..., 3)."""
        right = np.cross(self.forward, [0.0, 1.0, 0.0])
        rel = np.asarray(points, dtype=float) - self.position
        z = np.maximum(rel @ self.forward, 1.0)
        u = self.width / 2 + self.focal * (rel @ right) / z
        v = self.height / 2 - self.focal * rel[..., 1] / z
        return np.stack([u, v], axis=-1), z

    def to_dict(self) -> dict:
        return {
            "position": self.position.tolist(),
            "forward": self.forward.tolist(),
            "focal": self.focal,
            "width": self.width,
            "height": self.height,
        }


def side_camera(
    people: Sequence[Person],
    distance: float = 6000.0,
    height: float = 900.0,
    focal: float = 700.0,
    size: tuple[int, int] = FRAME_SIZE,
) -> Camera:
    """The fixed camera of a take: ``distance`` mm from its middle, across the partners' main axis.

    The main axis is the principal direction of the (horizontal) line from the
    first person's pelvis to the second's over the take.
    """
    refs = np.stack([p.reference for p in people], axis=1)  # (F, P, 3)
    centre = refs.reshape(-1, 3).mean(axis=0)
    centre[1] = 0.0
    axis = np.array([1.0, 0.0, 0.0])
    if len(people) > 1:
        sep = refs[:, 1, GROUND] - refs[:, 0, GROUND]
        _, _, vt = np.linalg.svd(sep, full_matrices=False)
        axis = np.array([vt[0, 0], 0.0, vt[0, 1]])
    forward = np.cross(axis, [0.0, 1.0, 0.0])
    forward /= np.linalg.norm(forward)
    position = centre - distance * forward + np.array([0.0, height, 0.0])
    return Camera(position, forward, focal, *size)


def background(size: tuple[int, int] = FRAME_SIZE, seed: int = 0) -> np.ndarray:
    """A static background (H, W, 3) uint8: a wall and a floor with soft texture."""
    w, h = size
    rng = np.random.default_rng(seed)
    y = np.linspace(0, 1, h)[:, None, None]
    wall = np.array([190.0, 185.0, 170.0]) - 25 * y
    img = np.broadcast_to(wall, (h, w, 3)).copy()
    img[int(0.62 * h) :] = [150.0, 140.0, 125.0]
    blotches = cv2.GaussianBlur(rng.normal(0, 1, (h, w)), (0, 0), 9)
    img += 60 * blotches[..., None]
    return np.clip(img, 0, 255).astype(np.uint8)


class Canvas:
    """Coverage mask (H, W) drawn at ``scale`` times the resolution and averaged down.

    Pixel centres are at integer coordinates; OpenCV fills at the fine scale
    without anti-aliasing, and averaging gives each pixel its covered fraction.
    """

    def __init__(self, width: int, height: int, scale: int = 4):
        self.width, self.height, self.scale = width, height, scale
        self.fine = np.zeros((height * scale, width * scale), np.uint8)

    def _fixed(self, p: np.ndarray) -> np.ndarray:
        return np.round(((np.asarray(p) + 0.5) * self.scale - 0.5) * (1 << SHIFT)).astype(np.int32)

    def polygon(self, points: np.ndarray) -> None:
        cv2.fillPoly(self.fine, [self._fixed(points)], 255, cv2.LINE_8, SHIFT)

    def disc(self, centre: np.ndarray, radius: float) -> None:
        r = int(round(radius * self.scale * (1 << SHIFT)))
        cv2.circle(self.fine, tuple(self._fixed(centre)), r, 255, -1, cv2.LINE_8, SHIFT)

    def capsule(self, a: np.ndarray, b: np.ndarray, ra: float, rb: float) -> None:
        """The capsule between points a and b with end radii ra, rb (pixels)."""
        self.disc(a, ra)
        self.disc(b, rb)
        d = b - a
        n = np.linalg.norm(d)
        if n > 1e-6:
            normal = np.array([-d[1], d[0]]) / n
            self.polygon(
                np.array([a + ra * normal, b + rb * normal, b - rb * normal, a - ra * normal])
            )

    def coverage(self) -> np.ndarray:
        """(H, W) uint8 covered fraction of each pixel (0-255)."""
        return cv2.resize(self.fine, (self.width, self.height), interpolation=cv2.INTER_AREA)


@dataclass(frozen=True)
class BodyShape:
    """A body as capsules between points and balls beside them (mm), for any list of points.

    ``capsules`` (S, 2) point indices with radii (S, 2) at either end (tapered);
    ``balls`` are (point, from_point, offset, radius): a ball of ``radius``
    centred ``offset * radius`` beyond ``point`` along the bone from
    ``from_point`` (the head above the neck, a hand past the wrist).
    :meth:`points` adds the ball centres after the points, and :meth:`segments`
    lists capsules and balls (as zero-length capsules) over those, so a
    renderer or a tracker draws or tests one kind of primitive.
    """

    capsules: tuple[tuple[int, int], ...]
    radii: tuple[tuple[float, float], ...]
    balls: tuple[tuple[int, int, float, float], ...]
    n_points: int

    def points(self, joints: np.ndarray) -> np.ndarray:
        """(..., P + balls, 3): the joints (..., P, 3) and the centres of the balls."""
        joints = np.asarray(joints, dtype=float)
        at = [b[0] for b in self.balls]
        d = joints[..., at, :] - joints[..., [b[1] for b in self.balls], :]
        d = d / np.maximum(np.linalg.norm(d, axis=-1, keepdims=True), 1e-6)
        shift = np.array([offset * r for _, _, offset, r in self.balls])[:, None]
        return np.concatenate([joints, joints[..., at, :] + shift * d], axis=-2)

    def segments(self) -> tuple[np.ndarray, np.ndarray]:
        """(S, 2) indices into :meth:`points` and (S, 2) radii in mm of every primitive."""
        ball_idx = [(self.n_points + i,) * 2 for i in range(len(self.balls))]
        ball_r = [(b[3], b[3]) for b in self.balls]
        return (
            np.array(list(self.capsules) + ball_idx, dtype=np.intp),
            np.array(list(self.radii) + ball_r, dtype=float),
        )

    @classmethod
    def build(
        cls,
        names: Sequence[str],
        capsules: Sequence[tuple[str, str, float, float]],
        balls: Sequence[tuple[str, str, float, float]],
    ) -> BodyShape:
        idx = {n: i for i, n in enumerate(names)}
        return cls(
            tuple((idx[a], idx[b]) for a, b, _, _ in capsules),
            tuple((float(ra), float(rb)) for _, _, ra, rb in capsules),
            tuple((idx[k], idx[f], float(o), float(r)) for k, f, o, r in balls),
            len(names),
        )


#: The silhouettes' body over :data:`MAJOR_JOINTS`.
MAJOR_SHAPE = BodyShape.build(
    MAJOR_JOINTS,
    [(a, b, r, r) for a, b, r in CAPSULES],
    [("head", "neck", 1.0, HEAD_RADIUS)]
    + [(f"{s}Hand", f"{s}ForeArm", 0.6, HAND_RADIUS) for s in "rl"],
)


def draw_body(
    canvas: Canvas, joints: np.ndarray, camera: CalibratedCamera, shape: BodyShape
) -> None:
    """Fill the body ``shape`` with joints (P, 3) mm seen by ``camera`` into ``canvas``.

    ``camera`` is anything with ``project(points) -> (pixels, depths)`` and a
    ``focal`` length in pixels (:class:`Camera`, a calibrated camera).
    """
    seg, radii = shape.segments()
    pix, depth = camera.project(shape.points(joints))
    r = camera.focal * radii / depth[seg]
    for (i, j), (ri, rj) in zip(seg, r, strict=True):
        canvas.capsule(pix[i], pix[j], ri, rj)


def silhouette_mask(
    joints: np.ndarray, camera: Camera, shape: BodyShape = MAJOR_SHAPE
) -> np.ndarray:
    """(H, W) uint8 coverage of one body with joints (P, 3) (default: :data:`MAJOR_JOINTS`)."""
    canvas = Canvas(camera.width, camera.height)
    draw_body(canvas, joints, camera, shape)
    return canvas.coverage()


def check_body(n_points: int, what: str) -> None:
    if n_points != len(MAJOR_JOINTS):
        raise MotionFormatError(
            what, f"silhouettes need the {len(MAJOR_JOINTS)} joints {', '.join(MAJOR_JOINTS)}"
        )


def render_frames(
    people: Sequence[Person],
    camera: Camera,
    noise: float = 4.0,
    seed: int = 0,
    colours: Sequence[tuple[int, int, int]] = PEOPLE_COLOURS,
) -> Iterator[np.ndarray]:
    """RGB frames (H, W, 3) uint8 of ``people`` (3-D, :data:`MAJOR_JOINTS`) over the background."""
    for p in people:
        check_body(p.points.shape[1], "people")
    bg = background((camera.width, camera.height), seed).astype(np.float32)
    noisy = np.empty_like(bg)
    cv2.setRNGSeed(seed + 1)
    for t in range(len(people[0].points)):
        img = bg.copy()
        order = np.argsort([-camera.project(p.reference[t])[1] for p in people])  # far first
        for k in order:
            mask = silhouette_mask(people[k].points[t], camera)
            x, y, w, h = cv2.boundingRect(mask)
            if not w:
                continue
            alpha = mask[y : y + h, x : x + w, None].astype(np.float32) / 255.0
            colour = np.asarray(colours[k % len(colours)], np.float32)
            box = img[y : y + h, x : x + w]
            box += alpha * (colour - box)
        cv2.randn(noisy, (0.0, 0.0, 0.0), (noise, noise, noise))
        img += noisy
        yield np.clip(img, 0, 255).round().astype(np.uint8)


def empty_frames(
    n: int, size: tuple[int, int] = FRAME_SIZE, noise: float = 4.0, seed: int = 0
) -> Iterator[np.ndarray]:
    """``n`` RGB frames (H, W, 3) uint8 of the empty scene: :func:`background` with the sensor
    noise of :func:`render_frames` (a clean plate to learn the background from)."""
    bg = background(size, seed).astype(np.float32)
    noisy = np.empty_like(bg)
    cv2.setRNGSeed(seed + 1)
    for _ in range(n):
        cv2.randn(noisy, (0.0, 0.0, 0.0), (noise, noise, noise))
        yield np.clip(bg + noisy, 0, 255).round().astype(np.uint8)


def write_video(frames: Iterable[np.ndarray], path: str | os.PathLike[str], fps: float) -> Path:
    """Write RGB frames to ``path``: an ``.mp4`` file, or else a folder of ``NNNNN.png`` files.

    MP4 is H.264 at constant quality (CRF 18) with a fast preset: sensor noise
    makes every frame expensive to encode at the slower presets.
    """
    path = Path(path)
    if path.suffix.lower() == ".mp4":
        from markovmotion.viz.video import write_mp4

        return write_mp4(frames, path, fps, preset="veryfast", crf=18)
    path.mkdir(parents=True, exist_ok=True)
    for i, f in enumerate(frames):
        with atomic_path(path / f"{i:05d}.png") as tmp:
            cv2.imwrite(str(tmp), cv2.cvtColor(f, cv2.COLOR_RGB2BGR))
    return path


def shortest_note(
    names: Sequence[str], lengths: Sequence[int], short: Sequence[str] | None = None
) -> str | None:
    """One line when some views' videos (``names``) end before the others' (``lengths``: the
    frames read of each): which, and how many frames the views have together, the ones
    tracked; None when they end together (nothing is cut silently), unless one gave fewer
    frames than its header counts. ``short``: each video's :func:`header_shortfall` (""
    when it gave what its header counts)."""
    n = min(lengths)
    short = short or [""] * len(names)
    ended = [
        (name, why)
        for name, k, why in zip(names, lengths, short, strict=True)
        if k == n and (why or n < max(lengths))
    ]
    if not ended:
        return None
    if len(ended) == 1:
        said = f"{ended[0][0]} ended after {n} frames{ended[0][1]}"
    else:
        said = f"{', '.join(name + why for name, why in ended)} ended after {n} frames"
    if n == max(lengths):
        return f"note: {said}"
    return f"note: {said}, before the other views: {n} frames tracked"


def header_shortfall(
    path: str | os.PathLike[str],
    frames: int,
    camera: CalibratedCamera | None = None,
    max_frames: int | None = None,
) -> str:
    """What to add to a note on a video that gave ``frames`` frames (read from ``camera``'s
    skipped ones on, :func:`read_frames`) when its header counts more: "(100 frames by its
    header: damaged or cut short?)"; "" when it gave them all (within 1 %, a container's
    estimate), was cut by ``max_frames``, or has no count (an image folder).

    OpenCV stops at a frame it cannot decode as at the end: a video damaged in its middle
    gave 18 of its 100 frames, and was tracked as an 18-frame video without a word."""
    if max_frames is not None and frames >= max_frames:
        return ""
    path = Path(path)
    header = frame_count(path, decode=False) if path.is_file() else 0
    skip = camera.skip if camera is not None else 0
    if header <= 0 or frames + skip >= header - max(1, round(0.01 * header)):
        return ""
    read = f", {frames + skip} with the {skip} skipped" if skip else ""
    return f" ({header} frames by its header{read}: damaged or cut short?)"


def read_frames(
    path: str | os.PathLike[str], camera: CalibratedCamera | None = None
) -> Iterator[np.ndarray]:
    """RGB frames of a video file (anything OpenCV/FFmpeg reads) or of a folder of images;
    with ``camera``, from its shared first frame on (its ``skip`` frames before are passed
    over), each frame checked to be the camera's size and, if the camera has lens
    distortion, undistorted (:meth:`CalibratedCamera.undistorter`)."""
    path = Path(path)
    fix = camera.undistorter() if camera is not None else None
    skip = camera.skip if camera is not None else 0
    n = -1
    for n, frame in enumerate(_decoded(path, skip), start=skip):
        if camera is not None and frame.shape[:2] != (camera.height, camera.width):
            raise MotionFormatError(
                path, f"camera {camera.name} is {camera.width}x{camera.height} but frame {n} "
                f"of its video is {frame.shape[1]}x{frame.shape[0]}",
            )  # fmt: skip
        yield frame if fix is None else fix(frame)
    if n < skip and skip and camera is not None:
        raise MotionFormatError(
            path,
            f"camera {camera.name} skips {skip} frames (skip_frames) but its video has "
            f"{frame_count(path)}",
        )


def natural_key(name: str) -> list:
    """A sort key of ``name`` that orders its numbers by value (``frame_2`` before
    ``frame_10``): a folder of frames named without leading zeros had been read as frame_1,
    frame_10, frame_100, frame_11 ... (106.9 mm from the reference for 79.5)."""
    return [int(x) if x.isdigit() else x.lower() for x in re.split(r"(\d+)", name)]


#: The suffixes of the images a folder of frames holds (any case).
FRAME_SUFFIXES = (".png", ".jpg", ".jpeg")


def frame_files(path: str | os.PathLike[str]) -> list[Path]:
    """The image frames of the folder ``path``, in the order of the numbers in their names
    (:func:`natural_key`); [] for a folder without any."""
    files = (p for p in Path(path).iterdir() if p.suffix.lower() in FRAME_SUFFIXES)
    return sorted(files, key=lambda p: natural_key(p.name))


def missing_frames(files: Sequence[Path]) -> tuple[list[int], int, int]:
    """The numbers missing from a folder's frames ``files`` (:func:`frame_files`), each
    numbered by the last number in its name, counting by their common step (``frame_0``,
    ``frame_2`` ... is not missing the odd ones), and the first and last number; ([], 0, 0)
    when a name holds no number or two hold the same one (a numbering not to judge). The
    frames are read in order, so the ones after a missing number are shown one frame early:
    a folder without ``frame_50.png`` was tracked so without a word."""
    numbers = []
    for f in files:
        found = re.findall(r"\d+", f.stem)
        if not found:
            return [], 0, 0
        numbers.append(int(found[-1]))
    if len(numbers) < 2 or len(set(numbers)) < len(numbers):
        return [], 0, 0
    numbers.sort()
    step = math.gcd(*(b - a for a, b in zip(numbers, numbers[1:], strict=False)))
    missing = sorted(set(range(numbers[0], numbers[-1] + 1, step)) - set(numbers))
    return missing, numbers[0], numbers[-1]


def missing_frames_note(name: str, folder: str | os.PathLike[str]) -> str | None:
    """A note naming the camera ``name``, the numbers missing from the frames of its
    ``folder`` (:func:`missing_frames`) and its numbering's range; None when none is."""
    missing, first, last = missing_frames(frame_files(folder))
    if not missing:
        return None
    runs: list[list[int]] = []
    for k in missing:
        if runs and k == runs[-1][-1] + 1:
            runs[-1].append(k)
        else:
            runs.append([k])
    listed = ", ".join(f"{r[0]}" if len(r) == 1 else f"{r[0]}-{r[-1]}" for r in runs[:8])
    more = f", ... ({len(missing)} in all)" if len(runs) > 8 else ""
    early = "one" if len(missing) == 1 else f"up to {len(missing)}"
    return (
        f"note: {name}: frames {listed}{more} missing from its numbering ({first}-{last}): "
        f"the frames after are {early} early"
    )


def _quiet_imread(path: Path) -> np.ndarray | None:
    """``cv2.imread`` (BGR) with OpenCV's own log silenced: a damaged frame's "[ERROR:0@3.7]
    global grfmt_png.cpp ... IHDR chunk shall be first" had come before the one line that
    names it."""
    from cv2.utils import logging as cv_log

    level = cv_log.getLogLevel()
    cv_log.setLogLevel(cv_log.LOG_LEVEL_SILENT)
    try:
        return cv2.imread(str(path), cv2.IMREAD_COLOR)
    finally:
        cv_log.setLogLevel(level)


def _decoded(path: Path, skip: int = 0) -> Iterator[np.ndarray]:
    """RGB frames from frame ``skip`` on; the frames before are passed over unconverted
    (a video's are decoded, ``grab``, as they must be; an image folder's are not read)."""
    if path.is_dir():
        files = frame_files(path)
        if not files:
            raise MotionFormatError(path, "no PNG or JPEG frames in this folder")
        for f in files[skip:]:
            img = _quiet_imread(f)
            if img is None:
                raise MotionFormatError(f, "not an image")
            yield cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
        return
    if not path.is_file():
        raise MotionFormatError(path, "no such video")
    cap = cv2.VideoCapture(str(path))
    if not cap.isOpened():
        raise MotionFormatError(path, "cannot read this video")
    try:
        n = 0
        while n < skip and cap.grab():
            n += 1
        while True:
            ok, img = cap.read()
            if not ok:
                break
            n += 1
            yield cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
        if n == 0:
            raise MotionFormatError(path, "no frames in this video")
    finally:
        cap.release()


def frame_count(path: str | os.PathLike[str], decode: bool = True) -> int:
    """Number of frames of a video file or image folder: the file's own count, else (with
    ``decode``) counted by decoding, else 0."""
    path = Path(path)
    if path.is_dir():
        return len(frame_files(path))
    cap = cv2.VideoCapture(str(path))
    n = int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) if cap.isOpened() else 0
    cap.release()
    return n if n > 0 or not decode else sum(1 for _ in read_frames(path))


def spread_frames(
    video: str | os.PathLike[str], frames: int, camera: CalibratedCamera | None = None
) -> list[np.ndarray]:
    """Up to ``frames`` frames spread evenly over ``video`` (``camera``'s: checked and
    undistorted, :func:`read_frames`), for a background.

    Raises:
        MotionFormatError: no frames.
    """
    n = frame_count(video) - (camera.skip if camera is not None else 0)  # those read_frames gives
    keep = set(np.linspace(0, max(n - 1, 0), min(frames, max(n, 1))).round().astype(int).tolist())
    stack = [f for i, f in enumerate(read_frames(video, camera)) if i in keep]
    if not stack:
        raise MotionFormatError(video, "no frames in this video")
    return stack


def expected_frames(
    videos: Sequence[str | os.PathLike[str]],
    max_frames: int | None = None,
    cameras: Sequence[CalibratedCamera] | None = None,
) -> int | None:
    """How many frames the videos give together, from their files' own counts (not decoded:
    for a progress bar), less each of ``cameras``' skipped frames, at most ``max_frames``;
    None when a count is unknown."""
    counts = [frame_count(path, decode=False) for path in videos]
    if cameras is not None:
        counts = [n - c.skip if n > 0 else n for n, c in zip(counts, cameras, strict=True)]
    if not counts or min(counts) <= 0:
        return max_frames
    return min(counts) if max_frames is None else min(min(counts), max_frames)


def video_fps(path: str | os.PathLike[str], default: float = 25.0) -> float:
    """Frame rate of a video file (``default`` for image folders or when unknown)."""
    path = Path(path)
    if path.is_dir():
        return default
    cap = cv2.VideoCapture(str(path))
    fps = cap.get(cv2.CAP_PROP_FPS) if cap.isOpened() else 0.0
    cap.release()
    return float(fps) if fps and fps > 0 else default


def write_y4m(frames: Iterable[np.ndarray], path: str | os.PathLike[str], fps: int = 30) -> Path:
    """RGB frames (H, W, 3) uint8 as an uncompressed YUV4MPEG2 file (4:2:0, even sizes): what
    Chromium's fake camera plays (``--use-file-for-fake-video-capture``)."""
    path = Path(path)
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        for k, frame in enumerate(frames):
            if k == 0:
                h, w = frame.shape[:2]
                fh.write(f"YUV4MPEG2 W{w} H{h} F{int(fps)}:1 Ip A1:1 C420jpeg\n".encode())
            fh.write(b"FRAME\n" + cv2.cvtColor(frame, cv2.COLOR_RGB2YUV_I420).tobytes())
    return path
