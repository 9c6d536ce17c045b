"""Biovision Hierarchy (BVH) reading and writing.

Units: BVH carries no unit. ``length_unit`` names the file's (``"cm"`` by
default, the unit of both the CMU conversion and the Bandai Namco data;
``"mm"``, ``"m"`` and ``"inch"`` are accepted) and lengths are multiplied into
millimetres on reading and divided back on writing. Blender and some other tools write
metres, some American pipelines inches: a body skeleton (at least :data:`BODY_JOINTS`
joints) whose rest pose is not a person's size in the unit read (:data:`BODY_SPAN_MM`) but
is in another gets a logged warning naming that unit; ``length_unit="auto"`` (or the
environment's ``MARKOVMOTION_BVH_UNIT``, for the command line: a unit or ``auto``) reads
such a file in that unit instead.

Rotation channels are intrinsic Euler angles in degrees applied in the order
they are listed (``Zrotation Xrotation Yrotation`` is R = Rz Rx Ry), which is
SciPy's upper-case sequence convention. Any order and any subset of the six
channels is accepted per joint.

Our own reader rather than bvhio or pymo: those build per-joint Python objects
frame by frame (slow on long takes), do not report the line of a malformed
file, and pymo is unmaintained; the motion block here is parsed as one NumPy
array (see ``benchmarks/io_bench.py``).
"""

from __future__ import annotations

import io
import logging
import math
import os
import warnings
from collections import defaultdict, deque
from dataclasses import replace

import numpy as np

from markovmotion.core.motion import Motion
from markovmotion.core.rotations import euler_to_quat
from markovmotion.core.skeleton import POSITION_CHANNELS, VALID_CHANNELS, Skeleton
from markovmotion.errors import LimitError, MotionFormatError
from markovmotion.io.files import atomic_write, is_gzip, open_regular, read_text
from markovmotion.limits import (
    MAX_CHANNELS,
    MAX_FRAMES,
    MAX_JOINTS,
    MAX_VALUES,
    check_rate,
    exceeded,
    max_channels,
    max_frames,
    max_joints,
    max_values,
)

UNIT_TO_MM = {"mm": 1.0, "cm": 10.0, "m": 1000.0, "inch": 25.4}
#: The environment's BVH length unit (a key of :data:`UNIT_TO_MM`, ``auto``, or the millimetres
#: of one file unit as a number: ``56.44``, CMU's ASF unit), when none is given.
UNIT_ENV = "MARKOVMOTION_BVH_UNIT"
#: A person's rest pose spans this much (mm, its largest extent): a child of about a metre
#: to a tall adult with the arms out. Wider than any take of the collection (about 1,500-1,900).
#: Not below 900: a person in inches read as centimetres spans 1/2.54 of their size (a 1.84 m
#: arm span gave 723 mm, passed for a person, and the walker was learnt 553 mm tall).
BODY_SPAN_MM = (900.0, 2600.0)
#: Fewer joints are not taken for a whole body (a hand, a tool, a test's small tree).
BODY_JOINTS = 15

log = logging.getLogger(__name__)


#: How a BVH header's unusable frame time is answered: with the true rate.
GIVE_RATE = "give the true frame rate: --fps, fps= in Python, or the fps column of the INDEX.csv listing the file"


#: What a length unit may be, for messages.
UNITS_ALLOWED = f"use one of {', '.join([*UNIT_TO_MM, 'auto'])} or the millimetres of one unit"


def _unit_scale(length_unit: str) -> float:
    """Millimetres of one ``length_unit``: a key of :data:`UNIT_TO_MM`, or a number of mm
    (a unit of no name: CMU's ASF unit, 1/0.45 inch, is ``"56.44"``)."""
    if length_unit in UNIT_TO_MM:
        return UNIT_TO_MM[length_unit]
    try:
        mm = float(length_unit)
    except (TypeError, ValueError):
        mm = math.nan
    if not (math.isfinite(mm) and 0 < mm <= 1e6):
        raise ValueError(f"unknown length unit {length_unit!r}; {UNITS_ALLOWED}")
    return mm


