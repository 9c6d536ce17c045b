"""The articulated body model a tracker fits to video: a skeleton, its degrees of freedom, its flesh.

Built from motion capture of any skeleton whose body points
(:mod:`markovmotion.features.body_points`) can be found (:meth:`BodyModel.fit`), or from
poses of it given as rotation vectors, such as takes of other skeletons retargeted onto it
(:meth:`BodyModel.fit_rotvecs`, :mod:`~markovmotion.video.retarget`). The state of a pose
is a vector of ~30 numbers (Deutscher et al.'s model has 29):

* the root position (3, mm) and heading (yaw about the vertical, 1);
* the root's remaining tilt and every joint that moves a body point, each as
  a few coefficients of its local rotation vector on the principal axes of
  the training data (``k`` axes per joint: 1 for an elbow or knee that only
  bends, up to 3 for a shoulder, chosen greedily by how well they rebuild the
  training poses' body points);
* joints left without an axis (on the interaction takes: collar bones, the hip
  sockets) and joints that move no body point (fingers) stay at their mean rotation.

Joint limits are the range of each coefficient over the training data (with
a margin; optionally without the extreme quantiles). The flesh is :data:`BODY_SHAPE`: tapered capsules on the
segments between body points, a ball for the head and one per hand, as the
renderer draws them.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property

import numba
import numpy as np
from scipy.spatial.transform import Rotation

from markovmotion.algorithms.kinematics import KinematicChain, rotvec_positions
from markovmotion.core.motion import Motion
from markovmotion.core.skeleton import Skeleton
from markovmotion.errors import SkeletonMismatchError
from markovmotion.features.body_points import (
    BODY_POINTS,
    body_point_index,
    find_points,
    point_bones,
)
from markovmotion.video.render import BodyShape

#: Tapered capsules (mm) on the segments between :data:`BODY_POINTS`, a head and two hands.
BODY_SHAPE = BodyShape.build(
    BODY_POINTS,
    [
        ("pelvis", "spine", 125, 120),
        ("spine", "chest", 120, 125),
        ("chest", "neck", 110, 80),
        ("neck", "head", 50, 50),
        *(
            item
            for s in ("left", "right")
            for item in (
                ("chest", f"{s}_shoulder", 70, 60),
                (f"{s}_shoulder", f"{s}_elbow", 52, 42),
                (f"{s}_elbow", f"{s}_wrist", 42, 33),
                ("pelvis", f"{s}_hip", 105, 95),
                (f"{s}_hip", f"{s}_knee", 85, 60),
                (f"{s}_knee", f"{s}_ankle", 55, 42),
                (f"{s}_ankle", f"{s}_toe", 42, 35),
            )
        ),
    ],
    [("head", "neck", 1.0, 105.0)]
    + [(f"{s}_wrist", f"{s}_elbow", 0.6, 45.0) for s in ("left", "right")],
)


def marker_shape(names: Sequence[str]) -> tuple[BodyShape, list[str]]:
    """The flesh of a marker set (a partner that answers with markers, such as a depth
    sensor's 8 upper-body points), for drawing it as a body: a capsule on each bone of
    :func:`~markovmotion.features.body_points.point_bones` (the markers that name body
    points, joined along the body's tree), tapered from :data:`BODY_SHAPE`'s radius where
    a capsule leaves the parent's body point to its radius where one reaches the child's;
    a ball on the head marker (a marker lies on the head, not below it) and past each wrist.
    Returns the shape (over the markers, in their order) and each marker's body point
    (``""`` for a marker that names none), for :func:`capsule_colours`.

    Raises:
        SkeletonMismatchError: fewer than two markers name body points (nothing to join).
    """
    found = find_points(names)
    bones = point_bones(names)
    if not len(bones):
        raise SkeletonMismatchError(
            f"markers {', '.join(names)}: fewer than two name body points, nothing to draw"
        )
    point_of = {i: p for p, i in found.items()}
    seg, radii = BODY_SHAPE.segments()
    starts = {BODY_POINTS[a]: r[0] for (a, b), r in zip(seg, radii, strict=False) if a != b}
    ends = {BODY_POINTS[b]: r[1] for (a, b), r in zip(seg, radii, strict=False) if a != b}
    capsules, rad = [], []
    for child, parent in bones:
        pc, pp = point_of[child], point_of[parent]
        capsules.append((int(parent), int(child)))
        rad.append((float(starts.get(pp, ends.get(pp, 50.0))), float(ends.get(pc, 50.0))))
    balls = []
    up = next((p for c, p in bones if c == found.get("head")), None)
    if up is not None:
        balls.append((found["head"], int(up), 0.0, 105.0))
    for side in ("left", "right"):
        wrist, elbow = found.get(f"{side}_wrist"), found.get(f"{side}_elbow")
        if wrist is not None and elbow is not None:
            balls.append((wrist, elbow, 0.6, 45.0))
    shape = BodyShape(tuple(capsules), tuple(rad), tuple(balls), len(names))
    return shape, [point_of.get(i, "") for i in range(len(names))]


ROOT_DOF = 4  # x, y, z, yaw


def _greedy_axes(
    skeleton: Skeleton,
    points: np.ndarray,
    rv: np.ndarray,
    mean: np.ndarray,
    axes: dict[int, np.ndarray],
    budget: int,
    sample: int = 400,
    backward: bool = False,
) -> dict[int, int]:
    """Axes per joint (leading principal axes first) that best rebuild the body points.

    Forward: from none, add the axis that most lowers the error. ``backward``: from every
    axis, take away the one whose loss raises it least; where joints move together (a
    pelvis tilt the hips take back, a knee bent with its hip) an axis helps only beside the
    others, which forward selection does not see: on a first form of the retargeted collection
    it chose no knee.
    """
    rng = np.random.default_rng(0)
    rv = rv[rng.choice(len(rv), min(sample, len(rv)), replace=False)]
    rv = rv.copy()
    rv[:, 0] = Rotation.from_rotvec(rv[:, 0]).as_rotvec()  # root tilt (heading removed)
    zero = np.zeros((len(rv), 3))
    truth = rotvec_positions(skeleton, rv, zero, points)

    def error(kk: dict[int, int]) -> float:
        out = np.broadcast_to(mean, rv.shape).copy()
        for j, n in kk.items():
            if n:
                b = axes[j][:n].T
                out[:, j] += (rv[:, j] - mean[j]) @ b @ b.T
        p = rotvec_positions(skeleton, out, zero, points)
        return float(np.linalg.norm(p - truth, axis=-1).mean())

    k = dict.fromkeys(axes, 3 if backward else 0)
    step = -1 if backward else 1
    while (sum(k.values()) > budget) if backward else (sum(k.values()) < budget):
        moves = [j for j in axes if 0 <= k[j] + step <= 3]
        if not moves:
            break
        best = min(moves, key=lambda j: error({**k, j: k[j] + step}))
        k[best] += step
    return k


@numba.njit(cache=True)
def _turned(yaw, rotvec):  # pragma: no cover - compiled
    """Rotation vectors (M, 3) of the rotations ``rotvec`` (M, 3) followed by turns of ``yaw``
    (M,) rad about Y: scipy's ``(from_euler("y", yaw) * from_rotvec(rotvec)).as_rotvec()``
    (the same quaternion product and conversions; tests compare them), compiled, as the
    tracker calls it for every particle set."""
    out = np.empty_like(rotvec)
    for m in range(rotvec.shape[0]):
        rx, ry, rz = rotvec[m, 0], rotvec[m, 1], rotvec[m, 2]
        t2 = rx * rx + ry * ry + rz * rz
        theta = math.sqrt(t2)
        if theta <= 1e-3:
            half = 0.5 - t2 / 48.0 + t2 * t2 / 3840.0
        else:
            half = math.sin(0.5 * theta) / theta
        bx, by, bz, bw = rx * half, ry * half, rz * half, math.cos(0.5 * theta)
        s, c = math.sin(0.5 * yaw[m]), math.cos(0.5 * yaw[m])
        # (0, s, 0, c) * (bx, by, bz, bw), Hamilton product
        qx = c * bx + s * bz
        qy = c * by + s * bw
        qz = c * bz - s * bx
        qw = c * bw - s * by
        if qw < 0:
            qx, qy, qz, qw = -qx, -qy, -qz, -qw
        angle = 2.0 * math.atan2(math.sqrt(qx * qx + qy * qy + qz * qz), qw)
        if angle <= 1e-3:
            a2 = angle * angle
            scale = 2.0 + a2 / 12.0 + 7.0 * a2 * a2 / 2880.0
        else:
            scale = angle / math.sin(0.5 * angle)
        out[m, 0] = qx * scale
        out[m, 1] = qy * scale
        out[m, 2] = qz * scale
    return out


def _yaw(rot: Rotation) -> np.ndarray:
    """Heading (rad) about Y of rotations: where the local Z axis points, seen from above."""
    z = rot.apply([0.0, 0.0, 1.0])
    return np.arctan2(z[..., 0], z[..., 2])


def local_rotvecs(motion: Motion) -> np.ndarray:
    """(F, J, 3) local rotation vectors of a motion (joint 0's global)."""
    rot = Rotation.from_quat(motion.rotations.reshape(-1, 4))
    return rot.as_rotvec().reshape(motion.n_frames, -1, 3)


def moving_joints(skeleton: Skeleton, points: np.ndarray) -> np.ndarray:
    """Joints (sorted) that move a body point: those with one of ``points`` strictly below."""
    moves = np.zeros(skeleton.n_joints, bool)
    for p in points:
        j = skeleton.parents[p]
        while j >= 0:
            moves[j] = True
            j = skeleton.parents[j]
    return np.flatnonzero(moves)


def split_heading(root: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Root rotation vectors (F, 3) as their tilt (rotation vectors, heading removed) and
    heading (F,) in rad: ``root = yaw(heading) * tilt``."""
    rot = Rotation.from_rotvec(root)
    yaw = _yaw(rot)
    return (Rotation.from_euler("y", yaw[:, None]).inv() * rot).as_rotvec(), yaw


@dataclass
class BodyModel:
    """Skeleton, degrees of freedom and limits of the tracked body (see the module docstring).

    Attributes:
        skeleton: the template skeleton; poses are motions of it.
        points: (19,) joint indices of :data:`BODY_POINTS`.
        mean: (J, 3) mean local rotation vector of every joint (the root's tilt for joint 0).
        joints: joints with degrees of freedom (joint 0 is the root's tilt).
        bases: per joint in ``joints``, (3, k) principal axes of its rotation vector.
        lower, upper: (D,) limits of the state; root position unbounded.
        speed: (D,) typical change of each state value per second (its diffusion scale).
        height: mean height (mm) of the root above the floor.
    """

    skeleton: Skeleton
    points: np.ndarray
    mean: np.ndarray
    joints: list[int]
    bases: list[np.ndarray]
    lower: np.ndarray
    upper: np.ndarray
    speed: np.ndarray
    height: float

    @property
    def n_dof(self) -> int:
        return len(self.lower)

    @property
    def slices(self) -> list[slice]:
        """Where each joint's coefficients sit in the state."""
        out, start = [], ROOT_DOF
        for b in self.bases:
            out.append(slice(start, start + b.shape[1]))
            start += b.shape[1]
        return out

    @classmethod
    def fit(cls, motions: Sequence[Motion], max_dof: int = 28, margin: float = 0.15) -> BodyModel:
        """Learn degrees of freedom and joint limits from motions of one skeleton (the first's);
        motions of other skeletons are left out (:meth:`fit_rotvecs` takes them retargeted).

        Raises:
            SkeletonMismatchError: the body points are not found on the skeleton.
        """
        skeleton = motions[0].skeleton
        body_point_index(skeleton, BODY_POINTS, motions[0].name or "template")
        takes = [
            (local_rotvecs(m), m.translations[:, 0], m.fps)
            for m in motions
            if m.skeleton.same_topology(skeleton)
        ]
        return cls.fit_rotvecs(skeleton, takes, max_dof, margin, backward=False)

    @classmethod
    def fit_rotvecs(
        cls,
        skeleton: Skeleton,
        takes: Sequence[tuple[np.ndarray, np.ndarray, float]],
        max_dof: int = 28,
        margin: float = 0.15,
        backward: bool = True,
        tail: float = 0.0,
        speed_fps: float = 0.0,
    ) -> BodyModel:
        """Learn degrees of freedom and joint limits from poses of ``skeleton`` given as local
        rotation vectors: per take ``(rotvecs (F, J, 3), root positions (F, 3) mm, fps)``,
        joint 0's rotation global (e.g. takes of other skeletons retargeted by
        :func:`~markovmotion.video.retarget.retarget`).

        The ``max_dof - 4`` rotation axes (besides root position and heading) are
        chosen greedily among the joints' principal axes by the error of the training
        poses rebuilt from the state: ``backward`` (the default) from all of them, each
        time leaving out the one whose loss raises it least, else forward (:meth:`fit`, the
        interaction takes' model as it was), each time adding the one that lowers it most.
        Limits: each coefficient's range over the takes, widened by ``margin`` of it on
        both sides; with ``tail``, the range between its ``tail`` and ``1 - tail``
        quantiles (retargeted takes: a few frames where the IK fell into a wrong basin, an
        elbow bent backwards, would otherwise set the limits). Speeds (the diffusion's
        scale): from the takes at ``speed_fps`` or more (changes over longer steps are
        not a frame's), all if none is.

        Raises:
            SkeletonMismatchError: the body points are not found on the skeleton.
        """
        points = body_point_index(skeleton, BODY_POINTS, "template")
        rv, pos, yaw, rates = [], [], [], []
        for r, root, fps in takes:
            r = np.array(r, dtype=float)
            r[:, 0], y = split_heading(r[:, 0])
            rv.append(r)
            pos.append(np.asarray(root, dtype=float))
            yaw.append(np.unwrap(y))
            rates.append(float(fps))
        allrv = np.concatenate(rv)
        mean = allrv.mean(axis=0)
        still = allrv.std(axis=0).max(axis=1) < 1e-9  # never moves in these takes: no axis
        cand = [int(j) for j in moving_joints(skeleton, points) if not still[j] or j == 0]
        axes = {j: np.linalg.svd(allrv[:, j] - mean[j], full_matrices=False)[2] for j in cand}
        k = _greedy_axes(skeleton, points, allrv, mean, axes, max_dof - ROOT_DOF, backward=backward)

        fast = [f >= speed_fps for f in rates]
        fast = fast if any(fast) else [True] * len(rates)

        def per_second(values: list[np.ndarray]) -> np.ndarray:
            """Standard deviation of the change per second (each take at its own rate)."""
            return np.concatenate(
                [np.diff(v, axis=0) * f for v, f, ok in zip(values, rates, fast, strict=True) if ok]
            ).std(axis=0)

        joints, bases, lo, hi, coef_speed = [], [], [], [], []
        for j in cand:
            if k[j] == 0:
                continue
            basis = axes[j][: k[j]].T  # (3, k)
            c = (allrv[:, j] - mean[j]) @ basis
            cmin, cmax = np.quantile(c, [tail, 1.0 - tail], axis=0)
            span = cmax - cmin
            joints.append(j)
            bases.append(basis)
            lo.append(cmin - margin * span)
            hi.append(cmax + margin * span)
            coef_speed.append(per_second([r[:, j] @ basis for r in rv]))
        inf = np.inf
        lower = np.concatenate([[-inf, -inf, -inf, -inf], *lo])
        upper = np.concatenate([[inf, inf, inf, inf], *hi])
        speed = np.concatenate([per_second(pos), [per_second(yaw)], *coef_speed])
        height = float(np.concatenate(pos)[:, 1].mean())
        return cls(skeleton, points, mean, joints, bases, lower, upper, speed, height)

    def limb_mask(self, points: Sequence[str]) -> np.ndarray:
        """(D,) bool: the state values of joints that move the body points named like ``points``
        (e.g. ``("elbow", "wrist")``: the arms)."""
        names = [BODY_POINTS[i] for i in range(len(BODY_POINTS))]
        wanted = [self.points[i] for i, n in enumerate(names) if any(w in n for w in points)]
        movers = set()
        for p in wanted:
            j = self.skeleton.parents[p]
            if j >= 0:
                movers.add(int(j))
        mask = np.zeros(self.n_dof, bool)
        for j, sl in zip(self.joints, self.slices, strict=True):
            if j in movers:
                mask[sl] = True
        return mask

    @cached_property
    def _expansion(self) -> np.ndarray:
        """(D, J * 3): the state to the joints' rotation vectors less their mean (the bases in
        one matrix; zero for the root's position and heading)."""
        out = np.zeros((self.n_dof, *self.mean.shape))
        for j, basis, sl in zip(self.joints, self.bases, self.slices, strict=True):
            out[sl, j] = basis.T
        return out.reshape(self.n_dof, -1)

    # ------------------------------------------------------------------ poses
    def standing(self, position: np.ndarray, yaw: float = 0.0) -> np.ndarray:
        """The state (D,) of the mean pose with the root at ``position`` (mm) facing ``yaw``."""
        x = np.zeros(self.n_dof)
        x[:3] = position
        x[3] = yaw
        return x

    def clip(self, states: np.ndarray) -> np.ndarray:
        """States (..., D) within the joint limits (in place)."""
        np.clip(states, self.lower, self.upper, out=states)
        return states

    def rotvecs(self, states: np.ndarray) -> np.ndarray:
        """Local rotation vectors (M, J, 3) of states (M, D); joint 0's is global."""
        states = np.atleast_2d(states)
        rv = (states @ self._expansion).reshape(len(states), *self.mean.shape)
        rv += self.mean
        rv[:, 0] = _turned(np.ascontiguousarray(states[:, 3], dtype=float), rv[:, 0])
        return rv

    def joint_positions(self, states: np.ndarray) -> np.ndarray:
        """Body points (M, 19, 3) in mm of states (M, D)."""
        states = np.atleast_2d(states)
        return self._chain.positions(self.rotvecs(states), states[:, :3])

    @cached_property
    def _chain(self) -> KinematicChain:
        return KinematicChain.of(self.skeleton, self.points)

    def motion(self, states: np.ndarray, fps: float, name: str = "tracked") -> Motion:
        """The poses (F, D) as a motion of the template skeleton."""
        rv = self.rotvecs(states)
        f, j = rv.shape[:2]
        quats = Rotation.from_rotvec(rv.reshape(-1, 3)).as_quat().reshape(f, j, 4)
        return Motion.from_rotations(self.skeleton, quats, states[:, :3], fps=fps, name=name)

    def states_of(self, motion: Motion) -> np.ndarray:
        """The states (F, D) nearest to a motion of the template skeleton (for tests, truth)."""
        if not motion.skeleton.same_topology(self.skeleton):
            raise SkeletonMismatchError(f"{motion.name or 'motion'}: not the body model's skeleton")
        r = local_rotvecs(motion)
        r[:, 0], yaw = split_heading(r[:, 0])
        x = np.zeros((motion.n_frames, self.n_dof))
        x[:, :3] = motion.translations[:, 0]
        x[:, 3] = np.unwrap(yaw)
        for j, basis, sl in zip(self.joints, self.bases, self.slices, strict=True):
            x[:, sl] = (r[:, j] - self.mean[j]) @ basis
        return x
