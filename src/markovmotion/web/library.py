"""The motions a server shows: files of one folder, turned into JSON joint positions.

Request paths are relative to the folder and are resolved and checked to stay
inside it (no ``..``, absolute paths or symbolic links out of it).
"""

from __future__ import annotations

import functools
import gzip
import io
import json
import os
import tempfile
import threading
import zlib
from collections import OrderedDict
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, BinaryIO, TypeVar

import numpy as np

from markovmotion.core.markers import Markers
from markovmotion.core.motion import Motion
from markovmotion.core.skeleton import Skeleton
from markovmotion.data.index import INDEX_NAME, MocapIndex
from markovmotion.errors import MarkovMotionError, MotionFormatError
from markovmotion.io import ALL_SUFFIXES, read_motion
from markovmotion.io.bvh import read_bvh
from markovmotion.io.files import base_suffix
from markovmotion.limits import Limit

MAX_UPLOAD = Limit(
    "MARKOVMOTION_MAX_UPLOAD_BYTES", 64 * 1024 * 1024, "bytes of one upload (after decompression)"
)
"""Largest upload the server reads, counted on the wire and again after decompression."""
MAX_UPLOAD_BYTES = int(MAX_UPLOAD.default)
MAX_PATH_CHARS = 1024
"""Longest library path a request may name."""
CHUNK = 1 << 20


def max_upload_bytes() -> int:
    """The upload limit in force (``MARKOVMOTION_MAX_UPLOAD_BYTES``, default 64 MiB)."""
    return int(MAX_UPLOAD)


def shown(text: str, limit: int = 80) -> str:
    """``text`` fit for a one-line message: control characters replaced, cut to ``limit``."""
    text = "".join(c if c.isprintable() else "?" for c in text[: limit + 1])
    return text if len(text) <= limit else text[: limit - 3] + "..."


class LibraryPathError(MarkovMotionError):
    """A requested path that is not a motion file inside the library folder."""


class UploadTooLargeError(MotionFormatError):
    """An upload above :func:`max_upload_bytes` (before or after decompression)."""


class UploadBusyError(MarkovMotionError):
    """:data:`MAX_READING` uploads are being read already (HTTP 429)."""


MAX_READING = 2
"""Uploads one server process reads at once (``/api/upload`` and the live page's): reading
a 60 MB BVH takes about 300 MB for a few seconds, and the reads share the interpreter
lock with every live session; four at once had taken 1.6-1.9 GB, and 40 (the server's
threads) would take 12 GB. Another upload meanwhile is refused, to be sent again."""
_READING = threading.BoundedSemaphore(MAX_READING)


def display_parents(skeleton: Skeleton | Sequence[str]) -> list[int]:
    """Parents of the bones to draw: none above the pelvis (Bandai's ground-level
    ``joint_Root`` would otherwise be linked to the hips by a long false bone). For marker
    names, the bones between the named body points
    (:func:`~markovmotion.features.body_points.point_bones`; none if none are named)."""
    if not isinstance(skeleton, Skeleton):
        from markovmotion.features.body_points import point_bones

        parents = [-1] * len(skeleton)
        for child, parent in point_bones(list(skeleton)).tolist():
            parents[child] = parent
        return parents
    parents = skeleton.parents.tolist()
    parents[skeleton.body_root] = -1
    return parents


def figure_parents(take: Motion | Markers) -> list[int]:
    """:func:`display_parents` of a take's skeleton, or of its marker names."""
    return display_parents(take.names if isinstance(take, Markers) else take.skeleton)


T = TypeVar("T")


def flat_positions(positions: np.ndarray) -> list[float]:
    """Joint positions as the pages get them: mm to one decimal, flat (``F*J*3`` or ``J*3``)."""
    return np.round(positions, 1).ravel().tolist()


def positions_json(positions: np.ndarray) -> str:
    """:func:`flat_positions` as JSON text (a flat array, mm to one decimal), formatted in
    one ``%`` operation: twice as fast as ``json.dumps`` of the rounded list, which a live
    session does for B's every frame."""
    flat = np.asarray(positions, dtype=float).ravel().tolist()
    return _json_format(len(flat)) % tuple(flat)


