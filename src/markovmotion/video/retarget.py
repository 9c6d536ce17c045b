"""Takes of any skeleton as poses of the body model's template, by their body points.

The body model (:mod:`~markovmotion.video.body_model`) learns its joints' principal axes and
ranges from rotations of one template skeleton. The collection's other takes (salsa, dance,
martial arts, Bandai's walks, CMU's ASF/AMC) are other skeletons, whose joint rotations do
not carry over: another rest pose, other joints between the same body points. They are
retargeted by what every skeleton shares, the 19 body points
(:mod:`~markovmotion.features.body_points`):

1. **size and trunk**: the source's body points are rebuilt on the body points' tree
   (:data:`~markovmotion.features.body_points.PARENT`) with the template's segment lengths
   (medians over the template's own takes) and the source's directions, from the pelvis
   scaled by the ratio of the leg lengths (template to source) about the floor's origin,
   so each limb keeps its angles and the body its height above the floor in leg lengths.
   The trunk's segments (pelvis to spine, chest, neck, head; pelvis to hips; chest to
   shoulders) point differently on each skeleton at the same pose (where its joints sit:
   CMU's ``abdomen`` is not cgspeed's ``Spine``): each is turned, in the pelvis's frame
   (left from the hips, up the vertical), by the rotation that takes the take's median
   direction onto the template's. Without it the IK bent the template's lower back by
   0.38 rad (median) on every other skeleton's take. (A take whose trunk keeps one
   posture throughout has that posture taken for its skeleton's.)
2. **inverse kinematics**: the template's root position and the local rotations of every
   joint that moves a body point and moves at all in the template's own takes (cgspeed's hip
   sockets and collar bones never do: left free, they absorbed where other skeletons put
   their points, took principal axes, and the tracker lost a jump it had followed) (:func:`~markovmotion.algorithms.kinematics.points_ik`),
   with a Gaussian prior per joint from the template's own takes (mean and covariance of
   the local rotation vector, a floor of :data:`PRIOR_FLOOR` rad on every axis, weight
   :data:`PRIOR_WEIGHT` mm per standard deviation), and one on the root's tilt from the
   vertical (its spread over the template's takes): they settle what the 19 points do not
   show (a limb's twist, how a bend shares out between the pelvis and the spine's three
   joints) and are weak next to the points where they do. Without the tilt's prior the
   pelvis took the trunk's bends (its tilt's spread 0.21 rad, the template's 0.14) and the
   hips bent back against it. Each frame starts from the template's mean pose turned
   by the rotation (Kabsch) that best maps its trunk points onto the target's.

Frames are taken every ``stride``-th (the collection's takes at about
:data:`RETARGET_FPS`), which bounds the cost: about 6 ms a frame.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from markovmotion.algorithms.kinematics import points_ik, rotvec_positions
from markovmotion.core.motion import Motion
from markovmotion.core.skeleton import Skeleton
from markovmotion.features.body_points import BODY_POINTS, PARENT, body_point_index, body_points
from markovmotion.persist import load_npz, save_npz
from markovmotion.video.body_model import local_rotvecs, moving_joints

#: Frames per second of the takes retargeted (every ``round(fps / RETARGET_FPS)``-th frame).
RETARGET_FPS = 7.5
#: Weight of the pose prior: mm of point error worth one standard deviation of a joint.
PRIOR_WEIGHT = 10.0
#: Smallest standard deviation (rad) of the prior on any axis of any joint.
PRIOR_FLOOR = 0.1
#: A joint whose local rotation varies less than this (rad) over the template's takes stays
#: fixed in the retargeting.
STILL = 1e-3
#: Version of the retargeting, part of the cache key.
VERSION = 2
KIND = "retargeted-take"

_PARENTS = np.array([BODY_POINTS.index(PARENT[p]) if p in PARENT else -1 for p in BODY_POINTS])
_TRUNK = [BODY_POINTS.index(p) for p in ("pelvis", "spine", "chest", "left_hip", "right_hip",
                                          "left_shoulder", "right_shoulder")]  # fmt: skip
_LEG = [BODY_POINTS.index(f"left_{p}") for p in ("hip", "knee", "ankle")]


#: Segments of the trunk (child points): their directions differ between skeletons by where
#: each places its joints, not by the pose; corrected in the pelvis's frame (step 1).
TRUNK_SEGMENTS = tuple(BODY_POINTS.index(p) for p in ("spine", "chest", "neck", "head",
                       "left_hip", "right_hip", "left_shoulder", "right_shoulder"))  # fmt: skip


def _segment_lengths(points: np.ndarray) -> np.ndarray:
    """(19,) median length (mm) of each body point's segment to its parent (0 for the pelvis)."""
    d = np.linalg.norm(points[:, 1:] - points[:, _PARENTS[1:]], axis=-1)
    return np.concatenate([[0.0], np.median(d, axis=0)])


