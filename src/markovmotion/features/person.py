"""Person normalisation: features of a person relative to that person, so that a model learnt
from some people answers others (``DualHMM(normalise="person")``, docs/hmm.md).

With few people in the training data, a dual HMM's states learn *who* moves more than *how*:
each person's body, posture and the tracker's view of them shift every pose by an offset of
their own (on the Bütepage handshakes, B's own mean pose is 76 mm from B's frames against 155
mm for the training people's mean pose), and decoding a new person picks the training person
who looks most alike. Two steps take the offset out:

- :class:`RunningCentre`: A's features minus A's own mean so far (a causal running mean that
  starts from the training mean, so it runs online, frame by frame, and needs no look-ahead).
- :func:`on_average_body`: B's training frames with each take's mean shape replaced by the
  mean shape of every training take, so the frames the trellis picks show how the training
  people moved, on one average body, not on whoever the trellis happens to pick.

Written here rather than taken from scikit-learn: its scalers centre on a fixed mean, not on
each sequence's causal running mean.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from markovmotion.features.base import FeatureStep
from markovmotion.state import StateError, check_shape, is_fitted, register, require


@register
class RunningCentre(FeatureStep):
    """Each sequence minus its causal running mean: row t becomes
    ``x_t - (prior * mean_ + x_1 + ... + x_t) / (prior + t)``.

    The running mean starts from the training mean ``mean_`` with the weight of ``prior``
    frames, so the first frames are not all zero. :meth:`online` gives the same rows one
    frame at a time. ``inverse_transform`` cannot restore the mean and passes data through.
    """

    def __init__(self, prior: float = 30.0):
        self.prior = prior

    def fit(self, sequences: Sequence[np.ndarray]) -> RunningCentre:
        if not self.prior >= 0:
            raise ValueError(f"prior must be a number of frames >= 0, got {self.prior}")
        self.mean_ = np.vstack([np.asarray(s, dtype=float) for s in sequences]).mean(axis=0)
        return self

    def check_state(self) -> None:
        if not is_fitted(self):
            return
        require(self, "mean_")
        check_shape("mean_", self.mean_, (None,))
        if not np.isfinite(self.mean_).all():
            raise StateError("mean_: not finite")

    def input_width(self) -> int | None:
        return len(self.mean_) if is_fitted(self) else None

    def output_width(self) -> int | None:
        return self.input_width()

    def transform(self, sequences: Sequence[np.ndarray]) -> list[np.ndarray]:
        out = []
        for s in sequences:
            x = np.asarray(s, dtype=float)
            t = np.arange(1, len(x) + 1)[:, None]
            out.append(x - (self.prior * self.mean_ + np.cumsum(x, axis=0)) / (self.prior + t))
        return out

    def inverse_transform(self, sequences: Sequence[np.ndarray]) -> list[np.ndarray]:
        return [np.asarray(s) for s in sequences]

    def online(self) -> OnlineCentre:
        """A running state that centres one row at a time as :meth:`transform` does."""
        return OnlineCentre(self.prior * self.mean_, float(self.prior))


class OnlineCentre:
    """The running sum and count of :class:`RunningCentre`, for a stream of rows."""

    def __init__(self, total: np.ndarray, count: float):
        self.total, self.count = np.array(total, dtype=float), count

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """Row ``x`` (D,) centred; the running mean takes it in."""
        self.total += x
        self.count += 1.0
        return x - self.total / self.count


def on_average_body(takes: Sequence[np.ndarray]) -> list[np.ndarray]:
    """Positions (F, M, 3) per take with each take's mean shape about its centroid replaced
    by the mean shape of all the takes' frames: the same motion (the centroid's path and the
    shape's change), on the average training body."""
    shapes = [p - p.mean(axis=1, keepdims=True) for p in takes]
    average = np.concatenate(shapes).mean(axis=0)
    return [p - s.mean(axis=0) + average for p, s in zip(takes, shapes, strict=True)]
