"""A pytest plugin that runs hmmlearn's own tests against markovmotion's HMM (issue 26).

Loaded with ``-p hmmlearn_adapter`` before hmmlearn's test modules are imported, it puts
our classes and recursions where those modules look for hmmlearn's: ``hmmlearn.hmm.
GaussianHMM``, ``hmmlearn.base.BaseHMM`` and ``ConvergenceMonitor``, and ``hmmlearn._hmmc``.
The adapters only rename: hmmlearn's constructor defaults (one state, diagonal covariances,
10 iterations, tol 1e-2, no seed), its name for the emission hook
(``_compute_log_likelihood``), and its recursions' argument order (probabilities where ours
take their logarithms). No expected value of hmmlearn's tests is touched.

    python3 -m pytest -p hmmlearn_adapter --pyargs hmmlearn.tests.test_gaussian_hmm \\
        hmmlearn.tests.test_base      # with tests/ on PYTHONPATH
"""

from __future__ import annotations

import sys
import types
from typing import Any

import hmmlearn
import hmmlearn.base
import hmmlearn.hmm
import numpy as np

from markovmotion.algorithms import hmm_recursions as rec
from markovmotion.models.hmm import gaussian as ours


class GaussianHMM(ours.GaussianHMM):
    """Ours with hmmlearn's constructor defaults."""

    def __init__(
        self,
        n_components: int = 1,
        covariance_type: str = "diag",
        min_covar: float = 1e-3,
        startprob_prior: Any = 1.0,
        transmat_prior: Any = 1.0,
        means_prior: Any = 0,
        means_weight: Any = 0,
        covars_prior: Any = 1e-2,
        covars_weight: Any = 1,
        algorithm: str = "viterbi",
        random_state: Any = None,
        n_iter: int = 10,
        tol: float = 1e-2,
        verbose: bool = False,
        params: str = "stmc",
        init_params: str = "stmc",
        implementation: str = "log",
    ):
        super().__init__(
            n_components,
            covariance_type,
            min_covar,
            startprob_prior,
            transmat_prior,
            means_prior,
            means_weight,
            covars_prior,
            covars_weight,
            algorithm,
            random_state,
            n_iter,
            tol,
            verbose,
            params,
            init_params,
            implementation,
        )


class BaseHMM(ours.BaseHMM):
    """Ours with hmmlearn's constructor defaults and its emission hook's name."""

    def __init__(
        self,
        n_components: int = 1,
        startprob_prior: Any = 1.0,
        transmat_prior: Any = 1.0,
        algorithm: str = "viterbi",
        random_state: Any = None,
        n_iter: int = 10,
        tol: float = 1e-2,
        verbose: bool = False,
        params: str = "st",
        init_params: str = "st",
        implementation: str = "log",
    ):
        super().__init__(
            n_components,
            startprob_prior,
            transmat_prior,
            algorithm,
            random_state,
            n_iter,
            tol,
            verbose,
            params,
            init_params,
            implementation,
        )

    def _log_frameprob(self, x: np.ndarray) -> np.ndarray:
        return self._compute_log_likelihood(x)

    def _compute_log_likelihood(self, x: np.ndarray) -> np.ndarray:
        raise NotImplementedError


def _log(p: Any) -> np.ndarray:
    with np.errstate(divide="ignore"):
        return np.log(np.asarray(p, dtype=float))


def _forward_log(startprob, transmat, log_frameprob):
    log_alpha, ll = rec.forward(_log(startprob), transmat, log_frameprob)
    return ll, log_alpha


def _backward_log(startprob, transmat, log_frameprob):
    return rec.backward(transmat, log_frameprob)


def _forward_scaling(startprob, transmat, frameprob):
    alpha, scale, ll = rec.forward_scaling(startprob, transmat, frameprob)
    return ll, alpha, scale


def _backward_scaling(startprob, transmat, frameprob, scaling_factors):
    return rec.backward_scaling(transmat, frameprob, scaling_factors)


def _viterbi(startprob, transmat, log_frameprob):
    path, lp = rec.viterbi(_log(startprob), _log(transmat), log_frameprob)
    return lp, path


_hmmc = types.ModuleType("hmmlearn._hmmc", "markovmotion's recursions under hmmlearn's names")
_hmmc.forward_log = _forward_log
_hmmc.backward_log = _backward_log
_hmmc.forward_scaling = _forward_scaling
_hmmc.backward_scaling = _backward_scaling
_hmmc.viterbi = _viterbi


def pytest_configure(config) -> None:
    hmmlearn.hmm.GaussianHMM = GaussianHMM
    hmmlearn.base.BaseHMM = BaseHMM
    hmmlearn.base.ConvergenceMonitor = ours.ConvergenceMonitor
    hmmlearn._hmmc = _hmmc
    sys.modules["hmmlearn._hmmc"] = _hmmc
