"""B's place from the hands' contact: where A holds a hand out to B, B's hand meets it.

Our addition to the dual HMM (not in the paper), the option ``contact_weight`` (0, the
default, leaves the paper's placement alone). For people it has never seen, what the partner
knows worst is where B stands (docs/hmm.md, "Where the world error is"): a new pair may stand
100-150 mm further apart than the training pairs, and neither A's ground frame nor A's
states say so. In a handshake the hands meet, and A's hand shows where.

Learnt from the training takes (:meth:`HandContact.learn`), in A's ground frame as the model
places B:

* the **contact frames**, where the real right hands are closer than :data:`CONTACT_MM`, and a
  logistic regression (scikit-learn) that tells them from A's right hand relative to A's
  centroid (three numbers; B's real hand is not seen live);
* the **offset** of B's right hand from A's over those frames (mean);
* the **bounds** of a handshake there, from the 1st to the 99th percentile: A's hand
  relative to A's centroid (in A's ground frame), and the two people's separation (their
  centroids' horizontal distance).

In generation (:func:`contact_shifts`, causal, the same offline and online through
:class:`OnlineContact`), in each frame where A's hand says contact, the horizontal shift that
would put the generated B's hand at A's hand plus the offset; B is moved by ``weight`` times
the mean of those shifts over the contact frames so far (within ``memory`` frames: people
stand still while they shake hands, so the place, once seen, holds). A frame is not taken
for contact when A's hand lies more than :data:`REACH_MARGIN_MM` outside the training
handshakes' hands, or the move would leave the pair more than :data:`SEPARATION_MARGIN_MM`
outside their separation: the regression is linear, and a hand raised or out to the side
is "out" to it too (a new user's trial on the real video of a man balancing alone: B was
pulled onto him).
Who is taller is not
what the hands' meeting tells, so the height is left alone. Before the first contact, and
for a model whose training takes hold none (waves), nothing moves.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from markovmotion.features.body_points import find_points
from markovmotion.features.markers import turn_about_up

#: Frames whose real right hands are closer than this are in contact (the Bütepage
#: handshakes' hands meet at 9-113 mm, their data README; other hands stay 500 mm apart).
CONTACT_MM = 150.0
#: How far outside the training pairs' separation in contact (mm) a new pair may stand: the
#: three Bütepage pairs' median separations differ by 150 mm (777-928 mm).
SEPARATION_MARGIN_MM = 150.0
#: How far outside the training handshakes' hands (relative to the centroid, mm) a new
#: person's hand may be and count as a handshake: a person reaching further than any training
#: person (pair 3 reaches 375-460 mm against pairs 1-2's 255-400).
REACH_MARGIN_MM = 100.0
#: Fewest contact frames in the training takes for the model to learn the contact.
MIN_CONTACT_FRAMES = 10


def right_hand(names: list[str] | tuple[str, ...]) -> int | None:
    """Index of the right hand among marker or body-point names (``R_HAND``, ``RHand``,
    ``right_wrist`` ...: the body point ``right_wrist``, :func:`find_points`), or None."""
    return find_points(names).get("right_wrist")


@dataclass(frozen=True)
class HandContact:
    """What the training takes say of the hands' contact (module docstring): the right
    hand's index among the compared points, B's hand's ``offset`` (3,) from A's in A's
    ground frame, the logistic regression's ``coef`` (3,) and ``intercept``, and the
    ``bounds`` of a handshake."""

    hand: int
    offset: np.ndarray
    coef: np.ndarray
    intercept: float
    #: (4, 2) the 1st and 99th percentiles, over the training contact frames, of A's hand
    #: relative to A's centroid in A's ground frame (x, y, z) and of the pair's separation
    #: (mm); None (a model saved before they were learnt): no check.
    bounds: np.ndarray | None = None

    @classmethod
    def learn(
        cls,
        a_points: list[np.ndarray],
        b_points: list[np.ndarray],
        yaws: list[np.ndarray],
        hand: int,
    ) -> HandContact | None:
        """From the training takes' compared points of A and B (each (F, P, 3), world) and
        A's ground-frame heading (F,); None when fewer than :data:`MIN_CONTACT_FRAMES`
        frames are in contact, or all are."""
        from sklearn.linear_model import LogisticRegression

        reach, touch, offsets, apart = [], [], [], []
        for a, b, yaw in zip(a_points, b_points, yaws, strict=True):
            n = min(len(a), len(b), len(yaw))
            a, b, yaw = a[:n], b[:n], yaw[:n]
            contact = np.linalg.norm(a[:, hand] - b[:, hand], axis=-1) < CONTACT_MM
            reach.append(_reach(a, yaw, hand))
            touch.append(contact)
            apart.append(_separation(a, b)[contact])
            offsets.append(turn_about_up((b[:, hand] - a[:, hand])[:, None], -yaw)[contact, 0])
        x, y = np.concatenate(reach), np.concatenate(touch)
        ok = np.isfinite(x).all(axis=1)
        x, y = x[ok], y[ok]
        if y.sum() < MIN_CONTACT_FRAMES or y.all():
            return None
        clf = LogisticRegression().fit(x, y)
        offset = np.concatenate(offsets)
        offset = offset[np.isfinite(offset).all(axis=1)].mean(axis=0)
        apart = np.concatenate(apart)
        bounds = np.r_[
            np.percentile(x[y], [1, 99], axis=0).T,
            [np.percentile(apart[np.isfinite(apart)], [1, 99])],
        ]
        return cls(int(hand), offset, clf.coef_[0].copy(), float(clf.intercept_[0]), bounds)

    def shifts(self, a: np.ndarray, yaw: np.ndarray, b: np.ndarray) -> np.ndarray:
        """(F, 3) for A's and the generated B's compared points (F, P, 3) and A's heading
        (F,): where A's hand says contact (and the move leaves the pair standing as the
        training pairs did, within the margin), the horizontal move putting B's hand at A's
        plus the offset; NaN elsewhere (no evidence)."""
        reach = _reach(a, yaw, self.hand)
        touch = reach @ self.coef + self.intercept > 0.0  # probability above 0.5
        target = (
            a[:, self.hand]
            + turn_about_up(np.broadcast_to(self.offset, (len(yaw), 1, 3)), yaw)[:, 0]
        )
        out = target - b[:, self.hand]
        out[:, 1] = 0.0
        if self.bounds is not None:  # a hand held out as in a handshake, the pair standing so
            seen = np.c_[reach, _separation(a, b + out[:, None])]
            margin = np.array([REACH_MARGIN_MM] * 3 + [SEPARATION_MARGIN_MM])
            inside = (seen >= self.bounds[:, 0] - margin) & (seen <= self.bounds[:, 1] + margin)
            touch &= inside.all(axis=1)
        out[~touch] = np.nan
        return out


def _separation(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(F,) horizontal distance of A's and B's centroids (points (F, P, 3))."""
    d = b.mean(axis=1) - a.mean(axis=1)
    return np.hypot(d[:, 0], d[:, 2])


