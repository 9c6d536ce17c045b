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

from collections.abc import Callable, Sequence

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
        return [self.centre(s) for s in sequences]

    def centre(self, x: np.ndarray, seen: np.ndarray | None = None) -> np.ndarray:
        """One sequence (T, D) minus its causal running mean, over the rows ``seen`` (T,)
        only (all if None): an unseen row (a frame of A that was missing, filled in) does
        not enter the mean, as the online partner never sees it (:meth:`online`)."""
        x = np.asarray(x, dtype=float)
        return x - self.running_mean(x, seen)

    def running_mean(self, x: np.ndarray, seen: np.ndarray | None = None) -> np.ndarray:
        """(T, D) the causal running mean of ``x`` (T, D) over the rows ``seen`` (all if
        None), started from ``mean_`` with the weight of ``prior`` rows; an unseen row (NaN
        allowed) keeps the mean of the rows before it."""
        x = np.asarray(x, dtype=float)
        seen = np.ones(len(x), dtype=bool) if seen is None else np.asarray(seen, dtype=bool)
        total = np.cumsum(np.where(seen[:, None], x, 0.0), axis=0)
        count = np.cumsum(seen)[:, None]
        return (self.prior * self.mean_ + total) / np.maximum(self.prior + count, 1e-12)

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


@register
class ShapeCentre(FeatureStep):
    """The behaviour chain's person normalisation (``VirtualPartner(normalise="person")``):
    combined shape vectors C (:class:`~markovmotion.features.joint_shape.JointShape`, the
    two people's shapes in its first ``2 * shape_size`` columns) with each person's shape
    minus its causal running mean plus the training people's mean shape ``mean_``
    (:class:`RunningCentre`'s running mean, with its ``prior``).

    Each person's body and posture shift their shape vectors by an offset of their own; with
    few training pairs the chain's prototypes learn who moves more than how, and the partner
    shows a training person's posture. Centred, the chain learns how the training people
    moved on the average body, and the real person is observed the same way, frame by frame
    (:meth:`person`, :meth:`online`), as the dual HMM's ``normalise="person"``. The
    separation and scale columns pass through.
    """

    def __init__(self, shape_size: int = 1, prior: float = 30.0):
        self.shape_size = shape_size
        self.prior = prior

    def fit(self, sequences: Sequence[np.ndarray]) -> ShapeCentre:
        k = 2 * int(self.shape_size)
        if not self.prior >= 0 or k < 2:
            raise ValueError(f"prior >= 0 and shape_size >= 1 needed, got {self.prior}, {k // 2}")
        self.mean_ = np.vstack([np.asarray(s, dtype=float) for s in sequences])[:, :k].mean(axis=0)
        return self

    def check_state(self) -> None:
        if not is_fitted(self):
            return
        require(self, "mean_")
        check_shape("mean_", self.mean_, (2 * int(self.shape_size),))
        if not np.isfinite(self.mean_).all():
            raise StateError("mean_: not finite")

    def _centred(self, x: np.ndarray, mean: np.ndarray) -> np.ndarray:
        step = RunningCentre(self.prior)
        step.mean_ = mean
        return step.transform([x])[0] + mean

    def transform(self, sequences: Sequence[np.ndarray]) -> list[np.ndarray]:
        k = len(self.mean_)
        out = []
        for s in sequences:
            c = np.array(s, dtype=float)
            half = k // 2
            for sl in (slice(0, half), slice(half, k)):
                c[:, sl] = self._centred(c[:, sl], self.mean_[sl])
            out.append(c)
        return out

    def inverse_transform(self, sequences: Sequence[np.ndarray]) -> list[np.ndarray]:
        return [np.asarray(s) for s in sequences]

    def target(self, person: int | None) -> np.ndarray:
        """The mean shape a real person is centred on: their half's, or (``None``, either
        half) the two halves' average."""
        half = len(self.mean_) // 2
        halves = self.mean_[:half], self.mean_[half:]
        return (halves[0] + halves[1]) / 2 if person is None else halves[person]

    def person(self, shapes: np.ndarray, person: int | None) -> np.ndarray:
        """One real person's shape vectors S^H (F, KD) centred as :meth:`transform` centres
        the training people's."""
        return self._centred(np.asarray(shapes, dtype=float), self.target(person))

    def online(self, person: int | None) -> Callable[[np.ndarray], np.ndarray]:
        """:meth:`person` one row at a time."""
        target = self.target(person)
        centre = OnlineCentre(self.prior * target, float(self.prior))
        return lambda row: centre(np.asarray(row, dtype=float)) + target


def on_average_body(takes: Sequence[np.ndarray]) -> list[np.ndarray]:
    """Positions (F, M, 3) per take with each take's mean shape about its centroid replaced
    by the mean shape of all the takes' frames: the same motion (the centroid's path and the
    shape's change), on the average training body."""
    shapes = [p - p.mean(axis=1, keepdims=True) for p in takes]
    average = np.concatenate(shapes).mean(axis=0)
    return [p - s.mean(axis=0) + average for p, s in zip(takes, shapes, strict=True)]


def body_radius(positions: np.ndarray) -> np.ndarray:
    """(F,) a person's size per frame: the root mean square distance (mm) of the frame's
    points (F, P, 3) from their centroid (NaN in a frame with a point unseen, NaN)."""
    p = np.asarray(positions, dtype=float)
    return np.sqrt(((p - p.mean(axis=1, keepdims=True)) ** 2).sum(axis=-1).mean(axis=-1))


def size_scale(
    radius: np.ndarray, seen: np.ndarray, size: float, prior: float = 30.0
) -> np.ndarray:
    """(F,) how far a pair stands apart, against the training pairs' average, from A's size
    alone: ``(r_t + size) / (2 size)``, with ``r_t`` the causal running mean of A's
    :func:`body_radius` (:meth:`RunningCentre.running_mean`, started from ``size``, the
    training people's mean, with the weight of ``prior`` frames) and B taken to be of the
    average size, as ``normalise="person"`` draws B (``DualHMM(place_scale="size")``)."""
    step = RunningCentre(prior)
    step.mean_ = np.array([float(size)])
    running = step.running_mean(np.asarray(radius, dtype=float)[:, None], seen)[:, 0]
    return _pair_scale(running, size)


def _pair_scale(radius_a, size: float):
    """The pair's size against the training pairs', A of ``radius_a`` and B of ``size``."""
    return (radius_a + size) / (2.0 * size)


class OnlineSizeScale:
    """:func:`size_scale` one frame at a time (the live partner's)."""

    def __init__(self, size: float, prior: float = 30.0):
        self.size = float(size)
        self._centre = OnlineCentre(np.array([prior * self.size]), float(prior))
        self.scale = 1.0  # before the first frame: the training people's average

    def __call__(self, radius: float) -> float:
        """Take in A's radius of one seen frame; the scale now."""
        r = np.array([float(radius)])
        self.scale = _pair_scale(float((r - self._centre(r))[0]), self.size)
        return self.scale
