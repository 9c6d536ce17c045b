"""Dropping feature columns that do not vary (fixed joints), restored on the way back."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from markovmotion.features.base import FeatureStep
from markovmotion.state import check_index, check_shape, is_fitted, register, require


@register
class DropStaticColumns(FeatureStep):
    """(F, D) -> (F, D') without the columns whose range over the training data is <= ``tol``.

    Joints that never move (fingers, eyes in CMU's retargeted figure) still
    carry rounding noise; a per-column [0, 1] normalisation downstream would
    blow that noise up to the size of real motion. ``inverse_transform`` puts
    the dropped columns back at their training means.
    """

    def __init__(self, tol: float = 1e-3):
        self.tol = tol

    def fit(self, sequences: Sequence[np.ndarray]) -> DropStaticColumns:
        x = np.vstack([np.asarray(s, dtype=float) for s in sequences])
        self.keep_ = np.flatnonzero(np.ptp(x, axis=0) > self.tol)
        self.mean_ = x.mean(axis=0)
        return self

    def check_state(self) -> None:
        """mean_ (D,), keep_ column indices in [0, D)."""
        if is_fitted(self):
            require(self, "keep_", "mean_")
            d = len(check_shape("mean_", self.mean_, (None,)))
            check_index("keep_", check_shape("keep_", self.keep_, (None,)), d)

    def input_width(self) -> int | None:
        return len(self.mean_)

    def output_width(self) -> int | None:
        return len(self.keep_)

    def transform(self, sequences: Sequence[np.ndarray]) -> list[np.ndarray]:
        return [np.asarray(s, dtype=float)[:, self.keep_] for s in sequences]

    def inverse_transform(self, sequences: Sequence[np.ndarray]) -> list[np.ndarray]:
        out = []
        for s in sequences:
            full = np.tile(self.mean_, (len(s), 1))
            full[:, self.keep_] = s
            out.append(full)
        return out
