"""Input limits, declared once and applied at every boundary (readers, options, model files).

Each limit has a generous default and can be raised (or lowered) through an
environment variable read at the time of the check, so a test or a user with a
very large take can change it without code::

    MARKOVMOTION_MAX_BYTES=8000000000 markovmotion info huge.bvh.gz

Limits (see also ``docs/limits.md``):

``MARKOVMOTION_MAX_BYTES`` (default 256,000,000 = 256 MB)
    Largest decompressed size of one input file (BVH, AMC/ASF, C3D,
    INDEX.csv, ``.gz`` files measured after decompression) and largest
    uncompressed size of one array in a model file. Readers stop at the
    limit instead of inflating the whole file.
``MARKOVMOTION_MAX_JOINTS`` (default 10,000)
    Joints (including end sites) in one skeleton.
``MARKOVMOTION_MAX_FRAMES`` (default 1,000,000: over two hours at 120 fps)
    Frames of one motion, as read or as produced by resampling.
``MARKOVMOTION_MAX_CHANNELS`` (default 60,000)
    Channels (values per frame) of one skeleton or points of one marker set.
``MARKOVMOTION_MAX_FPS`` (default 1,000)
    Highest frame rate of a file, an option or a resampling target.
``MARKOVMOTION_MIN_FPS`` (default 0.001)
    Lowest frame rate of a file, an option or a resampling target (a
    ``Frame Time`` of more than 1,000 s is a damaged header, not a motion).
``MARKOVMOTION_MAX_VALUES`` (default 20,000,000)
    Values (frames x channels) of one motion or marker set, checked before
    they are parsed (20 M values is a ten-minute 120 fps take of 90 joints).
"""

from __future__ import annotations

import math
import numbers
import os
from dataclasses import dataclass

from markovmotion.errors import LimitError


@dataclass(frozen=True)
class Limit:
    """One input limit: its environment variable, default and what it counts."""

    env: str
    default: float
    what: str

    @property
    def value(self) -> float:
        """The limit in force: the environment variable if set to a positive number."""
        raw = os.environ.get(self.env)
        if raw:
            try:
                value = float(raw)
            except ValueError:
                return self.default
            if math.isfinite(value) and value > 0:
                return value
        return self.default

    def __int__(self) -> int:
        return int(self.value)


MAX_BYTES = Limit("MARKOVMOTION_MAX_BYTES", 256_000_000, "decompressed bytes of one file")
MAX_JOINTS = Limit("MARKOVMOTION_MAX_JOINTS", 10_000, "joints of one skeleton")
MAX_FRAMES = Limit("MARKOVMOTION_MAX_FRAMES", 1_000_000, "frames of one motion")
MAX_CHANNELS = Limit("MARKOVMOTION_MAX_CHANNELS", 60_000, "channels of one skeleton")
MAX_FPS = Limit("MARKOVMOTION_MAX_FPS", 1_000, "frames per second")
MIN_FPS = Limit("MARKOVMOTION_MIN_FPS", 0.001, "frames per second (lowest)")
MAX_VALUES = Limit("MARKOVMOTION_MAX_VALUES", 20_000_000, "values of one motion")
#: An hour at ``render``'s default 15 fps, the longest ``--max-seconds`` allows.
MAX_ANIMATION_FRAMES = Limit(
    "MARKOVMOTION_MAX_ANIMATION_FRAMES", 54_000, "frames of one rendered animation"
)
#: Two minutes at ``render``'s default 15 fps: Pillow holds every frame of a GIF until it is
#: written (about 0.5 MB a frame at the default size), where an MP4 is streamed.
MAX_GIF_FRAMES = Limit("MARKOVMOTION_MAX_GIF_FRAMES", 1_800, "frames of one GIF")
#: The command line's bound on ``gait synthesize --steps``, in the library too.
MAX_STEPS = Limit("MARKOVMOTION_MAX_STEPS", 10_000, "steps of one synthesized walk")

ALL = (
    MAX_BYTES,
    MAX_JOINTS,
    MAX_FRAMES,
    MAX_CHANNELS,
    MAX_FPS,
    MIN_FPS,
    MAX_VALUES,
    MAX_ANIMATION_FRAMES,
    MAX_GIF_FRAMES,
    MAX_STEPS,
)


def max_bytes() -> int:
    return int(MAX_BYTES)


def max_joints() -> int:
    return int(MAX_JOINTS)


def max_frames() -> int:
    return int(MAX_FRAMES)


def max_channels() -> int:
    return int(MAX_CHANNELS)


def max_fps() -> float:
    return MAX_FPS.value


def min_fps() -> float:
    return MIN_FPS.value


def max_values() -> int:
    return int(MAX_VALUES)


def max_animation_frames() -> int:
    return int(MAX_ANIMATION_FRAMES)


def max_gif_frames() -> int:
    return int(MAX_GIF_FRAMES)


def megabytes(n: float) -> str:
    """``n`` bytes as a short human number (``'2000 MB'``)."""
    return f"{n / 1e6:.0f} MB" if n >= 1e6 else f"{n:.0f} bytes"


def exceeded(limit: Limit, found: str | None = None) -> str:
    """The one-line problem for a limit that was exceeded (without the file name)."""
    seen = f" ({found})" if found else ""
    v = limit.value
    shown = f"{v:.0f}" if v == int(v) else f"{v:g}"
    return f"more than {shown} {limit.what}{seen} (limit {limit.env})"


def check_rate(fps: float, what: str = "frame rate") -> float:
    """``fps`` as a float if finite and in [MIN_FPS, MAX_FPS]; else :class:`LimitError`."""
    try:
        value = float(fps)
    except (TypeError, ValueError):
        raise LimitError(f"{what} must be a number, got {fps!r}") from None
    if not math.isfinite(value) or value <= 0:
        raise LimitError(f"{what} must be a finite number above 0, got {value:g}")
    if value < min_fps():
        raise LimitError(f"{what} {value:g} is below {min_fps():g} fps (limit {MIN_FPS.env})")
    if value > max_fps():
        raise LimitError(f"{what} {value:g} is above {max_fps():g} fps (limit {MAX_FPS.env})")
    return value


def check_length(
    amount: object, per_unit: float, limit: Limit, what: str, integer: bool = False
) -> float:
    """``amount`` (seconds, steps) of something a model makes, as a number: finite, above 0
    (a whole number with ``integer``), and ``amount * per_unit`` (its frames, or steps) not
    past ``limit``; else :class:`LimitError` in one line. The command line bounds these
    options; the library takes them from any caller (a day of routine at 30 fps was an
    S x R array of 1.5 TiB)."""
    ok = isinstance(amount, numbers.Real) and not isinstance(amount, bool)  # NumPy's too
    if not ok or not math.isfinite(amount) or amount <= 0 or (integer and amount != int(amount)):
        kind = "a whole number" if integer else "a finite number"
        raise LimitError(f"{what} must be {kind} above 0, got {amount!r}")
    if amount * per_unit > limit.value:
        raise LimitError(exceeded(limit, f"{what} {amount:g}"))
    return float(amount)