@functools.lru_cache(maxsize=64)
def _json_format(n: int) -> str:
    return "[" + ",".join(["%.1f"] * n) + "]"


def encoded_frames(motion: Motion | Markers) -> list[str]:
    """Each frame's positions as JSON text (:func:`positions_json`), for streaming frame by
    frame (markers: their positions; a live take's gaps are filled first, :meth:`stream`)."""
    pos = motion.positions if isinstance(motion, Markers) else motion.positions()
    return [positions_json(p) for p in pos]


def motion_payload(motion: Motion) -> dict:
    """The JSON sent to pages: global joint positions (mm, flat ``F*J*3``), the
    parents of the bones to draw (:func:`display_parents`), fps."""
    pos = motion.positions()
    return {
        "name": motion.name,
        "fps": motion.fps,
        "frames": motion.n_frames,
        "joints": list(motion.skeleton.names),
        "parents": display_parents(motion.skeleton),
        "positions": flat_positions(pos),
    }


JSON_CHUNK = 256
"""Frames whose positions :func:`motion_json` computes and encodes at a time."""


def motion_json(motion: Motion, name: str | None = None) -> bytes:
    """:func:`motion_payload` encoded (the bytes of ``json.dumps`` of it, ``name`` in place of
    the motion's if given), the positions computed and encoded :data:`JSON_CHUNK` frames at a
    time. Forward kinematics, ``tolist`` and ``json.dumps`` each hold the interpreter lock
    throughout: in one go, a 60 MB BVH's took 0.8, 0.3 and 3.1 s, the server's event loop
    (every other request and live session) stopped meanwhile, even from a worker thread.
    Chunked, the lock is let go between chunks, and no list of every float is built."""
    payload = motion_payload(motion.trim(0, 0))
    payload["frames"] = motion.n_frames
    if name is not None:
        payload["name"] = name
    head = json.dumps(payload, separators=(",", ":"))
    assert head.endswith('"positions":[]}')
    parts = []
    for a in range(0, motion.n_frames, JSON_CHUNK):
        chunk = Motion(
            motion.skeleton,
            motion.rotations[a : a + JSON_CHUNK],
            motion.translations[a : a + JSON_CHUNK],
            motion.fps,
        )
        parts.append(json.dumps(flat_positions(chunk.positions()), separators=(",", ":"))[1:-1])
    return f"{head[:-3]}[{','.join(parts)}]}}".encode()


def markers_payload(markers: Markers) -> dict:
    """Markers as a skeleton-less figure (every parent -1); missing samples are ``null``."""
    pos = np.round(np.asarray(markers.positions, dtype=float), 1)
    flat: list = pos.ravel().tolist()
    if np.isnan(pos).any():
        flat = [None if v != v else v for v in flat]
    return {
        "name": markers.name,
        "fps": float(markers.fps),
        "frames": int(pos.shape[0]),
        "joints": list(markers.names),
        "parents": [-1] * pos.shape[1],
        "positions": flat,
    }


def _filled(markers: Markers) -> Markers:
    """``markers`` with gaps filled over time; a marker never seen: one line naming it."""
    from markovmotion.features.markers import fill_gaps

    try:
        return fill_gaps(markers)
    except ValueError as exc:
        raise MotionFormatError(markers.name or "markers", str(exc)) from None


def _markers_payload(path: Path) -> dict:
    """A C3D file's markers (:func:`markers_payload`)."""
    from markovmotion.io.c3d import read_c3d

    return {**markers_payload(read_c3d(path)), "name": path.name}


