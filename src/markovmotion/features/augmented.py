"""Augmented configuration vectors F = [C, lambda dC/dt] (VLMM paper, eqs. 1-4)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from markovmotion.features.base import FeatureStep
from markovmotion.state import check_positive, check_shape, is_fitted, register, require


@register
class AugmentedConfiguration(FeatureStep):
    """(F, d) configurations -> (F, 2d) augmented vectors [C, lambda * dC].

    Each component of C is first scaled into [0, 1] with its range over the
    training data (eq. 4 and §2.1.2); dC is the frame-to-frame difference of the
    scaled configuration (the first frame repeats the second's), and ``lam``
    balances its weight in Euclidean distances (eq. 2; the paper uses 10 for
    silhouettes and 30 for motion capture).
    """

    def __init__(self, lam: float = 10.0):
        self.lam = lam

    def fit(self, sequences: Sequence[np.ndarray]) -> AugmentedConfiguration:
        x = np.vstack([np.asarray(s, dtype=float) for s in sequences])
        self.min_ = x.min(axis=0)
        span = x.max(axis=0) - self.min_
        self.scale_ = np.where(span > 1e-12, span, 1.0)
        return self

    def check_state(self) -> None:
        """min_ and scale_ (D,), scale_ positive."""
        if is_fitted(self):
            require(self, "min_", "scale_")
            d = len(check_shape("min_", self.min_, (None,)))
            check_positive("scale_", check_shape("scale_", self.scale_, (d,)))

    def input_width(self) -> int | None:
        return len(self.min_)

    def output_width(self) -> int | None:
        return 2 * len(self.min_)

    def transform(self, sequences: Sequence[np.ndarray]) -> list[np.ndarray]:
        out = []
        for s in sequences:
            c = (np.asarray(s, dtype=float) - self.min_) / self.scale_
            dc = np.diff(c, axis=0, prepend=c[:1]) if len(c) else c
            if len(c) > 1:
                dc[0] = dc[1]
            out.append(np.hstack([c, self.lam * dc]))
        return out

    def inverse_transform(self, sequences: Sequence[np.ndarray]) -> list[np.ndarray]:
        d = len(self.min_)
        return [np.asarray(f)[:, :d] * self.scale_ + self.min_ for f in sequences]