def _leg_length(lengths: np.ndarray) -> float:
    return float(lengths[_LEG[1]] + lengths[_LEG[2]])


def _pelvis_frames(points: np.ndarray) -> np.ndarray:
    """(F, 3, 3) the pelvis's frame per frame (columns: left, up, forward): left from the right
    hip to the left, up the world's vertical made square to it."""
    left = points[:, BODY_POINTS.index("left_hip")] - points[:, BODY_POINTS.index("right_hip")]
    left /= np.maximum(np.linalg.norm(left, axis=-1, keepdims=True), 1e-9)
    up = np.array([0.0, 1.0, 0.0]) - left[:, 1:2] * left
    up /= np.maximum(np.linalg.norm(up, axis=-1, keepdims=True), 1e-9)
    return np.stack([left, up, np.cross(left, up)], axis=-1)


def trunk_directions(points: np.ndarray) -> np.ndarray:
    """(8, 3) median unit direction of each of :data:`TRUNK_SEGMENTS` in the pelvis's frame."""
    d = _directions(points)[:, TRUNK_SEGMENTS]
    local = np.einsum("fba,fsb->fsa", _pelvis_frames(points), d)
    m = np.median(local, axis=0)
    return m / np.maximum(np.linalg.norm(m, axis=-1, keepdims=True), 1e-9)


def _directions(points: np.ndarray) -> np.ndarray:
    """(F, 19, 3) unit direction of each body point from its parent (zero for the pelvis)."""
    d = np.zeros_like(points)
    d[:, 1:] = points[:, 1:] - points[:, _PARENTS[1:]]
    return d / np.maximum(np.linalg.norm(d, axis=-1, keepdims=True), 1e-9)


def rebuild_points(
    points: np.ndarray, lengths: np.ndarray, trunk: np.ndarray | None = None
) -> np.ndarray:
    """Body points (F, 19, 3) rebuilt with segment ``lengths`` (19,), the source's directions
    and its pelvis scaled by the ratio of leg lengths (module docstring, step 1); given the
    template's ``trunk`` (:func:`trunk_directions`), each trunk segment turned in the pelvis's
    frame by the rotation taking the source's median direction onto the template's."""
    own = _segment_lengths(points)
    d = _directions(points)
    if trunk is not None:
        frames = _pelvis_frames(points)
        medians = trunk_directions(points)
        for k, i in enumerate(TRUNK_SEGMENTS):
            src = medians[k]
            axis = np.cross(src, trunk[k])
            angle = np.arctan2(np.linalg.norm(axis), src @ trunk[k])
            q = Rotation.from_rotvec(axis / max(np.linalg.norm(axis), 1e-12) * angle).as_matrix()
            local = np.einsum("fba,fb->fa", frames, d[:, i])
            d[:, i] = (frames @ (q @ local[..., None]))[..., 0]
    out = np.empty_like(points)
    out[:, 0] = points[:, 0] * (_leg_length(lengths) / _leg_length(own))
    for i in range(1, len(BODY_POINTS)):
        out[:, i] = out[:, _PARENTS[i]] + lengths[i] * d[:, i]
    return out


