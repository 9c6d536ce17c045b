"""Joint rotations taken relative to a reference pose, so exponential maps stay far from pi.

An exponential map is singular at rotations of pi (the axis flips), and some
skeletons rest far from their animated pose: Bandai Namco's thighs turn by
nearly pi in every frame. Grassia (1998; gait paper ref. 26) avoids the
singularity by expressing each rotation relative to a nearby one; here that is
the joint's mean rotation over the training frames, ``R = R_ref R_rel``, so
the rotation vectors of :class:`~markovmotion.features.ExpMaps` stay small.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.spatial.transform import Rotation

from markovmotion.core.motion import Motion
from markovmotion.features.base import FeatureStep
from markovmotion.state import StateError, check_shape, is_fitted, register, require


@register
class ReferencePose(FeatureStep):
    """Motion -> Motion whose local rotations are relative to each joint's mean rotation.

    The motion in between is only a carrier for the next step (its forward
    kinematics mean nothing); ``inverse_transform`` composes the reference back.
    """

    def fit(self, sequences: Sequence[Motion]) -> ReferencePose:
        quats = np.concatenate([m.rotations for m in sequences])  # (F, J, 4)
        self.reference_ = np.array(
            [Rotation.from_quat(quats[:, j]).mean().as_quat() for j in range(quats.shape[1])]
        )
        return self

    def check_state(self) -> None:
        """reference_ (J, 4) unit quaternions."""
        if is_fitted(self):
            require(self, "reference_")
            norms = np.linalg.norm(check_shape("reference_", self.reference_, (None, 4)), axis=1)
            if not np.allclose(norms, 1.0, atol=1e-6):
                raise StateError("reference_: not unit quaternions")

    def _compose(self, sequences: Sequence[Motion], inverse: bool) -> list[Motion]:
        out = []
        for m in sequences:
            r = Rotation.from_quat(m.rotations.reshape(-1, 4))
            refs = Rotation.from_quat(np.tile(self.reference_, (m.n_frames, 1)))
            new = refs.inv() * r if inverse else refs * r
            res = m.copy()
            res.rotations = new.as_quat().reshape(m.rotations.shape)
            out.append(res)
        return out

    def transform(self, sequences: Sequence[Motion]) -> list[Motion]:
        return self._compose(sequences, inverse=True)

    def inverse_transform(self, sequences: Sequence[Motion]) -> list[Motion]:
        return self._compose(sequences, inverse=False)
