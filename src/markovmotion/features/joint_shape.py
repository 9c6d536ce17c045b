"""Joint shape vectors of two interacting people (interaction paper, §2, eqs. 2-4).

At each instant the joint configuration of two people is one combined shape
vector C = [S_0, S_1, d, s] (eq. 2): each person's shape in actor-centred
coordinates scaled by that person's height, their relative separation d (eq. 3)
and their relative scale s (eq. 4). The two people are either silhouettes
tracked in video (shape = the 32 B-spline control points, reference point = the
top of the head, person 0 = the left-hand individual) or 3-D motion capture
(shape = joint positions, reference point = the pelvis on the floor, person 0 =
the first file of the take), or named 3-D markers (C3D: shape = the markers, picked
by name; reference point = their centroid, heading from the markers named left and
right shoulder or hip, as the dual HMM's
:class:`~markovmotion.features.markers.MarkerFeatures`; "height" = the body's size,
:func:`marker_size`, since markers such as an upper-body tracker's need not show
the floor: :func:`person_from_markers`). The modelling that follows is the same for all.

Definitions (the equations of eqs. 3-4 are lost from the paper's text; these
follow its description):

- silhouettes: d = (X_1 - X_0) / (h_0 + h_1) (horizontal separation of the
  reference points), shape points (P - X) / h.
- 3-D: d = [R(-yaw_0) (X_1 - X_0) / (h_0 + h_1) on the floor (x, z),
  cos(yaw_1 - yaw_0), sin(yaw_1 - yaw_0)] (separation in person 0's facing
  frame and relative facing), shape points R(-yaw) (P - X) / h with X the
  pelvis on the floor (heights above the floor are kept). Where the reference
  points are not on the floor (markers: the centroid), d also holds their
  vertical separation (Y_1 - Y_0) / (h_0 + h_1), last (``vertical_``).
- both: s = h_0 / (h_0 + h_1).

Smoothing, normalisation to [0, 1] and the state vectors F = [C, lambda dC]
(eq. 5) are the generic steps :class:`TemporalSmoothing` and
:class:`AugmentedConfiguration` (here with one range for all shape
coordinates, so that shapes keep their geometry); :func:`joint_shape_pipeline`
chains them.
"""

from __future__ import annotations

import weakref
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from markovmotion.core.markers import Markers, find_markers
from markovmotion.core.motion import Motion
from markovmotion.core.skeleton import Skeleton
from markovmotion.core.words import bare_name, first_names
from markovmotion.errors import SkeletonMismatchError
from markovmotion.features.augmented import AugmentedConfiguration
from markovmotion.features.base import FeaturePipeline, FeatureStep
from markovmotion.features.markers import MarkerFeatures, fill_gaps
from markovmotion.features.person import ShapeCentre
from markovmotion.features.smoothing import TemporalSmoothing
from markovmotion.state import StateError, check_count, is_fitted, register, require

#: Joints of CMU's retargeted figure kept for 3-D shapes (no fingers or eyes).
MAJOR_JOINTS = (
    "hip",
    "abdomen",
    "chest",
    "neck",
    "head",
    "rShldr",
    "rForeArm",
    "rHand",
    "lShldr",
    "lForeArm",
    "lHand",
    "rThigh",
    "rShin",
    "rFoot",
    "rFoot_end",
    "lThigh",
    "lShin",
    "lFoot",
    "lFoot_end",
)


def rotate_yaw(v: np.ndarray, yaw: np.ndarray | float) -> np.ndarray:
    """Rotate 3-D vectors ``v`` (..., 3) about +Y by ``yaw`` (broadcast over leading axes)."""
    v = np.asarray(v, dtype=float)
    c, s = np.cos(yaw), np.sin(yaw)
    out = v.copy()
    out[..., 0] = c * v[..., 0] + s * v[..., 2]
    out[..., 2] = -s * v[..., 0] + c * v[..., 2]
    return out


@dataclass
class Person:
    """One person over F frames: shape points (F, K, D), reference (F, D), height and heading (F,)."""

    points: np.ndarray
    reference: np.ndarray
    height: np.ndarray
    heading: np.ndarray

    @property
    def n_frames(self) -> int:
        return len(self.points)