class MotionLibrary:
    """A folder of motion files (BVH, ASF/AMC, C3D) served as JSON, with a small cache.

    A folder with an ``INDEX.csv`` (the motion-capture collection) is read
    through it: true frame rates, CMU's reference frame dropped. ``anonymous``
    leaves file names out of the JSON (evaluation stimuli must not tell what
    they are).
    """

    def __init__(self, root: str | os.PathLike[str], anonymous: bool = False, cache_size: int = 32):
        self.root = Path(root).resolve()
        self.anonymous = anonymous
        self.index = MocapIndex.load(self.root) if (self.root / INDEX_NAME).is_file() else None
        if not self.root.is_dir():
            raise LibraryPathError(f"{root}: no such folder")
        self.cache_size = cache_size
        self._cache: OrderedDict[tuple, Any] = OrderedDict()
        self._lock = threading.Lock()
        self._building: dict[tuple, threading.Lock] = {}

    def public(self, message: str) -> str:
        """``message`` as the browser may see it: paths inside the library relative to it, the
        server's own absolute folder never shown (a reader's error names the file it read)."""
        return message.replace(f"{self.root}{os.sep}", "").replace(str(self.root), "library")

    def files(self) -> list[str]:
        """Every motion file under the folder, as sorted POSIX paths relative to it."""
        out = []
        for dirpath, dirnames, filenames in os.walk(self.root):
            dirnames[:] = sorted(d for d in dirnames if not d.startswith("."))
            for name in filenames:
                path = Path(dirpath) / name
                if (
                    not name.startswith(".")
                    and base_suffix(name) in ALL_SUFFIXES
                    and path.resolve().is_relative_to(self.root)  # no links out
                ):
                    out.append(path.relative_to(self.root).as_posix())
        return sorted(out)

    def resolve(self, relative: str) -> Path:
        """The file at ``relative`` inside the folder; :class:`LibraryPathError` otherwise."""
        name = repr(shown(relative))
        if len(relative) > MAX_PATH_CHARS:
            raise LibraryPathError(f"{name}: longer than {MAX_PATH_CHARS} characters")
        try:
            if not relative or Path(relative).is_absolute() or "\\" in relative:
                raise ValueError
            path = (self.root / relative).resolve()
        except (ValueError, OSError, RuntimeError):
            raise LibraryPathError(f"{name}: not a path inside the library") from None
        if not path.is_relative_to(self.root):
            raise LibraryPathError(f"{name}: outside the library")
        try:
            found = path.is_file() and base_suffix(path) in ALL_SUFFIXES
        except (OSError, ValueError):
            found = False
        if not found:
            raise LibraryPathError(f"{name}: no such motion file in the library")
        return path

    def motion(self, relative: str) -> Motion | Markers:
        """The take at ``relative``, cached by mtime: the same object for every caller, which
        must not change it. A skeletal motion (BVH or ASF/AMC) or, from a C3D file, its
        markers with their gaps filled over time (what a live partner of markers is shown:
        :func:`~markovmotion.features.markers.fill_gaps`)."""
        return self._cached(relative, "motion", lambda path: self._read(path))

    def _read(self, path: Path) -> Motion | Markers:
        if self.index is not None:
            rel = path.relative_to(self.root).as_posix()
            entry = next((e for e in self.index if e.file == rel), None)
            if entry is not None:
                take = self.index.load_motion(entry)
                return _filled(take) if isinstance(take, Markers) else take
        if base_suffix(path) == ".c3d":
            from markovmotion.io.c3d import read_c3d

            markers = read_c3d(path)
            markers.name = path.name
            return _filled(markers)
        return read_motion(path)

    def stream(self, relative: str, fps: float | None = None) -> tuple[Motion | Markers, list[str]]:
        """The motion at ``relative`` at ``fps`` (its own if None) and each frame's joint
        positions as JSON text (mm, flat, one decimal), cached by mtime: a live session's
        person A, read, resampled and encoded once for every session that streams it."""

        def build(path: Path) -> tuple[Motion | Markers, list[str]]:
            motion = self.motion(relative)
            motion = motion.resample(fps) if fps else motion  # the same arrays at its own rate
            return motion, encoded_frames(motion)

        return self._cached(relative, ("stream", fps), build)

    def json(self, relative: str) -> bytes:
        """The file at ``relative`` as encoded JSON (:func:`motion_payload`), cached by mtime."""

        def build(path: Path) -> bytes:
            if base_suffix(path) == ".c3d":
                payload = _markers_payload(path)
            else:
                return motion_json(self.motion(relative), self._shown_name(relative))
            payload["name"] = self._shown_name(relative)
            return json.dumps(payload, separators=(",", ":")).encode()

        return self._cached(relative, "json", build)

    def _shown_name(self, relative: str) -> str:
        return "" if self.anonymous else Path(relative).name

    def _cached(self, relative: str, kind: object, build: Callable[[Path], T]) -> T:
        """``build(path)`` of the file at ``relative``, kept (least recently used first out,
        ``cache_size`` entries) until the file's mtime changes."""
        path = self.resolve(relative)
        key = (path, path.stat().st_mtime_ns, kind)
        with self._lock:
            if key in self._cache:
                self._cache.move_to_end(key)
                return self._cache[key]
            building = self._building.setdefault(key, threading.Lock())
        with building:  # sessions that start together build it once
            with self._lock:
                if key in self._cache:
                    return self._cache[key]
            try:
                value = build(path)
                with self._lock:
                    self._cache[key] = value
                    while len(self._cache) > self.cache_size:
                        self._cache.popitem(last=False)
            finally:
                with self._lock:
                    self._building.pop(key, None)
        return value


