"""Markers as a person's observation: virtual markers on a skeleton, and marker features.

The dual-HMM paper (``papers/dual-hmm-windowed-viterbi-interaction.txt``,
§4) records each person with 30 PhaseSpace markers, a pose being 90 numbers:
marker positions, not a skeleton. This module lets the models see people
that way, from C3D files (:func:`markovmotion.io.c3d.read_c3d`) or from a
skeleton's take with markers placed on it.

Virtual markers (:func:`virtual_markers`, ``--markers N``): N markers
(default 30, as the paper's suit; 13 to :data:`MAX_VIRTUAL`) fixed on the
segments of any skeleton that has the common body points
(:mod:`~markovmotion.features.body_points`). Each marker is rigid with one
joint's segment: its position is that joint's position plus the joint's
global rotation applied to a constant vector, so it keeps its distance to
the joint in every frame, as a marker taped to the suit does. The vector is
set in the skeleton's rest pose (every rotation the identity, where each
joint's frame is the world's): the marker sits at a body point, or a
fraction of the way to another, moved by a fixed offset in mm along the
rest pose's forward, outward (away from the midline; to the left for
midline markers) and up directions (forward from the hips, as
:meth:`Motion.heading <markovmotion.core.motion.Motion.heading>`). Where
each goes is :data:`MARKER_LAYOUT` (first 13: the VLMM paper's points, so
``--markers 13`` is that set; 30: the PhaseSpace-sized suit; 32: with the
head's sides); beyond those, markers ring the limb segments
(:func:`marker_layout`).

Marker features (:class:`MarkerFeatures`): the positions of a person's
markers relative to their own centroid on the floor and their heading, the
paper's 90-number pose; optionally their change and the body's travel
(:class:`~markovmotion.features.BodyMotion`'s rows, as for skeletons).
The heading (:func:`heading_markers`, :meth:`MarkerFeatures.place`) is
taken from the markers whose names say left/right hip or shoulder
(``L_HIP``/``R_HIP``, ``LASI``/``RASI``, ``LSHO``/``RSHO`` ...): forward is
(left - right) x up, as for skeletons. When no names say so, it is the
horizontal direction in which the markers spread least (the body is wider
than deep), turned to stay within 90 degrees of the frame before; its sign
is then a guess (the first frame's forward has a positive Z), which only
matters for where B is placed relative to a person whose front it cannot
tell.
"""

from __future__ import annotations

import warnings
import weakref
from collections import deque
from collections.abc import Sequence

import numpy as np

from markovmotion.core.markers import Markers, bare_label, find_markers, not_found
from markovmotion.core.motion import GROUND, Motion
from markovmotion.core.skeleton import Skeleton
from markovmotion.errors import MarkersNotFoundError, MotionFormatError, SkeletonMismatchError
from markovmotion.features.base import FeatureStep
from markovmotion.features.body_motion import BodyMotion
from markovmotion.features.body_points import body_point_index, find_points, normalise
from markovmotion.progress import note
from markovmotion.state import StateError, check_index, check_shape, is_fitted, register, require

#: Most virtual markers :func:`virtual_markers` places.
MAX_VIRTUAL = 200
#: Fewest virtual markers (the VLMM paper's 13 points).
MIN_VIRTUAL = 13

