"""C3D reading and writing (marker trajectories) through the maintained ``c3d`` package.

Units: ``POINT:UNITS`` (``mm``, ``cm`` or ``m``; ``mm`` when absent) is
converted to millimetres.

Axes: C3D stores lab coordinates, usually Z up. ``POINT:X_SCREEN`` and
``POINT:Y_SCREEN`` name the lab axes that point right and up on a viewer's
screen; they become our X and Y, and Z is X x Y (right-handed). Without them
the lab is taken as Z up with X to the right (``+X``, ``+Z``), so a lab point
(x, y, z) becomes (x, z, -y): a -90 degree turn about X.

A file without ``POINT:X_SCREEN``/``Y_SCREEN`` whose head markers (labels naming the head)
are not above the body read Z up but are read Y up is read with Y up (``+X``, ``+Y``),
said in a note: a Y-up lab that left the screen axes out had otherwise put every person
on their back, silently. A negative ``POINT:Y_SCREEN`` that puts the head below the body
runs down the screen (as image rows do; Qualisys writes ``-X``/``-Z`` for a Z-up lab): that
axis is read up, said in a note.

Samples the file marks invalid (negative residual, or NaN coordinates) are NaN, and so are
samples at exactly (0, 0, 0), how some software writes a gap (counted in a note).

Writing (:func:`write_c3d`): float32 coordinates in mm, ``POINT:X_SCREEN`` =
``+X`` and ``POINT:Y_SCREEN`` = ``+Y`` (so our axes are the file's and a
reader turns nothing), unseen (NaN) samples with a negative residual, the
labels in ``POINT:LABELS``; written atomically, no analog channels.
"""

from __future__ import annotations

import itertools
import os
import warnings

import numpy as np

from markovmotion.core.markers import Markers, bare_label
from markovmotion.errors import MotionFormatError
from markovmotion.io.files import atomic_write, base_suffix, open_regular
from markovmotion.limits import (
    MAX_BYTES,
    MAX_CHANNELS,
    MAX_VALUES,
    check_rate,
    exceeded,
    max_bytes,
    max_channels,
    max_frames,
    max_values,
)
from markovmotion.progress import say

UNIT_TO_MM = {"mm": 1.0, "cm": 10.0, "m": 1000.0}
DEFAULT_SCREEN = ("+X", "+Z")


def _axis(path: str, key: str, text: str) -> np.ndarray:
    """``'+Z'`` -> (0, 0, 1)."""
    text = text.strip().upper()
    if len(text) != 2 or text[0] not in "+-" or text[1] not in "XYZ":
        raise MotionFormatError(path, f"{key} must be +X, -Y, +Z ..., found {text!r}")
    out = np.zeros(3)
    out["XYZ".index(text[1])] = 1.0 if text[0] == "+" else -1.0
    return out


def lab_to_y_up(path: str, x_screen: str, y_screen: str) -> np.ndarray:
    """The rotation (3, 3) taking lab coordinates to ours (see the module docstring)."""
    x = _axis(path, "POINT:X_SCREEN", x_screen)
    y = _axis(path, "POINT:Y_SCREEN", y_screen)
    if abs(x @ y) > 0:
        raise MotionFormatError(path, f"POINT:X_SCREEN {x_screen} and Y_SCREEN {y_screen} agree")
    return np.stack([x, y, np.cross(x, y)])


def _string(reader, key: str) -> str | None:
    param = reader.get(key)
    return None if param is None else param.string_value.strip()


def _labels(reader, n_points: int) -> tuple[str, ...]:
    """``POINT:LABELS`` (continued in ``LABELS2``, ...), padded with ``marker<k>``."""
    labels: list[str] = []
    for k in itertools.count(1):
        param = reader.get(f"POINT:LABELS{k if k > 1 else ''}")
        if param is None:
            break
        labels.extend(str(s).strip() for s in np.atleast_1d(param.string_array))
    labels = labels[:n_points]
    labels += [""] * (n_points - len(labels))
    return tuple(s or f"marker{k + 1}" for k, s in enumerate(labels))


