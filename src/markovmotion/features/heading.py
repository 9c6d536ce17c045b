"""Object-centred motion: each frame turned to face +Z with the pelvis above the origin."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.spatial.transform import Rotation

from markovmotion.core.motion import Motion
from markovmotion.features.base import FeatureStep
from markovmotion.state import register


@register
class RemoveHeading(FeatureStep):
    """Motion -> Motion without global yaw or ground-plane travel (VLMM paper §2.1.2).

    Every frame is rotated about the vertical through its pelvis so that the
    body faces +Z (:meth:`Motion.heading`), then moved so the pelvis is above
    the origin; height and all joint rotations below the root are untouched.
    The change is rigid per frame, so joint rotations stay exact; which way the
    performer faced is dropped, so ``inverse_transform`` passes motion through.
    """

    def transform(self, sequences: Sequence[Motion]) -> list[Motion]:
        out = []
        for m in sequences:
            pos = m.positions()
            turn = Rotation.from_rotvec(np.outer(-m.heading(pos), [0.0, 1.0, 0.0]))
            ground = pos[:, m.skeleton.body_root] * [1.0, 0.0, 1.0]
            res = m.copy()
            res.rotations[:, 0] = (turn * Rotation.from_quat(m.rotations[:, 0])).as_quat()
            res.translations[:, 0] = turn.apply(m.translations[:, 0] - ground)
            out.append(res)
        return out

    def inverse_transform(self, sequences: Sequence[Motion]) -> list[Motion]:
        return list(sequences)