@dataclass
class TwoPeople:
    """Two people over F frames in image or world coordinates.

    Attributes:
        points: (F, 2, K, D) each person's shape points: B-spline control points
            (D = 2, image pixels, y down) or joint positions (D = 3, mm, Y up).
        reference: (F, 2, D) each person's reference point (top of the head;
            pelvis on the floor).
        height: (F, 2) each person's height (pixels; mm).
        heading: (F, 2) facing angle about +Y in radians (3-D only, else zeros).
        fps: frames per second.
        name: where it came from, for messages.
    """

    points: np.ndarray
    reference: np.ndarray
    height: np.ndarray
    heading: np.ndarray
    fps: float
    name: str = ""

    @property
    def n_frames(self) -> int:
        return len(self.points)

    @property
    def dims(self) -> int:
        return self.points.shape[-1]

    def person(self, i: int) -> Person:
        """Person 0 or 1 alone."""
        return Person(
            self.points[:, i], self.reference[:, i], self.height[:, i], self.heading[:, i]
        )

    def trim(self, start: int = 0, stop: int | None = None) -> TwoPeople:
        sl = slice(start, stop)
        return TwoPeople(
            self.points[sl],
            self.reference[sl],
            self.height[sl],
            self.heading[sl],
            self.fps,
            self.name,
        )

    @classmethod
    def from_motions(
        cls,
        a: Motion | Markers,
        b: Motion | Markers,
        fps: float | None = 25.0,
        joints: Sequence[str] | None = None,
    ) -> TwoPeople:
        """Both people of a motion-capture take in one shared world frame
        (:func:`person_from_take`: skeletons, or markers picked by the names ``joints``)."""
        people = [m.resample(fps) if fps else m for m in (a, b)]
        n = min(m.n_frames for m in people)
        one, two = (person_from_take(m.trim(0, n), joints) for m in people)
        return cls.from_people(one, two, float(people[0].fps), f"{a.name}+{b.name}")

    @classmethod
    def from_people(cls, a: Person, b: Person, fps: float, name: str = "") -> TwoPeople:
        """Two people seen over the same frames (cut to the shorter)."""
        n = min(a.n_frames, b.n_frames)
        return cls(
            np.stack([a.points[:n], b.points[:n]], axis=1),
            np.stack([a.reference[:n], b.reference[:n]], axis=1),
            np.stack([a.height[:n], b.height[:n]], axis=1),
            np.stack([a.heading[:n], b.heading[:n]], axis=1),
            fps,
            name,
        )


_SHAPE_JOINTS: weakref.WeakKeyDictionary[Skeleton, dict[tuple[str, ...], list[int]]] = (
    weakref.WeakKeyDictionary()
)


def shape_joints(skeleton: Skeleton, joints: Sequence[str] | None = None) -> list[int]:
    """Indices of the joints that make a 3-D shape: ``joints`` (by name, in that order), else
    :data:`MAJOR_JOINTS` when the skeleton has them, else all.

    A name is matched as marker labels are (:func:`~markovmotion.core.markers.find_markers`:
    as it is, else whatever its case, else without a namespace, Mixamo's ``mixamorig:Hips``,
    when one joint alone matches so), and a learnt name's own namespace is dropped likewise:
    the same skeleton exported with or without one is the same skeleton.

    Raises:
        SkeletonMismatchError: ``joints`` the skeleton lacks, named."""
    have = skeleton.names
    names = tuple(joints or (MAJOR_JOINTS if not find_markers(have, MAJOR_JOINTS)[1] else have))
    known = _SHAPE_JOINTS.setdefault(skeleton, {})
    if names in known:
        return list(known[names])
    idx, missing = find_markers(have, names)
    if missing:  # each name again, a learnt namespace ('mixamorig:Hips') dropped if need be
        idx, missing = [], []
        for n in names:
            hit = find_markers(have, [n])[0] or find_markers(have, [bare_name(n)])[0]
            idx += hit
            missing += [] if hit else [n]
    if missing:
        raise SkeletonMismatchError(
            f"its skeleton lacks the joints {first_names(missing, 8)} (joints are matched by "
            f"name; it has {first_names(have, 8)})"
        )
    known[names] = idx
    return list(idx)


