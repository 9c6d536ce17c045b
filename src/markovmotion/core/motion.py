"""Motion: a skeleton animated over frames, with forward kinematics and basic edits.

Rotations are unit quaternions in SciPy's scalar-last order ``(x, y, z, w)``;
translations are each joint's local translation from its parent in mm (the rest
offset, unless the file animates that joint's position channels).
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass

import numpy as np

from markovmotion.core.skeleton import Skeleton

UP = np.array([0.0, 1.0, 0.0])
#: The ground plane's axes (x and z: Y is up), for horizontal parts of positions.
GROUND = [0, 2]


@dataclass(eq=False, repr=False)
class Motion:
    """Per-frame local rotations and translations of a :class:`Skeleton`.

    Attributes:
        skeleton: the kinematic tree.
        rotations: (F, J, 4) local unit quaternions, scalar last.
        translations: (F, J, 3) local translations in mm; joint 0 holds the
            global root position.
        fps: frames per second.
        name: where it came from (file name), for messages.
        source: the path of the file it was read from ("" if none); models
            record its content hash in ``train_files_``.
    """

    skeleton: Skeleton
    rotations: np.ndarray
    translations: np.ndarray
    fps: float
    name: str = ""
    source: str = ""

    def __post_init__(self) -> None:
        self.rotations = np.asarray(self.rotations, dtype=float)
        self.translations = np.asarray(self.translations, dtype=float)
        f, j = self.rotations.shape[:2]
        if self.rotations.shape != (f, j, 4) or self.translations.shape != (f, j, 3):
            raise ValueError("rotations must be (F, J, 4) and translations (F, J, 3)")
        if j != self.skeleton.n_joints:
            raise ValueError(f"{j} joints in the data but {self.skeleton.n_joints} in the skeleton")
        if not self.fps > 0:
            raise ValueError(f"frame rate must be positive, got {self.fps}")

    # ------------------------------------------------------------------ build
    @classmethod
    def from_rotations(
        cls,
        skeleton: Skeleton,
        rotations: np.ndarray,
        root_positions: np.ndarray | None = None,
        fps: float = 30.0,
        name: str = "",
    ) -> Motion:
        """A motion whose joints sit at their rest offsets, driven by ``rotations``.

        ``root_positions`` (F, 3) in mm goes to joint 0; omitted, the root stays
        at its rest offset.
        """
        rotations = np.asarray(rotations, dtype=float)
        translations = np.broadcast_to(
            skeleton.offsets, (len(rotations), skeleton.n_joints, 3)
        ).copy()
        if root_positions is not None:
            translations[:, 0] = root_positions
        return cls(skeleton, rotations, translations, fps, name)

    # --------------------------------------------------------------- queries
    @property
    def n_frames(self) -> int:
        return self.rotations.shape[0]

    @property
    def duration(self) -> float:
        """Length in seconds."""
        return self.n_frames / self.fps

    def __len__(self) -> int:
        return self.n_frames

    def __repr__(self) -> str:
        """One short line (the arrays would print every frame): frames, joints, rate, name."""
        joints = self.skeleton.n_joints
        frames = f"{self.n_frames} frame{'' if self.n_frames == 1 else 's'}"
        return f"Motion({frames}, {joints} joints, {self.fps:g} fps" + (
            f", {self.name!r})" if self.name else ")"
        )

    def copy(self) -> Motion:
        return Motion(
            self.skeleton,
            self.rotations.copy(),
            self.translations.copy(),
            self.fps,
            self.name,
            self.source,
        )

    def global_transforms(self, compiled: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """Forward kinematics: global rotation matrices (F, J, 3, 3) and positions (F, J, 3) mm.

        ``compiled=False`` runs it in NumPy, level by level of the tree and vectorised over
        frames: about 10x slower than the compiled loop, but without importing numba
        (0.9 s on a busy 2-core machine), for one-off calls of a short-lived process such
        as ``markovmotion info``. The two agree (tested)."""
        local = _quat_matrices(self.rotations) if compiled else _quat_matrices_numpy(self.rotations)
        if local is None:  # a zero quaternion: SciPy's error names it
            from scipy.spatial.transform import Rotation

            Rotation.from_quat(self.rotations.reshape(-1, 4))
        if not compiled:
            return _chain_numpy(local, self.translations, self.skeleton.parents)
        from markovmotion.core.compiled import chain

        return chain(local, self.translations, self.skeleton.parents)

    def positions(self, compiled: bool = True) -> np.ndarray:
        """Global joint positions (F, J, 3) in mm (``compiled``: see :meth:`global_transforms`)."""
        return self.global_transforms(compiled)[1]

    def hip_joints(self) -> tuple[int, int] | None:
        """The (left, right) hip joints under the pelvis, if their names tell them apart.

        The legs are the two children of the pelvis whose subtrees reach lowest in
        the first frame (else the middle or the last: a generated walk once began with
        a leg at hip height); left and right are told by the first character at which
        the two names differ being ``l``/``L`` against ``r``/``R``
        (``lfemur``/``rfemur``, ``UpperLeg_L``/``UpperLeg_R``). Found once per
        skeleton and remembered; a skeleton whose legs were not found is looked at
        again with the next motion (a failure is not remembered: the answer must not
        depend on which motion came first).
        """
        sk = self.skeleton
        if sk not in _HIPS:
            for frame in dict.fromkeys((0, self.n_frames // 2, self.n_frames - 1)):
                found = self._find_hip_joints(frame)
                if found is not None:
                    _HIPS[sk] = found
                    break
            else:
                return None
        return _HIPS[sk]

    def _find_hip_joints(self, frame: int = 0) -> tuple[int, int] | None:
        sk = self.skeleton
        pelvis = sk.body_root
        kids = sk.children(pelvis)
        if len(kids) < 2 or self.n_frames == 0:
            return None
        height = self.positions_at(frame)[:, 1]
        lowest = {}
        for k in kids:
            sub = _subtree(sk, k)
            lowest[k] = height[sub].min()
        a, b = sorted(kids, key=lowest.get)[:2]
        na, nb = sk.names[a], sk.names[b]
        for ca, cb in zip(na, nb, strict=False):
            if ca != cb:
                pair = (ca.lower(), cb.lower())
                if pair == ("l", "r"):
                    return _off_pelvis(sk, a), _off_pelvis(sk, b)
                if pair == ("r", "l"):
                    return _off_pelvis(sk, b), _off_pelvis(sk, a)
                return None
        return None

    def positions_at(self, frame: int) -> np.ndarray:
        """Global joint positions (J, 3) of one frame."""
        return Motion(
            self.skeleton,
            self.rotations[frame : frame + 1],
            self.translations[frame : frame + 1],
            self.fps,
        ).positions()[0]

    def heading(self, positions: np.ndarray | None = None) -> np.ndarray:
        """Facing direction per frame as a yaw angle about +Y (radians, 0 = facing +Z).

        Forward is ``(left hip - right hip) x up``; when the hips cannot be told
        apart, the pelvis's global rotation applied to +Z.
        """
        hips = self.hip_joints()
        if hips is not None:
            pos = self.positions() if positions is None else positions
            lateral = pos[:, hips[0]] - pos[:, hips[1]]
            return np.arctan2(-lateral[:, 2], lateral[:, 0])  # forward = (-lateral_z, 0, lateral_x)
        rot, _ = self.global_transforms()
        forward = rot[:, self.skeleton.body_root, :, 2]
        return np.arctan2(forward[:, 0], forward[:, 2])

    # ----------------------------------------------------------------- edits
    def trim(self, start: int = 0, stop: int | None = None) -> Motion:
        """Frames ``start:stop`` as a new motion."""
        sl = slice(start, stop)
        return Motion(
            self.skeleton,
            self.rotations[sl].copy(),
            self.translations[sl].copy(),
            self.fps,
            self.name,
            self.source,
        )

    def resample(self, fps: float) -> Motion:
        """The same motion sampled at ``fps``: slerp for rotations, linear for translations.

        Raises:
            ValueError: ``fps`` not finite, not above 0 or above
                :data:`markovmotion.limits.MAX_FPS`, or a result of more frames
                or values than :mod:`markovmotion.limits` allows.
        """
        from markovmotion.errors import LimitError
        from markovmotion.limits import MAX_FRAMES, MAX_VALUES, check_rate, max_frames, max_values

        fps = check_rate(fps, "resampling frame rate")
        if self.n_frames < 2 or np.isclose(fps, self.fps):
            return Motion(
                self.skeleton, self.rotations, self.translations, fps, self.name, self.source
            )
        t_old = np.arange(self.n_frames) / self.fps
        span = float(t_old[-1]) * fps
        n_values = span * self.skeleton.n_joints * 7
        if not np.isfinite(span) or span >= max_frames() or n_values > max_values():
            raise LimitError(
                f"resampling {self.n_frames} frames at {self.fps:g} fps to {fps:g} fps gives "
                f"{span:.3g} frames, more than the limits allow "
                f"({MAX_FRAMES.env}, {MAX_VALUES.env})"
            )
        n_new = int(np.floor(span + 1e-9)) + 1
        t_new = np.arange(n_new) / fps
        rot = slerp_frames(self.rotations, t_new * self.fps)
        flat = self.translations.reshape(self.n_frames, -1)
        trans = np.stack([np.interp(t_new, t_old, c) for c in flat.T], axis=1)
        return Motion(self.skeleton, rot, trans.reshape(n_new, -1, 3), fps, self.name, self.source)

    def align_heading(self, yaw: float = 0.0, to_origin: bool = True) -> Motion:
        """Rotate the whole motion about +Y so that frame 0 faces ``yaw``.

        With ``to_origin``, the pelvis of frame 0 is also moved above the origin
        (its height is kept).
        """
        from scipy.spatial.transform import Rotation

        pos = self.positions()
        turn = Rotation.from_rotvec([0.0, yaw - self.heading(pos[:1])[0], 0.0])
        out = self.copy()
        out.rotations[:, 0] = (turn * Rotation.from_quat(self.rotations[:, 0])).as_quat()
        out.translations[:, 0] = turn.apply(self.translations[:, 0])
        if to_origin:
            pelvis0 = turn.apply(pos[0, self.skeleton.body_root])
            out.translations[:, 0, GROUND] -= pelvis0[GROUND]
        return out

    def body_centred_positions(self, positions: np.ndarray | None = None) -> np.ndarray:
        """Joint positions (F, J, 3) in mm relative to the pelvis, with each frame's yaw removed.

        The body faces +Z in every frame; height stays relative to the pelvis.
        ``positions``: this motion's :meth:`positions`, if already computed.
        """
        pos = self.positions() if positions is None else positions
        yaw = self.heading(pos)
        centred = pos - pos[:, self.skeleton.body_root : self.skeleton.body_root + 1]
        c, s = np.cos(-yaw), np.sin(-yaw)
        x, z = centred[..., 0], centred[..., 2]
        out = centred.copy()
        out[..., 0] = c[:, None] * x + s[:, None] * z
        out[..., 2] = -s[:, None] * x + c[:, None] * z
        return out


def slerp_frames(quats: np.ndarray, at: np.ndarray) -> np.ndarray:
    """Unit quaternions (F, J, 4) interpolated at fractional frames ``at`` (n,) in [0, F - 1]:
    spherical linear interpolation between the two frames around each time, the
    shorter way round, every joint at once.

    SciPy's ``Slerp`` gives the same rotations and signs (it composes frame k with a
    fraction of the relative rotation to frame k + 1) but takes one joint per call,
    which made resampling a take a fifth of a second of a live session's start."""
    q = np.asarray(quats, dtype=float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    at = np.asarray(at, dtype=float)
    at = np.where(np.abs(at - np.rint(at)) < 1e-6, np.rint(at), at)  # a frame is itself
    k = np.clip(np.floor(at).astype(int), 0, len(q) - 1)
    u = (at - k)[:, None, None]
    q0, q1 = q[k], q[np.minimum(k + 1, len(q) - 1)]
    dot = np.sum(q0 * q1, axis=-1, keepdims=True)
    q1 = np.where(dot < 0, -q1, q1)
    dot = np.minimum(np.abs(dot), 1.0)
    omega = np.arccos(dot)
    sin = np.sin(omega)
    near = sin < 1e-9  # the same rotation: any weights do
    safe = np.where(near, 1.0, sin)
    w0 = np.where(near, 1.0 - u, np.sin((1.0 - u) * omega) / safe)
    w1 = np.where(near, u, np.sin(u * omega) / safe)
    out = w0 * q0 + w1 * q1
    return out / np.linalg.norm(out, axis=-1, keepdims=True)


def _quat_matrices_numpy(quats: np.ndarray) -> np.ndarray | None:
    """:func:`_quat_matrices` vectorised in NumPy (for many frames at once)."""
    q = np.asarray(quats, dtype=float)
    n = np.einsum("...i,...i->...", q, q)
    if np.any(n == 0.0):
        return None
    s = 2.0 / n
    x, y, z, w = np.moveaxis(q, -1, 0)
    out = np.empty((*q.shape[:-1], 3, 3))
    out[..., 0, 0] = 1.0 - s * (y * y + z * z)
    out[..., 0, 1] = s * (x * y - z * w)
    out[..., 0, 2] = s * (x * z + y * w)
    out[..., 1, 0] = s * (x * y + z * w)
    out[..., 1, 1] = 1.0 - s * (x * x + z * z)
    out[..., 1, 2] = s * (y * z - x * w)
    out[..., 2, 0] = s * (x * z - y * w)
    out[..., 2, 1] = s * (y * z + x * w)
    out[..., 2, 2] = 1.0 - s * (x * x + y * y)
    return out


def _chain_numpy(
    local: np.ndarray, trans: np.ndarray, parents: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The compiled ``chain`` in NumPy: the joints of one tree depth at once (their parents
    are done), every frame at once; R_j = R_p(j) L_j and p_j = p_p(j) + R_p(j) t_j."""
    depth = np.zeros(len(parents), dtype=np.intp)
    for j in range(1, len(parents)):  # parents come before their children
        depth[j] = depth[parents[j]] + 1
    rot = np.empty_like(local)
    pos = np.empty(trans.shape)
    rot[:, 0], pos[:, 0] = local[:, 0], trans[:, 0]
    for level in range(1, int(depth.max(initial=0)) + 1):
        joints = np.flatnonzero(depth == level)
        up = parents[joints]
        pos[:, joints] = pos[:, up] + np.einsum("fjab,fjb->fja", rot[:, up], trans[:, joints])
        rot[:, joints] = rot[:, up] @ local[:, joints]
    return rot, pos


def _quat_matrices(quats: np.ndarray) -> np.ndarray | None:
    """Rotation matrices (..., 3, 3) of unit quaternions (..., 4), scalar last, each
    normalised first (as SciPy's ``Rotation.from_quat``); None if one has zero norm.

    Compiled, not SciPy's: the one-frame calls of online partners spent most of
    their forward kinematics in ``Rotation``'s argument checks."""
    from markovmotion.core.compiled import quat_matrices_into

    q = np.ascontiguousarray(quats, dtype=float).reshape(-1, 4)
    out = np.empty((len(q), 3, 3))
    if not quat_matrices_into(q, out):
        return None
    return out.reshape(*quats.shape[:-1], 3, 3)


_HIPS: weakref.WeakKeyDictionary[Skeleton, tuple[int, int]] = weakref.WeakKeyDictionary()


def _off_pelvis(sk: Skeleton, j: int) -> int:
    """The first joint at or below ``j`` on a chain of single children that does not sit
    where its parent does: cgspeed's CMU skeleton has ``LHipJoint`` at the pelvis itself
    (a zero offset) and the hip at its child ``LeftUpLeg``; two hips at one point tell no
    direction."""
    while not np.any(sk.offsets[j]) and len(sk.children(j)) == 1:
        j = sk.children(j)[0]
    return j


def _subtree(sk: Skeleton, root: int) -> list[int]:
    out = [root]
    for j in range(root + 1, sk.n_joints):
        if sk.parents[j] in out:
            out.append(j)
    return out
