"""The trellis of §3.2 of the dual-HMM paper: B's poses chosen among real training frames.

``papers/dual-hmm-windowed-viterbi-interaction.txt``, §3.2 "Estimating Output
Behaviours" (after Cosker et al., 2004), Fig. 2:

- Column t of the trellis holds candidate data vectors C_t^j of person B for
  frame t of the input (the paper's figure: three per column).
- Each candidate is given an error. For the first column, E = D4: the
  Mahalanobis distance between the new input b_input (A's pose at t) and the
  data vector b_a of person A stored with the candidate (same location in
  the training data).
- For the other columns t = 2 .. M, D1, D2, D3 are the distances between a
  candidate C_t^j and the candidates C_{t-1}^1..3 of the column before, and
  E = (D1 + D2 + D3) x D4.
- Once the errors are known, one works backwards through the trellis and
  picks, per column, B's motion data with the lowest error.

Two trellises, chosen by ``DualHMM(trellis=...)`` (``--trellis``):

- ``"paper"``: §3.2 as printed. E = D4 in the first column; afterwards
  E_t(j) = (D1 + ... + DK) x D4, the distances from candidate j to *every*
  candidate of the column before, and each column's lowest-error entry is
  picked. The pick in a column does not depend on the picks around it, so
  consecutive frames may come from anywhere in the training data.
- ``"path"`` (the default, ours): a lowest-error path by dynamic
  programming, as Viterbi: a step from candidate j of column t - 1 into
  candidate i of column t costs D_t(i, j') x D4_t(i), where j' is the
  training frame that *followed* j in its recording (:func:`successors`), and
  E_t(i) = min_j E_{t-1}(j) + D_t(i, j') D4_t(i), from E_1 = D4
  (:func:`lowest_error_path`); the path is back-tracked from the last column.
  Going on with the same recording costs nothing, a cut costs how far B's
  pose jumps, so the chosen frames follow each other as the real B's did.

Common to both:

- Column t holds ``size`` (K, default 10, not 3) training frames of B taken
  from the training frames decoded to A's state q_t: the K whose paired A
  frames are nearest the input, by D4 under B_A of q_t (the state's
  covariance; a missing A frame gives D4 = 1 for all). A state no training
  frame decodes to uses the frames nearest its mean.
- D between two candidates is the Mahalanobis distance under B_B of q_t
  between B's features (body points in A's ground frame + PCA).
- Online (:mod:`.partner`), the trellis runs over each slice of the windowed
  decoder, starting from the B frame already shown (E_1 = D x D4 from it),
  and only its first step is shown.
- B's place relative to A is the mean of the path's root positions over
  ``placement_window`` frames (:meth:`Trellis.placement`), and B's joint
  rotations are blended over ``blend_window`` frames (:meth:`Trellis.blend`):
  a cut between two training frames becomes a short transition instead of a
  jump (our additions; online both look no further ahead than the slice).
- On markers (B's training frames are Markers), B's place is the centroid of
  its markers and the blend is the mean of the markers' positions about it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numba
import numpy as np

from markovmotion.core.markers import Markers
from markovmotion.core.motion import Motion
from markovmotion.features.body_motion import mean_place, place_rows

#: The trellis costs: ``"path"`` (a lowest-error path, ours) and ``"paper"`` (§3.2 as printed).
TRELLISES = ("path", "paper")


@dataclass
class Trellis:
    """Training frames grouped by state, pre-whitened for the Mahalanobis distances of §3.2.

    Attributes:
        members: per state, the indices of its training frames.
        white_a: per state, their A features times the state's precision factor under B_A.
        prec_a: (N, Da, Da) precision factors of B_A.
        prec_b: (N, Db, Db) precision factors of B_B.
        train_b: (frames, Db) B's training features.
        size: candidates per column K.
        motion_b: B's training frames relative to A, decoded once (Motion, or Markers).
        successor: (frames,) the training frame after each in its recording
            (:func:`successors`); None: D measured from the frame itself.
        kind: ``"path"`` or ``"paper"`` (module docstring).
    """

    members: list[np.ndarray]
    white_a: list[np.ndarray]
    prec_a: np.ndarray
    prec_b: np.ndarray
    train_b: np.ndarray
    size: int
    motion_b: Motion | Markers
    successor: np.ndarray | None = None
    kind: str = "path"
    _unseen: dict = field(default_factory=dict, init=False, repr=False, compare=False)
    """The column of a missing A frame per state, computed once."""

    def candidates(self, state: int, xa: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """Column entries (K,) for one frame and their D4; a missing A frame gives D4 = 1."""
        if xa is None and state in self._unseen:  # the same for every missing frame
            return self._unseen[state]
        wa = self.white_a[state]
        k = min(self.size, len(wa))
        if xa is None:
            d4 = np.linalg.norm(wa - wa.mean(axis=0), axis=1)
        else:
            d4 = whitened_distances(wa, np.asarray(xa, dtype=float), self.prec_a[state])
        pick = np.argpartition(d4, k - 1)[:k] if k < len(wa) else np.arange(len(wa))
        if xa is not None:
            return self.members[state][pick], d4[pick]
        # shared by every missing frame's column (no caller writes to a column; read-only
        # flags would make numba compile its kernels once more for read-only arrays)
        self._unseen[state] = (self.members[state][pick], np.ones(k))
        return self._unseen[state]

    def distances(self, state: int, idx: np.ndarray, prev: np.ndarray) -> np.ndarray:
        """(K, K') Mahalanobis distances D1..DK' between B candidates and those of the column
        before, under B_B of ``state``. The ``"path"`` trellis measures from the training
        frame that *followed* each earlier candidate (:attr:`successor`), so that going on
        with the same recording costs nothing and a cut costs how far B's pose jumps."""
        if self.kind == "path" and self.successor is not None:
            prev = self.successor[prev]
        return pair_distances(self.train_b, idx, prev, self.prec_b[state])

    def columns(self, states: Sequence[int], xa: Sequence[np.ndarray | None]) -> list[tuple]:
        """The trellis columns (:meth:`candidates`) of frames in ``states`` seen as ``xa``."""
        return [self.candidates(q, x) for q, x in zip(states, xa, strict=True)]

    def best_path(
        self,
        states: Sequence[int],
        cols: list[tuple],
        previous: int | None = None,
        steps: list[np.ndarray] | None = None,
    ) -> np.ndarray:
        """Training frame per column on the lowest-error path; E = D4 in the first column, or
        D x D4 from the frame ``previous`` already shown. ``steps[t - 1]``: the
        :meth:`distances` from column t - 1 to column t, if already computed."""
        idx, cost = cols[0]
        if previous is not None:
            cost = cost * self.distances(states[0], idx, np.array([previous]))[:, 0]
        if steps is None:
            steps = [
                self.distances(states[t], cols[t][0], cols[t - 1][0]) for t in range(1, len(cols))
            ]
        k = len(idx)  # every column holds K = min(size, training frames) (see build_trellis)
        d4 = np.array([c[1] for c in cols[1:]]).reshape(-1, k)
        steps = np.array(steps).reshape(-1, k, k)
        if self.kind == "paper":
            # E = (D1 + ... + DK) x D4 per column, the lowest per column (§3.2 as printed)
            pick = np.concatenate([[np.argmin(cost)], np.argmin(steps.sum(axis=2) * d4, axis=1)])
        else:
            pick = lowest_error_path(cost, d4, steps)
        return np.array([c[0][j] for c, j in zip(cols, pick, strict=True)], dtype=int)

    def blend(
        self, path: np.ndarray, half: int, before: Sequence[int] = (), count: int | None = None
    ) -> np.ndarray:
        """(F, J, 4) B's joint rotations along ``path``, each frame's the normalised mean of
        the quaternions of frames t - half .. t + half (those that exist; ``before``: frames
        shown before the path's first), each turned to the hemisphere of frame t's: a cut
        between two training frames becomes a blend over ``2 half + 1`` frames, and a
        sequence of consecutive training frames stays close to itself. ``half = 0``: the
        frames' own rotations. ``count``: only the path's first ``count`` frames (online,
        the one frame shown). On markers: (F, M, 3) B's markers about their centroid, the
        plain mean over the same frames."""
        frames = np.concatenate([before, path]).astype(int)
        t = np.arange(len(before), len(frames))[:count]
        if isinstance(self.motion_b, Markers):
            shape = self.motion_b.positions[frames]
            shape = shape - shape.mean(axis=1, keepdims=True)
            return _window_mean(shape.reshape(len(frames), -1), t, half).reshape(
                -1, *shape.shape[1:]
            )
        quats = self.motion_b.rotations
        if half <= 0:
            return quats[frames[t]]
        return blend_quaternions(np.ascontiguousarray(quats, dtype=float), frames, t, half)

    def placement(
        self, path: np.ndarray, half: int, before: Sequence[int] = (), count: int | None = None
    ) -> np.ndarray:
        """(F, 3) B's root in A's ground frame along ``path``: the mean over frames t - half ..
        t + half (those that exist; ``before``: frames shown before the path's first).
        ``count``: only the path's first ``count`` frames (as :meth:`blend`)."""
        frames = np.concatenate([before, path]).astype(int)
        if isinstance(self.motion_b, Markers):  # B's centroid
            roots = self.motion_b.positions[frames].mean(axis=1)
        else:
            roots = self.motion_b.translations[frames, 0]
        return _window_mean(roots, np.arange(len(before), len(roots))[:count], half)


def blend_positions(
    positions: np.ndarray, t: np.ndarray, half: int
) -> tuple[np.ndarray, np.ndarray]:
    """Generated markers (F, M, 3) blended over frames t - half .. t + half (those that
    exist) at the frames ``t``: their centroid (len(t), 3) and their shape about it
    (len(t), M, 3), what :meth:`DualHMM.frames_to_motion` places (``output="regression"``)."""
    mean = _window_mean(positions.reshape(len(positions), -1), t, half)
    mean = mean.reshape(len(t), *positions.shape[1:])
    root = mean.mean(axis=1)
    return root, mean - root[:, None]


def _window_mean(
    values: np.ndarray, t: np.ndarray, half: int, before: int | None = None
) -> np.ndarray:
    """(len(t), D) the mean of rows t - before .. t + half of ``values`` (F, D) (those that
    exist; ``before`` defaults to ``half``)."""
    before = half if before is None else before
    if len(t) == 1:  # online, one frame shown: its mean directly (cheaper than the cumsum)
        k = int(t[0])
        near = values[max(k - before, 0) : k + half + 1]
        return near.sum(axis=0, keepdims=True) / len(near)
    csum = np.vstack([np.zeros((1, values.shape[1])), np.cumsum(values, axis=0)])
    lo, hi = np.maximum(t - before, 0), np.minimum(t + half + 1, len(values))
    return (csum[hi] - csum[lo]) / (hi - lo)[:, None]


def smooth_place(
    origin: np.ndarray,
    yaw: np.ndarray,
    half: int,
    before: int | None = None,
    seen: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """A's ground frame (origin (F, 3), yaw (F,)) averaged over frames t - before .. t + half
    (those that exist; ``before`` defaults to ``half``): origins by their mean, headings by
    the direction of their mean unit vector. B is placed through it, so that A's heading,
    which wobbles from frame to frame with the hips, does not swing B around A (B stands a
    metre away: 3 degrees are 50 mm). A longer ``before`` (``DualHMM(place_memory=...)``)
    remembers where A has stood and faced: people who wave or shake hands turn their
    shoulders, not their feet.

    ``seen`` (F,) bool: only the frames where A was seen count (a missing frame's place is
    A's last one held, not where A was: with ``place_memory`` 300, 20 held frames of a wave
    had moved B by 30 mm to the end of the take); a frame with none seen around it keeps its
    own (held) place."""
    before = half if before is None else before
    if (half <= 0 and before <= 0) or len(yaw) < 2:
        return origin, yaw
    rows, t = place_rows(origin, yaw), np.arange(len(yaw))
    if seen is None or seen.all():
        return mean_place(_window_mean(rows, t, half, before))
    weight = np.asarray(seen, dtype=float)[:, None]
    total = _window_mean(weight, t, half, before)
    mean = _window_mean(rows * weight, t, half, before) / np.maximum(total, 1e-12)
    return mean_place(np.where(total > 0, mean, rows))


def successors(lengths: Sequence[int]) -> np.ndarray:
    """(T,) the training frame that follows each one in its recording (the last frame of a
    recording: itself), for training sequences of ``lengths``."""
    out = np.arange(int(np.sum(lengths))) + 1
    ends = np.cumsum(lengths) - 1
    out[ends] = ends
    return out


def build_trellis(
    train_a: np.ndarray,
    train_b: np.ndarray,
    train_states: np.ndarray,
    means_a: np.ndarray,
    prec_a: np.ndarray,
    prec_b: np.ndarray,
    size: int,
    motion_b: Motion,
    successor: np.ndarray | None = None,
    kind: str = "path",
) -> Trellis:
    """A :class:`Trellis` over training frames (A's and B's features, their states).

    A state with fewer than ``size`` training frames takes the ``size`` frames
    whose A features are nearest its mean (under its B_A), so every column
    holds the same number of candidates.
    """
    members, white = [], []
    for k in range(len(prec_a)):
        idx = np.flatnonzero(train_states == k)
        if len(idx) < size:  # a state no training frame decodes to: nearest frames
            d = np.linalg.norm((train_a - means_a[k]) @ prec_a[k], axis=1)
            idx = np.argsort(d)[:size]
        members.append(idx)
        white.append(train_a[idx] @ prec_a[k])
    if kind not in TRELLISES:
        raise ValueError(f"trellis must be one of {TRELLISES}, got {kind!r}")
    return Trellis(members, white, prec_a, prec_b, train_b, size, motion_b, successor, kind)


@numba.njit(cache=True)
def whitened_distances(white, x, prec):  # pragma: no cover - numba
    """(n,) ||white_i - x prec|| for rows ``white`` (n, D) already times ``prec`` (D, D):
    D4 of every training frame of a state (§3.2). Compiled: online it runs for each new
    column, where NumPy's calls on a few hundred rows cost more than the sums."""
    d = len(x)
    y = np.zeros(d)
    for a in range(d):
        for b in range(d):
            y[b] += x[a] * prec[a, b]
    out = np.empty(len(white))
    for i in range(len(white)):
        acc = 0.0
        for b in range(d):
            diff = white[i, b] - y[b]
            acc += diff * diff
        out[i] = np.sqrt(acc)
    return out


@numba.njit(cache=True)
def pair_distances(train, idx, prev, prec):  # pragma: no cover - numba
    """(K, K') ||train[idx_i] prec - train[prev_j] prec||: the Mahalanobis distances
    D1..DK' between two trellis columns (:meth:`Trellis.distances`), each row whitened once."""
    d = train.shape[1]
    white = np.zeros((len(idx) + len(prev), d))
    for r in range(len(idx) + len(prev)):
        row = idx[r] if r < len(idx) else prev[r - len(idx)]
        for a in range(d):
            v = train[row, a]
            for b in range(d):
                white[r, b] += v * prec[a, b]
    out = np.empty((len(idx), len(prev)))
    for i in range(len(idx)):
        for j in range(len(prev)):
            acc = 0.0
            for b in range(d):
                diff = white[i, b] - white[len(idx) + j, b]
                acc += diff * diff
            out[i, j] = np.sqrt(acc)
    return out


@numba.njit(cache=True)
def lowest_error_path(cost, d4, steps):  # pragma: no cover - numba
    """Entry per column (T,) on the lowest-error path through the trellis: E_t(i) =
    min_j E_{t-1}(j) + D_t(i, j) D4_t(i), from E_0 = ``cost`` (K,), ``d4`` (T - 1, K) and
    ``steps`` D_t (T - 1, K, K); ties go to the first entry, as with ``argmin``. Compiled:
    in NumPy each column cost several calls, most of an online step's trellis time."""
    n, k = len(d4) + 1, len(cost)
    back = np.zeros((n, k), dtype=np.int64)
    cost, new = cost.copy(), np.empty(k)
    for t in range(1, n):
        for i in range(k):
            best, arg = np.inf, 0
            for j in range(k):
                e = cost[j] + steps[t - 1, i, j] * d4[t - 1, i]
                if e < best:
                    best, arg = e, j
            new[i], back[t, i] = best, arg
        cost[:] = new
    path = np.empty(n, dtype=np.int64)
    path[-1] = np.argmin(cost)
    for t in range(n - 1, 0, -1):
        path[t - 1] = back[t, path[t]]
    return path


@numba.njit(cache=True)
def blend_quaternions(quats, frames, t, half):  # pragma: no cover - numba
    """(len(t), J, 4) for each t, the normalised sum of the quaternions ``quats[frames[k]]``
    (quats (N, J, 4)) for k = t - half .. t + half within ``frames``, each turned to the
    hemisphere of ``quats[frames[t]]``'s (:meth:`Trellis.blend`). Compiled: online it runs
    once per frame on one frame, where NumPy's calls cost more than the sums."""
    n_out, n_joints, n_frames = len(t), quats.shape[1], len(frames)
    out = np.zeros((n_out, n_joints, 4))
    for a in range(n_out):
        centre = frames[t[a]]
        for k in range(max(t[a] - half, 0), min(t[a] + half + 1, n_frames)):
            f = frames[k]
            for j in range(n_joints):
                dot = 0.0
                for x in range(4):
                    dot += quats[f, j, x] * quats[centre, j, x]
                sign = -1.0 if dot < 0.0 else 1.0
                for x in range(4):
                    out[a, j, x] += sign * quats[f, j, x]
        for j in range(n_joints):
            norm = np.sqrt((out[a, j] ** 2).sum())
            for x in range(4):
                out[a, j, x] /= norm
    return out