def _copy_bounded(src: BinaryIO, dst: BinaryIO, name: str, limit: int) -> None:
    """Copy ``src`` to ``dst`` chunk by chunk, stopping as soon as ``limit`` bytes are passed."""
    total = 0
    while chunk := src.read(CHUNK):
        total += len(chunk)
        if total > limit:
            raise UploadTooLargeError(
                name, f"larger than {limit // 2**20} MiB (limit {MAX_UPLOAD.env})"
            )
        dst.write(chunk)


def read_upload(name: str, content: bytes | BinaryIO) -> Motion:
    """A BVH file sent by a browser (bytes or a binary file); errors name the uploaded
    file, not a temporary one.

    The file is copied to a temporary folder in chunks, a ``.gz`` one decompressed
    on the way, and refused (:class:`UploadTooLargeError`) as soon as it passes
    :func:`max_upload_bytes`, so a gzip bomb never inflates past the limit. Any
    failure to read it is a :class:`MotionFormatError` with one line; an upload while
    :data:`MAX_READING` others are read, :class:`UploadBusyError`.
    """
    base = Path(name or "upload.bvh").name or "upload.bvh"
    label = shown(base)
    if base_suffix(base) != ".bvh":
        raise MotionFormatError(label, "only BVH files (.bvh, .bvh.gz) can be uploaded")
    if not _READING.acquire(blocking=False):
        raise UploadBusyError(
            f"the server is reading {MAX_READING} uploads already: send {label} again in a moment"
        )
    try:
        return _read_upload(label, base, content)
    finally:
        _READING.release()


def _read_upload(label: str, base: str, content: bytes | BinaryIO) -> Motion:
    limit = max_upload_bytes()
    src: BinaryIO = io.BytesIO(content) if isinstance(content, bytes | bytearray) else content
    with tempfile.TemporaryDirectory(prefix="markovmotion-upload-") as tmp:
        path = Path(tmp) / "upload.bvh"
        try:
            with open(path, "wb") as dst:
                if base.lower().endswith(".gz"):
                    with gzip.GzipFile(fileobj=src, mode="rb") as gz:
                        _copy_bounded(gz, dst, label, limit)
                else:
                    _copy_bounded(src, dst, label, limit)
        except (gzip.BadGzipFile, EOFError, zlib.error) as exc:
            raise MotionFormatError(label, f"not a valid gzip file ({exc})") from None
        try:
            motion = read_bvh(path)
        except MotionFormatError as exc:
            raise MotionFormatError(label, exc.problem, exc.line) from None
        except MarkovMotionError as exc:
            raise MotionFormatError(label, str(exc).replace(str(path), label)) from None
        except RecursionError:
            raise MotionFormatError(label, "the hierarchy is nested too deeply") from None
        except MemoryError:
            raise MotionFormatError(label, "too large to read in memory") from None
        except (ValueError, OverflowError, IndexError) as exc:
            problem = shown(str(exc).splitlines()[0] if str(exc) else type(exc).__name__, 200)
            raise MotionFormatError(label, f"cannot be read: {problem}") from None
    motion.name = label
    return motion
