"""The motions a server shows: files of one folder, turned into JSON joint positions.

Request paths are relative to the folder and are resolved and checked to stay
inside it (no ``..``, absolute paths or symbolic links out of it).
"""

from __future__ import annotations

import json
import os
import tempfile
import threading
from collections import OrderedDict
from pathlib import Path

import numpy as np

from markovmotion.core.motion import Motion
from markovmotion.core.skeleton import Skeleton
from markovmotion.data.index import INDEX_NAME, MocapIndex
from markovmotion.errors import MarkovMotionError, MotionFormatError
from markovmotion.io import ALL_SUFFIXES, read_motion
from markovmotion.io.bvh import read_bvh
from markovmotion.io.files import base_suffix

MAX_UPLOAD_BYTES = 64 * 1024 * 1024


class LibraryPathError(MarkovMotionError):
    """A requested path that is not a motion file inside the library folder."""


def display_parents(skeleton: Skeleton) -> list[int]:
    """Parents of the bones to draw: none above the pelvis (Bandai's ground-level
    ``joint_Root`` would otherwise be linked to the hips by a long false bone)."""
    parents = skeleton.parents.tolist()
    parents[skeleton.body_root] = -1
    return parents


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
        "positions": np.round(pos, 1).ravel().tolist(),
    }


def _markers_payload(path: Path) -> dict:
    """C3D markers as a skeleton-less figure (every parent -1); missing samples are ``null``."""
    from markovmotion.io.c3d import read_c3d

    markers = read_c3d(path)
    pos = np.round(np.asarray(markers.positions, dtype=float), 1)
    flat: list = pos.ravel().tolist()
    if np.isnan(pos).any():
        flat = [None if v != v else v for v in flat]
    return {
        "name": path.name,
        "fps": float(markers.fps),
        "frames": int(pos.shape[0]),
        "joints": list(markers.names),
        "parents": [-1] * pos.shape[1],
        "positions": flat,
    }


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
        self._cache: OrderedDict[tuple[Path, float], bytes] = OrderedDict()
        self._lock = threading.Lock()

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
        try:
            if not relative or Path(relative).is_absolute() or "\\" in relative:
                raise ValueError
            path = (self.root / relative).resolve()
        except (ValueError, OSError):
            raise LibraryPathError(f"{relative!r}: not a path inside the library") from None
        if not path.is_relative_to(self.root):
            raise LibraryPathError(f"{relative!r}: outside the library")
        if not path.is_file() or base_suffix(path) not in ALL_SUFFIXES:
            raise LibraryPathError(f"{relative!r}: no such motion file in the library")
        return path

    def motion(self, relative: str) -> Motion:
        """The skeletal motion at ``relative`` (BVH or ASF/AMC)."""
        path = self.resolve(relative)
        if self.index is not None:
            rel = path.relative_to(self.root).as_posix()
            entry = next((e for e in self.index if e.file == rel), None)
            if entry is not None:
                return self.index.load_motion(entry)
        return read_motion(path)

    def json(self, relative: str) -> bytes:
        """The file at ``relative`` as encoded JSON (:func:`motion_payload`), cached by mtime."""
        path = self.resolve(relative)
        key = (path, path.stat().st_mtime)
        with self._lock:
            if key in self._cache:
                self._cache.move_to_end(key)
                return self._cache[key]
        if base_suffix(path) == ".c3d":
            payload = _markers_payload(path)
        else:
            payload = motion_payload(self.motion(relative))
        payload["name"] = "" if self.anonymous else Path(relative).name
        data = json.dumps(payload, separators=(",", ":")).encode()
        with self._lock:
            self._cache[key] = data
            while len(self._cache) > self.cache_size:
                self._cache.popitem(last=False)
        return data


def read_upload(name: str, content: bytes) -> Motion:
    """A BVH file sent by a browser; errors name the uploaded file, not a temporary one."""
    shown = Path(name or "upload.bvh").name
    if len(content) > MAX_UPLOAD_BYTES:
        raise MotionFormatError(shown, f"larger than {MAX_UPLOAD_BYTES // 2**20} MB")
    if base_suffix(shown) != ".bvh":
        raise MotionFormatError(shown, "only BVH files (.bvh, .bvh.gz) can be uploaded")
    with tempfile.TemporaryDirectory(prefix="markovmotion-upload-") as tmp:
        path = Path(tmp) / shown
        path.write_bytes(content)
        try:
            motion = read_bvh(path)
        except MotionFormatError as exc:
            raise MotionFormatError(shown, exc.problem, exc.line) from None
    motion.name = shown
    return motion
