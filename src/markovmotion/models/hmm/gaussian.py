"""Hidden Markov models with Gaussian emissions (Rabiner 1989), to hmmlearn's standard.

The shape is hmmlearn's: one small base class (:class:`BaseHMM`) owns the
initial distribution pi, the transition matrix T and everything built on
them -- Baum-Welch EM, scoring, Viterbi and MAP decoding, sampling, AIC/BIC,
the stationary distribution -- and a variant supplies its emission model in
a few methods. Several sequences are one concatenated array ``X`` (frames,
dims) plus ``lengths``. The recursions are the pure functions of
:mod:`markovmotion.algorithms.hmm_recursions` (log space by default, no
underflow on long sequences; Rabiner's scaled form with
``implementation="scaling"``). Learnt attributes end in ``_``; the
log-likelihood of every EM iteration is kept in ``history_``.

hmmlearn's meanings are kept, so that its own test suite runs against
:class:`GaussianHMM` (tests/test_hmmlearn_suite.py): the four covariance types
and their compact ``covars_`` forms, ``params`` / ``init_params`` letters
(``s`` pi, ``t`` T, ``m`` means, ``c`` covariances: what EM updates / what
``fit`` initialises; a parameter not initialised and not set is initialised
anyway), conjugate priors, ValueError for pi or T that are not distributions.
Ours besides: the variance floor (:class:`GaussianHMM`, ``min_covar`` and
``var_floor``), k-means-based initial pi and T, parallel E-step, no pickles.
"""

from __future__ import annotations

import logging
import sys
from collections.abc import Sequence
from typing import Any

import numpy as np
from sklearn.base import BaseEstimator
from sklearn.cluster import KMeans
from sklearn.utils import check_random_state
from sklearn.utils.validation import check_is_fitted

from markovmotion.algorithms.gaussian import (
    check_covariance_type,
    compact_covariances,
    compact_of_full,
    covariance_floor,
    floor_covariances,
    full_covariances,
    gaussian_m_step,
    log_density,
)
from markovmotion.algorithms.hmm_recursions import forward_backward, viterbi
from markovmotion.algorithms.parallel import map_sequences
from markovmotion.core.frames import check_frames
from markovmotion.errors import TooLittleDataError
from markovmotion.state import StateError, check_count, register, require

_log = logging.getLogger(__name__)

DECODERS = ("viterbi", "map")
IMPLEMENTATIONS = ("log", "scaling")


# ------------------------------------------------------------------ EM bookkeeping
class ConvergenceMonitor:
    """Log-likelihood history of EM (hmmlearn's): EM stops after ``n_iter`` reports or once an
    iteration gains less than ``tol``; ``verbose`` prints each report to stderr."""

    _template = "{iter:>10d} {log_prob:>16.8f} {delta:>+16.8f}"

    def __init__(self, tol: float, n_iter: int | None = None, verbose: bool = False):
        self.tol = tol
        self.n_iter = n_iter
        self.verbose = verbose
        self.history: list[float] = []
        self.iter = 0

    def _reset(self) -> None:
        self.iter = 0
        self.history.clear()

    def report(self, log_likelihood: float) -> None:
        if self.verbose:
            delta = log_likelihood - self.history[-1] if self.history else np.nan
            line = self._template.format(iter=self.iter + 1, log_prob=log_likelihood, delta=delta)
            print(line, file=sys.stderr)
        self.history.append(float(log_likelihood))
        self.iter += 1

    @property
    def gained_less_than_tol(self) -> bool:
        h = self.history
        return len(h) >= 2 and h[-1] - h[-2] < self.tol

    @property
    def converged(self) -> bool:
        return self.iter == self.n_iter or self.gained_less_than_tol


