"""Behaviour model and Markov chain over behaviour prototypes (interaction paper, §3-4).

State vectors F = [C, lambda dC] are quantised into state prototypes A (eq. 8);
each training vector's proximity to every state prototype (eq. 9) feeds a
conditional decay operator (eq. 10) whose output, the behaviour vector G, keeps
a fading trace of the behaviour so far; behaviour prototypes B quantise the
behaviour vectors (eq. 12). A Markov chain has one state per behaviour
prototype plus an end state (eq. 13); traversing it visits state prototypes,
joined by cubic Hermite segments whose durations come from the mean speed
(eq. 15) and sampled at the frame rate (eq. 16).

Extrapolations and the hypotheses of :mod:`markovmotion.models.chain.condensation`
share one vectorised representation, :class:`Hypotheses`: each is a Hermite
segment from a start vector towards the state prototype of a chain state, with
the time elapsed on it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from markovmotion.algorithms.hermite import constant_acceleration_intervals, hermite_sample
from markovmotion.algorithms.vector_quantisation import (
    collapse_repeats,
    competitive_learning,
    nearest_prototype,
)
from markovmotion.core.frames import check_frames
from markovmotion.models.base import Component
from markovmotion.state import (
    StateError,
    check_distribution_rows,
    check_index,
    check_positive,
    check_shape,
    is_fitted,
    register,
    require,
)


def proximities(x: np.ndarray, prototypes: np.ndarray) -> np.ndarray:
    """p_ij of eq. (9): 1 at zero distance, falling linearly to 0 at the unit hypercube's diagonal.

    ``x`` (F, D) state vectors, ``prototypes`` (U, D); returns (F, U).
    """
    x = np.asarray(x, dtype=float)
    d2 = (x**2).sum(1)[:, None] - 2 * x @ prototypes.T + (prototypes**2).sum(1)[None]
    dist = np.sqrt(np.maximum(d2, 0.0))
    return np.clip(1.0 - dist / np.sqrt(x.shape[1]), 0.0, 1.0)


def decay_behaviour(p: np.ndarray, gamma: float = 0.995) -> np.ndarray:
    """Behaviour vectors by the conditional decay operator of eq. (10).

    z_j(0) = 0 and z_j(t) = p_tj if p_tj > gamma z_j(t-1), else gamma z_j(t-1):
    each component holds the closest recent proximity to its prototype,
    fading by ``gamma`` per frame. ``p`` (F, U) -> G (F, U).
    """
    p = np.asarray(p, dtype=float)
    g = np.empty_like(p)
    z = np.zeros(p.shape[1])
    for t in range(len(p)):
        z = np.maximum(p[t], gamma * z)
        g[t] = z
    return g


@dataclass
class Hypotheses:
    """N interaction hypotheses H = (F, f) (§5), each on a Hermite segment of the chain.

    Attributes:
        start: (N, D) state vector where the current segment began.
        state: (N,) chain state whose prototype the segment heads for (the end
            state: the hypothesis has stopped at ``start``).
        elapsed: (N,) frames since the segment began.
        interval: (N,) the segment's duration in frames (eq. 15).
    """

    start: np.ndarray
    state: np.ndarray
    elapsed: np.ndarray
    interval: np.ndarray

    def __len__(self) -> int:
        return len(self.state)

    def take(self, index: np.ndarray) -> Hypotheses:
        """The hypotheses at ``index`` (copies; an index may repeat)."""
        return Hypotheses(
            self.start[index].copy(),
            self.state[index].copy(),
            self.elapsed[index].copy(),
            self.interval[index].copy(),
        )

    def put(self, index: np.ndarray, other: Hypotheses) -> None:
        """Replace the hypotheses at ``index`` by ``other`` (same length), in place."""
        self.start[index] = other.start
        self.state[index] = other.state
        self.elapsed[index] = other.elapsed
        self.interval[index] = other.interval

    @staticmethod
    def concatenate(parts: Sequence[Hypotheses]) -> Hypotheses:
        return Hypotheses(
            np.concatenate([p.start for p in parts]),
            np.concatenate([p.state for p in parts]),
            np.concatenate([p.elapsed for p in parts]),
            np.concatenate([p.interval for p in parts]),
        )


@register
class BehaviourChain(Component):
    """State prototypes, behaviour prototypes and the Markov chain over them (§3-4).

    Args:
        n_state_prototypes: u, the number of state prototypes (paper: 300).
        n_behaviour_prototypes: v, the number of behaviour prototypes (paper: 300).
        gamma: decay constant of eq. (10) (paper: 0.995).
        lam: the lambda that scaled the derivative half of the state vectors
            (per-frame speeds are that half divided by ``lam``).
        n_epochs: passes of each robust competitive learning over its data
            (the paper ran 10^6 presentations).
        min_interval, max_interval: bounds on segment durations in frames;
            eq. (15) gives zero between equal prototypes and infinity between
            static ones.
        interval_noise: (a, b): stochastic extrapolations add uniform noise on
            [-a T, b T] to each interval T (§5.2, biased toward shorter; the
            paper's values are lost from its text).
        calibrate_intervals: scale eq. (15) by the median ratio of observed
            to predicted intervals between successive chain states in the
            training data (our addition: the prototypes' averaged speeds make
            eq. (15) overestimate intervals, §5.2); else by 1.
        random_state: seed of the quantisations.

    Learnt: ``state_prototypes_`` (u, D), ``behaviour_prototypes_`` (v, u),
    ``chain_prototype_`` (v,) the state prototype of each chain state (the
    largest component of its behaviour prototype, §4), ``transmat_``
    (v+1, v+1) with the end state last and absorbing, ``startprob_`` (v+1,)
    and ``occupancy_`` (v+1,) how often training frames sit in each chain state,
    ``interval_scale_`` the factor applied to eq. (15).
    """

    def __init__(
        self,
        n_state_prototypes: int = 300,
        n_behaviour_prototypes: int = 300,
        gamma: float = 0.995,
        lam: float = 10.0,
        n_epochs: int = 5,
        min_interval: float = 0.5,
        max_interval: float = 50.0,
        interval_noise: tuple[float, float] = (0.5, 0.25),
        calibrate_intervals: bool = True,
        random_state: int = 0,
    ):
        self.n_state_prototypes = n_state_prototypes
        self.n_behaviour_prototypes = n_behaviour_prototypes
        self.gamma = gamma
        self.lam = lam
        self.n_epochs = n_epochs
        self.min_interval = min_interval
        self.max_interval = max_interval
        self.interval_noise = interval_noise
        self.calibrate_intervals = calibrate_intervals
        self.random_state = random_state

    # ---------------------------------------------------------------- learning
    def fit(self, sequences: Sequence[np.ndarray]) -> BehaviourChain:
        """Learn both sets of prototypes and the chain from state-vector sequences (F_i, D)."""
        seqs = [check_frames(s, f"sequence {i}") for i, s in enumerate(sequences)]
        widths = {s.shape[1] for s in seqs}
        if len(widths) != 1:
            raise ValueError(
                f"state-vector sequences of one width needed, got widths {sorted(widths)}"
            )
        self.n_features_in_ = seqs[0].shape[1]
        self.state_prototypes_ = competitive_learning(
            np.vstack(seqs), self.n_state_prototypes, self.n_epochs, seed=self.random_state
        )
        behaviours = [self.behaviour_vectors(s) for s in seqs]
        self.behaviour_prototypes_ = competitive_learning(
            np.vstack(behaviours),
            self.n_behaviour_prototypes,
            self.n_epochs,
            seed=self.random_state,
        )
        self.chain_prototype_ = self.behaviour_prototypes_.argmax(axis=1)
        self.fit_chain([nearest_prototype(g, self.behaviour_prototypes_) for g in behaviours])
        return self

    def fit_chain(self, labels: Sequence[np.ndarray]) -> BehaviourChain:
        """Transition, start and occupancy probabilities from chain-state sequences (§4).

        Only changes of state count as transitions; each sequence's last state
        moves to the end state, which is absorbing. A state never left in the
        data moves to the end state.
        """
        v = len(self.behaviour_prototypes_)
        counts = np.zeros((v + 1, v + 1))
        start = np.zeros(v + 1)
        occupancy = np.zeros(v + 1)
        ratios = []
        self.interval_scale_ = 1.0
        for lab in labels:
            if not len(lab):
                continue
            np.add.at(occupancy, lab, 1.0)
            runs, starts = collapse_repeats(lab)
            start[runs[0]] += 1
            np.add.at(counts, (runs[:-1], runs[1:]), 1.0)
            counts[runs[-1], v] += 1
            if len(runs) > 1:
                proto = self.state_vectors(runs)
                ratios.append(np.diff(starts) / self.intervals(proto[:-1], proto[1:]))
        if self.calibrate_intervals and ratios:
            self.interval_scale_ = float(np.median(np.concatenate(ratios)))
        counts[counts.sum(axis=1) == 0, v] = 1.0
        self.transmat_ = counts / counts.sum(axis=1, keepdims=True)
        self.startprob_ = start / start.sum()
        self.occupancy_ = occupancy / occupancy.sum()
        return self

    # -------------------------------------------------------------- recognition
    def check_state(self) -> None:
        """u state prototypes of an even width D, v behaviour prototypes over them, each
        chain state's prototype in [0, u), transition rows, start and occupancy
        distributions over the v + 1 chain states, a positive interval scale."""
        if not is_fitted(self):
            return
        require(self, "state_prototypes_", "behaviour_prototypes_", "chain_prototype_")
        require(self, "transmat_", "startprob_", "occupancy_", "interval_scale_")
        u, d = check_shape("state_prototypes_", self.state_prototypes_, (None, None)).shape
        if d % 2 or u < 1:
            raise StateError(f"state_prototypes_: shape {(u, d)}, expected (u >= 1, an even D)")
        v = len(check_shape("behaviour_prototypes_", self.behaviour_prototypes_, (None, u)))
        check_index(
            "chain_prototype_", check_shape("chain_prototype_", self.chain_prototype_, (v,)), u
        )
        check_distribution_rows(
            "transmat_", check_shape("transmat_", self.transmat_, (v + 1, v + 1))
        )
        for name in ("startprob_", "occupancy_"):
            check_distribution_rows(name, check_shape(name, getattr(self, name), (v + 1,)))
        check_positive("interval_scale_", self.interval_scale_)

    @property
    def end_state(self) -> int:
        return len(self.behaviour_prototypes_)

    @property
    def dim(self) -> int:
        """Number of shape components d of F = [C, lambda dC] (half of F)."""
        return self.state_prototypes_.shape[1] // 2

    def behaviour_vectors(self, f: np.ndarray) -> np.ndarray:
        """(F, D) state vectors -> (F, u) behaviour vectors (eqs. 9-11)."""
        return decay_behaviour(proximities(f, self.state_prototypes_), self.gamma)

    def recognise(self, f: np.ndarray) -> np.ndarray:
        """Chain state (closest behaviour prototype) at every frame of ``f`` (§4)."""
        return nearest_prototype(self.behaviour_vectors(f), self.behaviour_prototypes_)

    def state_vectors(self, states: np.ndarray) -> np.ndarray:
        """The state prototypes a(e) of chain states (not the end state)."""
        return self.state_prototypes_[self.chain_prototype_[states]]

    # ------------------------------------------------------------ extrapolation
    def successors(self, state: int) -> np.ndarray:
        """Successor chain states of ``state`` with positive probability."""
        return np.flatnonzero(self.transmat_[state] > 0)

    def choose_successors(self, states: np.ndarray, rng: np.random.Generator | None) -> np.ndarray:
        """A successor of each state: sampled with ``rng``, else the most probable (§4)."""
        if rng is None:
            return self.transmat_[states].argmax(axis=1)
        cum = np.cumsum(self.transmat_[states], axis=1)
        u = rng.random(len(states))[:, None] * cum[:, -1:]
        return np.minimum((cum <= u).sum(axis=1), self.end_state)

    def intervals(
        self, f0: np.ndarray, f1: np.ndarray, rng: np.random.Generator | None = None
    ) -> np.ndarray:
        """Segment durations in frames between state vectors (N, D) (eq. 15), noisy with ``rng``."""
        d = self.dim
        knots = np.stack([f0, f1], axis=-2)
        raw = constant_acceleration_intervals(knots[..., :d], knots[..., d:] / self.lam, 0.0)
        t = np.clip(self.interval_scale_ * raw[..., 0], self.min_interval, self.max_interval)
        if rng is not None:
            a, b = self.interval_noise
            t = np.maximum(t * (1.0 + rng.uniform(-a, b, np.shape(t))), self.min_interval)
        return t

    def at(self, f: np.ndarray, states: np.ndarray) -> Hypotheses:
        """Hypotheses sitting at chain states ``states`` with state vectors ``f`` (N, D)."""
        f = np.atleast_2d(np.asarray(f, dtype=float))
        n = len(f)
        states = np.broadcast_to(np.asarray(states), (n,)).copy()
        return Hypotheses(f.copy(), states, np.zeros(n), np.zeros(n))

    def begin(
        self, f: np.ndarray, states: np.ndarray, rng: np.random.Generator | None = None
    ) -> Hypotheses:
        """Hypotheses at chain states ``states`` that set off from state vectors ``f``.

        Each starts a segment from its ``f`` (the current state replacing the
        first prototype, §4) towards a successor of its state.
        """
        h = self.at(f, states)
        self._enter(h, np.arange(len(h)), self.choose_successors(h.state, rng), rng)
        return h

    def _enter(
        self, h: Hypotheses, idx: np.ndarray, nxt: np.ndarray, rng: np.random.Generator | None
    ) -> None:
        """Hypotheses ``idx``, at the end of their segment, head for chain states ``nxt``.

        A segment starts at the prototype just reached (or, for a hypothesis
        sitting at a state, at its own vector); one entering the end state
        stops there, still.
        """
        sitting = h.interval[idx] <= 0
        start = h.start[idx].copy()
        reached = ~sitting & (h.state[idx] != self.end_state)
        start[reached] = self.state_vectors(h.state[idx][reached])
        moving = nxt != self.end_state
        interval = np.ones(len(idx))
        if moving.any():
            interval[moving] = self.intervals(start[moving], self.state_vectors(nxt[moving]), rng)
        start[~moving, self.dim :] = 0.0
        h.start[idx] = start
        h.state[idx] = nxt
        h.interval[idx] = interval

    def current(self, h: Hypotheses) -> np.ndarray:
        """(N, d) combined shape vectors C of the hypotheses on their Hermite segments.

        Hypotheses sitting at a state or stopped at the end state are at
        their start vector.
        """
        d = self.dim
        out = h.start[:, :d].copy()
        moving = (h.state != self.end_state) & (h.interval > 0)
        if moving.any():
            s = h.start[moving]
            e = self.state_vectors(h.state[moving])
            knots = np.stack([s, e], axis=1)
            times = np.column_stack([np.zeros(len(s)), h.interval[moving]])
            out[moving] = hermite_sample(
                knots[..., :d], knots[..., d:] / self.lam, times, h.elapsed[moving, None]
            )[:, 0]
        return out

    def advance(self, h: Hypotheses, rng: np.random.Generator | None = None) -> Hypotheses:
        """All hypotheses one frame on (in place, returned): stochastic with ``rng``, else ML."""
        h.elapsed = h.elapsed + 1.0
        self._settle(h, rng)
        return h

    def _settle(self, h: Hypotheses, rng: np.random.Generator | None) -> None:
        """Pass every segment end that the elapsed time has reached (several per frame if short)."""
        while True:
            idx = np.flatnonzero((h.elapsed >= h.interval) & (h.state != self.end_state))
            if not len(idx):
                return
            leftover = h.elapsed[idx] - np.maximum(h.interval[idx], 0.0)
            self._enter(h, idx, self.choose_successors(h.state[idx], rng), rng)
            h.elapsed[idx] = np.where(h.state[idx] != self.end_state, leftover, 0.0)

    def branch(self, h: Hypotheses) -> Hypotheses:
        """Every potential hypothesis one frame after ``h`` (§5.1, step 3).

        A hypothesis inside its segment has one continuation; one reaching a
        decision point has one per successor with positive probability (later
        segment ends within the same frame follow the most probable successor).
        """
        h = h.take(np.arange(len(h)))
        h.elapsed = h.elapsed + 1.0
        crossing = (h.elapsed >= h.interval) & (h.state != self.end_state)
        parts = [h.take(np.flatnonzero(~crossing))]
        for i in np.flatnonzero(crossing):
            nxt = self.successors(h.state[i])
            b = h.take(np.full(len(nxt), i))
            leftover = b.elapsed - np.maximum(b.interval, 0.0)
            self._enter(b, np.arange(len(nxt)), nxt, None)
            b.elapsed = np.where(b.state != self.end_state, leftover, 0.0)
            parts.append(b)
        out = Hypotheses.concatenate(parts)
        self._settle(out, None)
        return out

    def extrapolate(
        self,
        f: np.ndarray,
        state: int,
        max_frames: int = 10_000,
        rng: np.random.Generator | None = None,
    ) -> np.ndarray:
        """State vectors at the frame rate from ``f`` in chain state ``state`` until the end (eq. 16).

        Successors are sampled with ``rng`` (intervals then noisy, §5.2), else
        the most probable are taken. Returns (T, D) with ``f`` first and
        derivatives as frame differences (eq. 5); from the end state nothing
        follows, so only ``f`` is returned.
        """
        f = np.asarray(f, dtype=float)
        shapes = [f[: self.dim]]
        if state != self.end_state:
            h = self.begin(f, [state], rng)
            while h.state[0] != self.end_state and len(shapes) < max_frames:
                self.advance(h, rng)
                shapes.append(self.current(h)[0])
        c = np.array(shapes)
        dc = np.diff(c, axis=0, prepend=c[:1])
        dc[0] = f[self.dim :] / self.lam
        return np.hstack([c, self.lam * dc])