def _unit_words(length_unit: str) -> str:
    """A length unit as a message says it: ``cm``, or ``units of 56.44 mm``."""
    return length_unit if length_unit in UNIT_TO_MM else f"units of {length_unit} mm"


def _given_unit(length_unit: str | None) -> str:
    """``length_unit``, else the environment's (:data:`UNIT_ENV`), else ``cm``; checked."""
    if length_unit:
        if length_unit != "auto":
            _unit_scale(length_unit)
        return length_unit
    unit = os.environ.get(UNIT_ENV, "").strip() or "cm"
    if unit != "auto":
        try:
            _unit_scale(unit)
        except ValueError:
            raise LimitError(f"{UNIT_ENV}={unit!r} is not a length unit; {UNITS_ALLOWED}") from None
    return unit


def rest_span(skeleton: Skeleton) -> float:
    """The largest extent (mm) of the body in ``skeleton``'s rest pose (its offsets, no
    rotation): the pelvis (:attr:`Skeleton.body_root`) and the joints below it, not a static
    joint above it that may stand metres away (Bandai's ``joint_Root``)."""
    pos = np.zeros_like(skeleton.offsets)
    body = np.zeros(skeleton.n_joints, dtype=bool)
    body[skeleton.body_root] = True
    for j in range(skeleton.body_root + 1, skeleton.n_joints):
        parent = skeleton.parents[j]
        pos[j] = pos[parent] + skeleton.offsets[j]
        body[j] = body[parent]
    pos = pos[body]
    return float((pos.max(axis=0) - pos.min(axis=0)).max())


def likely_unit(skeleton: Skeleton, length_unit: str) -> str | None:
    """The unit in which a body ``skeleton``, read in ``length_unit``, would be a person's
    size (:data:`BODY_SPAN_MM`) when it is not in ``length_unit``; None when it is, when it
    is no whole body (fewer than :data:`BODY_JOINTS` joints), or when no unit makes it one.
    Of several, the one nearest a 1.7 m person (on a log scale)."""
    low, high = BODY_SPAN_MM
    span = rest_span(skeleton)
    if skeleton.n_joints < BODY_JOINTS or not np.isfinite(span) or low <= span <= high:
        return None
    raw = span / _unit_scale(length_unit)
    fits = [u for u, mm in UNIT_TO_MM.items() if low <= raw * mm <= high]
    return min(fits, key=lambda u: abs(math.log(raw * UNIT_TO_MM[u] / 1700.0)), default=None)


def _in_unit(skeleton: Skeleton, length_unit: str, where: str) -> tuple[Skeleton, str]:
    """``skeleton`` (read in ``length_unit``, or in cm for ``auto``) and the unit it is in:
    for ``auto`` the :func:`likely_unit` when there is one (the skeleton rescaled); for a unit
    given, that one, with a logged warning when another would make a person of it."""
    read_in = "cm" if length_unit == "auto" else length_unit
    better = likely_unit(skeleton, read_in)
    span = rest_span(skeleton)
    low, high = BODY_SPAN_MM
    if better is None:
        if skeleton.n_joints >= BODY_JOINTS and np.isfinite(span) and not low <= span <= high:
            # a person's size in no unit (Xia's style walks as deep-motion-editing gives them,
            # 25 cm tall in cm): its lengths in mm are off, which every model would learn
            log.warning(
                "%s: its skeleton spans %.0f mm read in %s, and in none of %s is it a "
                "person's size: its lengths in mm are off; if you know its unit, set %s to "
                "the millimetres of one (or read it with length_unit='<mm>')",
                where, span, _unit_words(read_in), ", ".join(UNIT_TO_MM), UNIT_ENV,
            )  # fmt: skip
        return skeleton, read_in
    factor = UNIT_TO_MM[better] / _unit_scale(read_in)
    if length_unit == "auto":
        return replace(skeleton, offsets=skeleton.offsets * factor), better
    log.warning(
        "%s: its skeleton spans %.0f mm read in %s, not a person's size; in %s it spans %.0f "
        "mm: if the file is in %s, set %s=%s (or auto), or read it with length_unit=%r",
        where, span, _unit_words(read_in), better, span * factor, better, UNIT_ENV, better,
        better,
    )  # fmt: skip
    return skeleton, read_in