#: Where each virtual marker goes, in order: (name, rigid with the segment of this body
#: point, at this point, toward this point (or None), fraction of the way, offset (forward,
#: outward, up) in mm in the rest pose). ``{s}``/``{side}``: one marker per side, L then R.
MARKER_LAYOUT: tuple[tuple[str, str, str, str | None, float, tuple[float, float, float]], ...] = (
    ("HEAD_FRONT", "head", "head", None, 0.0, (90.0, 0.0, 100.0)),
    ("{s}_SHOULDER", "{side}_shoulder", "{side}_shoulder", None, 0.0, (0.0, 0.0, 50.0)),
    ("{s}_ELBOW", "{side}_elbow", "{side}_elbow", None, 0.0, (-40.0, 0.0, 0.0)),
    ("{s}_WRIST", "{side}_elbow", "{side}_wrist", None, 0.0, (0.0, 0.0, 30.0)),
    ("{s}_HIP", "pelvis", "{side}_hip", None, 0.0, (50.0, 60.0, 30.0)),
    ("{s}_KNEE", "{side}_hip", "{side}_knee", None, 0.0, (0.0, 60.0, 0.0)),
    ("{s}_ANKLE", "{side}_knee", "{side}_ankle", None, 0.0, (0.0, 50.0, 0.0)),
    ("HEAD_BACK", "head", "head", None, 0.0, (-90.0, 0.0, 100.0)),
    ("STERNUM", "chest", "chest", None, 0.0, (100.0, 0.0, 0.0)),
    ("C7", "chest", "neck", None, 0.0, (-70.0, 0.0, 0.0)),
    ("{s}_TOE", "{side}_ankle", "{side}_toe", None, 0.0, (0.0, 0.0, 30.0)),
    ("SACRUM", "pelvis", "pelvis", None, 0.0, (-100.0, 0.0, 30.0)),
    ("{s}_UPPER_ARM", "{side}_shoulder", "{side}_shoulder", "{side}_elbow", 0.5, (0, 0, 45.0)),
    ("{s}_FOREARM", "{side}_elbow", "{side}_elbow", "{side}_wrist", 0.5, (0.0, 0.0, 35.0)),
    ("{s}_THIGH", "{side}_hip", "{side}_hip", "{side}_knee", 0.5, (70.0, 0.0, 0.0)),
    ("{s}_SHIN", "{side}_knee", "{side}_knee", "{side}_ankle", 0.5, (55.0, 0.0, 0.0)),
    ("{s}_HEEL", "{side}_ankle", "{side}_ankle", None, 0.0, (-70.0, 0.0, -40.0)),
    ("T10", "spine", "spine", None, 0.0, (-100.0, 0.0, 0.0)),
    ("{s}_HEAD", "head", "head", None, 0.0, (0.0, 80.0, 100.0)),
)

#: The limb segments extra markers ring, beyond :data:`MARKER_LAYOUT`: (name, from, to).
_LIMBS = (
    ("UPPER_ARM", "{side}_shoulder", "{side}_elbow"),
    ("FOREARM", "{side}_elbow", "{side}_wrist"),
    ("THIGH", "{side}_hip", "{side}_knee"),
    ("SHIN", "{side}_knee", "{side}_ankle"),
)
_RING_MM = 45.0  # how far from the bone extra markers sit
_GOLDEN = (np.sqrt(5.0) - 1) / 2


def _expanded() -> list[tuple[str, str, str, str | None, float, tuple[float, float, float]]]:
    """:data:`MARKER_LAYOUT` with each sided entry as its left and right markers."""
    out = []
    for name, rigid, at, toward, frac, off in MARKER_LAYOUT:
        sides = (("L", "left"), ("R", "right")) if "{s}" in name else (("", ""),)
        for s, side in sides:
            out.append(
                (
                    name.format(s=s),
                    rigid.format(side=side),
                    at.format(side=side),
                    None if toward is None else toward.format(side=side),
                    frac,
                    off,
                )
            )
    return out


def virtual_marker_names(n: int = 30) -> tuple[str, ...]:
    """The names of the first ``n`` virtual markers (deterministic, skeleton-independent)."""
    _check_count(n)
    names = [row[0] for row in _expanded()]
    r = 0
    while len(names) < n:
        r += 1
        names += [f"{s}_{limb}_{r}" for limb, _, _ in _LIMBS for s in ("L", "R")]
    return tuple(names[:n])


def _check_count(n: int) -> None:
    if isinstance(n, bool) or not isinstance(n, int | np.integer):
        raise ValueError(f"virtual markers: a count is an integer, got {n!r}")
    if not MIN_VIRTUAL <= n <= MAX_VIRTUAL:
        raise ValueError(f"virtual markers: {MIN_VIRTUAL} to {MAX_VIRTUAL}, got {n}")


_LAYOUTS: weakref.WeakKeyDictionary[Skeleton, dict[int, tuple[np.ndarray, np.ndarray]]] = (
    weakref.WeakKeyDictionary()
)


