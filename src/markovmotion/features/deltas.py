"""Dynamic features: static, delta and delta-delta windows (gait paper, eqs. 2-4)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from markovmotion.features.base import FeatureStep
from markovmotion.state import register


def add_deltas(c: np.ndarray) -> np.ndarray:
    """(T, D) static features -> (T, 3D) observations [c, dc, d2c] (eqs. 2-3, edges replicated)."""
    c = np.asarray(c, dtype=float)
    pad = np.concatenate([c[:1], c[:1], c, c[-1:], c[-1:]])
    d1 = 0.5 * (pad[3:-1] - pad[1:-3])
    d2 = 0.25 * (pad[4:] - 2 * pad[2:-2] + pad[:-4])
    return np.hstack([c, d1, d2])


@register
class Deltas(FeatureStep):
    """(F, D) -> (F, 3D) observation vectors o_t = [c_t, dc_t, d2c_t]; inverse keeps c_t."""

    def transform(self, sequences: Sequence[np.ndarray]) -> list[np.ndarray]:
        return [add_deltas(s) for s in sequences]

    def inverse_transform(self, sequences: Sequence[np.ndarray]) -> list[np.ndarray]:
        return [np.asarray(o)[:, : np.asarray(o).shape[1] // 3] for o in sequences]
