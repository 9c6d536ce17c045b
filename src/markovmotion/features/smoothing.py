"""Moving-window temporal smoothing."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.ndimage import uniform_filter1d

from markovmotion.features.base import FeatureStep
from markovmotion.state import register


@register
class TemporalSmoothing(FeatureStep):
    """Centred moving average over ``window`` frames (edges repeat the end frames).

    Smoothing loses information, so ``inverse_transform`` passes data through.
    """

    def __init__(self, window: int = 5):
        self.window = window

    def transform(self, sequences: Sequence[np.ndarray]) -> list[np.ndarray]:
        if self.window < 1:
            raise ValueError("window must be at least one frame")
        return [
            uniform_filter1d(np.asarray(s, dtype=float), self.window, axis=0, mode="nearest")
            for s in sequences
        ]

    def inverse_transform(self, sequences: Sequence[np.ndarray]) -> list[np.ndarray]:
        return [np.asarray(s) for s in sequences]
