"""The articulated body model a tracker fits to video: a skeleton, its degrees of freedom, its flesh.

Built from motion capture of any skeleton whose body points
(:mod:`markovmotion.features.body_points`) can be found. The state of a pose
is a vector of ~30 numbers (Deutscher et al.'s model has 29):

* the root position (3, mm) and heading (yaw about the vertical, 1);
* the root's remaining tilt and every joint that moves a body point, each as
  a few coefficients of its local rotation vector on the principal axes of
  the training data (``k`` axes per joint: 1 for an elbow or knee that only
  bends, up to 3 for a shoulder, chosen by the variance they explain);
* joints that barely move (collar bones, the hip sockets) and joints that
  move no body point (fingers) stay at their mean rotation.

Joint limits are the range of each coefficient over the training data (with
a margin). The flesh is :data:`BODY_SHAPE`: tapered capsules on the
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
from markovmotion.features.body_points import BODY_POINTS, body_point_index
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

ROOT_DOF = 4  # x, y, z, yaw


def _greedy_axes(
    skeleton: Skeleton,
    points: np.ndarray,
    rv: np.ndarray,
    mean: np.ndarray,
    axes: dict[int, np.ndarray],
    budget: int,
    sample: int = 400,
) -> dict[int, int]:
    """Axes per joint (leading principal axes first) that best rebuild the body points."""
    rng = np.random.default_rng(0)
    rv = rv[rng.choice(len(rv), min(sample, len(rv)), replace=False)]
    rv = rv.copy()
    rv[:, 0] = Rotation.from_rotvec(rv[:, 0]).as_rotvec()  # root tilt (heading removed)
    zero = np.zeros((len(rv), 3))
    truth = rotvec_positions(skeleton, rv, zero, points)
    k = dict.fromkeys(axes, 0)

    def rebuilt(kk: dict[int, int]) -> np.ndarray:
        out = np.broadcast_to(mean, rv.shape).copy()
        for j, n in kk.items():
            if n:
                b = axes[j][:n].T
                out[:, j] += (rv[:, j] - mean[j]) @ b @ b.T
        return out

    for _ in range(budget):
        best, best_err = None, np.inf
        for j in axes:
            if k[j] >= 3:
                continue
            trial = {**k, j: k[j] + 1}
            p = rotvec_positions(skeleton, rebuilt(trial), zero, points)
            err = np.linalg.norm(p - truth, axis=-1).mean()
            if err < best_err:
                best, best_err = j, err
        if best is None:
            break
        k[best] += 1
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
        """Learn degrees of freedom and joint limits from motions of one skeleton (the first's).

        The ``max_dof - 4`` rotation axes (besides root position and heading) are
        chosen greedily among the joints' principal axes, each time the one
        that most lowers the error of the training poses rebuilt from the state.

        Raises:
            SkeletonMismatchError: the body points are not found on the skeleton.
        """
        skeleton = motions[0].skeleton
        points = body_point_index(skeleton, BODY_POINTS, motions[0].name or "template")
        motions = [m for m in motions if m.skeleton.same_topology(skeleton)]
        rv, pos, yaw = [], [], []
        for m in motions:
            rot = Rotation.from_quat(m.rotations.reshape(-1, 4))
            r = rot.as_rotvec().reshape(m.n_frames, -1, 3)
            root = Rotation.from_quat(m.rotations[:, 0])
            y = _yaw(root)
            r[:, 0] = (Rotation.from_euler("y", y[:, None]).inv() * root).as_rotvec()
            rv.append(r)
            pos.append(m.translations[:, 0])
            yaw.append(np.unwrap(y))
        fps = motions[0].fps
        allrv = np.concatenate(rv)
        mean = allrv.mean(axis=0)
        moves = np.zeros(skeleton.n_joints, bool)  # joints with a body point strictly below
        for p in points:
            j = skeleton.parents[p]
            while j >= 0:
                moves[j] = True
                j = skeleton.parents[j]
        cand = [j for j in range(skeleton.n_joints) if moves[j]]
        axes = {j: np.linalg.svd(allrv[:, j] - mean[j], full_matrices=False)[2] for j in cand}
        k = _greedy_axes(skeleton, points, allrv, mean, axes, max_dof - ROOT_DOF)
        joints, bases, lo, hi, coef_speed = [], [], [], [], []
        for j in cand:
            if k[j] == 0:
                continue
            basis = axes[j][: k[j]].T  # (3, k)
            c = (allrv[:, j] - mean[j]) @ basis
            span = c.max(axis=0) - c.min(axis=0)
            joints.append(j)
            bases.append(basis)
            lo.append(c.min(axis=0) - margin * span)
            hi.append(c.max(axis=0) + margin * span)
            d = np.concatenate([np.diff(r[:, j] @ basis, axis=0) for r in rv])
            coef_speed.append(d.std(axis=0) * fps)
        dpos = np.concatenate([np.diff(p, axis=0) for p in pos]).std(axis=0) * fps
        dyaw = np.concatenate([np.diff(y) for y in yaw]).std() * fps
        inf = np.inf
        lower = np.concatenate([[-inf, -inf, -inf, -inf], *lo])
        upper = np.concatenate([[inf, inf, inf, inf], *hi])
        speed = np.concatenate([dpos, [dyaw], *coef_speed])
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
        rot = Rotation.from_quat(motion.rotations.reshape(-1, 4))
        r = rot.as_rotvec().reshape(motion.n_frames, -1, 3)
        root = Rotation.from_quat(motion.rotations[:, 0])
        yaw = _yaw(root)
        r[:, 0] = (Rotation.from_euler("y", yaw[:, None]).inv() * root).as_rotvec()
        x = np.zeros((motion.n_frames, self.n_dof))
        x[:, :3] = motion.translations[:, 0]
        x[:, 3] = np.unwrap(yaw)
        for j, basis, sl in zip(self.joints, self.bases, self.slices, strict=True):
            x[:, sl] = (r[:, j] - self.mean[j]) @ basis
        return x