def read_c3d(path: str | os.PathLike[str]) -> Markers:
    """Read the 3-D points of a C3D file as :class:`Markers` (mm, Y up).

    Raises:
        MotionFormatError: for a missing, damaged or truncated file, one with
            no points or frames, or unknown units or axes.
    """
    import c3d

    path = str(path)
    handle = open_regular(path)
    with handle, warnings.catch_warnings(), np.errstate(all="ignore"):
        warnings.simplefilter("ignore")  # the package warns on truncation; counted below
        size = os.fstat(handle.fileno()).st_size
        if size == 0:
            raise MotionFormatError(path, "the file is empty")
        if size > max_bytes():
            raise MotionFormatError(path, f"the file is {exceeded(MAX_BYTES)}")
        try:
            reader = c3d.Reader(handle)
            _flat_trial_fields(reader)
            # Python numbers: the header's are NumPy uint16, whose products wrap (60,000
            # frames x 200 points passed the limit) or raise (a file of 100,000 frames)
            n_points, expected = int(reader.point_used), int(reader.frame_count)
            rate = float(reader.point_rate)
            if n_points > max_channels():
                raise MotionFormatError(path, f"{exceeded(MAX_CHANNELS, f'{n_points} points')}")
            if expected > max_frames() or expected * max(n_points, 1) * 3 > max_values():
                found = f"{expected} frames x {n_points} points"
                raise MotionFormatError(path, exceeded(MAX_VALUES, found))
            names = _labels(reader, n_points)
            unit = (_string(reader, "POINT:UNITS") or "mm").lower()
            given = (_string(reader, "POINT:X_SCREEN"), _string(reader, "POINT:Y_SCREEN"))
            screen = (given[0] or DEFAULT_SCREEN[0], given[1] or DEFAULT_SCREEN[1])
            frames = [
                points[:, :4].astype(float)
                for _, points, _ in reader.read_frames(copy=False, analog_transform=False)
            ]
        except MotionFormatError:
            raise
        except Exception as exc:  # the package fails in many ways on a damaged file
            raise MotionFormatError(
                path, f"not a readable C3D file ({type(exc).__name__}: {exc})"
            ) from None
    if n_points == 0:
        raise MotionFormatError(path, "the file has no 3-D points")
    try:
        rate = check_rate(rate, "POINT:RATE")
    except ValueError as exc:
        raise MotionFormatError(path, str(exc)) from None
    if expected <= 0 or not frames:
        raise MotionFormatError(path, "the file has zero frames")
    if len(frames) < expected:
        raise MotionFormatError(
            path, f"truncated: the header says {expected} frames but {len(frames)} could be read"
        )
    if unit not in UNIT_TO_MM:
        raise MotionFormatError(path, f"unknown POINT:UNITS {unit!r}; expected mm, cm or m")
    data = np.stack(frames)
    lab = data[..., :3] * UNIT_TO_MM[unit]
    gaps = np.all(data[..., :3] == 0, axis=-1) & ~(data[..., 3] < 0)
    lab[(data[..., 3] < 0) | gaps] = np.nan
    notes = []
    if gaps.any():
        notes.append(f"{int(gaps.sum())} samples at exactly (0, 0, 0) read as unseen (a gap)")
    notes += _unit_notes(lab, unit)
    if not any(given) and not _head_above(lab, names, screen) >= HEAD_ABOVE_MM:
        if _head_above(lab, names, YUP_SCREEN) >= HEAD_ABOVE_MM:
            screen = YUP_SCREEN
            notes.append(
                "no POINT:X_SCREEN/Y_SCREEN, and the head is not above the body with Z up "
                "but is with Y up: read with Y up"
            )
    elif screen[1].strip().startswith("-") and _head_above(lab, names, screen) <= -HEAD_ABOVE_MM:
        # a negative screen Y whose up is the head's down: the screen's Y runs down, as image
        # rows do (Qualisys writes -X / -Z for a Z-up lab); every person had been read upside
        # down, silently. A positive one (ours, +X / +Y) is read as stated.
        down = "+" + screen[1].strip()[1:]
        notes.append(
            f"POINT:Y_SCREEN {screen[1]} puts the head below the body: read with {down} up "
            "(the screen's Y taken downwards)"
        )
        screen = (screen[0], down)
    with np.errstate(all="ignore"):
        positions = lab @ lab_to_y_up(path, *screen).T
    if notes:
        say([f"note: {os.path.basename(path)}: {n}" for n in notes], about=path)
    return Markers(names, positions, float(rate), name=os.path.basename(path), source=path)


#: A take's markers whose extent (mm; the median over frames of the largest extent along an
#: axis) lies outside this when read in the file's ``POINT:UNITS`` are noted, if another
#: unit makes them :data:`PERSON_SPAN_MM`: a file in metres labelled mm is a body 0.9 mm
#: across, which every family would answer as if it were a person (a new user's trial).
#: Wide, as a marker set may be a hand alone or a room with a person walking in it.
MARKER_SPAN_MM = (10.0, 20_000.0)
#: The extent (mm) of a person's markers, from a hand's alone to a body with arms out.
PERSON_SPAN_MM = (100.0, 3_000.0)