def marker_layout(
    skeleton: Skeleton, n: int = 30, what: str = "skeleton"
) -> tuple[np.ndarray, np.ndarray]:
    """Per virtual marker, the joint it is rigid with (n,) and its vector in that joint's
    frame (n, 3) mm (module docstring). Markers past :data:`MARKER_LAYOUT` ring the limb
    segments: round r puts one on each limb (upper arm, forearm, thigh, shin; left then
    right) at a fraction 0.25-0.75 of its length (stepping by the golden ratio) and
    :data:`_RING_MM` from the bone, turned by the golden angle about it each round.

    Raises:
        SkeletonMismatchError: the skeleton lacks a body point the markers need (naming
            ``what`` and the points).
    """
    _check_count(n)
    known = _LAYOUTS.setdefault(skeleton, {})
    if n in known:
        return known[n]
    rows = _expanded()
    r = 0
    while len(rows) < n:
        r += 1
        frac = 0.25 + 0.5 * ((r * _GOLDEN) % 1.0)
        for limb, start, end in _LIMBS:
            for s, side in (("L", "left"), ("R", "right")):
                a, b = start.format(side=side), end.format(side=side)
                rows.append((f"{s}_{limb}_{r}", a, a, b, frac, (np.nan, r, 0.0)))
    rows = rows[:n]
    points = sorted({p for row in rows for p in row[1:4] if p is not None})
    idx = dict(zip(points, body_point_index(skeleton, points, what), strict=True))
    rest = Motion(
        skeleton,
        np.tile([0.0, 0.0, 0.0, 1.0], (1, skeleton.n_joints, 1)),
        skeleton.offsets[None].copy(),
        30.0,
    ).positions()[0]
    lateral = rest[idx["left_hip"]] - rest[idx["right_hip"]] if "left_hip" in idx else None
    if lateral is None or np.hypot(lateral[0], lateral[2]) < 1e-6:
        lateral = np.array([1.0, 0.0, 0.0])
    left = np.array([lateral[0], 0.0, lateral[2]]) / np.hypot(lateral[0], lateral[2])
    up = np.array([0.0, 1.0, 0.0])
    forward = np.cross(left, up)
    rigid, vectors = np.zeros(n, dtype=np.intp), np.zeros((n, 3))
    for k, (name, body, at, toward, frac, off) in enumerate(rows):
        where = rest[idx[at]]
        if toward is not None:
            where = where + frac * (rest[idx[toward]] - where)
        if np.isnan(off[0]):  # a ring marker: round off[1], around the bone
            where = where + _ring(rest[idx[toward]] - rest[idx[at]], forward, up, off[1])
        else:
            out = -1.0 if name.startswith("R_") else 1.0
            where = where + off[0] * forward + out * off[1] * left + off[2] * up
        rigid[k], vectors[k] = idx[body], where - rest[idx[body]]
    known[n] = (rigid, vectors)
    return known[n]


def _ring(bone: np.ndarray, forward: np.ndarray, up: np.ndarray, r: float) -> np.ndarray:
    """Offset (3,) :data:`_RING_MM` from ``bone``, turned r golden angles about it from its
    front (or top, for a bone pointing forward)."""
    d = bone / max(np.linalg.norm(bone), 1e-9)
    p1 = forward - (forward @ d) * d
    if np.linalg.norm(p1) < 0.3:
        p1 = up - (up @ d) * d
    p1 /= np.linalg.norm(p1)
    p2 = np.cross(d, p1)
    angle = r * 2 * np.pi * (1 - _GOLDEN)
    return _RING_MM * (np.cos(angle) * p1 + np.sin(angle) * p2)


def virtual_markers(motion: Motion, n: int = 30) -> Markers:
    """``n`` virtual markers (module docstring, :data:`MARKER_LAYOUT`) on ``motion``'s
    skeleton over its frames: :class:`Markers` (mm) named by :func:`virtual_marker_names`,
    at the motion's rate, named and sourced as the motion.

    Raises:
        SkeletonMismatchError: the skeleton lacks a body point the markers need.
        ValueError: ``n`` outside 13 .. :data:`MAX_VIRTUAL`.
    """
    rigid, vectors = marker_layout(motion.skeleton, n, motion.name or "motion")
    rot, pos = motion.global_transforms()
    points = pos[:, rigid] + np.einsum("fmij,mj->fmi", rot[:, rigid], vectors)
    return Markers(virtual_marker_names(n), points, motion.fps, motion.name, motion.source)


