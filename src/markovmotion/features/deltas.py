"""Dynamic features: static, delta and delta-delta windows (gait paper, eqs. 2-4)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy import sparse

from markovmotion.features.base import FeatureStep
from markovmotion.state import register

#: Regression windows of eqs. (2) and (3): offsets -> weights.
DELTA_WINDOW = {-1: -0.5, 1: 0.5}
DELTA2_WINDOW = {-2: 0.25, 0: -0.5, 2: 0.25}


def delta_matrix(n_frames: int) -> sparse.csr_matrix:
    """W of eq. (4) for one dimension: (3T, T) with rows [c_t, dc_t, d2c_t] per frame t.

    Frames outside the sequence take the value of the nearest edge frame, so a
    constant sequence has zero deltas everywhere.
    """
    rows, cols, vals = [], [], []
    for t in range(n_frames):
        for block, window in enumerate(({0: 1.0}, DELTA_WINDOW, DELTA2_WINDOW)):
            for off, w in window.items():
                rows.append(3 * t + block)
                cols.append(min(max(t + off, 0), n_frames - 1))
                vals.append(w)
    return sparse.csr_matrix((vals, (rows, cols)), shape=(3 * n_frames, n_frames))


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
