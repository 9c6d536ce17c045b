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


# ------------------------------------------------------------------ IK on a few points
_UP = np.array([0.0, 1.0, 0.0])


def _skew(v: np.ndarray) -> np.ndarray:
    """(..., 3, 3) cross-product matrices of vectors (..., 3)."""
    s = np.zeros((*v.shape[:-1], 3, 3))
    s[..., 0, 1], s[..., 0, 2] = -v[..., 2], v[..., 1]
    s[..., 1, 0], s[..., 1, 2] = v[..., 2], -v[..., 0]
    s[..., 2, 0], s[..., 2, 1] = -v[..., 1], v[..., 0]
    return s


def _right_jacobian_inverse(phi: np.ndarray) -> np.ndarray:
    """(..., 3, 3) inverse right Jacobians of SO(3) at rotation vectors (..., 3): how
    ``log(exp(phi) exp(delta))`` changes with a small ``delta``."""
    th = np.linalg.norm(phi, axis=-1)[..., None, None]
    k = _skew(phi)
    safe = np.where(th < 1e-6, 1.0, th)
    c = np.where(
        th < 1e-6, 1.0 / 12.0, 1.0 / safe**2 - (1 + np.cos(safe)) / (2 * safe * np.sin(safe))
    )
    return np.eye(3) + 0.5 * k + c * (k @ k)