@dataclass
class Template:
    """The skeleton takes are retargeted to, and what its own takes say about its poses.

    Attributes:
        skeleton: the template skeleton.
        points: (19,) its joints that are the body points.
        free: joints fitted by the IK (every joint with a body point below it that the
            template's takes move; 0 first).
        mean: (J, 3) mean local rotation vector over the template's takes.
        precision: (J, 3, 3) the prior's precision (mm^2 per rad^2, module docstring).
        lengths: (19,) median segment lengths (mm) of the body points.
        trunk: (8, 3) median directions of the trunk's segments in the pelvis's frame
            (:func:`trunk_directions`).
        upright: the root's axis that is vertical on average (3,), and the weight of its
            prior (mm per rad: :data:`PRIOR_WEIGHT` over the tilt's standard deviation).
        height: mean height (mm) of the root above the floor in the template's takes.
    """

    skeleton: Skeleton
    points: np.ndarray
    free: np.ndarray
    mean: np.ndarray
    precision: np.ndarray
    lengths: np.ndarray
    trunk: np.ndarray
    upright: tuple[np.ndarray, float]
    height: float

    @classmethod
    def fit(cls, motions: Sequence[Motion]) -> Template:
        """The template of the first motion's skeleton, from the motions of its topology.

        Raises:
            SkeletonMismatchError: the body points are not found on the skeleton.
        """
        skeleton = motions[0].skeleton
        points = body_point_index(skeleton, BODY_POINTS, motions[0].name or "template")
        own = [m for m in motions if m.skeleton.same_topology(skeleton)]
        rv = np.concatenate([local_rotvecs(m) for m in own])
        root = np.concatenate([m.translations[:, 0] for m in own])
        mean = rv.mean(axis=0)
        d = rv - mean
        cov = np.einsum("fja,fjb->jab", d, d) / len(rv) + PRIOR_FLOOR**2 * np.eye(3)
        precision = PRIOR_WEIGHT**2 * np.linalg.inv(cov)
        # joints the template's own takes never move (cgspeed's hip sockets and collar
        # bones) stay fixed: moving them only absorbs where other skeletons put their points
        moves = rv.std(axis=0).max(axis=1) > STILL
        free = np.array([j for j in moving_joints(skeleton, points) if j == 0 or moves[j]])
        at = rotvec_positions(skeleton, rv, root, points)
        up = Rotation.from_rotvec(rv[:, 0]).inv().apply([0.0, 1.0, 0.0])  # world up, root's axes
        axis = up.mean(axis=0) / np.linalg.norm(up.mean(axis=0))
        tilt = np.arccos(np.clip(up @ axis, -1.0, 1.0))
        sd = max(float(np.sqrt(np.mean(tilt**2))), PRIOR_FLOOR)
        return cls(
            skeleton, points, free, mean, precision, _segment_lengths(at),
            trunk_directions(at), (axis, PRIOR_WEIGHT / sd), float(root[:, 1].mean()),
        )  # fmt: skip

    def key(self) -> str:
        """A digest of everything the retargeting depends on (for the cache)."""
        h = hashlib.sha256(
            json.dumps([VERSION, self.skeleton.to_dict(), self.free.tolist()]).encode()
        )
        for a in (self.mean, self.precision, self.lengths, self.trunk, self.upright[0]):
            h.update(np.ascontiguousarray(a, dtype=np.float64).round(6).tobytes())
        return h.hexdigest()[:16]

    def _initial(self, targets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The mean pose at each frame's pelvis, turned so its trunk best fits the target's."""
        f = len(targets)
        rest = self.mean.copy()
        rest[0] = 0.0
        q = rotvec_positions(self.skeleton, rest[None], np.zeros((1, 3)), self.points)[0]
        q = q[_TRUNK] - q[0]
        p = targets[:, _TRUNK] - targets[:, :1]
        h = np.einsum("ia,fib->fab", q, p)
        u, _, vt = np.linalg.svd(h)
        s = np.sign(np.linalg.det(u @ vt))
        vt[:, 2] *= s[:, None]
        r = np.swapaxes(u @ vt, 1, 2)  # p ~ r q
        rv = np.broadcast_to(self.mean, (f, *self.mean.shape)).copy()
        rv[:, 0] = Rotation.from_matrix(r).as_rotvec()
        return rv, targets[:, 0].copy()

    def retarget(
        self, motion: Motion, stride: int = 1
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every ``stride``-th frame of a motion of any skeleton as the template's poses:
        local rotation vectors (F, J, 3) (joint 0's global), root positions (F, 3) mm, and
        the mean distance (mm) per frame of the template's body points from the rebuilt ones.

        Raises:
            SkeletonMismatchError: the motion's skeleton has not every body point (one line
                naming the motion and the points missing).
        """
        pts = body_points(_every(motion, stride) if stride > 1 else motion)
        targets = rebuild_points(pts, self.lengths, self.trunk)
        rv, root = self._initial(targets)
        return points_ik(
            self.skeleton, targets, self.points, self.free, rv, root, self.mean, self.precision,
            upright=self.upright,
        )  # fmt: skip


def _every(motion: Motion, stride: int) -> Motion:
    return Motion(
        motion.skeleton,
        motion.rotations[::stride],
        motion.translations[::stride],
        motion.fps / stride,
        motion.name,
        motion.source,
    )


def cache_dir() -> Path:
    """Where retargeted takes are kept: ``$MARKOVMOTION_CACHE/retarget``, else
    ``~/.cache/markovmotion/retarget``."""
    base = os.environ.get("MARKOVMOTION_CACHE")
    root = Path(base) if base else Path.home() / ".cache" / "markovmotion"
    return root / "retarget"


def retarget_file(
    template: Template, path: Path, read: Callable[[], Motion], stride: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:meth:`Template.retarget` of the motion ``read()`` returns (the file at ``path``),
    kept in :func:`cache_dir` by the file's size and modification time, the stride and
    :meth:`Template.key`; a cache that cannot be written is skipped."""
    st = path.stat()
    key = hashlib.sha256(
        f"{template.key()}|{path.resolve()}|{st.st_size}|{st.st_mtime_ns}|{stride}".encode()
    ).hexdigest()[:24]
    where = cache_dir() / f"{key}.npz"
    if where.is_file():
        try:
            _, a = load_npz(where, KIND)
            return a["rotvecs"], a["root"], a["error"]
        except Exception:  # noqa: BLE001 - a damaged cache entry is rebuilt
            pass
    rv, root, err = template.retarget(read(), stride)
    try:
        where.parent.mkdir(parents=True, exist_ok=True)
        save_npz(where, KIND, {"file": str(path), "stride": stride},
                 {"rotvecs": rv, "root": root, "error": err})  # fmt: skip
    except OSError:
        pass
    return rv, root, err
