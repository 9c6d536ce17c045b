"""The feature-step protocol and the pipeline that chains steps.

Every step is a scikit-learn-style estimator over *lists of sequences*: the
first step of a pipeline takes :class:`~markovmotion.Motion` objects, later
steps take arrays of shape (frames, dims). ``inverse_transform`` walks back,
so a model that generates features hands back motion.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from sklearn.base import BaseEstimator

from markovmotion.state import StateError, estimator_state, is_fitted, register, restore_estimator


class FeatureStep(BaseEstimator):
    """One fit/transform/inverse_transform stage over a list of sequences."""

    def fit(self, sequences: Sequence[Any]) -> FeatureStep:
        return self

    def transform(self, sequences: Sequence[Any]) -> list[Any]:
        raise NotImplementedError

    def inverse_transform(self, sequences: Sequence[Any]) -> list[Any]:
        raise NotImplementedError

    def fit_transform(self, sequences: Sequence[Any]) -> list[Any]:
        return self.fit(sequences).transform(sequences)

    def output_width(self) -> int | None:
        """Columns of the fitted step's output arrays, when the step knows them."""
        return None

    def input_width(self) -> int | None:
        """Columns of the arrays the fitted step takes, when the step knows them."""
        return None


@register
class FeaturePipeline(FeatureStep):
    """Steps applied in order; saved with every model trained on its output.

    >>> pipe = FeaturePipeline([JointPositions(), PCA(energy=0.95)])  # doctest: +SKIP
    >>> X = pipe.fit_transform(motions)                                # doctest: +SKIP
    """

    def __init__(self, steps: list[FeatureStep] | None = None):
        self.steps = steps

    def fit(self, sequences: Sequence[Any]) -> FeaturePipeline:
        self.fit_transform(sequences)
        return self

    def fit_transform(self, sequences: Sequence[Any]) -> list[Any]:
        data = list(sequences)
        for step in self.steps or []:
            data = step.fit_transform(data)
        return data

    def transform(self, sequences: Sequence[Any]) -> list[Any]:
        data = list(sequences)
        for step in self.steps or []:
            data = step.transform(data)
        return data

    def inverse_transform(self, sequences: Sequence[Any]) -> list[Any]:
        data = list(sequences)
        for step in reversed(self.steps or []):
            data = step.inverse_transform(data)
        return data

    def output_width(self) -> int | None:
        return self.steps[-1].output_width() if self.steps else None

    def check_state(self) -> None:
        """Steps are feature steps; each fitted one takes the width the one before gives."""
        steps = self.steps or []
        if not isinstance(steps, list) or not all(isinstance(s, FeatureStep) for s in steps):
            raise StateError("steps: expected a list of feature steps")
        for i in range(1, len(steps)):
            if is_fitted(steps[i - 1]) and is_fitted(steps[i]):
                given, taken = steps[i - 1].output_width(), steps[i].input_width()
                if None not in (given, taken) and given != taken:
                    raise StateError(
                        f"steps[{i}]: takes {taken} features, steps[{i - 1}] gives {given}"
                    )

    def to_state(self, arrays: dict[str, np.ndarray], prefix: str = "pipeline") -> dict[str, Any]:
        """JSON description for a model header; arrays are added to ``arrays``."""
        return estimator_state(self, prefix, arrays)

    @staticmethod
    def from_state(state: dict[str, Any], arrays: dict[str, np.ndarray]) -> FeaturePipeline:
        return restore_estimator(state, arrays)
