"""Hidden semi-Markov models of labelled units with explicit Gaussian state durations (gait paper §5.1).

Each unit (a walk step) is a left-to-right model of ``n_states`` states
without skips; one diagonal Gaussian per state over the observation vector
(static + delta + delta-delta) and one Gaussian duration density per state,
discretised over 1..``max_duration`` frames (Yoshimura et al. 1998). A training
sequence is the concatenation of its units' models, so every state is
visited exactly once; EM runs the explicit-duration forward-backward over that
chain (:func:`forward_backward`, log space).

Units carry a context label (an integer); which states of which contexts
share their output and duration densities is decided by context clustering
(:mod:`markovmotion.models.gait.context_tree`), so that contexts never seen in
training still get densities. The recursions are pure functions; the model
class only gathers statistics and re-estimates.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass, fields

import numpy as np

from markovmotion.algorithms.gaussian import log_gaussian_diag
from markovmotion.algorithms.hsmm_recursions import check_chain, duration_log_pmf, forward_backward
from markovmotion.algorithms.parallel import map_sequences
from markovmotion.core.frames import check_frames
from markovmotion.models.base import Component
from markovmotion.models.gait.context_tree import cluster
from markovmotion.state import (
    StateError,
    check_count,
    check_index,
    check_positive,
    check_shape,
    is_fitted,
    register,
    require,
)

#: Default floor of the state duration variances, in frames squared: HTS's (0.01 x 10),
#: and the best floor common to average, adapted and from-scratch gait models by the
#: likelihood of step durations of other training takes (README, "Stylistic walks").
#: At 1 frame squared, five states add up to steps far more irregular than real ones.
DUR_VAR_FLOOR = 0.1


# ------------------------------------------------------------------ pure functions
def draw_durations(
    means: np.ndarray, variances: np.ndarray, max_duration: int, rng: np.random.Generator
) -> np.ndarray:
    """One duration per state (Q,) drawn from its discretised Gaussian (:func:`duration_log_pmf`)."""
    cdf = np.cumsum(np.exp(duration_log_pmf(means, variances, max_duration)), axis=1)
    u = rng.random(len(means)) * cdf[:, -1]
    return 1 + np.minimum((cdf < u[:, None]).sum(axis=1), max_duration - 1)


# ------------------------------------------------------------------ statistics
@dataclass
class ContextStats:
    """Sufficient statistics per (context, state): outputs and durations."""

    occ: np.ndarray  # (C, S) frames
    sum: np.ndarray  # (C, S, O)
    sumsq: np.ndarray  # (C, S, O)
    dur_occ: np.ndarray  # (C, S) state visits
    dur_sum: np.ndarray  # (C, S)
    dur_sumsq: np.ndarray  # (C, S)
    log_like: float = 0.0
    n_frames: int = 0

    @classmethod
    def zeros(cls, n_contexts: int, n_states: int, n_dims: int) -> ContextStats:
        z = np.zeros((n_contexts, n_states))
        return cls(
            z.copy(),
            np.zeros(z.shape + (n_dims,)),
            np.zeros(z.shape + (n_dims,)),
            z.copy(),
            z.copy(),
            z.copy(),
        )

    def add(
        self, contexts: np.ndarray, x: np.ndarray, gamma: np.ndarray, dur_post: np.ndarray
    ) -> None:
        """Add one sequence: gamma (T, N) and dur_post (N, Dmax) over its chain of N = units x S states."""
        s = self.occ.shape[1]
        g = gamma.reshape(len(x), len(contexts), s)
        np.add.at(self.occ, contexts, g.sum(axis=0))
        np.add.at(self.sum, contexts, np.einsum("tus,to->uso", g, x))
        np.add.at(self.sumsq, contexts, np.einsum("tus,to->uso", g, x**2))
        d = np.arange(1, dur_post.shape[1] + 1)
        p = dur_post.reshape(len(contexts), s, -1)
        np.add.at(self.dur_occ, contexts, p.sum(axis=2))
        np.add.at(self.dur_sum, contexts, p @ d)
        np.add.at(self.dur_sumsq, contexts, p @ d**2)
        self.n_frames += len(x)

    def merge(self, other: ContextStats) -> ContextStats:
        """Add the statistics of other sequences (a partial E-step); returns ``self``."""
        for f in fields(self):
            setattr(self, f.name, getattr(self, f.name) + getattr(other, f.name))
        return self


def hard_posteriors(
    n_frames: int, boundaries: np.ndarray, n_states: int, max_duration: int
) -> tuple[np.ndarray, np.ndarray]:
    """gamma and dur_post of a fixed alignment: each unit split evenly among its states."""
    n_units = len(boundaries) - 1
    gamma = np.zeros((n_frames, n_units * n_states))
    dur_post = np.zeros((n_units * n_states, max_duration))
    k = 0
    for u in range(n_units):
        for part in np.array_split(np.arange(boundaries[u], boundaries[u + 1]), n_states):
            gamma[part, k] = 1.0
            dur_post[k, min(max(len(part), 1), max_duration) - 1] = 1.0
            k += 1
    return gamma, dur_post


# ------------------------------------------------------------------ the model
@register
class HSMM(Component):
    """Context-dependent left-to-right HSMMs of units, trained by EM from unit boundaries.

    Args:
        n_states: states per unit (5 in the paper).
        n_iter: EM iterations after clustering (``n_iter_untied`` before it).
        tol: stop when the log-likelihood per frame gains less than this.
        var_floor: output variances are floored at this fraction of the
            data's variance per dimension.
        dur_var_floor: floor of the duration variances, in frames squared
            (> 0), for training and adaptation alike (:data:`DUR_VAR_FLOOR`).
        max_duration: longest state duration considered (frames); by default
            0.6 of the longest unit in the training data.
        mdl_factor: weight of the MDL penalty of context clustering (0 keeps
            every context that has data apart).
        n_jobs: parallel jobs of the E-step, over chunks of sequences
            (:mod:`markovmotion.algorithms.parallel`: None is one unless a
            joblib context says otherwise, -1 every core, Dask through joblib).

    Learnt: ``means_``/``variances_`` (P, O) output densities,
    ``dur_means_``/``dur_variances_`` (Q,) duration densities, ``out_map_``/
    ``dur_map_`` (C, S) the density of each state of each context.
    """

    def __init__(
        self,
        n_states: int = 5,
        n_iter: int = 10,
        n_iter_untied: int = 3,
        tol: float = 1e-4,
        var_floor: float = 0.01,
        dur_var_floor: float = DUR_VAR_FLOOR,
        max_duration: int | None = None,
        mdl_factor: float = 1.0,
        n_jobs: int | None = None,
    ):
        self.n_states = n_states
        self.n_iter = n_iter
        self.n_iter_untied = n_iter_untied
        self.tol = tol
        self.var_floor = var_floor
        self.dur_var_floor = dur_var_floor
        self.max_duration = max_duration
        self.mdl_factor = mdl_factor
        self.n_jobs = n_jobs

    # -------------------------------------------------------------- training
    def fit(
        self,
        sequences: Sequence[np.ndarray],
        contexts: Sequence[np.ndarray],
        boundaries: Sequence[np.ndarray],
        n_contexts: int,
        questions: Sequence[np.ndarray] = (),
    ) -> HSMM:
        """EM from unit boundaries (used only to initialise, §5.1.2).

        Args:
            sequences: (T_i, O) observations.
            contexts: (n_i,) context label of each unit of each sequence.
            boundaries: (n_i + 1,) first frame of each unit, then T_i.
            n_contexts: number of possible context labels C.
            questions: boolean masks (C,) of context sets for clustering.
        """
        if self.dur_var_floor <= 0:
            raise ValueError("dur_var_floor must be positive")
        sequences = [check_frames(x, f"sequence {i}") for i, x in enumerate(sequences)]
        x_all = np.vstack(sequences)
        self.n_features_in_ = x_all.shape[1]
        self.var_floor_ = np.maximum(self.var_floor * x_all.var(axis=0), 1e-8)
        lengths = np.concatenate([np.diff(b) for b in boundaries])
        longest = int(np.ceil(0.6 * lengths.max()))
        self.max_duration_ = int(self.max_duration or max(longest, 2 * self.n_states))
        s = self.n_states
        stats = ContextStats.zeros(n_contexts, s, x_all.shape[1])
        for x, c, b in zip(sequences, contexts, boundaries, strict=True):
            stats.add(np.asarray(c), x, *hard_posteriors(len(x), b, s, self.max_duration_))
        # untied: every seen (context, state) its own density, then EM
        seen = stats.occ.sum(axis=1) > 0
        ids = np.cumsum(seen) - 1
        untied = np.where(seen[:, None], ids[:, None] * s + np.arange(s), 0)
        self.out_map_ = self.dur_map_ = untied
        self._m_step(stats)
        self.log_likelihood_ = []
        for _ in range(self.n_iter_untied):
            stats = self._e_step(sequences, contexts)
            self.log_likelihood_.append(stats.log_like / stats.n_frames)
            self._m_step(stats)
        self.out_map_ = cluster(
            stats.occ, stats.sum, stats.sumsq, questions, self.var_floor_, self.mdl_factor
        )
        self.dur_map_ = cluster(
            stats.dur_occ,
            stats.dur_sum[..., None],
            stats.dur_sumsq[..., None],
            questions,
            np.array([self.dur_var_floor]),
            self.mdl_factor,
        )
        self._m_step(stats)
        self.em(sequences, contexts)
        return self

    def em(self, sequences: Sequence[np.ndarray], contexts: Sequence[np.ndarray]) -> HSMM:
        """Up to ``n_iter`` EM iterations with the current tying; appends to ``log_likelihood_``."""
        history = list(getattr(self, "log_likelihood_", []))
        start = len(history)
        for _ in range(self.n_iter):
            stats = self._e_step(sequences, contexts)
            if stats.n_frames == 0:
                raise ValueError("no training sequence can be aligned with the model")
            history.append(stats.log_like / stats.n_frames)
            if len(history) > start + 1 and abs(history[-1] - history[-2]) < self.tol:
                break
            self._m_step(stats)
        self.log_likelihood_ = np.array(history)
        return self

    def _e_step(
        self, sequences: Sequence[np.ndarray], contexts: Sequence[np.ndarray]
    ) -> ContextStats:
        """Statistics of all sequences, gathered over chunks of them (``n_jobs``)."""
        return map_sequences(
            self._e_step_chunk,
            lambda parts: functools.reduce(ContextStats.merge, parts),
            [len(x) for x in sequences],
            lambda i, j: (sequences[i:j], contexts[i:j]),
            self.n_jobs,
        )

    def _e_step_chunk(
        self, sequences: Sequence[np.ndarray], contexts: Sequence[np.ndarray]
    ) -> ContextStats:
        """Statistics of the sequences that the chain of their contexts can produce."""
        stats = ContextStats.zeros(self.out_map_.shape[0], self.n_states, sequences[0].shape[1])
        for x, c in zip(sequences, contexts, strict=True):
            ll, gamma, dur_post = self.posteriors(x, np.asarray(c))
            if np.isfinite(ll):
                stats.log_like += ll
                stats.add(np.asarray(c), x, gamma, dur_post)
        return stats

    def _m_step(self, stats: ContextStats) -> None:
        occ, mean, var = _pool(stats.occ, stats.sum, stats.sumsq, self.out_map_)
        self.means_ = mean
        self.variances_ = np.maximum(var, self.var_floor_)
        occ, mean, var = _pool(
            stats.dur_occ, stats.dur_sum[..., None], stats.dur_sumsq[..., None], self.dur_map_
        )
        self.dur_means_ = np.maximum(mean[:, 0], 1.0)
        self.dur_variances_ = np.maximum(var[:, 0], self.dur_var_floor)

    # -------------------------------------------------------------- inference
    def check_state(self) -> None:
        """P output densities of O dims with positive variances (and floor), Q duration
        densities with positive means and variances, each context's n_states states
        mapped to densities in range."""
        if not is_fitted(self):
            return
        require(self, "means_", "variances_", "var_floor_", "dur_means_", "dur_variances_")
        require(self, "out_map_", "dur_map_", "max_duration_")
        p, o = check_shape("means_", self.means_, (None, None)).shape
        check_positive("variances_", check_shape("variances_", self.variances_, (p, o)))
        check_positive("var_floor_", check_shape("var_floor_", self.var_floor_, (o,)))
        q = len(check_positive("dur_means_", check_shape("dur_means_", self.dur_means_, (None,))))
        check_positive("dur_variances_", check_shape("dur_variances_", self.dur_variances_, (q,)))
        c = len(check_shape("out_map_", self.out_map_, (None, self.n_states)))
        check_index("out_map_", self.out_map_, p)
        check_index("dur_map_", check_shape("dur_map_", self.dur_map_, (c, self.n_states)), q)
        check_count("max_duration_", self.max_duration_)
        if p < 1 or q < 1:
            raise StateError("means_: no output or duration densities")

    def chain(self, contexts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Output and duration density indices of the chain of units with these contexts."""
        return self.out_map_[contexts].ravel(), self.dur_map_[contexts].ravel()

    def posteriors(
        self, x: np.ndarray, contexts: np.ndarray, log_out: np.ndarray | None = None
    ) -> tuple[float, np.ndarray, np.ndarray]:
        """log P(x), state occupancies and duration posteriors of one sequence (:func:`forward_backward`).

        ``log_out`` (T, P) replaces the output log densities of the frames
        (adaptation scores them through feature transforms).
        """
        out, dur = self.chain(contexts)
        check_chain(len(x), len(out))  # before (T, N) output densities are gathered
        if log_out is None:
            log_out = log_gaussian_diag(x, self.means_, self.variances_)
        log_d = duration_log_pmf(self.dur_means_, self.dur_variances_, self.max_duration_)[dur]
        return forward_backward(log_out[:, out], log_d)

    def score(self, sequences: Sequence[np.ndarray], contexts: Sequence[np.ndarray]) -> float:
        """Total log-likelihood of the sequences."""
        return float(
            sum(
                self.posteriors(x, np.asarray(c))[0]
                for x, c in zip(sequences, contexts, strict=True)
            )
        )

    # -------------------------------------------------------------- generation
    def durations(
        self, contexts: np.ndarray, speed: float = 1.0, rng: np.random.Generator | None = None
    ) -> np.ndarray:
        """State durations (units x S,) in frames for a chain, at ``speed`` x the mean pace.

        The most likely durations for a total of ``sum(m) / speed`` frames
        (Yoshimura et al.): ``d = m + rho sigma^2`` with one rho for the chain,
        rounded so that every partial sum is the rounded partial sum of the
        real-valued d (rounding each state alone drifts: five states of 3.3
        frames make 15-frame steps, not 16.5), at least one frame. With
        ``rng``, each duration is drawn
        instead from its density with the mean moved to ``m + rho sigma^2``
        (at ``speed`` 1, the model's own densities).
        """
        _, dur = self.chain(contexts)
        m, v = self.dur_means_[dur], self.dur_variances_[dur]
        rho = (m.sum() / speed - m.sum()) / v.sum()
        if rng is None:
            ends = np.rint(np.cumsum(m + rho * v))
            return np.maximum(np.diff(ends, prepend=0.0), 1).astype(int)
        return draw_durations(m + rho * v, v, self.max_duration_, rng)

    def frame_parameters(
        self, contexts: np.ndarray, durations: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Per-frame means and variances (T, O) of the chain held for the given state durations."""
        out, _ = self.chain(contexts)
        idx = np.repeat(out, durations)
        return self.means_[idx], self.variances_[idx]

    def sample(
        self, contexts: np.ndarray, rng: np.random.Generator
    ) -> tuple[np.ndarray, np.ndarray]:
        """Observations (T, O) and state durations drawn from the chain of these contexts."""
        out, dur = self.chain(contexts)
        d = draw_durations(self.dur_means_[dur], self.dur_variances_[dur], self.max_duration_, rng)
        idx = np.repeat(out, d)
        x = self.means_[idx] + np.sqrt(self.variances_[idx]) * rng.standard_normal(
            (len(idx), self.means_.shape[1])
        )
        return x, d


def _pool(
    occ: np.ndarray, sums: np.ndarray, sumsq: np.ndarray, mapping: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Occupancy, mean and variance of each density from (C, S) statistics tied by ``mapping``."""
    n_pdf = int(mapping.max()) + 1
    o = np.bincount(mapping.ravel(), occ.ravel(), minlength=n_pdf)
    dims = sums.shape[-1]
    s1 = np.zeros((n_pdf, dims))
    s2 = np.zeros((n_pdf, dims))
    np.add.at(s1, mapping.ravel(), sums.reshape(-1, dims))
    np.add.at(s2, mapping.ravel(), sumsq.reshape(-1, dims))
    safe = np.maximum(o, 1e-10)[:, None]
    mean = s1 / safe
    return o, mean, s2 / safe - mean**2