def person_from_motion(m: Motion, joints: Sequence[str] | None = None) -> Person:
    """One person of motion capture: shape joints (mm), pelvis on the floor, heading and height.

    The height is the standing height of the rest pose (vertical extent of the
    joints), constant over the motion.
    """
    sk = m.skeleton
    pos = m.positions()
    ref = pos[:, sk.body_root].copy()
    ref[:, 1] = 0.0
    rest_y = Motion.from_rotations(sk, np.tile([0.0, 0, 0, 1], (1, sk.n_joints, 1))).positions()
    height = np.ptp(rest_y[0, :, 1])
    return Person(
        pos[:, shape_joints(sk, joints)], ref, np.full(m.n_frames, height), m.heading(pos)
    )


def marker_size(positions: np.ndarray) -> float:
    """A person's size from markers (F, M, 3), in mm: the median over frames of the root mean
    square distance of the markers from their centroid.

    Stands in for the standing height of a skeleton's rest pose, which markers need not
    show (the Bütepage tracker's 8 upper-body points have no feet and an arbitrary
    vertical origin). Chosen over a single bone because it needs no names, and over the
    vertical extent because it hardly depends on the action: on the Bütepage takes it
    stays within 7 % for one person across handshakes and waves, while the extent, which
    follows the idle hand, varies by up to 20 %.
    """
    centred = positions - positions.mean(axis=1, keepdims=True)
    return float(np.median(np.sqrt((centred**2).sum(axis=-1).mean(axis=1))))


def person_from_markers(m: Markers, names: Sequence[str] | None = None) -> Person:
    """One person of markers: the markers ``names`` (default: all, in the file's order; gaps
    filled over time, :func:`~markovmotion.features.markers.fill_gaps`), their centroid as
    reference, the heading of
    :meth:`MarkerFeatures.place <markovmotion.features.markers.MarkerFeatures.place>` and
    the size of :func:`marker_size` as height, constant over the take.

    The reference keeps its height (unlike a skeleton's pelvis, put on the floor): shapes
    are scaled about it, and a vertical origin that is not the floor (an upper-body
    tracker's: the sensor's height) would scale the markers' heights by the person's size.
    On the Bütepage handshakes and waves, leaving out one pair of people, the mean shape's
    body-centred error was 5 % lower (139 against 148 mm, both roles learnt) with the
    centroid than with the centroid on the floor.

    Raises:
        ValueError: a marker of ``names`` is missing from ``m`` or never seen.
    """
    step = MarkerFeatures().fit([m if names is None else _select(m, names)])
    pos = fill_gaps(step.select(m)).positions
    _, yaw = step.place(pos)
    return Person(pos, pos.mean(axis=1), np.full(m.n_frames, marker_size(pos)), yaw)


def _select(m: Markers, names: Sequence[str]) -> Markers:
    try:
        return m.select(list(names))
    except KeyError as exc:
        raise ValueError(f"{m.name or 'markers'}: {exc.args[0]}") from None


def person_from_take(take: Motion | Markers, names: Sequence[str] | None = None) -> Person:
    """:func:`person_from_motion` of a skeleton's take (``names``: its shape joints) or
    :func:`person_from_markers` of markers (``names``: the markers)."""
    if isinstance(take, Markers):
        return person_from_markers(take, names)
    return person_from_motion(take, names)


