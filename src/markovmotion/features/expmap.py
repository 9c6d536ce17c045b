"""Joint rotations as exponential maps (rotation vectors), continuous over time."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.spatial.transform import Rotation

from markovmotion.core.motion import Motion
from markovmotion.features.base import FeatureStep
from markovmotion.state import check_joint_index, register

ROOT_POSITION = ("none", "height", "full")


def continuous_rotvec(rotvec: np.ndarray) -> np.ndarray:
    """Remove the flips of rotation vectors (F, ..., 3) along axis 0.

    A rotation by angle t about axis u is also one by t - 2 pi about u. SciPy
    returns t in [0, pi], so a joint turning through pi flips its vector. Where
    t > pi/2 each frame keeps whichever of the two forms is nearer the previous
    frame's vector; below pi/2 the short form is always kept, so vectors never
    drift towards norm 2 pi around the rest pose (where axes are unstable).
    """
    out = np.array(rotvec, dtype=float)
    angle = np.linalg.norm(out, axis=-1, keepdims=True)
    axis = np.divide(out, angle, out=np.zeros_like(out), where=angle > 1e-12)
    alt = out - 2 * np.pi * axis
    near_pi = angle[..., 0] > np.pi / 2
    for t in np.flatnonzero(near_pi.reshape(len(out), -1).any(axis=1)):
        if t == 0:
            continue
        prev = out[t - 1]
        use_alt = near_pi[t] & (
            np.linalg.norm(alt[t] - prev, axis=-1) < np.linalg.norm(out[t] - prev, axis=-1)
        )
        out[t][use_alt] = alt[t][use_alt]
    return out


@register
class ExpMaps(FeatureStep):
    """Motion -> (F, 3R [+1 or 3]) exponential maps of the rotating joints.

    Args:
        root_position: the pelvis translation to append: ``"none"``,
            ``"height"`` (its Y, in mm) or ``"full"`` (X, Y, Z in mm).

    Joints without rotation channels (end sites, fixed joints) are left out and
    restored to identity by ``inverse_transform``, which returns motions on the
    training skeleton.
    """

    def __init__(self, root_position: str = "height"):
        self.root_position = root_position

    def fit(self, sequences: Sequence[Motion]) -> ExpMaps:
        if self.root_position not in ROOT_POSITION:
            raise ValueError(f"root_position must be one of {ROOT_POSITION}")
        sk = sequences[0].skeleton
        for m in sequences[1:]:
            sk.check_compatible(m.skeleton)
        self.skeleton_ = sk
        self.joint_index_ = np.array([j for j in range(sk.n_joints) if sk.rotation_order(j)])
        self.fps_ = float(sequences[0].fps)
        return self

    def _root_columns(self) -> list[int]:
        return {"none": [], "height": [1], "full": [0, 1, 2]}[self.root_position]

    def check_state(self) -> None:
        """skeleton_ a Skeleton, joint_index_ joints of it."""
        check_joint_index(self)

    def output_width(self) -> int | None:
        return 3 * len(self.joint_index_) + len(self._root_columns())

    def transform(self, sequences: Sequence[Motion]) -> list[np.ndarray]:
        out = []
        cols = self._root_columns()
        for m in sequences:
            self.skeleton_.check_compatible(m.skeleton)
            q = m.rotations[:, self.joint_index_]
            rv = Rotation.from_quat(q.reshape(-1, 4)).as_rotvec().reshape(len(q), -1, 3)
            feats = continuous_rotvec(rv).reshape(len(q), -1)
            root = m.translations[:, self.skeleton_.body_root][:, cols]
            out.append(np.hstack([feats, root]))
        return out

    def inverse_transform(self, sequences: Sequence[np.ndarray]) -> list[Motion]:
        sk = self.skeleton_
        cols = self._root_columns()
        n_rot = 3 * len(self.joint_index_)
        out = []
        for x in sequences:
            x = np.asarray(x)
            f = len(x)
            quats = np.zeros((f, sk.n_joints, 4))
            quats[..., 3] = 1.0
            rv = x[:, :n_rot].reshape(-1, 3)
            quats[:, self.joint_index_] = Rotation.from_rotvec(rv).as_quat().reshape(f, -1, 4)
            motion = Motion.from_rotations(sk, quats, fps=self.fps_)
            if cols:
                motion.translations[:, sk.body_root, cols] = x[:, n_rot : n_rot + len(cols)]
            out.append(motion)
        return out
