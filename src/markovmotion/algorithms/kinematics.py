"""Batched forward kinematics from rotation vectors, and inverse kinematics from positions.

:meth:`Motion.global_transforms` is the reference; this compiled version
computes only the joints asked for (and their ancestors), straight from
exponential maps, which makes Monte Carlo evaluation of millions of predicted
poses affordable. Tests check that the two agree.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
from scipy.spatial.transform import Rotation

from markovmotion.core.motion import Motion
from markovmotion.core.skeleton import Skeleton


@numba.njit(cache=True)
def _fk(rotvecs, root_pos, root_joint, parents, offsets, joints, wanted, turns):  # pragma: no cover
    m = rotvecs.shape[0]
    n_j = parents.shape[0]
    out = np.empty((m, wanted.shape[0], 3))
    g = np.empty((n_j, 3, 3))
    p = np.empty((n_j, 3))
    r = np.empty((3, 3))
    for f in range(m):
        for j in joints:
            t0, t1, t2 = offsets[j, 0], offsets[j, 1], offsets[j, 2]
            if j == root_joint:
                t0, t1, t2 = root_pos[f, 0], root_pos[f, 1], root_pos[f, 2]
            par = parents[j]
            if par < 0:
                p[j, 0], p[j, 1], p[j, 2] = t0, t1, t2
            else:
                for a_ in range(3):
                    p[j, a_] = (
                        p[par, a_] + g[par, a_, 0] * t0 + g[par, a_, 1] * t1 + g[par, a_, 2] * t2
                    )
            if not turns[j]:  # no joint of the chain hangs from it: its rotation moves nothing
                continue
            x, y, z = rotvecs[f, j, 0], rotvecs[f, j, 1], rotvecs[f, j, 2]
            th2 = x * x + y * y + z * z
            if th2 < 1e-16:
                a = 1.0 - th2 / 6.0
                b = 0.5 - th2 / 24.0
            else:
                th = np.sqrt(th2)
                a = np.sin(th) / th
                b = (1.0 - np.cos(th)) / th2
            r[0, 0] = 1.0 - b * (y * y + z * z)
            r[1, 1] = 1.0 - b * (x * x + z * z)
            r[2, 2] = 1.0 - b * (x * x + y * y)
            r[0, 1] = b * x * y - a * z
            r[1, 0] = b * x * y + a * z
            r[0, 2] = b * x * z + a * y
            r[2, 0] = b * x * z - a * y
            r[1, 2] = b * y * z - a * x
            r[2, 1] = b * y * z + a * x
            if par < 0:
                for a_ in range(3):
                    for b_ in range(3):
                        g[j, a_, b_] = r[a_, b_]
            else:
                for a_ in range(3):
                    for b_ in range(3):
                        g[j, a_, b_] = (
                            g[par, a_, 0] * r[0, b_]
                            + g[par, a_, 1] * r[1, b_]
                            + g[par, a_, 2] * r[2, b_]
                        )
        for k in range(wanted.shape[0]):
            for a_ in range(3):
                out[f, k, a_] = p[wanted[k], a_]
    return out


def ancestors_closure(skeleton: Skeleton, joints: np.ndarray) -> np.ndarray:
    """The joints with all their ancestors, in skeleton (depth-first) order."""
    keep = np.zeros(skeleton.n_joints, dtype=bool)
    for j in np.asarray(joints, dtype=int):
        while j >= 0 and not keep[j]:
            keep[j] = True
            j = skeleton.parents[j]
    return np.flatnonzero(keep)


@dataclass(frozen=True)
class KinematicChain:
    """What :func:`rotvec_positions` needs of a skeleton, prepared once for many calls
    (:meth:`of`): parents, rest offsets, the joints asked for with their ancestors, which of
    those carry a child, and the root joint."""

    parents: np.ndarray
    offsets: np.ndarray
    closure: np.ndarray
    wanted: np.ndarray
    #: (J,) bool: joints of the closure that are a parent within it (whose rotation matters).
    turns: np.ndarray
    root_joint: int = 0

    @classmethod
    def of(
        cls, skeleton: Skeleton, joints: np.ndarray | None = None, root_joint: int = 0
    ) -> KinematicChain:
        wanted = np.arange(skeleton.n_joints) if joints is None else np.asarray(joints)
        closure = ancestors_closure(skeleton, wanted).astype(np.intp)
        turns = np.zeros(skeleton.n_joints, bool)
        parents = skeleton.parents[closure]
        turns[parents[parents >= 0]] = True
        return cls(
            skeleton.parents.astype(np.intp),
            np.ascontiguousarray(skeleton.offsets, dtype=float),
            closure,
            wanted.astype(np.intp),
            turns,
            int(root_joint),
        )

    def positions(self, rotvecs: np.ndarray, root_positions: np.ndarray) -> np.ndarray:
        """Global positions (M, len(wanted), 3) in mm (see :func:`rotvec_positions`)."""
        return _fk(
            np.ascontiguousarray(rotvecs, dtype=float),
            np.ascontiguousarray(root_positions, dtype=float),
            self.root_joint,
            self.parents,
            self.offsets,
            self.closure,
            self.wanted,
            self.turns,
        )


def rotvec_positions(
    skeleton: Skeleton,
    rotvecs: np.ndarray,
    root_positions: np.ndarray,
    joints: np.ndarray | None = None,
    root_joint: int = 0,
) -> np.ndarray:
    """Global positions (M, len(joints), 3) in mm of poses given as rotation vectors.

    Args:
        skeleton: rest offsets and parents.
        rotvecs: (M, J, 3) local rotation vectors of every joint (zeros: identity).
        root_positions: (M, 3) local translation of ``root_joint``; every other
            joint sits at its rest offset (as :meth:`Motion.from_rotations`).
        joints: which joints to return (default: all).
        root_joint: the joint whose translation ``root_positions`` gives.
    """
    return KinematicChain.of(skeleton, joints, root_joint).positions(rotvecs, root_positions)


def fit_rotations(skeleton: Skeleton, positions: np.ndarray, fps: float = 30.0) -> Motion:
    """Inverse kinematics: a motion of ``skeleton`` whose joints follow ``positions`` (F, J, 3) mm.

    Joint by joint from the root, the global rotation maps the rest offsets of
    the joint's children onto their target directions: the least-squares
    rotation (Kabsch) where there are two or more children, otherwise the
    smallest rotation turning the one bone from where the parent's frame puts
    it (the twist about a lone bone is not observable from positions). Bone
    lengths stay the skeleton's; only directions are fitted.
    """
    pos = np.asarray(positions, dtype=float)
    f, n_j = pos.shape[:2]
    glob = np.empty((f, n_j, 3, 3))
    local = np.empty((f, n_j, 3, 3))
    eye = np.broadcast_to(np.eye(3), (f, 3, 3))
    for j in range(n_j):
        par = skeleton.parents[j]
        g_par = eye if par < 0 else glob[:, par]
        kids = [c for c in skeleton.children(j) if np.linalg.norm(skeleton.offsets[c]) > 1e-9]
        if len(kids) >= 2:
            rest = skeleton.offsets[kids]  # (C, 3)
            target = pos[:, kids] - pos[:, j : j + 1]  # (F, C, 3)
            h = np.einsum("ca,fcb->fab", rest, target)
            u, _, vt = np.linalg.svd(h)
            d = np.sign(np.linalg.det(np.einsum("fab,fbc->fac", u, vt)))
            vt[:, 2] *= d[:, None]
            g = np.einsum("fba,fcb->fac", vt, u)
        elif len(kids) == 1:
            now = np.einsum("fab,b->fa", g_par, skeleton.offsets[kids[0]])
            want = pos[:, kids[0]] - pos[:, j]
            g = _swing(now, want) @ g_par
        else:
            g = g_par.copy()
        glob[:, j] = g
        local[:, j] = np.swapaxes(g_par, 1, 2) @ g
    quats = Rotation.from_matrix(local.reshape(-1, 3, 3)).as_quat().reshape(f, n_j, 4)
    return Motion.from_rotations(skeleton, quats, pos[:, 0], fps=fps)


def _swing(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(F, 3, 3) smallest rotations taking directions ``a`` (F, 3) to ``b`` (F, 3)."""
    a = a / np.maximum(np.linalg.norm(a, axis=1, keepdims=True), 1e-12)
    b = b / np.maximum(np.linalg.norm(b, axis=1, keepdims=True), 1e-12)
    axis = np.cross(a, b)
    sin = np.linalg.norm(axis, axis=1, keepdims=True)
    angle = np.arctan2(sin, np.sum(a * b, axis=1, keepdims=True))
    rotvec = np.divide(axis, sin, out=np.zeros_like(axis), where=sin > 1e-12) * angle
    return Rotation.from_rotvec(rotvec).as_matrix()