def joints_skeleton(skeleton: Skeleton, joints: Sequence[int]) -> Skeleton:
    """The skeleton of ``joints`` only: each joint hangs from its nearest kept ancestor.

    Offsets come from the rest pose; kept joints without kept children become
    end sites. Used to write a 3-D partner as BVH after inverse kinematics.
    """
    keep = sorted(joints)
    rest = Motion.from_rotations(skeleton, np.tile([0.0, 0, 0, 1], (1, skeleton.n_joints, 1)))
    rest_pos = rest.positions()[0]
    parents, offsets = [], []
    for j in keep:
        p = skeleton.parents[j]
        while p >= 0 and p not in keep:
            p = skeleton.parents[p]
        parents.append(keep.index(p) if p >= 0 else -1)
        offsets.append(rest_pos[j] - rest_pos[p] if p >= 0 else skeleton.offsets[j])
    parents_arr = np.array(parents)
    leaf = np.array([i not in parents_arr[1:] for i in range(len(keep))])
    leaf[0] = False
    channels = [
        () if leaf[i] else (skeleton.channels[j] or ("Zrotation", "Xrotation", "Yrotation"))
        for i, j in enumerate(keep)
    ]
    return Skeleton(
        names=tuple(skeleton.names[j] for j in keep),
        parents=parents_arr,
        offsets=np.array(offsets),
        channels=tuple(channels),
        end_site=leaf,
    )


def actor_centred(
    points: np.ndarray, reference: np.ndarray, height: np.ndarray, heading: np.ndarray
) -> np.ndarray:
    """Shape points in actor-centred coordinates scaled by height (§2).

    ``points`` (..., K, D) with ``reference`` (..., D), ``height`` and
    ``heading`` (...); 3-D points are also turned so the person faces +Z.
    """
    rel = (np.asarray(points) - np.asarray(reference)[..., None, :]) / np.asarray(height)[
        ..., None, None
    ]
    if rel.shape[-1] == 3:
        rel = rotate_yaw(rel, -np.asarray(heading)[..., None])
    return rel


@register
class JointShape(FeatureStep):
    """:class:`TwoPeople` -> (F, 2KD + |d| + 1) combined shape vectors C (eqs. 2-4).

    Layout: person 0's shape, person 1's shape (K points of D coordinates each),
    the separation d (1 component for silhouettes, 4 for 3-D, 5 with ``vertical_``) and
    the scale s.

    Learnt: ``n_points_``, ``n_dims_``, ``vertical_`` (3-D reference points off the floor,
    as markers' centroids: d holds their vertical separation too; absent from files of
    older versions: False).
    """

    def fit(self, sequences: Sequence[TwoPeople]) -> JointShape:
        first = sequences[0]
        self.n_points_ = int(first.points.shape[2])
        self.n_dims_ = int(first.dims)
        self.vertical_ = bool(
            self.n_dims_ == 3 and any(np.any(p.reference[..., 1] != 0) for p in sequences)
        )
        for p in sequences[1:]:
            if p.points.shape[2:] != first.points.shape[2:]:
                raise ValueError(f"{p.name}: shape points differ from {first.name}'s")
        return self

    @property
    def shape_size(self) -> int:
        """Number of components of one person's shape vector."""
        return self.n_points_ * self.n_dims_

    def person_slice(self, person: int) -> slice:
        """Columns of C holding person 0's or person 1's shape."""
        return slice(person * self.shape_size, (person + 1) * self.shape_size)

    def check_state(self) -> None:
        """n_points_ >= 1 points of n_dims_ (2 or 3) coordinates."""
        if is_fitted(self):
            require(self, "n_points_", "n_dims_")
            check_count("n_points_", self.n_points_)
            if check_count("n_dims_", self.n_dims_) not in (2, 3):
                raise StateError(f"n_dims_: must be 2 or 3, found {self.n_dims_}")

    def transform(self, sequences: Sequence[TwoPeople]) -> list[np.ndarray]:
        return [self._combine(p) for p in sequences]

    def _combine(self, p: TwoPeople) -> np.ndarray:
        shapes = actor_centred(p.points, p.reference, p.height, p.heading)
        h0, h1 = p.height[:, 0], p.height[:, 1]
        total = h0 + h1
        delta = p.reference[:, 1] - p.reference[:, 0]
        if self.n_dims_ == 2:
            sep = (delta[:, :1]) / total[:, None]
        else:
            local = rotate_yaw(delta, -p.heading[:, 0]) / total[:, None]
            turn = p.heading[:, 1] - p.heading[:, 0]
            sep = np.column_stack([local[:, 0], local[:, 2], np.cos(turn), np.sin(turn)])
            if getattr(self, "vertical_", False):
                sep = np.column_stack([sep, local[:, 1]])
        return np.hstack([shapes.reshape(p.n_frames, -1), sep, (h0 / total)[:, None]])

    def shape_vectors(self, p: Person) -> np.ndarray:
        """(F, KD) actor-centred shape vectors of one person (S of eq. 2, S^H of eq. 18)."""
        s = actor_centred(p.points, p.reference, p.height, p.heading)
        return s.reshape(p.n_frames, -1)

    def place(self, c: np.ndarray, person: int, real: Person) -> Person:
        """The partner of the real person in image / world coordinates (eqs. 3-4 re-arranged, §5.1).

        Args:
            c: (F, len(C)) combined shape vectors (not normalised).
            person: 0 or 1, which half of C is the real person.
            real: the real person over the same F frames.

        Returns:
            The partner. Silhouette partners stand on the real person's floor line.
        """
        c = np.atleast_2d(c)
        reference, height, heading = real.reference, real.height, real.heading
        other = 1 - person
        shape = c[:, self.person_slice(other)].reshape(len(c), self.n_points_, self.n_dims_)
        sep = c[:, 2 * self.shape_size : -1]
        s = np.clip(c[:, -1], 1e-3, 1 - 1e-3)
        ratio = (1 - s) / s if person == 0 else s / (1 - s)
        h_other = height * ratio
        total = height + h_other
        sign = 1.0 if person == 0 else -1.0
        if self.n_dims_ == 2:
            ref = np.column_stack(
                [reference[:, 0] + sign * sep[:, 0] * total, reference[:, 1] + height - h_other]
            )
            points = ref[:, None] + shape * h_other[:, None, None]
            return Person(points, ref, h_other, np.zeros(len(c)))
        turn = np.arctan2(sep[:, 3], sep[:, 2])
        rise = sep[:, 4] if getattr(self, "vertical_", False) else np.zeros(len(c))
        local = np.column_stack([sep[:, 0], rise, sep[:, 1]]) * total[:, None]
        if person == 0:
            yaw_other = heading + turn
            ref = reference + rotate_yaw(local, heading)
        else:
            yaw_other = heading - turn
            ref = reference - rotate_yaw(local, yaw_other)
        points = ref[:, None] + rotate_yaw(shape * h_other[:, None, None], yaw_other[:, None])
        return Person(points, ref, h_other, yaw_other)