def check_sequences(
    x: Any, lengths: Sequence[int] | int | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """``X`` as a finite float (T, D) array and ``lengths`` as positive ints summing to T.

    Refused with one ValueError naming the problem: sparse or complex input, no frames,
    NaN or infinite values, values so large that their squares (the M-step's second
    moments) overflow, lengths that do not split the frames.
    """
    x = check_frames(x)
    with np.errstate(over="ignore"):
        if not np.isfinite(np.einsum("ij,ij->j", x, x)).all():
            big = float(np.abs(x).max())
            raise ValueError(f"X holds values too large for a Gaussian (|x| up to {big:.3g})")
    given = np.atleast_1d(np.asarray([len(x)] if lengths is None else lengths))
    lengths = given.astype(int) if given.dtype.kind in "biuf" else given
    if (
        lengths.dtype.kind not in "biu"
        or lengths.ndim != 1
        or np.any(lengths != given)
        or lengths.sum() != len(x)
        or np.any(lengths < 1)
    ):
        shown: Any = given.tolist() if given.ndim == 1 else f"of shape {given.shape}"
        if given.ndim == 1 and len(given) > 8:
            shown = f"{str(shown[:8])[:-1]}, ...] ({len(given)} values)"
        raise ValueError(
            f"lengths {shown} do not split {len(x)} frames: the second argument of fit and "
            "score is hmmlearn's lengths (whole numbers >= 1 summing to the frames), not "
            "scikit-learn's y"
        )
    return x, lengths


def _bounds(lengths: np.ndarray) -> list[tuple[int, int]]:
    ends = np.cumsum(lengths)
    return list(zip(ends - lengths, ends, strict=True))


def safe_log(p: np.ndarray) -> np.ndarray:
    """log p with log 0 = -inf and no warning."""
    with np.errstate(divide="ignore"):
        return np.log(p)


def _check_distribution(name: str, p: Any, shape: tuple[int, ...]) -> np.ndarray:
    """``p`` as a float array of ``shape`` whose last axis holds probabilities summing to one
    (hmmlearn's meaning: ValueError otherwise)."""
    p = np.asarray(p, dtype=float)
    if p.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {p.shape}")
    if not np.isfinite(p).all() or (p < 0).any():
        raise ValueError(f"{name} must hold probabilities in [0, 1]")
    sums = p.sum(axis=-1)
    if not np.allclose(sums, 1):
        raise ValueError(f"{name} must sum to 1 along its last axis (got {np.round(sums, 4)})")
    return p


# ------------------------------------------------------------------ models
class BaseHMM(BaseEstimator):
    """pi, T and the algorithms on them; a variant supplies the emission model.

    Args:
        n_components: number of hidden states N.
        startprob_prior, transmat_prior: Dirichlet priors of pi and of T's rows
            (1: none, maximum likelihood).
        algorithm: the decoder of ``decode`` and ``predict``: ``"viterbi"`` (the best
            state path, Rabiner eqs. 32-35) or ``"map"`` (each frame's most probable state).
        random_state: seed for the initialisation and (by default) sampling.
        n_iter: most EM iterations.
        tol: stop when an iteration gains less log-likelihood than this.
        verbose: print each EM iteration's log-likelihood to stderr.
        params: which parameters EM updates (``s`` pi, ``t`` T, and the variant's letters).
        init_params: which parameters ``fit`` initialises; the others are used as already set
            (and initialised if they are not).
        implementation: forward-backward in ``"log"`` space or ``"scaling"``.
        n_jobs: parallel jobs of the E-step, over chunks of sequences
            (:mod:`markovmotion.algorithms.parallel`: None is one unless a
            joblib context says otherwise, -1 every core, Dask through joblib).

    Variants implement ``_init_emissions``, ``_log_frameprob(X) -> (T, N)``,
    ``_m_step_emissions(X, gamma)``, ``_sample_emissions(states, rng)``, ``_check_emissions``
    and ``_n_fit_scalars_per_param``.
    """

    _CHAIN = {"s": "startprob_", "t": "transmat_"}
    _EMISSIONS: dict[str, str] = {}

    def __init__(
        self,
        n_components: int = 8,
        startprob_prior: Any = 1.0,
        transmat_prior: Any = 1.0,
        algorithm: str = "viterbi",
        random_state: Any = 0,
        n_iter: int = 50,
        tol: float = 1e-3,
        verbose: bool = False,
        params: str = "stmc",
        init_params: str = "stmc",
        implementation: str = "log",
        n_jobs: int | None = None,
    ):
        self.n_components = n_components
        self.startprob_prior = startprob_prior
        self.transmat_prior = transmat_prior
        self.algorithm = algorithm
        self.random_state = random_state
        self.n_iter = n_iter
        self.tol = tol
        self.verbose = verbose
        self.params = params
        self.init_params = init_params
        self.implementation = implementation
        self.n_jobs = n_jobs

    # ---------------------------------------------------------------- fitting
    def fit(self, x: Any, lengths: Sequence[int] | None = None) -> BaseHMM:
        """Baum-Welch EM (Rabiner eqs. 40a-c, with the priors' MAP form) after
        :meth:`_init`; returns ``self``."""
        x, lengths = check_sequences(x, lengths)
        if self.implementation not in IMPLEMENTATIONS:
            raise ValueError(f"implementation must be one of {IMPLEMENTATIONS}")
        self._init(x, lengths)
        self._check()
        monitor = ConvergenceMonitor(self.tol, self.n_iter, self.verbose)
        for _ in range(self.n_iter):
            ll, gamma, starts, counts = self._e_step(x, lengths)
            self._m_step(x, gamma, starts, counts)
            monitor.report(ll)
            if monitor.converged:
                break
        self.history_ = np.array(monitor.history)
        self.n_iter_ = len(monitor.history)
        self.converged_ = monitor.gained_less_than_tol
        return self

    def _needs_init(self, code: str, name: str) -> bool:
        """Whether ``fit`` initialises parameter ``name`` (letter ``code``): asked to, or not
        set; says so in the log when a set value is overwritten (as hmmlearn does)."""
        if code in self.init_params:
            if hasattr(self, name):
                _log.warning(
                    "Even though the %r attribute is set, it will be overwritten during "
                    "initialization because 'init_params' contains %r",
                    name,
                    code,
                )
            return True
        return not hasattr(self, name)

    def _init(self, x: np.ndarray, lengths: Sequence[int] | int | None = None) -> None:
        """Initialise what ``init_params`` asks for (and what is missing): the variant's
        emissions, then pi and T from the frames' initial labels (k-means or nearest means);
        log a warning when there are fewer numbers than free parameters to fit."""
        x = np.asarray(x, dtype=float)
        lengths = np.atleast_1d(np.array(len(x) if lengths is None else lengths, dtype=int))
        if lengths.sum() != len(x):
            lengths = np.array([len(x)])
        self._check_and_set_n_features(x)
        need = {
            c: self._needs_init(c, name) for c, name in {**self._CHAIN, **self._EMISSIONS}.items()
        }
        rng = check_random_state(self.random_state)
        labels = self._init_emissions(x, rng, need)
        self._init_chain(labels, lengths, need)
        per_param = self._n_fit_scalars_per_param()
        n_fit = sum(per_param.get(p, 0) for p in set(self.params))
        if x.size < n_fit:
            _log.warning(
                "Fitting a model with %d free scalar parameters with only %d data points "
                "will result in a degenerate solution.",
                n_fit,
                x.size,
            )

    def _check_and_set_n_features(self, x: np.ndarray) -> None:
        self.n_features_in_ = x.shape[1]

    def _init_chain(self, labels: np.ndarray | None, lengths: np.ndarray, need: dict) -> None:
        """pi and T from the labels' first frames and transitions (+1 each), or uniform."""
        n = self.n_components
        starts = np.ones(n)
        counts = np.ones((n, n))
        if labels is not None:
            for s, e in _bounds(lengths):
                starts[labels[s]] += 1
                np.add.at(counts, (labels[s : e - 1], labels[s + 1 : e]), 1)
        if need.get("s"):
            self.startprob_ = starts / starts.sum()
        if need.get("t"):
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
            ll, gamma[s:e], xi = forward_backward(log_pi, trans, log_b[s:e], self.implementation)
            total += ll
            starts += gamma[s]
            counts += xi
        return total, gamma, starts, counts

    def _m_step(self, x: np.ndarray, gamma: np.ndarray, starts: np.ndarray, counts: np.ndarray):
        """Re-estimate the parameters in ``params``: pi and T as the Dirichlet priors' MAP
        (negative counts clipped to zero; probabilities that are zero stay zero; a state never
        left keeps its row), then the emissions."""
        if "s" in self.params:
            pi = np.maximum(np.asarray(self.startprob_prior) - 1 + starts, 0)
            pi = np.where(self.startprob_ == 0, 0, pi)
            if pi.sum() > 0:
                self.startprob_ = pi / pi.sum()
        if "t" in self.params:
            t = np.maximum(np.asarray(self.transmat_prior) - 1 + counts, 0)
            t = np.where(self.transmat_ == 0, 0, t)
            self.transmat_ = _normalise_rows(t, self.transmat_)
        self._m_step_emissions(x, gamma)

    # ---------------------------------------------------------------- checks
    def _check(self) -> None:
        """ValueError unless pi is a distribution over the N states and T's rows are (and the
        variant's emissions fit); arrays given as lists become arrays."""
        n = self.n_components
        self.startprob_ = _check_distribution("startprob_", self.startprob_, (n,))
        self.transmat_ = _check_distribution("transmat_", self.transmat_, (n, n))
        self._check_emissions()

    def _check_fitted(self) -> None:
        """NotFittedError before the model has its parameters, then :meth:`_check`."""
        check_is_fitted(self, [*self._CHAIN.values(), *self._EMISSIONS.values()])
        self._check()

    def _check_input(
        self, x: Any, lengths: Sequence[int] | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """The model's parameters checked (:meth:`_check_fitted`), then :func:`check_sequences`,
        and ``X`` as wide as the model's observations (the compiled densities do not check:
        wider input read past their arrays)."""
        self._check_fitted()
        x, lengths = check_sequences(x, lengths)
        width = self._n_features()
        if width is not None and x.shape[1] != width:
            raise ValueError(
                f"X has {x.shape[1]} features, but {type(self).__name__} is expecting {width} "
                "features as input"
            )
        return x, lengths

    def _n_features(self) -> int | None:
        """Width of the observations the emission model holds (None: not known yet)."""
        return None

    # ---------------------------------------------------------------- inference
    def log_frameprob(self, x: Any) -> np.ndarray:
        """(T, N) log b_j(o_t) of every frame under every state's emission density."""
        return self._log_frameprob(self._check_input(x)[0])

    def score(self, x: Any, lengths: Sequence[int] | None = None) -> float:
        """log P(X | model), summed over the sequences."""
        x, lengths = self._check_input(x, lengths)
        return self._e_step(x, lengths)[0]

    def score_samples(
        self, x: Any, lengths: Sequence[int] | None = None
    ) -> tuple[float, np.ndarray]:
        """(log P(X | model), state posteriors gamma (T, N))."""
        x, lengths = self._check_input(x, lengths)
        ll, gamma, _, _ = self._e_step(x, lengths)
        return ll, gamma

    def predict_proba(self, x: Any, lengths: Sequence[int] | None = None) -> np.ndarray:
        """State posteriors gamma (T, N)."""
        return self.score_samples(x, lengths)[1]

    def predict(self, x: Any, lengths: Sequence[int] | None = None) -> np.ndarray:
        """States (T,) by the model's decoder (``algorithm``)."""
        return self.decode(x, lengths)[1]

    def decode(
        self, x: Any, lengths: Sequence[int] | None = None, algorithm: str | None = None
    ) -> tuple[float, np.ndarray]:
        """(log probability, states (T,)) by ``algorithm`` (default: the model's).

        ``"viterbi"``: the best state paths and their joint log probability with X;
        ``"map"``: each frame's most probable state and sum_t log max_j gamma_t(j)
        (hmmlearn returns sum_t max_j gamma_t(j) there, not a log probability).
        """
        algorithm = algorithm or self.algorithm
        if algorithm not in DECODERS:
            raise ValueError(f"algorithm must be one of {DECODERS}, got {algorithm!r}")
        x, lengths = self._check_input(x, lengths)
        if algorithm == "map":
            gamma = self._e_step(x, lengths)[1]
            with np.errstate(divide="ignore"):
                return float(np.log(gamma.max(axis=1)).sum()), gamma.argmax(axis=1)
        log_b = self._log_frameprob(x)
        log_pi, log_t = safe_log(self.startprob_), safe_log(self.transmat_)
        states = np.empty(len(x), dtype=int)
        total = 0.0
        for s, e in _bounds(lengths):
            states[s:e], lp = viterbi(log_pi, log_t, log_b[s:e])
            total += lp
        return total, states

    def sample(
        self, n_samples: int = 1, random_state: Any = None, currstate: int | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Draw ``n_samples`` frames: observations (n, D) and their states (n,).

        ``random_state`` defaults to the model's; ``currstate`` is the first frame's state
        (so ``sample(n, currstate=states[-1])`` continues a sample), else drawn from pi.
        """
        self._check_fitted()
        n_samples = check_count("n_samples", n_samples)
        rng = check_random_state(self.random_state if random_state is None else random_state)
        cum_trans = np.cumsum(self.transmat_, axis=1)
        u = rng.random_sample(n_samples)
        states = np.empty(n_samples, dtype=int)
        if currstate is None:
            cum_start = np.cumsum(self.startprob_)
            states[0] = min(np.searchsorted(cum_start, u[0], side="right"), self.n_components - 1)
        else:
            states[0] = check_count("currstate", currstate, 0)
            if states[0] >= self.n_components:
                raise ValueError(f"currstate {currstate} is not one of {self.n_components} states")
        for t in range(1, n_samples):
            row = cum_trans[states[t - 1]]
            states[t] = min(np.searchsorted(row, u[t], side="right"), self.n_components - 1)
        return self._sample_emissions(states, rng), states

    def get_stationary_distribution(self) -> np.ndarray:
        """The distribution p with p T = p and sum p = 1 (least squares: exact when the
        chain has one stationary distribution)."""
        check_is_fitted(self, "transmat_")
        trans = np.asarray(self.transmat_, dtype=float)
        n = len(trans)
        a = np.vstack([trans.T - np.eye(n), np.ones(n)])
        b = np.r_[np.zeros(n), 1.0]
        return np.linalg.lstsq(a, b, rcond=None)[0].astype(float)

    def aic(self, x: Any, lengths: Sequence[int] | None = None) -> float:
        """Akaike's information criterion -2 log P(X) + 2 k (k free parameters): lower is better."""
        k = sum(self._n_fit_scalars_per_param().values())
        return -2 * self.score(x, lengths) + 2 * k

    def bic(self, x: Any, lengths: Sequence[int] | None = None) -> float:
        """Bayesian information criterion -2 log P(X) + k log T: lower is better."""
        k = sum(self._n_fit_scalars_per_param().values())
        return -2 * self.score(x, lengths) + k * np.log(len(np.asarray(x)))

    # ---------------------------------------------------------------- emissions
    def _n_fit_scalars_per_param(self) -> dict[str, int]:
        n = self.n_components
        return {"s": n - 1, "t": n * (n - 1)}

    def _init_emissions(
        self, x: np.ndarray, rng: np.random.RandomState, need: dict
    ) -> np.ndarray | None:
        return None

    def _check_emissions(self) -> None:
        return None

    def _log_frameprob(self, x: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def _m_step_emissions(self, x: np.ndarray, gamma: np.ndarray) -> None:
        return None

    def _sample_emissions(self, states: np.ndarray, rng: np.random.RandomState) -> np.ndarray:
        """No emission model: frames of zero features (a state sequence alone)."""
        return np.empty((len(states), 0))


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
    """HMM with one Gaussian per state (``m`` means, ``c`` covariances).

    Args:
        covariance_type: ``"full"`` (a covariance matrix per state), ``"diag"`` (variances
            per state and feature), ``"spherical"`` (one variance per state), ``"tied"``
            (one matrix for every state); ``covars_`` reads as (N, D, D) matrices whatever
            the type and is set in the type's compact form: (N, D, D), (N, D), (N,), (D, D).
        min_covar: absolute variance floor, in the data's squared units (hmmlearn's, 1e-3).
        var_floor: variance floor relative to each feature's own variance over the
            training data (0: none). The floor of feature j is
            ``max(min_covar, var_floor * Var(X[:, j]))`` (``covar_floor_``, (D,)); every
            covariance is kept at or above it (:func:`~markovmotion.algorithms.gaussian.
            floor_covariances`: per feature for diag and spherical, along every direction for
            full and tied). Per feature, so a feature in mm does not floor one in radians;
            relative to the feature and never to the spread between states' means, it cannot
            exceed the data's own variance (docs/hmm.md, "The variance floor").
        means_prior, means_weight: normal prior of the means (weight 0: none).
        covars_prior, covars_weight: inverse gamma (diag, spherical) or inverse Wishart
            (full, tied) prior of the covariances (hmmlearn's defaults 1e-2 and 1).
        Others: :class:`BaseHMM`.

    Learnt: ``startprob_``, ``transmat_``, ``means_`` (N, D), ``covars_``,
    ``covar_floor_`` (D,), ``n_features_in_``, ``history_``, ``n_iter_``, ``converged_``.
    """

    _EMISSIONS = {"m": "means_", "c": "covars_"}

    def __init__(
        self,
        n_components: int = 8,
        covariance_type: str = "full",
        min_covar: float = 1e-3,
        startprob_prior: Any = 1.0,
        transmat_prior: Any = 1.0,
        means_prior: Any = 0.0,
        means_weight: Any = 0.0,
        covars_prior: Any = 1e-2,
        covars_weight: Any = 1.0,
        algorithm: str = "viterbi",
        random_state: Any = 0,
        n_iter: int = 50,
        tol: float = 1e-3,
        verbose: bool = False,
        params: str = "stmc",
        init_params: str = "stmc",
        implementation: str = "log",
        var_floor: float = 0.0,
        n_jobs: int | None = None,
    ):
        super().__init__(
            n_components,
            startprob_prior=startprob_prior,
            transmat_prior=transmat_prior,
            algorithm=algorithm,
            random_state=random_state,
            n_iter=n_iter,
            tol=tol,
            verbose=verbose,
            params=params,
            init_params=init_params,
            implementation=implementation,
            n_jobs=n_jobs,
        )
        self.covariance_type = covariance_type
        self.min_covar = min_covar
        self.means_prior = means_prior
        self.means_weight = means_weight
        self.covars_prior = covars_prior
        self.covars_weight = covars_weight
        self.var_floor = var_floor

    # ---------------------------------------------------------------- covariances
    @property
    def covars_(self) -> np.ndarray:
        """Covariance matrices (N, D, D) whatever ``covariance_type``; set in its compact form."""
        try:
            compact = self.__dict__["covars_"]
        except KeyError:
            raise AttributeError("covars_") from None
        return full_covariances(compact, self.covariance_type, self.n_components, self.n_features)

    @covars_.setter
    def covars_(self, covars: Any) -> None:
        self.__dict__["covars_"] = compact_covariances(
            covars, self.covariance_type, self.n_components
        )

    @property
    def _covars_(self) -> np.ndarray:
        """The covariances as stored, in ``covariance_type``'s compact form (hmmlearn's name)."""
        try:
            return self.__dict__["covars_"]
        except KeyError:
            raise AttributeError("_covars_") from None

    @property
    def n_features(self) -> int:
        """D, the width of the frames (hmmlearn's name for ``n_features_in_``)."""
        if "n_features_in_" in self.__dict__:
            return int(self.n_features_in_)
        if "means_" in self.__dict__:
            return int(np.shape(self.means_)[-1])
        raise AttributeError("n_features")

    @n_features.setter
    def n_features(self, value: int) -> None:
        self.n_features_in_ = int(value)

    def _n_features(self) -> int | None:
        means = getattr(self, "means_", None)
        return None if means is None else int(np.shape(means)[-1])

    def _check_and_set_n_features(self, x: np.ndarray) -> None:
        width = self._n_features()
        if width is not None and "m" not in self.init_params and x.shape[1] != width:
            raise ValueError(f"X has {x.shape[1]} columns but means_ has {width} features")
        self.n_features_in_ = x.shape[1]

    def _n_fit_scalars_per_param(self) -> dict[str, int]:
        n, d = self.n_components, self.n_features
        cov = {"spherical": n, "diag": n * d, "full": n * d * (d + 1) // 2}
        return {
            **super()._n_fit_scalars_per_param(),
            "m": n * d,
            "c": cov.get(self.covariance_type, d * (d + 1) // 2),
        }

    # ---------------------------------------------------------------- EM
    def _init_emissions(
        self, x: np.ndarray, rng: np.random.RandomState, need: dict
    ) -> np.ndarray | None:
        """Means by k-means; every state's covariance the data's (+ ``min_covar`` on the
        diagonal, as hmmlearn: EM's first posteriors are then soft, not k-means' hard
        clusters); the floor from the data. Returns the frames' labels (k-means, else the
        nearest mean), from which pi and T start."""
        check_covariance_type(self.covariance_type)
        self.covar_floor_ = covariance_floor(x, self.min_covar, self.var_floor)
        labels = None
        if need["m"]:
            if len(x) < self.n_components:
                raise TooLittleDataError(f"{len(x)} frames cannot train {self.n_components} states")
            km = KMeans(self.n_components, n_init=2, random_state=rng.randint(2**31 - 1)).fit(x)
            labels = km.labels_
            self.means_ = km.cluster_centers_.copy()
        if labels is None and (need["c"] or need["s"] or need["t"]):
            means = np.asarray(self.means_, dtype=float)
            labels = ((x[:, None, :] - means[None]) ** 2).sum(axis=-1).argmin(axis=1)
        if need["c"]:
            d = x.shape[1]
            total = np.cov(x, rowvar=False).reshape(d, d) if len(x) > 1 else np.zeros((d, d))
            covars = np.broadcast_to(total + self.min_covar * np.eye(d), (self.n_components, d, d))
            compact = compact_of_full(covars, self.covariance_type)
            self.covars_ = floor_covariances(compact, self.covar_floor_, self.covariance_type)
        return labels

    def _m_step_emissions(self, x: np.ndarray, gamma: np.ndarray) -> None:
        """Means and covariances in ``params``: :func:`~markovmotion.algorithms.gaussian.
        gaussian_m_step` (Rabiner eqs. 52-53 with the priors), floored at ``covar_floor_``;
        a state no frame visits keeps its Gaussian."""
        if not {"m", "c"} & set(self.params):
            return
        means, covars, mass = gaussian_m_step(
            x,
            gamma,
            self.covariance_type,
            self.means_prior,
            self.means_weight,
            self.covars_prior,
            self.covars_weight,
            means=None if "m" in self.params else np.asarray(self.means_, dtype=float),
        )
        used = mass > 1e-10
        if "m" in self.params:
            self.means_ = np.where(used[:, None], means, self.means_)
        if "c" in self.params:
            floor = getattr(self, "covar_floor_", self.min_covar)
            covars = floor_covariances(covars, floor, self.covariance_type)
            if self.covariance_type != "tied":
                shape = (-1,) + (1,) * (covars.ndim - 1)
                covars = np.where(used.reshape(shape), covars, self._covars_)
            self.__dict__["covars_"] = covars

    def _check_emissions(self) -> None:
        check_covariance_type(self.covariance_type)
        self.means_ = np.asarray(self.means_, dtype=float)
        if self.means_.ndim != 2 or len(self.means_) != self.n_components:
            raise ValueError(
                f"means_ must have shape ({self.n_components}, n_features), got {self.means_.shape}"
            )
        covars = compact_covariances(self._covars_, self.covariance_type, self.n_components)
        d = self.means_.shape[1]
        if self.covariance_type != "spherical" and covars.shape[-1] != d:
            raise ValueError(f"covars_ are {covars.shape[-1]}-dimensional, means_ {d}-dimensional")

    def check_state(self) -> None:
        """Raise StateError unless the learnt parameters (as read from a model file) fit:
        pi (N,) and T (N, N) distributions, means (N, D), covariances of the
        ``covariance_type``'s compact shape, symmetric positive definite."""
        check_count("n_components", self.n_components)
        require(self, "startprob_", "transmat_", "means_", "covars_")
        try:
            self._check()
        except ValueError as exc:
            raise StateError(str(exc)) from None

    def _log_frameprob(self, x: np.ndarray) -> np.ndarray:
        return log_density(x, self.means_, self._covars_, self.covariance_type)

    def _sample_emissions(self, states: np.ndarray, rng: np.random.RandomState) -> np.ndarray:
        chol = np.linalg.cholesky(self.covars_)
        noise = rng.standard_normal((len(states), self.means_.shape[1]))
        return self.means_[states] + np.einsum("tij,tj->ti", chol[states], noise)
