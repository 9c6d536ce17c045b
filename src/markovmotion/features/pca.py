"""Principal component analysis keeping a fraction of the energy (dual-HMM paper, §2)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from sklearn.decomposition import PCA as _SkPCA

from markovmotion.features.base import FeatureStep
from markovmotion.state import StateError, check_shape, is_fitted, register, require


@register
class PCA(FeatureStep):
    """(F, D) -> (F, K), with K the fewest components holding ``energy`` of the variance.

    Fitted with scikit-learn's PCA on all frames of all sequences; the learnt
    mean, components and explained-variance ratios are kept as plain arrays so
    the step saves as plain arrays in a model file.
    """

    def __init__(self, energy: float = 0.95, n_components: int | None = None):
        self.energy = energy
        self.n_components = n_components

    def fit(self, sequences: Sequence[np.ndarray]) -> PCA:
        x = np.vstack([np.asarray(s, dtype=float) for s in sequences])
        full = _SkPCA(svd_solver="full").fit(x)
        ratio = full.explained_variance_ratio_
        k = self.n_components or int(np.searchsorted(np.cumsum(ratio), self.energy - 1e-12) + 1)
        k = min(k, len(ratio))
        self.mean_ = full.mean_
        # C order, as a loaded model has it: the same BLAS kernel, so a loaded model gives
        # bit-identical features (a near-tie in the trellis turns 1e-12 into another frame)
        self.components_ = np.ascontiguousarray(full.components_[:k])
        self.explained_variance_ratio_ = ratio
        self.n_components_ = k
        return self

    def check_state(self) -> None:
        """mean_ (D,), components_ (K, D) with K >= 1, n_components_ == K."""
        if not is_fitted(self):
            return
        require(self, "mean_", "components_")
        d = len(check_shape("mean_", self.mean_, (None,)))
        k = len(check_shape("components_", self.components_, (None, d)))
        if k < 1 or getattr(self, "n_components_", k) != k:
            raise StateError(
                f"n_components_: {getattr(self, 'n_components_', k)}, components_ has {k}"
            )

    def input_width(self) -> int | None:
        return len(self.mean_)

    def output_width(self) -> int | None:
        return len(self.components_)

    def transform(self, sequences: Sequence[np.ndarray]) -> list[np.ndarray]:
        return [(np.asarray(s) - self.mean_) @ self.components_.T for s in sequences]

    def inverse_transform(self, sequences: Sequence[np.ndarray]) -> list[np.ndarray]:
        return [np.asarray(s) @ self.components_ + self.mean_ for s in sequences]