class _Tokens:
    """Header tokens with their line numbers, for error messages.

    Tokenised lazily, line by line, so a hierarchy refused at a limit is never
    held whole as tokens.
    """

    def __init__(self, path: str, lines: list[str]):
        self.path = path
        self._lines = lines
        self._next_line = 0
        self._pending: deque[tuple[str, int]] = deque()
        self._last: tuple[str, int] | None = None
        self.last_line = len(lines)

    def _fill(self) -> None:
        while not self._pending and self._next_line < len(self._lines):
            line = self._lines[self._next_line]
            self._next_line += 1
            n = self._next_line
            self._pending.extend(
                (t, n) for t in line.replace("{", " { ").replace("}", " } ").split()
            )

    def line(self) -> int:
        """The line of the next token (the last line at the end)."""
        self._fill()
        return self._pending[0][1] if self._pending else self.last_line

    def error(self, problem: str, line: int | None = None) -> MotionFormatError:
        return MotionFormatError(self.path, problem, self.line() if line is None else line)

    def peek(self) -> str | None:
        self._fill()
        return self._pending[0][0] if self._pending else None

    def back(self) -> None:
        """Put the last token read back (so that an error points at its line)."""
        if self._last is not None:
            self._pending.appendleft(self._last)
            self._last = None

    def next(self, what: str) -> str:
        self._fill()
        if not self._pending:
            raise self.error(f"file ends early, expected {what} (missing hierarchy or brace?)")
        self._last = self._pending.popleft()
        return self._last[0]

    def expect(self, word: str) -> None:
        tok = self.next(repr(word))
        if tok.upper() != word.upper():
            self.back()
            raise self.error(f"expected {word!r}, found {tok!r}")

    def number(self, what: str) -> float:
        tok = self.next(what)
        try:
            value = float(tok)
        except ValueError:
            self.back()
            raise self.error(f"expected a number for {what}, found {tok!r}") from None
        if not np.isfinite(value):
            self.back()
            raise self.error(f"{what} is not finite ({tok})")
        return value