def named_body_points(motion: Motion, names: Sequence[str]) -> Markers:
    """``motion`` as the markers ``names`` of a C3D marker set that names body points
    (``TORSO``, ``R_SHOULDER``, ``L_HAND``...,
    :func:`~markovmotion.features.body_points.find_points`): each marker the skeleton's
    joint of the body point its name stands for, in ``names`` order, at the motion's rate.
    For a model learnt from such markers to answer a skeleton (a capture, a tracked video,
    a webcam's points), with :class:`Lift` for the height.

    Raises:
        SkeletonMismatchError: a name that stands for no body point, or body points the
            skeleton lacks (named).
    """
    known = _NAMED.setdefault(motion.skeleton, {})  # a stream's frames share one skeleton
    index = known.get(tuple(names))
    if index is None:
        found = find_points(names)
        unknown = [n for i, n in enumerate(names) if i not in found.values()]
        if unknown:
            raise SkeletonMismatchError(
                f"the model's markers {', '.join(unknown)} name no body point, so they cannot "
                "be found on a skeleton (give markers)"
            )
        points = sorted(found, key=found.__getitem__)
        index = body_point_index(motion.skeleton, points, motion.name or "the skeleton")
        known[tuple(names)] = index
    return Markers(list(names), motion.positions()[:, index], motion.fps, motion.name)


#: Per skeleton, the joints of each marker set's names (:func:`named_body_points`).
_NAMED: weakref.WeakKeyDictionary[Skeleton, dict[tuple[str, ...], np.ndarray]] = (
    weakref.WeakKeyDictionary()
)


class Lift:
    """Markers moved up to a marker set's height: by ``height`` minus the causal running
    mean of their centroid's height (frames 1..t).

    A marker set from a depth sensor (Bütepage's Kinect points) has the sensor's height as
    its vertical origin, not the floor, so a model learnt from it places people at heights
    that mean nothing for a skeleton standing on a floor. Lifting the skeleton's points to
    the training people's mean centroid height (``height``), and moving B's answer down by
    the same lift, keeps B at A's height as the training pairs stood. :meth:`__call__` on a
    whole take and :meth:`step` frame by frame give the same lifts (a running sum and
    count); a frame with no marker seen keeps the last lift.
    """

    def __init__(self, height: float):
        self.height = float(height)
        self._total, self._count, self._last = 0.0, 0, 0.0

    def __call__(self, markers: Markers) -> tuple[Markers, np.ndarray]:
        """``markers`` lifted, and the lift per frame (F,)."""
        centre = _centre_heights(markers)
        seen = np.isfinite(centre)
        count = np.cumsum(seen)  # frames seen so far
        total = np.cumsum(np.where(seen, centre, 0.0))
        with np.errstate(invalid="ignore", divide="ignore"):
            lift = np.where(count > 0, self.height - total / count, 0.0)
        return _moved_up(markers, lift), lift

    def step(self, markers: Markers) -> tuple[Markers, float]:
        """One frame's markers lifted and its lift, the running mean taking the frame in."""
        centre = float(_centre_heights(markers)[0])
        if np.isfinite(centre):
            self._total += centre
            self._count += 1
            self._last = self.height - self._total / self._count
        return _moved_up(markers, np.array([self._last])), self._last


#: How long (s) a marker of A unseen is held (:class:`HeldMarkers`) before its frame counts
#: as missing: a frame with one marker unseen is otherwise a missing observation to the dual
#: HMM, and a lab's occlusions (a marker or two of dozens) would leave most frames unseen.
HOLD_SECONDS = 0.5


