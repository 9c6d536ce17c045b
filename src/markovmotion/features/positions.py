"""Joint positions as features: body-centred 3-D positions in mm."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from markovmotion.core.motion import Motion
from markovmotion.features.base import FeatureStep
from markovmotion.features.body_motion import pelvis_centred
from markovmotion.features.body_points import body_point_index
from markovmotion.state import check_joint_index, register


@register
class JointPositions(FeatureStep):
    """Motion -> (F, 3J) joint positions in mm.

    Args:
        body_centred: positions relative to the pelvis with each frame's heading
            removed (:meth:`Motion.body_centred_positions`); otherwise global.
        joints: names of the joints to keep (default: all, end sites included).
        points: body point names instead (:mod:`~markovmotion.features.body_points`),
            found by name on each motion's skeleton, so that motions of any
            skeleton that has them go through.
        turn: with ``body_centred``, whether each frame is turned to face +Z (else
            the positions about the pelvis keep the world's axes).

    ``inverse_transform`` gives (F, J, 3) positions: turning positions back into
    joint rotations needs inverse kinematics, which the position-based models
    do on their own skeleton.
    """

    def __init__(
        self,
        body_centred: bool = True,
        joints: list[str] | None = None,
        points: Sequence[str] | None = None,
        turn: bool = True,
    ):
        self.body_centred = body_centred
        self.joints = joints
        self.points = points
        self.turn = turn

    def fit(self, sequences: Sequence[Motion]) -> JointPositions:
        sk = sequences[0].skeleton
        self.skeleton_ = sk
        if self.points is not None:
            for m in sequences:
                self._index(m)
            self.joint_index_ = self._index(sequences[0])
            return self
        for m in sequences[1:]:
            sk.check_compatible(m.skeleton)
        self.joint_index_ = np.array(
            [sk.index(n) for n in self.joints] if self.joints else np.arange(sk.n_joints)
        )
        return self

    def _index(self, motion: Motion) -> np.ndarray:
        """The joints of ``motion`` the features hold."""
        if self.points is not None:
            return body_point_index(motion.skeleton, self.points, motion.name or "motion")
        self.skeleton_.check_compatible(motion.skeleton)
        return self.joint_index_

    def check_state(self) -> None:
        """skeleton_ a Skeleton, joint_index_ joints of it."""
        check_joint_index(self)

    def output_width(self) -> int | None:
        return 3 * len(self.joint_index_)

    def transform(self, sequences: Sequence[Motion]) -> list[np.ndarray]:
        out = []
        for m in sequences:
            idx = self._index(m)
            pos = pelvis_centred(m, None, self.turn) if self.body_centred else m.positions()
            out.append(pos[:, idx].reshape(len(pos), -1))
        return out

    def inverse_transform(self, sequences: Sequence[np.ndarray]) -> list[np.ndarray]:
        return [np.asarray(x).reshape(len(x), -1, 3) for x in sequences]