def _parse_hierarchy(tok: _Tokens, scale: float) -> Skeleton:
    """The skeleton, parsed with an explicit stack (any depth, no recursion)."""
    names: list[str] = []
    seen: set[str] = set()
    parents: list[int] = []
    offsets: list[tuple[float, float, float]] = []
    channels: list[tuple[str, ...]] = []
    end_site: list[bool] = []
    joint_cap, channel_cap = max_joints(), max_channels()
    n_channels = 0

    tok.expect("HIERARCHY")
    if (tok.peek() or "").upper() != "ROOT":
        raise tok.error("expected ROOT after HIERARCHY")

    def offset() -> tuple[float, float, float]:
        tok.expect("OFFSET")
        with np.errstate(over="ignore"):
            return tuple(tok.number("OFFSET") * scale for _ in range(3))  # type: ignore[return-value]

    def add(name: str, parent: int, chans: tuple[str, ...], end: bool) -> int:
        if len(names) >= joint_cap:
            raise tok.error(f"the skeleton has {exceeded(MAX_JOINTS)}")
        names.append(name)
        parents.append(parent)
        offsets.append(offset())
        channels.append(chans)
        end_site.append(end)
        return len(names) - 1

    def open_joint(parent: int) -> tuple[int, str]:
        nonlocal n_channels
        tok.next("ROOT or JOINT")
        name_line = tok.line()
        name = tok.next("joint name")
        if name in ("{", "}"):
            tok.back()
            raise tok.error("joint without a name")
        # a name is the rest of its line (3ds Max's 'Bip01 L Thigh', as Blender reads it)
        while tok.peek() not in (None, "{", "}") and tok.line() == name_line:
            name += " " + tok.next("joint name")
        if name in seen:
            tok.back()
            raise tok.error(f"joint name {name!r} used twice")
        seen.add(name)
        tok.expect("{")
        index = add(name, parent, (), False)
        tok.expect("CHANNELS")
        count_line = tok.line()
        count = tok.number("channel count")
        if count != int(count) or not 0 <= count <= 6:
            raise tok.error(f"channel count must be 0 to 6, found {count:g}", count_line)
        chans: list[str] = []
        for _ in range(int(count)):
            c = tok.next("channel name")
            if c not in VALID_CHANNELS:
                tok.back()
                raise tok.error(f"unknown channel {c!r} on joint {name!r}")
            if c in chans:
                tok.back()
                raise tok.error(f"channel {c!r} repeated on joint {name!r}")
            chans.append(c)
        n_channels += len(chans)
        if n_channels > channel_cap:
            raise tok.error(f"the skeleton has {exceeded(MAX_CHANNELS)}", count_line)
        channels[index] = tuple(chans)
        return index, name

    stack = [open_joint(-1)]
    while stack:
        index, name = stack[-1]
        word = tok.peek()
        if word is None:
            raise tok.error(f"file ends inside joint {name!r}: unbalanced braces")
        upper = word.upper()
        if upper == "JOINT":
            stack.append(open_joint(index))
        elif upper == "END":
            end_line = tok.line()
            tok.next("End Site")
            # 'End Site', or 'End LeftToeBase_End' as some exporters write it (Mixamo
            # characters re-exported: such a file had been refused at its first end site);
            # the name, one word on End's line, is not kept: an end site is its joint's
            after = tok.peek()
            named = after is not None and after not in ("{", "}") and after.upper() != "SITE"
            if named and tok.line() == end_line:
                tok.next("end site name")
            else:
                tok.expect("Site")
            tok.expect("{")
            if f"{name}_end" in seen:
                raise tok.error(f"joint name {name + '_end'!r} used twice")
            seen.add(f"{name}_end")
            add(f"{name}_end", index, (), True)
            tok.expect("}")
        elif word == "}":
            tok.next("}")
            stack.pop()
        else:
            raise tok.error(f"unexpected {word!r} in joint {name!r}")
    if (tok.peek() or "").upper() == "ROOT":
        raise tok.error("more than one ROOT: only one skeleton per file is supported")
    if tok.peek() is not None:
        raise tok.error(f"unexpected {tok.peek()!r} after the hierarchy (unbalanced braces?)")
    return Skeleton(
        names=tuple(names),
        parents=np.array(parents),
        offsets=np.array(offsets),
        channels=tuple(channels),
        end_site=np.array(end_site),
    )