class HeldMarkers:
    """Markers unseen for at most ``frames`` frames placed where they last were, moved as
    the markers seen both then and now have moved on average (a translation: over half a
    second a body turns little), causally: :meth:`__call__` on a whole take and
    :meth:`step` frame by frame give the same frames. A frame with no marker seen, or a
    marker unseen for longer, keeps its NaN (a missing frame, as before).

    Ours, not the papers': the dual HMM observes whole frames (its features are the PCA of
    every marker), and a lab's C3D loses a marker of dozens in many frames; training takes
    fill their gaps by interpolation over time (:func:`fill_gaps`), which a live partner
    cannot, as it does not know the frames to come."""

    def __init__(self, frames: int):
        self.frames = max(int(frames), 0)
        self._recent: deque = deque(maxlen=self.frames)  # the last frames, as given

    def __call__(self, markers: Markers) -> Markers:
        """``markers`` (a whole take) with their short gaps held."""
        pos = markers.positions
        unseen = np.flatnonzero(~np.isfinite(pos).all(axis=(1, 2)))
        if not len(unseen) or not self.frames:
            return markers
        out = markers.copy()
        for t in unseen:
            out.positions[t] = held(pos[t], pos[max(t - self.frames, 0) : t][::-1])
        return out

    def step(self, markers: Markers) -> Markers:
        """One frame's markers with their short gaps held, the frame kept for those after."""
        pos = markers.positions[0]
        if not self.frames or np.isfinite(pos).all():  # the live step's usual frame
            self._recent.append(pos)
            return markers
        out = held(pos, list(reversed(self._recent)))
        self._recent.append(pos)
        return Markers(markers.names, out[None], markers.fps, markers.name, markers.source)


def held(now: np.ndarray, earlier: Sequence[np.ndarray] | np.ndarray) -> np.ndarray:
    """``now`` (M, 3) with each unseen marker at its position in the latest of ``earlier``
    (frames (M, 3), latest first) that shows it, moved by the mean move since then of the
    markers seen in both (:class:`HeldMarkers`); unseen where none does."""
    out = now.copy()
    seen = np.isfinite(now).all(axis=1)
    if not seen.any():
        return out
    for m in np.flatnonzero(~seen):
        for old in earlier:
            if np.isfinite(old[m]).all():
                both = seen & np.isfinite(old).all(axis=1)
                if both.any():
                    out[m] = old[m] + (now[both] - old[both]).mean(axis=0)
                break
    return out


