"""Explicit-duration HSMM recursions (Yoshimura et al. 1998; gait paper §5.1), in log space.

The forward-backward over a left-to-right chain without skips in which every
state lasts d = 1..Dmax frames under a discretised Gaussian duration density;
compiled with numba (``cache=True``, free of the GIL), used by
:class:`markovmotion.models.gait.hsmm.HSMM`.
"""

from __future__ import annotations

import numba
import numpy as np
from scipy.special import logsumexp

from markovmotion.errors import LimitError
from markovmotion.limits import MAX_VALUES, exceeded, max_values


def duration_log_pmf(means: np.ndarray, variances: np.ndarray, max_duration: int) -> np.ndarray:
    """(Q, max_duration) log P(d) for d = 1..max_duration: Gaussians discretised and normalised."""
    d = np.arange(1, max_duration + 1)
    logp = -0.5 * ((d - means[:, None]) ** 2 / variances[:, None] + np.log(variances[:, None]))
    return logp - logsumexp(logp, axis=1, keepdims=True)


@numba.njit(cache=True)
def _lse(values, n):  # pragma: no cover - numba
    top = -np.inf
    for i in range(n):
        if values[i] > top:
            top = values[i]
    if top == -np.inf:
        return top
    acc = 0.0
    for i in range(n):
        acc += np.exp(values[i] - top)
    return top + np.log(acc)


@numba.njit(cache=True, nogil=True)
def _forward_backward(log_b, log_dur):  # pragma: no cover - numba
    t_len, n = log_b.shape
    dmax = log_dur.shape[1]
    cum = np.zeros((t_len + 1, n))
    for t in range(t_len):
        cum[t + 1] = cum[t] + log_b[t]
    # alpha[e, k]: frames [0, e) from states 0..k-1, state k-1 ending at e (k = 0: none yet)
    alpha = np.full((t_len + 1, n + 1), -np.inf)
    alpha[0, 0] = 0.0
    # beta[e, k]: frames [e, T) from states k..N-1
    beta = np.full((t_len + 1, n + 1), -np.inf)
    beta[t_len, n] = 0.0
    buf = np.empty(dmax)
    for e in range(1, t_len + 1):
        for k in range(n):
            m = min(dmax, e)
            for i in range(m):
                d = i + 1
                buf[i] = alpha[e - d, k] + log_dur[k, i] + cum[e, k] - cum[e - d, k]
            alpha[e, k + 1] = _lse(buf, m)
    for e in range(t_len - 1, -1, -1):
        for k in range(n):
            m = min(dmax, t_len - e)
            for i in range(m):
                d = i + 1
                buf[i] = beta[e + d, k + 1] + log_dur[k, i] + cum[e + d, k] - cum[e, k]
            beta[e, k] = _lse(buf, m)
    log_like = alpha[t_len, n]
    diff = np.zeros((t_len + 1, n))
    dur_post = np.zeros((n, dmax))
    if log_like == -np.inf:
        return log_like, diff[:t_len], dur_post
    for e in range(1, t_len + 1):
        for k in range(n):
            tail = beta[e, k + 1]
            if tail == -np.inf:
                continue
            for i in range(min(dmax, e)):
                d = i + 1
                head = alpha[e - d, k]
                if head == -np.inf:
                    continue
                p = np.exp(head + log_dur[k, i] + cum[e, k] - cum[e - d, k] + tail - log_like)
                dur_post[k, i] += p
                diff[e - d, k] += p
                diff[e, k] -= p
    gamma = np.empty((t_len, n))
    run = np.zeros(n)
    for t in range(t_len):
        run += diff[t]
        gamma[t] = run
    return log_like, gamma, dur_post


def chain_cells(n_frames: int, n_states: int) -> int:
    """The cells of each of an explicit-duration pass's arrays (frames + 1) x (states + 1)."""
    return (n_frames + 1) * (n_states + 1)


def check_chain(n_frames: int, n_states: int) -> None:
    """Raise :class:`LimitError` (one line) when a chain of ``n_states`` over ``n_frames``
    would need more than ``MARKOVMOTION_MAX_VALUES`` cells: a walk's chain grows with its
    steps, so its arrays grow with the square of its length (a 100,000-frame walk of 5,858
    steps asked for 22 GB and died in NumPy), checked before anything is allocated."""
    if chain_cells(n_frames, n_states) > max_values():
        found = f"{n_frames} frames x {n_states} chain states"
        raise LimitError(
            f"{exceeded(MAX_VALUES, found)}: an explicit-duration chain costs frames x states; "
            "cut the sequence (a walk into walks of fewer steps)"
        )


def forward_backward(
    log_b: np.ndarray, log_dur: np.ndarray
) -> tuple[float, np.ndarray, np.ndarray]:
    """Explicit-duration forward-backward over a left-to-right chain without skips, in log space.

    The chain starts in state 0 at frame 0, visits every state once for
    d >= 1 frames, and leaves state N-1 after frame T-1. With the cumulative
    sums of log_b, a segment's output probability is one subtraction, so a
    pass costs O(T N Dmax).

    Args:
        log_b: (T, N) log output densities of each frame in each chain state.
        log_dur: (N, Dmax) log duration probabilities, d = 1..Dmax.

    Returns:
        ``(log P(O), gamma, dur_post)``: gamma (T, N) state occupancies and
        dur_post (N, Dmax) the posterior of each state's duration. A sequence
        the chain cannot produce (T < N or T > N Dmax) has log P(O) = -inf
        and zero posteriors.

    Raises:
        LimitError: more than ``MARKOVMOTION_MAX_VALUES`` cells (:func:`check_chain`).
    """
    log_b = np.ascontiguousarray(log_b, dtype=float)
    log_dur = np.ascontiguousarray(log_dur, dtype=float)
    if log_dur.shape[0] != log_b.shape[1]:
        raise ValueError("log_b and log_dur disagree on the number of states")
    check_chain(*log_b.shape)
    ll, gamma, dur_post = _forward_backward(log_b, log_dur)
    return float(ll), gamma, dur_post