def _parse_motion_block(
    path: str, lines: list[str], first_line: int, n_channels: int, bad_frames: str = "error"
) -> tuple[np.ndarray, float, np.ndarray]:
    """Frames and frame time from the lines after ``MOTION``; returns (values, frame_time, broken).

    ``broken`` (F,) marks frame lines that are not ``n_channels`` finite numbers; with
    ``bad_frames="missing"`` they are kept (filled with the first good frame), with
    ``"error"`` the first one is an error (and ``broken`` is all False).
    """

    def header(idx: int, key: str) -> float:
        if idx >= len(lines):
            raise MotionFormatError(path, f"file ends before '{key}'", first_line + idx)
        line = lines[idx].strip()
        if not line.lower().startswith(key.lower()):
            raise MotionFormatError(
                path, f"expected '{key}', found {line[:40]!r}", first_line + idx
            )
        text = line[len(key) :].strip()
        try:
            value = float(text)
        except ValueError:
            value = np.nan
        if not np.isfinite(value):
            raise MotionFormatError(
                path, f"'{key}' needs a finite number, found {text[:40]!r}", first_line + idx
            )
        return value

    n_frames = header(0, "Frames:")
    frame_time = header(1, "Frame Time:")
    if n_frames != int(n_frames) or n_frames < 0:
        raise MotionFormatError(
            path, f"frame count must be a whole number, found {n_frames:g}", first_line
        )
    if n_frames > max_frames():
        raise MotionFormatError(path, f"{exceeded(MAX_FRAMES, f'{n_frames:.6g}')}", first_line)
    n_frames = int(n_frames)
    if n_frames == 0:
        raise MotionFormatError(path, "the file has zero frames", first_line)
    if n_frames * max(n_channels, 1) > max_values():
        found = f"{n_frames} frames x {n_channels} channels"
        raise MotionFormatError(path, exceeded(MAX_VALUES, found), first_line)
    body = lines[2:]
    while body and not body[-1].strip():
        body.pop()
    if len(body) < n_frames:
        raise MotionFormatError(
            path,
            f"truncated: header says {n_frames} frames but {len(body)} follow",
            first_line + 2 + len(body),
        )
    if len(body) > n_frames:
        raise MotionFormatError(
            path,
            f"header says {n_frames} frames but {len(body)} lines follow",
            first_line + 2 + n_frames,
        )
    broken = np.zeros(n_frames, dtype=bool)
    try:
        values = _frame_rows(body, n_channels)
    except ValueError:
        if bad_frames != "missing":
            raise _locate_bad_row(path, body, n_channels, first_line + 2) from None
        values, broken = _rows_with_missing(body, n_channels)
    bad = ~np.isfinite(values).all(axis=1)
    if bad_frames == "missing":
        broken |= bad
        if broken.all():  # nothing to keep: the first bad line's own error
            raise _locate_bad_row(path, body, n_channels, first_line + 2, finite=True)
        values[broken] = values[int(np.argmin(broken))]
    elif bad.any():
        i = int(np.argmax(bad))
        raise MotionFormatError(path, f"NaN or infinite value in frame {i}", first_line + 2 + i)
    return values, frame_time, broken


#: Frame lines read by one ``np.loadtxt`` call. One call is one C call that holds the
#: interpreter: a 56 MB upload to the web page, parsed in a worker thread, held it for 363 ms
#: (every live session stalled); 4,096 lines hold it for 20-40 ms, at the same total time.
LOADTXT_LINES = 4096


def _frame_rows(body: list[str], n_channels: int) -> np.ndarray:
    """(F, n_channels) values of the frame lines, read :data:`LOADTXT_LINES` at a time.

    Raises:
        ValueError: a line is not ``n_channels`` numbers (a blank line too: ``loadtxt``
            would skip it and the frames would shift by one).
    """
    values = np.empty((len(body), n_channels))
    for start in range(0, len(body), LOADTXT_LINES):
        with warnings.catch_warnings():  # blank lines only: "input contained no data"
            warnings.simplefilter("ignore", UserWarning)
            rows = np.loadtxt(
                body[start : start + LOADTXT_LINES], dtype=float, ndmin=2, comments=None
            )
        if rows.shape != (min(LOADTXT_LINES, len(body) - start), n_channels):
            raise ValueError("wrong number of lines or values")
        values[start : start + len(rows)] = rows
    return values


def _rows_with_missing(body: list[str], n_channels: int) -> tuple[np.ndarray, np.ndarray]:
    """(values, broken) of frame lines, a line that is not ``n_channels`` numbers being NaN."""
    values = np.full((len(body), n_channels), np.nan)
    broken = np.zeros(len(body), dtype=bool)
    for i, line in enumerate(body):
        row = line.split()
        try:
            if len(row) != n_channels:
                raise ValueError
            values[i] = [float(v) for v in row]
        except ValueError:
            broken[i] = True
    return values, broken