def _reach(a: np.ndarray, yaw: np.ndarray, hand: int) -> np.ndarray:
    """(F, 3) A's hand relative to A's centroid, in A's ground frame."""
    return turn_about_up((a[:, hand] - a.mean(axis=1))[:, None], -yaw)[:, 0]


def contact_shifts(shifts: np.ndarray, weight: float, memory: int | None) -> np.ndarray:
    """(F, 3) how far B is moved: ``weight`` times the mean of :meth:`HandContact.shifts`
    (NaN: no contact) over the contact frames among the last ``memory`` frames (None: all
    so far); 0 before any (module docstring). :class:`OnlineContact` frame by frame."""
    seen = np.isfinite(shifts).all(axis=1)
    total = np.cumsum(np.where(seen[:, None], shifts, 0.0), axis=0)
    count = np.cumsum(seen).astype(float)
    if memory is not None and memory < len(shifts):
        total[memory:] -= total[:-memory].copy()
        count[memory:] -= count[:-memory].copy()
    mean = np.divide(total, count[:, None], out=np.zeros_like(total), where=count[:, None] > 0)
    return weight * mean


class OnlineContact:
    """:func:`contact_shifts` one frame at a time (the online partner)."""

    def __init__(self, weight: float, memory: int | None):
        self.weight = weight
        self._recent: deque = deque(maxlen=memory)
        self._total = np.zeros(3)
        self._count = 0

    def step(self, shift: np.ndarray) -> np.ndarray:
        """One frame's :meth:`HandContact.shifts` row (NaN: no contact) in, B's move out."""
        seen = bool(np.isfinite(shift).all())
        if self._recent.maxlen is not None and len(self._recent) == self._recent.maxlen:
            old = self._recent[0]
            if old is not None:
                self._total -= old
                self._count -= 1
        self._recent.append(shift.copy() if seen else None)
        if seen:
            self._total += shift
            self._count += 1
        return self.weight * self._total / self._count if self._count else np.zeros(3)