def _unit_notes(lab: np.ndarray, unit: str) -> list[str]:
    """A note when the markers ``lab`` (F, M, 3; mm as read in ``unit``) are no person's
    size and would be in another unit (:data:`MARKER_SPAN_MM`): the file's ``POINT:UNITS``
    is surely wrong. A note, not a refusal: the data are read as the file says."""
    seen = np.isfinite(lab).all(axis=-1)
    enough = seen.sum(axis=1) >= 3
    if not enough.any():
        return []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        extent = np.nanmax(lab[enough], axis=1) - np.nanmin(lab[enough], axis=1)
    span = float(np.median(extent.max(axis=1)))
    if MARKER_SPAN_MM[0] <= span <= MARKER_SPAN_MM[1] or not span > 0:
        return []
    raw = span / UNIT_TO_MM[unit]
    low, high = PERSON_SPAN_MM
    fits = [u for u, mm in UNIT_TO_MM.items() if low <= raw * mm <= high]
    if not fits:
        return []
    u = fits[0]
    return [
        f"its markers span {span:.3g} mm read in {unit} (POINT:UNITS), no person's size; in "
        f"{u} they would span {raw * UNIT_TO_MM[u]:.0f} mm: is its POINT:UNITS wrong?"
    ]


def _flat_trial_fields(reader) -> None:
    """``TRIAL:ACTUAL_START_FIELD`` and ``ACTUAL_END_FIELD`` are two 16-bit words; a writer
    that gives them two dimensions (2, 1), as ezc3d's example files do, had the c3d package
    fail on every frame count ("not a readable C3D file (TypeError: only 0-dimensional
    arrays ...)"): they are read flat."""
    for name in ("TRIAL:ACTUAL_START_FIELD", "TRIAL:ACTUAL_END_FIELD"):
        param = reader.get(name)
        if param is not None and len(param.dimensions) > 1 and np.prod(param.dimensions) == 2:
            param.dimensions = [2]


#: The screen axes of a Y-up lab (X right, Y up), as :func:`write_c3d` writes them.
YUP_SCREEN = ("+X", "+Y")

#: How far (mm) a person's head markers stand above their markers' centroid, at least, for
#: a reading of the axes to be upright (the collection's upper bodies: 214-335 mm read
#: right, -191 to +10 read Z up from a Y-up lab).
HEAD_ABOVE_MM = 100.0


def _head_above(lab: np.ndarray, names: tuple[str, ...], screen: tuple[str, str]) -> float:
    """The median over frames of how far (mm) the markers labelled as the head (``HEAD``,
    Plug-in Gait's ``LFHD``/``RBHD``, Qualisys' ``L_HDF``/``R_HDB``...) stand above the
    markers' centroid, read with
    ``screen``; NaN without such markers."""
    bare = [bare_label(n) for n in names]
    head = [
        i for i, n in enumerate(bare) if "head" in n or n.endswith(("fhd", "bhd", "hdf", "hdb"))
    ]
    if not head or len(head) == len(names):
        return float("nan")
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore")  # frames with no head marker seen: NaN
        up = lab @ lab_to_y_up("", *screen)[1]
        return float(np.nanmedian(np.nanmean(up[:, head], axis=1) - np.nanmean(up, axis=1)))


#: Longest marker label C3D's ``POINT:LABELS`` holds.
MAX_LABEL = 32


def check_c3d_output(path: str | os.PathLike[str]) -> None:
    """Raise :class:`MotionFormatError` unless ``path`` names a ``.c3d`` file."""
    if base_suffix(path) != ".c3d" or str(path).endswith(".gz"):
        raise MotionFormatError(path, "markers are written as C3D: use a .c3d name")


def write_c3d(markers: Markers, path: str | os.PathLike[str]) -> None:
    """Write ``markers`` to ``path`` as C3D (module docstring), atomically: a failure
    part-way leaves any previous file untouched. :func:`read_c3d` gives back the same
    names, frame rate and positions to float32 precision (NaN where unseen).

    Raises:
        MotionFormatError: not a ``.c3d`` name, no frames or markers, or a label
            longer than :data:`MAX_LABEL` characters.
    """
    import c3d

    check_c3d_output(path)
    if markers.n_frames == 0 or markers.n_markers == 0:
        raise MotionFormatError(path, "cannot write markers with zero frames or markers")
    long = [n for n in markers.names if len(n) > MAX_LABEL or not n.isascii()]
    if long:
        raise MotionFormatError(path, f"marker labels must be ASCII of <= {MAX_LABEL}: {long[0]!r}")
    writer = c3d.Writer(point_rate=float(markers.fps), point_scale=-1.0, point_units="mm  ")
    writer.set_point_labels(list(markers.names))
    writer.set_screen_axis("+X", "+Y")
    seen = markers.visible()
    no_analog = np.zeros((0, 0), dtype=np.float32)
    frames = []
    for pos, ok in zip(markers.positions, seen, strict=True):
        points = np.zeros((markers.n_markers, 5), dtype=np.float32)
        points[:, :3] = np.where(ok[:, None], pos, 0.0)
        points[~ok, 3] = -1.0
        frames.append((points, no_analog))
    writer.add_frames(frames)
    with atomic_write(path, "wb") as fh, warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "no analog data": none is meant
        writer.write(fh)