def _locate_bad_row(
    path: str, body: list[str], n_channels: int, first: int, finite: bool = False
) -> MotionFormatError:
    """The error for the first frame line that is not ``n_channels`` (``finite``) numbers."""
    for i, line in enumerate(body):
        row = line.split()
        if len(row) != n_channels:
            return MotionFormatError(
                path,
                f"frame {i} has {len(row)} values, the hierarchy has {n_channels} channels",
                first + i,
            )
        for v in row:
            try:
                x = float(v)
            except ValueError:
                return MotionFormatError(
                    path, f"non-numeric value {v[:20]!r} in frame {i}", first + i
                )
            if finite and not np.isfinite(x):
                return MotionFormatError(path, f"NaN or infinite value in frame {i}", first + i)
    return MotionFormatError(path, "unreadable motion data", first)  # pragma: no cover


def _channel_layout(
    sk: Skeleton,
) -> tuple[list[tuple[int, int, int]], list[tuple[str, list[int], list[int]]]]:
    """Where each channel goes: position channels as (column, joint, axis) and rotation
    channels grouped by Euler order as (order, joints, columns), for vectorised conversion."""
    positions = []
    groups: dict[str, list[tuple[int, list[int]]]] = defaultdict(list)
    col = 0
    for j, chans in enumerate(sk.channels):
        rot_cols = []
        for c in chans:
            if c in POSITION_CHANNELS:
                positions.append((col, j, "XYZ".index(c[0])))
            else:
                rot_cols.append(col)
            col += 1
        if rot_cols:
            groups[sk.rotation_order(j)].append((j, rot_cols))
    rotations = [
        (order, [j for j, _ in members], [c for _, cs in members for c in cs])
        for order, members in groups.items()
    ]
    return positions, rotations


#: Frames converted from Euler angles at a time (:func:`_channels_to_motion`).
CONVERT_FRAMES = 8192


def _channels_to_motion(
    sk: Skeleton, values: np.ndarray, scale: float
) -> tuple[np.ndarray, np.ndarray]:
    """Channel values (F, C) -> local quaternions (F, J, 4) and translations (F, J, 3) mm."""
    f = len(values)
    trans = np.broadcast_to(sk.offsets, (f, sk.n_joints, 3)).copy()
    quats = np.zeros((f, sk.n_joints, 4))
    quats[..., 3] = 1.0
    positions, rotations = _channel_layout(sk)
    for col, j, axis in positions:
        trans[:, j, axis] = values[:, col] * scale
    # in runs of frames: the conversion's temporaries (half angles, one quaternion per axis,
    # their products) are several times the quaternions' size; over 100,000 frames at once
    # they made reading take 9-12 times the file's size in memory
    for s in range(0, f, CONVERT_FRAMES):
        e = min(f, s + CONVERT_FRAMES)
        for order, joints, cols in rotations:
            angles = values[s:e, cols].reshape(e - s, len(joints), len(order))
            quats[s:e, joints] = euler_to_quat(order, angles)
    return quats, trans


def read_bvh(
    path: str | os.PathLike[str],
    fps: float | None = None,
    length_unit: str | None = None,
    bad_frames: str = "error",
) -> Motion:
    """Read a BVH file (``.bvh`` or ``.bvh.gz``) into a :class:`Motion`.

    Args:
        path: the file.
        fps: the true frame rate, overriding the header's ``Frame Time`` (some
            files, such as the CMU salsa conversions, carry a wrong one).
        length_unit: the file's length unit, or ``"auto"`` (see module docstring); None:
            the environment's ``MARKOVMOTION_BVH_UNIT``, else ``"cm"``.
        bad_frames: ``"error"`` (a frame line with NaN, infinite or missing
            values is an error) or ``"missing"`` (such frames are kept with NaN
            rotations; :func:`read_bvh_stream` also returns which they are).

    Raises:
        MotionFormatError: naming the file, line and problem, for any malformed
            input, and for one beyond the limits of :mod:`markovmotion.limits`.
    """
    return read_bvh_stream(path, fps, length_unit, bad_frames)[0]


#: How much of a BVH file :func:`read_bvh_skeleton` reads for its hierarchy.
HEADER_BYTES = 1 << 20