def _frames(
    skeleton: Skeleton, rotvecs: np.ndarray, root: np.ndarray, joints: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Global rotations (F, J, 3, 3) and positions (F, J, 3) of ``joints`` (parents first)."""
    f = len(rotvecs)
    g = np.zeros((f, skeleton.n_joints, 3, 3))
    x = np.zeros((f, skeleton.n_joints, 3))
    r = Rotation.from_rotvec(rotvecs[:, joints].reshape(-1, 3)).as_matrix()
    r = r.reshape(f, len(joints), 3, 3)
    for k, j in enumerate(joints):
        p = skeleton.parents[j]
        if p < 0:
            g[:, j], x[:, j] = r[:, k], root
        else:
            g[:, j] = g[:, p] @ r[:, k]
            x[:, j] = x[:, p] + g[:, p] @ skeleton.offsets[j]
    return g, x


def points_ik(
    skeleton: Skeleton,
    targets: np.ndarray,
    points: np.ndarray,
    free: np.ndarray,
    rotvecs: np.ndarray,
    root: np.ndarray,
    prior_mean: np.ndarray,
    prior_precision: np.ndarray,
    iterations: int = 30,
    upright: tuple[np.ndarray, float] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Inverse kinematics on a few points, all frames at once (batch Levenberg-Marquardt).

    Finds per frame the root position and the local rotations of the ``free`` joints
    (joint 0, the root, among them) minimising

        sum_p |x_p(theta) - target_p|^2 + sum_{j in free, j > 0} (r_j - m_j)^T P_j (r_j - m_j)

    where ``x_p`` are the positions (mm) of the joints ``points`` by forward kinematics,
    ``r_j`` joint j's local rotation vector, and the second term a Gaussian prior (mean
    ``m_j``, precision ``P_j`` in mm^2/rad^2) that settles what the points do not show
    (the twist about a straight limb, how a bend shares out over several spine joints).
    Rotations are updated on the group (``R_j <- R_j exp(delta_j)``), so the Jacobian of a
    point below joint j is ``-[x_p - x_j]_x G_j`` (G_j the joint's global rotation); the
    prior's uses the inverse right Jacobian of SO(3). Each frame keeps its own damping
    (divided by 3 after a step that lowers its cost, multiplied by 4 and the step refused
    otherwise). Frames are independent: the caller warm-starts them (``rotvecs``, ``root``).

    Written here because no maintained Python library fits: robotics IK (ikpy, pinocchio's
    examples) solves one chain or one frame at a time for URDF models without a pose
    prior; this solves thousands of frames of a BVH/ASF skeleton in a few batched NumPy
    solves.

    Args:
        skeleton: parents and rest offsets (mm); parents must come before children.
        targets: (F, P, 3) target positions (mm) of the joints ``points`` (P,).
        free: joints whose rotations are fitted (must include 0); others keep ``rotvecs``.
        rotvecs: (F, J, 3) starting local rotation vectors (joint 0's is global).
        root: (F, 3) starting root position (mm).
        prior_mean, prior_precision: (J, 3) and (J, 3, 3); joint 0 has no prior.
        upright: ``(a, w)``: the root's tilt prior, a term ``w^2 |G_0 a - up|^2`` (``a`` the
            root's axis that is vertical on average, ``w`` in mm per rad of tilt): without it
            the root tilts freely where the points cannot tell it from a bent lower back.

    Returns:
        The fitted rotation vectors (F, J, 3), root positions (F, 3), and per frame the mean
        distance (mm) of the points from their targets.
    """
    points, free = np.asarray(points, np.intp), np.asarray(free, np.intp)
    if free[0] != 0 or np.any(skeleton.parents[1:] >= np.arange(1, skeleton.n_joints)):
        raise ValueError("free joints must start with the root; parents before children")
    rv, root = np.array(rotvecs, dtype=float), np.array(root, dtype=float)
    targets = np.asarray(targets, dtype=float)
    f, n_free = len(rv), len(free)
    n = 3 + 3 * n_free
    joints = ancestors_closure(skeleton, np.concatenate([points, free]))
    below = np.zeros((n_free, len(points)), dtype=bool)  # free joint k moves point p
    for i, p in enumerate(points):
        j = int(p)
        while j >= 0:
            below[np.flatnonzero(free == j), i] = True
            j = skeleton.parents[j]
    below &= free[:, None] != points[None, :]
    below[0] = True  # the root's rotation moves every point but turns the root point about itself
    mean, prec = prior_mean[free[1:]], prior_precision[free[1:]]

    def cost(rv_: np.ndarray, root_: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        g, x = _frames(skeleton, rv_, root_, joints)
        e = x[:, points] - targets
        d = rv_[:, free[1:]] - mean
        c = (e**2).sum(axis=(1, 2)) + (d[..., None, :] @ prec @ d[..., None]).sum(axis=(1, 2, 3))
        if upright is not None:
            c = c + upright[1] ** 2 * ((g[:, 0] @ upright[0] - _UP) ** 2).sum(axis=1)
        return c, g, x

    lam = np.full(f, 1e-3)
    c, g, x = cost(rv, root)
    for _ in range(iterations):
        e = x[:, points] - targets  # (F, P, 3)
        jac = np.zeros((f, len(points), 3, n))
        jac[:, :, :, :3] = np.eye(3)
        for k, j in enumerate(free):
            idx = np.flatnonzero(below[k])
            d = x[:, points[idx]] - x[:, j, None]  # (F, p, 3)
            jac[:, idx, :, 3 + 3 * k : 6 + 3 * k] = -_skew(d) @ g[:, j, None]
        jac = jac.reshape(f, -1, n)
        jt = np.swapaxes(jac, 1, 2)
        a = jt @ jac
        b = (jt @ e.reshape(f, -1, 1))[..., 0]
        jr = _right_jacobian_inverse(rv[:, free[1:]])  # (F, K-1, 3, 3)
        dp = rv[:, free[1:]] - mean
        jrt_p = np.swapaxes(jr, 2, 3) @ prec
        hp = jrt_p @ jr
        gp = (jrt_p @ dp[..., None])[..., 0]
        for k in range(1, n_free):
            s = slice(3 + 3 * k, 6 + 3 * k)
            a[:, s, s] += hp[:, k - 1]
            b[:, s] += gp[:, k - 1]
        if upright is not None:
            ju = -upright[1] * g[:, 0] @ _skew(upright[0])  # (F, 3, 3)
            ru = upright[1] * (g[:, 0] @ upright[0] - _UP)
            a[:, 3:6, 3:6] += np.swapaxes(ju, 1, 2) @ ju
            b[:, 3:6] += (np.swapaxes(ju, 1, 2) @ ru[..., None])[..., 0]
        diag = np.einsum("fii->fi", a)
        a[:, np.arange(n), np.arange(n)] += lam[:, None] * (diag + 1e-6)
        step = -np.linalg.solve(a, b[..., None])[..., 0]
        new_root = root + step[:, :3]
        new_rv = rv.copy()
        turn = Rotation.from_rotvec(step[:, 3:].reshape(-1, 3))
        now = Rotation.from_rotvec(rv[:, free].reshape(-1, 3))
        new_rv[:, free] = (now * turn).as_rotvec().reshape(f, n_free, 3)
        c_new, g_new, x_new = cost(new_rv, new_root)
        ok = c_new < c
        rv[ok], root[ok], c[ok], g[ok], x[ok] = (
            new_rv[ok],
            new_root[ok],
            c_new[ok],
            g_new[ok],
            x_new[ok],
        )
        lam = np.where(ok, lam / 3, lam * 4)
    err = np.linalg.norm(x[:, points] - targets, axis=-1).mean(axis=1)
    return rv, root, err