def _centre_heights(markers: Markers) -> np.ndarray:
    """(F,) the height of each frame's centroid of the markers seen (NaN: none seen)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # a frame with nothing seen
        return np.nanmean(markers.positions[..., 1], axis=1)


def _moved_up(markers: Markers, lift: np.ndarray) -> Markers:
    pos = markers.positions.copy()
    pos[..., 1] += lift[:, None]
    return Markers(markers.names, pos, markers.fps, markers.name, markers.source)


# ------------------------------------------------------------------ a person's ground frame
_PARTS = {
    "hip": ("hip", "asi", "asis", "psi", "psis", "pelvis", "ilium"),
    "shoulder": ("shoulder", "sho", "shldr", "acromion", "acr"),
}


def heading_markers(names: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
    """The markers (indices) on the left and on the right hip or shoulder, by their names:
    a name that starts or ends with ``l``/``left`` (``r``/``right``) with the rest one of
    the parts' words (``L_HIP``, ``LASI``, ``LSHO``, ``ShoulderLeft`` ...). A part counts
    only when both sides have it; empty arrays when no part does."""
    found: dict[tuple[str, str], list[int]] = {}
    for k, name in enumerate(names):
        n = normalise(name)
        for side, words in (("left", ("left", "l")), ("right", ("right", "r"))):
            for w in words:
                rest = n[len(w) :] if n.startswith(w) else n[: -len(w)] if n.endswith(w) else None
                for part, keys in _PARTS.items():
                    if rest is not None and rest in keys:
                        found.setdefault((part, side), []).append(k)
    left, right = [], []
    for part in _PARTS:
        if (part, "left") in found and (part, "right") in found:
            left += found[(part, "left")]
            right += found[(part, "right")]
    return np.array(sorted(set(left)), dtype=np.intp), np.array(sorted(set(right)), dtype=np.intp)


def turn_about_up(points: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """``points`` (F, ..., 3) turned by ``yaw`` (F,) radians about +Y (the turn that takes
    +Z, heading 0, to heading ``yaw``)."""
    yaw = np.asarray(yaw, dtype=float).reshape(len(yaw), *([1] * (np.ndim(points) - 2)))
    s, c = np.sin(yaw), np.cos(yaw)
    x, y, z = points[..., 0], points[..., 1], points[..., 2]
    return np.stack([c * x + s * z, y, c * z - s * x], axis=-1)


def principal_heading(positions: np.ndarray) -> np.ndarray:
    """(F,) yaw from the horizontal direction the markers spread least in (module
    docstring), continuous over frames; NaN for a frame with no marker seen."""
    out = np.full(len(positions), np.nan)
    prev = None
    for t, pos in enumerate(positions):
        seen = pos[np.isfinite(pos).all(axis=1)][:, GROUND]
        if len(seen) < 2:
            continue
        centred = seen - seen.mean(axis=0)
        _, vecs = np.linalg.eigh(centred.T @ centred)
        fwd = vecs[:, 0]  # least spread: front to back
        if (prev is None and fwd[1] < 0) or (prev is not None and fwd @ prev < 0):
            fwd = -fwd
        prev = fwd
        out[t] = np.arctan2(fwd[0], fwd[1])
    return out


def into_marker_frame(markers: Markers, origin: np.ndarray, yaw: np.ndarray) -> Markers:
    """``markers`` seen from the per-frame ground frame (origin (F, 3), yaw (F,))."""
    out = markers.copy()
    out.positions = turn_about_up(markers.positions - origin[:, None], -yaw)
    return out


def out_of_marker_frame(positions: np.ndarray, origin: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """Inverse of :func:`into_marker_frame` on positions (F, M, 3): back to the world."""
    return turn_about_up(positions, yaw) + origin[:, None]


def fill_gaps(markers: Markers) -> Markers:
    """``markers`` with each unseen (NaN) sample filled by linear interpolation over time
    between the samples seen before and after it (held at either end): training takes
    with occlusions.

    Raises:
        MotionFormatError: a marker never seen in the take, named (a model's own markers
            must be seen; training takes drop the others first, :func:`seen_in_every`)."""
    seen = markers.visible()
    if seen.all():
        return markers
    if never := markers.never_seen():
        raise MotionFormatError(markers.name or "markers", never)
    out = markers.copy()
    t = np.arange(markers.n_frames)
    for m in np.flatnonzero(~seen.all(axis=0)):
        ok = seen[:, m]
        for c in range(3):
            out.positions[~ok, m, c] = np.interp(t[~ok], t[ok], markers.positions[ok, m, c])
    return out


def seen_in_every(takes: Sequence[Markers]) -> list[Markers]:
    """Training takes without the markers some take never sees (one occluded throughout a
    capture, common in real labs), said in one note: a model learns the markers every take
    shows, rather than losing a whole take, or stopping, for one marker of dozens."""
    never: dict[str, list[str]] = {}  # by label as markers are matched (case, a prefix)
    shown: dict[str, str] = {}
    for t in takes:
        for m in np.flatnonzero(~t.visible().any(axis=0)):
            key = bare_label(t.names[m])
            shown.setdefault(key, t.names[m])
            takes_of = never.setdefault(key, [])
            if (t.name or "a take") not in takes_of:  # a take learnt in both roles: once
                takes_of.append(t.name or "a take")
    if not never:
        return list(takes)
    said = "; ".join(
        f"{shown[k]} (never seen in {', '.join(w[:3])})" for k, w in list(never.items())[:5]
    )
    note(f"left out the markers some take never sees: {said}")
    return [t.select([n for n in t.names if bare_label(n) not in never]) for t in takes]


@register
class MarkerFeatures(FeatureStep):
    """Markers -> (F, 3M) positions (mm), body-centred as the paper's 90-number poses.

    Args:
        body_centred: relative to the person's ground frame (:meth:`place`: centroid
            on the floor, heading); otherwise as given (B's markers already in A's
            ground frame).
        motion: also their change and the body's travel (:meth:`BodyMotion.rows`):
            (F, 6M + 3).
        horizon, travel_horizon: as :class:`~markovmotion.features.BodyMotion`'s.
        turn: whether the ground frame turns with the person's heading (else the
            world's axes at the person's centroid: :class:`DualHMM`'s ``frame``).

    Learnt: ``names_`` (the markers, in order: others' markers are picked by name),
    ``left_`` / ``right_`` (the markers the heading is taken from; empty: the principal
    horizontal direction, module docstring).
    """

    def __init__(
        self,
        body_centred: bool = True,
        motion: bool = False,
        horizon: float = 1 / 6,
        travel_horizon: float = 2 / 3,
        turn: bool = True,
    ):
        self.body_centred = body_centred
        self.motion = motion
        self.horizon = horizon
        self.travel_horizon = travel_horizon
        self.turn = turn

    def fit(self, sequences: Sequence[Markers]) -> MarkerFeatures:
        self.names_ = list(sequences[0].names)
        for m in sequences[1:]:
            self.select(m)
        self.left_, self.right_ = heading_markers(self.names_)
        return self

    def check_state(self) -> None:
        """names_ a list of names; left_ / right_ indices of them."""
        if not is_fitted(self):
            return
        require(self, "names_", "left_", "right_")
        if not isinstance(self.names_, list) or not all(isinstance(n, str) for n in self.names_):
            raise StateError("names_: expected a list of marker names")
        for name in ("left_", "right_"):
            check_index(name, check_shape(name, getattr(self, name), (None,)), len(self.names_))

    def output_width(self) -> int | None:
        m = 3 * len(self.names_)
        return 2 * m + 3 if self.motion else m

    def select(self, markers: Markers) -> Markers:
        """``markers``' markers of ``names_``, in that order (:class:`MarkersNotFoundError`,
        a ValueError, naming those lacking)."""
        if list(markers.names) == self.names_:
            return markers
        try:
            return markers.select(self.names_)
        except KeyError as exc:  # the take's own labels said beside: how it labels them
            missing = find_markers(markers.names, self.names_)[1]
            raise MarkersNotFoundError(
                f"{markers.name or 'markers'}: {not_found(markers.names, missing)}",
                reason=exc.args[0],
            ) from None

    def place(self, positions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Where a person stands and faces per frame, from their markers (F, M, 3) (in
        ``names_`` order): centroid of the markers seen, on the floor (F, 3), and heading
        (F,) (module docstring); NaN for frames with no marker seen."""
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN frames: NaN, said above
            origin = np.nanmean(positions, axis=1)
            if len(self.left_) and len(self.right_):
                lateral = np.nanmean(positions[:, self.left_], axis=1) - np.nanmean(
                    positions[:, self.right_], axis=1
                )
                yaw = np.arctan2(-lateral[:, 2], lateral[:, 0])
            else:
                yaw = principal_heading(positions)
        origin[:, 1] = 0.0
        if not self.turn:
            yaw = np.where(np.isnan(yaw), np.nan, 0.0)
        return origin, yaw

    def pose(self, markers: Markers, positions: np.ndarray | None = None) -> np.ndarray:
        """(F, M, 3) the markers relative to the person's ground frame (``body_centred``)
        or as given."""
        pos = self.select(markers).positions if positions is None else positions
        if not self.body_centred:
            return pos
        origin, yaw = self.place(pos)
        return turn_about_up(pos - origin[:, None], -yaw)

    def rows(self, pose: np.ndarray, origin: np.ndarray, yaw: np.ndarray, fps: float) -> np.ndarray:
        """Feature rows from poses (F, M, 3) and the ground frame: the flat poses, or (with
        ``motion``) :meth:`BodyMotion.rows` of them (change and travel from frames t - 1, t)."""
        if not self.motion:
            return pose.reshape(len(pose), -1)
        return BodyMotion(self.horizon, self.travel_horizon).rows(pose, origin, yaw, fps)

    def transform(self, sequences: Sequence[Markers]) -> list[np.ndarray]:
        out = []
        for m in sequences:
            pos = self.select(m).positions
            origin, yaw = self.place(pos) if self.motion else (None, None)
            out.append(self.rows(self.pose(m, pos), origin, yaw, m.fps))
        return out

    def inverse_transform(self, sequences: Sequence[np.ndarray]) -> list[np.ndarray]:
        """(F, M, 3) positions (the changes are dropped)."""
        m = len(self.names_)
        return [np.asarray(x)[:, : 3 * m].reshape(len(x), m, 3) for x in sequences]