def read_bvh_skeleton(path: str | os.PathLike[str], length_unit: str | None = None) -> Skeleton:
    """The skeleton of a BVH file from its HIERARCHY alone, without reading the frames (the
    first :data:`HEADER_BYTES` of the file, decompressed if ``.gz``): what ``data list``
    shows of every take.

    Raises:
        MotionFormatError: no MOTION line in that much of the file, or a malformed hierarchy.
    """
    import gzip
    import zlib

    with open_regular(path) as fh:
        try:
            stream = gzip.GzipFile(fileobj=fh, mode="rb") if is_gzip(path) else fh
            head = stream.read(HEADER_BYTES).decode("latin-1")
        except (OSError, EOFError, zlib.error) as exc:
            raise MotionFormatError(path, f"cannot read file ({exc})") from None
    lines = head.splitlines()
    motion_at = next((i for i, ln in enumerate(lines) if ln.strip().upper() == "MOTION"), None)
    if motion_at is None:
        raise MotionFormatError(path, f"no MOTION line in its first {HEADER_BYTES} bytes")
    unit = _given_unit(length_unit)
    try:
        skeleton = _parse_hierarchy(
            _Tokens(str(path), lines[:motion_at]), _unit_scale("cm" if unit == "auto" else unit)
        )
    except ValueError as exc:  # the Skeleton's own checks
        raise MotionFormatError(path, str(exc)) from None
    return _in_unit(skeleton, unit, os.path.basename(str(path)))[0]


def read_bvh_stream(
    path: str | os.PathLike[str],
    fps: float | None = None,
    length_unit: str | None = None,
    bad_frames: str = "missing",
) -> tuple[Motion, np.ndarray]:
    """``(motion, broken)``: a BVH read as a recorded stream, ``broken`` (F,) marking the
    frames whose line had NaN, infinite or missing values (their rotations are NaN).

    A file whose frame lines are all bad is an error, as in :func:`read_bvh`.
    """
    if bad_frames not in ("error", "missing"):
        raise ValueError(f"bad_frames must be 'error' or 'missing', got {bad_frames!r}")
    if fps is not None:
        fps = check_rate(fps, "fps")
    unit = _given_unit(length_unit)
    text = read_text(path)
    line_cap = max_frames() + 10 * max_joints() + 1000
    if text.count("\n") > line_cap:
        raise MotionFormatError(path, f"more than {line_cap} lines (limit {MAX_FRAMES.env})")
    lines = text.splitlines()
    del text
    motion_at = next((i for i, ln in enumerate(lines) if ln.strip().upper() == "MOTION"), None)
    first = next((ln.strip() for ln in lines if ln.strip()), None)
    if first is None:
        raise MotionFormatError(path, "the file is empty")
    if first.split()[0].upper() != "HIERARCHY":
        raise MotionFormatError(path, "not a BVH file (it does not begin with HIERARCHY)", 1)
    if motion_at is None:
        raise MotionFormatError(path, "no MOTION section (truncated file?)", len(lines))
    tok = _Tokens(str(path), lines[:motion_at])
    if tok.peek() is None:
        raise MotionFormatError(path, "missing HIERARCHY before MOTION", motion_at + 1)
    try:
        skeleton = _parse_hierarchy(tok, _unit_scale("cm" if unit == "auto" else unit))
    except ValueError as exc:  # the Skeleton's own checks
        raise MotionFormatError(path, str(exc)) from None
    skeleton, unit = _in_unit(skeleton, unit, os.path.basename(str(path)))
    scale = _unit_scale(unit)
    values, frame_time, broken = _parse_motion_block(
        str(path), lines[motion_at + 1 :], motion_at + 2, skeleton.n_channels, bad_frames
    )
    del lines
    with np.errstate(all="ignore"):  # overflow is reported below, not as a warning
        quats, trans = _channels_to_motion(skeleton, values, scale)
        usable = (
            np.isfinite(trans).all()
            and np.isfinite(skeleton.offsets).all()
            and np.isfinite(quats).all()
        )
    if not usable:
        raise MotionFormatError(path, f"values too large to convert from {unit} to mm")
    if fps is None and not frame_time > 0:  # the true rate given, the header's is not read
        raise MotionFormatError(
            path,
            f"frame time must be positive, found {frame_time:g} ({GIVE_RATE})",
            motion_at + 3,
        )
    if fps is None:
        try:
            fps = check_rate(1.0 / frame_time)
        except ValueError:
            raise MotionFormatError(
                path,
                f"Frame Time {frame_time:g} s gives {1.0 / frame_time:g} fps: "
                f"not a usable frame rate ({GIVE_RATE})",
            ) from None
    motion = Motion(skeleton, quats, trans, fps, name=os.path.basename(str(path)))
    if broken.any():
        motion.rotations[broken] = np.nan
    return motion, broken


