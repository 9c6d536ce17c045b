"""Reading and writing motion files; the format is chosen by the file suffix.

| suffix | reader | unit conversion to mm |
|---|---|---|
| ``.bvh``, ``.bvh.gz`` | :func:`read_bvh` | file lengths x 10 (centimetres; ``length_unit`` to change) |
| ``.amc``, ``.amc.gz`` (+ ``.asf``) | :func:`read_amc` | ASF lengths / ``:units length`` x 25.4 (inches) |
| ``.c3d`` | :func:`read_c3d` (markers, not a skeleton) | the file's ``POINT:UNITS`` |
"""

from __future__ import annotations

import os

from markovmotion.core.motion import Motion
from markovmotion.errors import MotionFormatError
from markovmotion.io.asfamc import asf_beside, read_amc, read_asf
from markovmotion.io.bvh import read_bvh, read_bvh_skeleton, write_bvh
from markovmotion.io.c3d import read_c3d, write_c3d
from markovmotion.io.files import base_suffix

MOTION_SUFFIXES = (".bvh", ".amc")
ALL_SUFFIXES = (".bvh", ".amc", ".c3d")


def read_motion(path: str | os.PathLike[str], fps: float | None = None) -> Motion:
    """Read a skeletal motion (BVH or ASF/AMC) from ``path``.

    ``fps`` overrides the file's frame rate (BVH header; AMC files carry none
    and default to CMU's 120 fps).
    """
    if os.path.isdir(path):
        raise MotionFormatError(path, "is a folder, not a motion file")
    suffix = base_suffix(path)
    if suffix in (".bvh", ".amc"):
        motion = (read_bvh if suffix == ".bvh" else read_amc)(path, fps=fps)
        motion.source = os.fspath(path)
        return motion
    if suffix == ".c3d":
        raise MotionFormatError(
            path, "a C3D file holds markers, not a skeleton: give a BVH or ASF/AMC take"
        )
    raise MotionFormatError(
        path,
        f"unknown motion format {suffix or '(no suffix)'!r}; "
        f"expected one of {', '.join(ALL_SUFFIXES)}",
    )


def describe_take(path: str | os.PathLike[str]) -> tuple[str, int]:
    """``("skeleton", joints)`` (end sites not counted) or ``("markers", markers)`` of a
    motion file, from its header (BVH hierarchy, ASF skeleton beside an AMC, C3D points)."""
    suffix = base_suffix(path)
    if suffix == ".c3d":
        return "markers", len(read_c3d(path).names)
    if suffix == ".bvh":
        skeleton = read_bvh_skeleton(path)
    elif suffix == ".amc":
        skeleton = read_asf(asf_beside(path))
    else:
        raise MotionFormatError(path, f"unknown motion format {suffix or '(no suffix)'!r}")
    return "skeleton", int((~skeleton.end_site).sum())


def check_motion_output(path: str | os.PathLike[str]) -> None:
    """Raise :class:`MotionFormatError` unless ``path`` names a BVH file (``.bvh``, ``.bvh.gz``)."""
    if base_suffix(path) != ".bvh":
        raise MotionFormatError(path, "motions are written as BVH: use a .bvh or .bvh.gz name")


def write_motion(motion: Motion, path: str | os.PathLike[str]) -> None:
    """Write ``motion`` to ``path`` (BVH, optionally ``.bvh.gz``), atomically."""
    check_motion_output(path)
    write_bvh(motion, path)


__all__ = [
    "check_motion_output",
    "read_amc",
    "read_asf",
    "read_bvh",
    "read_c3d",
    "read_motion",
    "write_bvh",
    "write_c3d",
    "write_motion",
]