@register
class JointShapeScaling(AugmentedConfiguration):
    """:class:`AugmentedConfiguration` whose first ``shared`` components share one range.

    The two people's shape coordinates (the first 2KD components of C) are
    mapped into [0, 1] by one offset and scale, the extremes over all of them,
    so shapes keep their geometry: distances between state vectors stay
    distances between bodies, as the paper's height scaling intends (§2).
    Separation and scale components are each mapped by their own range.
    """

    def __init__(self, lam: float = 10.0, shared: int = 0):
        super().__init__(lam)
        self.shared = shared

    def fit(self, sequences: Sequence[np.ndarray]) -> JointShapeScaling:
        super().fit(sequences)
        k = self.shared
        if k:
            lo = self.min_[:k].min()
            hi = (self.min_[:k] + self.scale_[:k]).max()
            self.min_[:k] = lo
            self.scale_[:k] = hi - lo if hi - lo > 1e-12 else 1.0
        return self


def joint_shape_pipeline(
    takes: Sequence[TwoPeople], window: int = 5, lam: float = 10.0, normalise: str = "none"
) -> FeaturePipeline:
    """TwoPeople -> state vectors F = [C, lambda dC] in [0, 1] (§2; paper: w = 5, lambda = 10).

    Unfitted but for the layout of C, which is read from ``takes``. ``normalise="person"``:
    each person's shapes centred on the training people's mean
    (:class:`~markovmotion.features.person.ShapeCentre`) before the smoothing.
    """
    shape = JointShape().fit(takes)
    centre = [ShapeCentre(shape.shape_size)] if normalise == "person" else []
    return FeaturePipeline(
        [
            shape,
            *centre,
            TemporalSmoothing(window),
            JointShapeScaling(lam, shared=2 * shape.shape_size),
        ]
    )