def motion_to_channels(motion: Motion, length_unit: str = "cm") -> np.ndarray:
    """Channel values (F, C) of ``motion`` in its skeleton's BVH channel layout."""
    from scipy.spatial.transform import Rotation

    sk = motion.skeleton
    scale = _unit_scale(length_unit)
    f = motion.n_frames
    out = np.empty((f, sk.n_channels))
    positions, rotations = _channel_layout(sk)
    for col, j, axis in positions:
        out[:, col] = motion.translations[:, j, axis] / scale
    for order, joints, cols in rotations:
        # complete a partial order (e.g. 'ZX') to three axes and drop the extra ones
        full = order + "".join(a for a in "XYZ" if a not in order)
        rot = Rotation.from_quat(motion.rotations[:, joints].reshape(-1, 4))
        angles = rot.as_euler(full, degrees=True)[:, : len(order)]
        out[:, cols] = angles.reshape(f, len(joints) * len(order))
    return out


def bvh_text(motion: Motion, length_unit: str = "cm", precision: int = 10) -> str:
    """The BVH text of ``motion`` (see :func:`write_bvh`)."""
    sk = motion.skeleton
    scale = _unit_scale(length_unit)
    out = io.StringIO()
    out.write("HIERARCHY\n")
    depth_close: list[int] = []

    def fmt(v: np.ndarray) -> str:
        return " ".join(f"{x:.{precision}g}" for x in v)

    for j in range(sk.n_joints):
        depth = 0
        p = sk.parents[j]
        while p != -1:
            depth += 1
            p = sk.parents[p]
        while depth_close and depth_close[-1] >= depth:
            d = depth_close.pop()
            out.write("\t" * d + "}\n")
        ind = "\t" * depth
        if sk.end_site[j]:
            out.write(f"{ind}End Site\n{ind}{{\n")
        else:
            out.write(f"{ind}{'ROOT' if j == 0 else 'JOINT'} {sk.names[j]}\n{ind}{{\n")
        out.write(f"{ind}\tOFFSET {fmt(sk.offsets[j] / scale)}\n")
        if not sk.end_site[j]:
            chans = sk.channels[j]
            out.write(f"{ind}\tCHANNELS {len(chans)}{' ' if chans else ''}{' '.join(chans)}\n")
        depth_close.append(depth)
    while depth_close:
        out.write("\t" * depth_close.pop() + "}\n")
    out.write(f"MOTION\nFrames: {motion.n_frames}\nFrame Time: {1.0 / motion.fps:.10g}\n")
    values = motion_to_channels(motion, length_unit)
    np.savetxt(out, values, fmt=f"%.{precision}g", delimiter=" ")
    return out.getvalue()


def write_bvh(
    motion: Motion, path: str | os.PathLike[str], length_unit: str = "cm", precision: int = 10
) -> None:
    """Write ``motion`` as BVH (gzip-compressed if ``path`` ends in ``.gz``), atomically.

    Joints without rotation or position channels in the skeleton (as read from
    ASF/AMC) are written with the channels they have; the file reads back into
    the same motion to ``10**-precision`` relative.
    """
    if motion.n_frames == 0:
        raise ValueError("cannot write a motion with zero frames")
    text = bvh_text(motion, length_unit, precision)
    with atomic_write(path) as fh:
        fh.write(text)
