"""Hidden Markov models with full-covariance Gaussian emissions (Rabiner 1989).

The shape is hmmlearn's: one small base class (:class:`BaseHMM`) owns the
initial distribution pi, the transition matrix T and everything built on
them -- Baum-Welch EM, scoring, Viterbi decoding, sampling -- and a variant
supplies its emission model in four methods. Several sequences are one
concatenated array ``X`` (frames, dims) plus ``lengths``. The recursions are
the pure functions of :mod:`markovmotion.algorithms.hmm_recursions` (log
space, no underflow on long sequences). Learnt attributes end in ``_``; the
log-likelihood of every EM iteration is kept in ``history_``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from sklearn.base import BaseEstimator
from sklearn.cluster import KMeans
from sklearn.utils import check_random_state

from markovmotion.algorithms.gaussian import (
    floor_covariances,
    gaussian_log_density,
    precision_cholesky,
    weighted_gaussians,
)
from markovmotion.algorithms.hmm_recursions import forward_backward, viterbi
from markovmotion.algorithms.parallel import map_sequences
from markovmotion.state import (
    StateError,
    check_count,
    check_distribution_rows,
    check_shape,
    register,
    require,
)


# ------------------------------------------------------------------ EM bookkeeping
class ConvergenceMonitor:
    """Log-likelihood history of EM; converged once an iteration gains less than ``tol``."""

    def __init__(self, tol: float):
        self.tol = tol
        self.history: list[float] = []

    def report(self, log_likelihood: float) -> None:
        self.history.append(float(log_likelihood))

    @property
    def converged(self) -> bool:
        h = self.history
        return len(h) >= 2 and h[-1] - h[-2] < self.tol


def check_sequences(
    x: np.ndarray, lengths: Sequence[int] | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """``X`` as a finite float (T, D) array and ``lengths`` as positive ints summing to T."""
    x = np.asarray(x, dtype=float)
    if x.ndim != 2 or len(x) == 0:
        raise ValueError(f"X must be a non-empty (frames, dims) array, got shape {x.shape}")
    if not np.isfinite(x).all():
        raise ValueError("X holds NaN or infinite values")
    lengths = np.array([len(x)] if lengths is None else lengths, dtype=int)
    if lengths.sum() != len(x) or np.any(lengths < 1):
        raise ValueError(f"lengths {lengths.tolist()} do not split {len(x)} frames")
    return x, lengths


def _bounds(lengths: np.ndarray) -> list[tuple[int, int]]:
    ends = np.cumsum(lengths)
    return list(zip(ends - lengths, ends, strict=True))


def safe_log(p: np.ndarray) -> np.ndarray:
    """log p with log 0 = -inf and no warning."""
    with np.errstate(divide="ignore"):
        return np.log(p)


# ------------------------------------------------------------------ models
class BaseHMM(BaseEstimator):
    """pi, T and the algorithms on them; a variant supplies the emission model.

    Args:
        n_components: number of hidden states N.
        n_iter: most EM iterations.
        tol: stop when an iteration gains less log-likelihood than this.
        init_params: which parameters ``fit`` initialises (``s`` pi, ``t`` T,
            and the variant's letters); the others are used as already set.
        random_state: seed for the initialisation and sampling.
        n_jobs: parallel jobs of the E-step, over chunks of sequences
            (:mod:`markovmotion.algorithms.parallel`: None is one unless a
            joblib context says otherwise, -1 every core, Dask through joblib).

    Variants implement ``_init_emissions(X, rng) -> labels | None``,
    ``_log_frameprob(X) -> (T, N)``, ``_m_step_emissions(X, gamma)`` and
    ``_sample_emission(state, rng)``.
    """

    def __init__(
        self,
        n_components: int = 8,
        n_iter: int = 50,
        tol: float = 1e-3,
        init_params: str = "stmc",
        random_state: int | None = 0,
        n_jobs: int | None = None,
    ):
        self.n_components = n_components
        self.n_iter = n_iter
        self.tol = tol
        self.init_params = init_params
        self.random_state = random_state
        self.n_jobs = n_jobs

    # ---------------------------------------------------------------- fitting
    def fit(self, x: np.ndarray, lengths: Sequence[int] | None = None) -> BaseHMM:
        """Baum-Welch EM (Rabiner eqs. 40a-c) from a k-means start; returns ``self``."""
        x, lengths = check_sequences(x, lengths)
        if len(x) < self.n_components:
            raise ValueError(f"{len(x)} frames cannot train {self.n_components} states")
        rng = check_random_state(self.random_state)
        labels = self._init_emissions(x, rng)
        self._init_chain(labels, lengths)
        monitor = ConvergenceMonitor(self.tol)
        for _ in range(self.n_iter):
            ll, gamma, starts, counts = self._e_step(x, lengths)
            self.startprob_ = starts / starts.sum()
            self.transmat_ = _normalise_rows(counts, self.transmat_)
            self._m_step_emissions(x, gamma)
            monitor.report(ll)
            if monitor.converged:
                break
        self.history_ = np.array(monitor.history)
        self.n_iter_ = len(monitor.history)
        self.converged_ = monitor.converged
        return self

    def _init_chain(self, labels: np.ndarray | None, lengths: np.ndarray) -> None:
        """pi and T from the k-means labels' first frames and transitions (+1 each), or uniform."""
        n = self.n_components
        starts = np.ones(n)
        counts = np.ones((n, n))
        if labels is not None:
            for s, e in _bounds(lengths):
                starts[labels[s]] += 1
                np.add.at(counts, (labels[s : e - 1], labels[s + 1 : e]), 1)
        if "s" in self.init_params:
            self.startprob_ = starts / starts.sum()
        if "t" in self.init_params:
            self.transmat_ = counts / counts.sum(axis=1, keepdims=True)

    def _e_step(self, x: np.ndarray, lengths: np.ndarray):
        """(log P(X), gamma (T, N), expected first states (N,), transition counts (N, N))."""
        ends = np.cumsum(lengths)

        def take(i: int, j: int) -> tuple[np.ndarray, np.ndarray]:
            return x[ends[i] - lengths[i] : ends[j - 1]], lengths[i:j]

        return map_sequences(self._e_step_chunk, _add_e_steps, lengths, take, self.n_jobs)

    def _e_step_chunk(self, x: np.ndarray, lengths: np.ndarray):
        """:meth:`_e_step` of whole sequences: forward-backward of each (Rabiner eqs. 27, 37-38)."""
        log_b = self._log_frameprob(x)
        log_pi, trans = safe_log(self.startprob_), self.transmat_
        gamma = np.empty_like(log_b)
        starts = np.zeros(self.n_components)
        counts = np.zeros((self.n_components, self.n_components))
        total = 0.0
        for s, e in _bounds(lengths):
            ll, gamma[s:e], xi = forward_backward(log_pi, trans, log_b[s:e])
            total += ll
            starts += gamma[s]
            counts += xi
        return total, gamma, starts, counts

    # ---------------------------------------------------------------- inference
    def _check_input(
        self, x: np.ndarray, lengths: Sequence[int] | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """:func:`check_sequences`, and ``X`` as wide as the model's observations (the
        compiled densities do not check: wider input read past their arrays)."""
        x, lengths = check_sequences(x, lengths)
        width = self._n_features()
        if width is not None and x.shape[1] != width:
            raise ValueError(
                f"X has {x.shape[1]} columns but {type(self).__name__} was fitted on "
                f"{width} features"
            )
        return x, lengths

    def _n_features(self) -> int | None:
        """Width of the observations the emission model holds (None: not known yet)."""
        return None

    def log_frameprob(self, x: np.ndarray) -> np.ndarray:
        """(T, N) log b_j(o_t) of every frame under every state's emission density."""
        return self._log_frameprob(self._check_input(x)[0])

    def score(self, x: np.ndarray, lengths: Sequence[int] | None = None) -> float:
        """log P(X | model), summed over the sequences."""
        x, lengths = self._check_input(x, lengths)
        return self._e_step(x, lengths)[0]

    def predict_proba(self, x: np.ndarray, lengths: Sequence[int] | None = None) -> np.ndarray:
        """State posteriors gamma (T, N)."""
        x, lengths = self._check_input(x, lengths)
        return self._e_step(x, lengths)[1]

    def decode(
        self, x: np.ndarray, lengths: Sequence[int] | None = None
    ) -> tuple[float, np.ndarray]:
        """Standard Viterbi: (log probability of the best paths, states (T,))."""
        x, lengths = self._check_input(x, lengths)
        log_b = self._log_frameprob(x)
        log_pi, log_t = safe_log(self.startprob_), safe_log(self.transmat_)
        states = np.empty(len(x), dtype=int)
        total = 0.0
        for s, e in _bounds(lengths):
            states[s:e], lp = viterbi(log_pi, log_t, log_b[s:e])
            total += lp
        return total, states

    def sample(
        self, n_samples: int, random_state: int | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Draw ``n_samples`` frames: observations (n, D) and their states (n,)."""
        rng = check_random_state(random_state)
        cum_start = np.cumsum(self.startprob_)
        cum_trans = np.cumsum(self.transmat_, axis=1)
        u = rng.random_sample(n_samples)
        states = np.empty(n_samples, dtype=int)
        states[0] = min(np.searchsorted(cum_start, u[0], side="right"), self.n_components - 1)
        for t in range(1, n_samples):
            row = cum_trans[states[t - 1]]
            states[t] = min(np.searchsorted(row, u[t], side="right"), self.n_components - 1)
        return self._sample_emissions(states, rng), states

    # ---------------------------------------------------------------- emissions
    def _init_emissions(self, x: np.ndarray, rng: np.random.RandomState) -> np.ndarray | None:
        raise NotImplementedError

    def _log_frameprob(self, x: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def _m_step_emissions(self, x: np.ndarray, gamma: np.ndarray) -> None:
        raise NotImplementedError

    def _sample_emissions(self, states: np.ndarray, rng: np.random.RandomState) -> np.ndarray:
        raise NotImplementedError


def _add_e_steps(parts: list[tuple]) -> tuple:
    """:meth:`BaseHMM._e_step` of all sequences from those of consecutive chunks."""
    lls, gammas, starts, counts = zip(*parts, strict=True)
    return sum(lls), np.concatenate(gammas), sum(starts), sum(counts)


def _normalise_rows(counts: np.ndarray, previous: np.ndarray) -> np.ndarray:
    """Rows of ``counts`` summing to one; a state never left keeps its previous row."""
    sums = counts.sum(axis=1, keepdims=True)
    return np.where(sums > 0, counts / np.maximum(sums, 1e-300), previous)


@register
class GaussianHMM(BaseHMM):
    """HMM with one full-covariance Gaussian per state (``m`` means, ``c`` covariances).

    Args:
        var_floor: every covariance eigenvalue is kept at or above this
            fraction of the training data's mean per-dimension variance (a
            variance floor that follows the data's scale: mm or radians alike).

    Learnt: ``startprob_``, ``transmat_``, ``means_`` (N, D), ``covars_``
    (N, D, D), ``covar_floor_`` (the absolute floor), ``history_``,
    ``n_iter_``, ``converged_``.
    """

    def __init__(
        self,
        n_components: int = 8,
        n_iter: int = 50,
        tol: float = 1e-3,
        var_floor: float = 1e-3,
        init_params: str = "stmc",
        random_state: int | None = 0,
        n_jobs: int | None = None,
    ):
        super().__init__(n_components, n_iter, tol, init_params, random_state, n_jobs)
        self.var_floor = var_floor

    def _init_emissions(self, x: np.ndarray, rng: np.random.RandomState) -> np.ndarray | None:
        spread = float(np.var(x, axis=0).mean()) if len(x) > 1 else 0.0
        # constant input (or one frame) has no scale: then the floor is absolute
        self.covar_floor_ = float(self.var_floor * (spread if spread > 0 else 1.0))
        if not {"m", "c", "s", "t"} & set(self.init_params):
            return None
        km = KMeans(self.n_components, n_init=2, random_state=rng.randint(2**31 - 1)).fit(x)
        labels = km.labels_
        if "m" in self.init_params:
            self.means_ = km.cluster_centers_.copy()
        if "c" in self.init_params:
            d = x.shape[1]
            total = np.cov(x, rowvar=False).reshape(d, d) if len(x) > 1 else np.zeros((d, d))
            covars = np.empty((self.n_components, x.shape[1], x.shape[1]))
            for k in range(self.n_components):
                members = x[labels == k]
                covars[k] = (
                    np.cov(members, rowvar=False).reshape(total.shape)
                    if len(members) > x.shape[1]
                    else total
                )
            self.covars_ = floor_covariances(covars, self.covar_floor_)
        return labels

    def check_state(self) -> None:
        """Raise StateError unless the learnt parameters (as read from a model file) fit:
        shapes of pi (N,), T (N, N), means (N, D) and covariances (N, D, D), probabilities
        in [0, 1] summing to one, covariances symmetric positive definite."""
        n = check_count("n_components", self.n_components)
        require(self, "startprob_", "transmat_", "means_", "covars_")
        d = check_shape("means_", self.means_, (n, None)).shape[1]
        covars = check_shape("covars_", self.covars_, (n, d, d))
        check_distribution_rows("startprob_", check_shape("startprob_", self.startprob_, (n,)))
        check_distribution_rows("transmat_", check_shape("transmat_", self.transmat_, (n, n)))
        if d < 1 or not np.allclose(covars, np.swapaxes(covars, 1, 2), rtol=1e-6, atol=1e-9):
            raise StateError("covars_: not symmetric")
        try:
            np.linalg.cholesky(covars)
        except np.linalg.LinAlgError:
            raise StateError("covars_: not positive definite") from None

    def _n_features(self) -> int | None:
        means = getattr(self, "means_", None)
        return None if means is None else int(np.shape(means)[-1])

    def _log_frameprob(self, x: np.ndarray) -> np.ndarray:
        prec, log_det = precision_cholesky(self.covars_)
        return gaussian_log_density(x, self.means_, prec, log_det)

    def _m_step_emissions(self, x: np.ndarray, gamma: np.ndarray) -> None:
        means, covars, mass = weighted_gaussians(x, gamma, self.covar_floor_)
        used = mass > 1e-10
        self.means_ = np.where(used[:, None], means, self.means_)
        self.covars_ = np.where(used[:, None, None], covars, self.covars_)

    def _sample_emissions(self, states: np.ndarray, rng: np.random.RandomState) -> np.ndarray:
        chol = np.linalg.cholesky(self.covars_)
        noise = rng.standard_normal((len(states), self.means_.shape[1]))
        return self.means_[states] + np.einsum("tij,tj->ti", chol[states], noise)
