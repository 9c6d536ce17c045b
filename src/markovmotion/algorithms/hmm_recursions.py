"""Hidden Markov model recursions as pure compiled functions: forward, backward, Viterbi.

Rabiner (1989) in log space, and forward-backward also in Rabiner's scaled form (§V.A). Every function takes the model as explicit
arrays (``log_startprob`` (N,), ``transmat`` or ``log_transmat`` (N, N),
``log_frameprob`` (T, N) = log b_j(o_t)) and one sequence; nothing is hidden
in objects, so the same code serves the Gaussian HMM, the dual HMM and the
windowed (fixed-lag) Viterbi decoder.

The sums over predecessor states are log-sum-exps computed with the usual
max shift: ``log sum_i exp(a_i) T_ij = m + log sum_i exp(a_i - m) T_ij``,
``m = max_i a_i`` -- one exponential per state rather than one per
transition, and no underflow whatever the sequence length (every frame is
renormalised by its own maximum).
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True)
def _shifted_exp(v, out):  # pragma: no cover - numba
    m = -np.inf
    for i in range(v.shape[0]):
        if v[i] > m:
            m = v[i]
    if m == -np.inf:
        out[:] = 0.0
        return m
    for i in range(v.shape[0]):
        out[i] = np.exp(v[i] - m)
    return m


@numba.njit(cache=True, nogil=True)
def _forward(log_startprob, transmat, log_frameprob):  # pragma: no cover - numba
    n_t, n = log_frameprob.shape
    log_alpha = np.empty((n_t, n))
    p = np.empty(n)
    for j in range(n):
        log_alpha[0, j] = log_startprob[j] + log_frameprob[0, j]
    for t in range(1, n_t):
        m = _shifted_exp(log_alpha[t - 1], p)
        acc = np.dot(p, transmat)
        for j in range(n):
            log_alpha[t, j] = np.log(acc[j]) + m + log_frameprob[t, j]
    m = _shifted_exp(log_alpha[n_t - 1], p)
    if m == -np.inf:
        return log_alpha, m
    return log_alpha, m + np.log(np.sum(p))


@numba.njit(cache=True, nogil=True)
def _backward(transmat, log_frameprob):  # pragma: no cover - numba
    n_t, n = log_frameprob.shape
    log_beta = np.empty((n_t, n))
    log_beta[n_t - 1] = 0.0
    v = np.empty(n)
    p = np.empty(n)
    for t in range(n_t - 2, -1, -1):
        for j in range(n):
            v[j] = log_frameprob[t + 1, j] + log_beta[t + 1, j]
        m = _shifted_exp(v, p)
        acc = np.dot(transmat, p)
        for i in range(n):
            log_beta[t, i] = np.log(acc[i]) + m
    return log_beta


@numba.njit(cache=True, nogil=True)
def _transition_counts(
    log_alpha, log_beta, transmat, log_frameprob, log_likelihood
):  # pragma: no cover
    n_t, n = log_frameprob.shape
    counts = np.zeros((n, n))
    u = np.empty(n)
    v = np.empty(n)
    w = np.empty(n)
    for t in range(n_t - 1):
        mu = _shifted_exp(log_alpha[t], u)
        for j in range(n):
            w[j] = log_frameprob[t + 1, j] + log_beta[t + 1, j]
        mv = _shifted_exp(w, v)
        if mu == -np.inf or mv == -np.inf:
            continue
        scale = np.exp(mu + mv - log_likelihood)
        for i in range(n):
            ui = u[i] * scale
            for j in range(n):
                counts[i, j] += ui * transmat[i, j] * v[j]
    return counts


@numba.njit(cache=True, nogil=True)
def _forward_scaling(startprob, transmat, frameprob):  # pragma: no cover - numba
    n_t, n = frameprob.shape
    alpha = np.empty((n_t, n))
    scale = np.empty(n_t)
    for t in range(n_t):
        if t == 0:
            for j in range(n):
                alpha[0, j] = startprob[j] * frameprob[0, j]
        else:
            acc = np.dot(alpha[t - 1], transmat)
            for j in range(n):
                alpha[t, j] = acc[j] * frameprob[t, j]
        total = alpha[t].sum()
        if not total > 0.0:
            return alpha, scale, t
        scale[t] = 1.0 / total
        alpha[t] *= scale[t]
    return alpha, scale, -1


@numba.njit(cache=True, nogil=True)
def _backward_scaling(transmat, frameprob, scale):  # pragma: no cover - numba
    n_t, n = frameprob.shape
    beta = np.empty((n_t, n))
    beta[n_t - 1] = scale[n_t - 1]
    for t in range(n_t - 2, -1, -1):
        beta[t] = np.dot(transmat, frameprob[t + 1] * beta[t + 1]) * scale[t]
    return beta


@numba.njit(cache=True, nogil=True)
def _transition_counts_scaling(alpha, beta, transmat, frameprob):  # pragma: no cover - numba
    n_t, n = frameprob.shape
    counts = np.zeros((n, n))
    for t in range(n_t - 1):
        for i in range(n):
            for j in range(n):
                counts[i, j] += alpha[t, i] * transmat[i, j] * frameprob[t + 1, j] * beta[t + 1, j]
    return counts


@numba.njit(cache=True, nogil=True)
def viterbi_kernel(log_startprob, log_transmat, log_frameprob):  # pragma: no cover - numba
    """Compiled Viterbi without checks, for hot loops (the windowed decoder's every frame);
    returns (path, log probability).

    delta_t(j) = max_i [delta_{t-1}(i) + log a_ij] + log b_j(o_t) (dual-HMM paper eq. 2,
    Rabiner's recursion in log space) as a max-plus product swept over predecessors i:
    each row log a_i. (C-contiguous) updates all N destinations at once, a branch-free
    select that LLVM turns into SIMD max and blend, the argmax kept as an index array.
    Rows with delta_{t-1}(i) = -inf are skipped (they can never win), so the first
    transition of a window started one-hot (eq. 4) costs N operations, not N^2. Ties go
    to the lowest i, as a scalar scan with a strict ``>`` would."""
    n_t, n = log_frameprob.shape
    delta = np.empty(n)
    best = np.empty(n)
    back = np.empty((n_t, n), dtype=np.int64)
    for j in range(n):
        delta[j] = log_startprob[j] + log_frameprob[0, j]
    for t in range(1, n_t):
        arg = back[t]
        for j in range(n):
            best[j] = -np.inf
            arg[j] = 0
        for i in range(n):
            d = delta[i]
            if d == -np.inf:
                continue
            row = log_transmat[i]
            for j in range(n):
                s = d + row[j]
                better = s > best[j]
                best[j] = s if better else best[j]
                arg[j] = i if better else arg[j]
        for j in range(n):
            delta[j] = best[j] + log_frameprob[t, j]
    path = np.empty(n_t, dtype=np.int64)
    path[n_t - 1] = np.argmax(delta)
    for t in range(n_t - 1, 0, -1):
        path[t - 1] = back[t, path[t]]
    return path, delta[path[n_t - 1]]


def _check(log_frameprob: np.ndarray, n: int) -> np.ndarray:
    log_frameprob = np.ascontiguousarray(log_frameprob, dtype=float)
    if log_frameprob.ndim != 2 or log_frameprob.shape[1] != n or len(log_frameprob) == 0:
        raise ValueError(f"log_frameprob must be (T >= 1, {n}), got {log_frameprob.shape}")
    return log_frameprob


def forward(
    log_startprob: np.ndarray, transmat: np.ndarray, log_frameprob: np.ndarray
) -> tuple[np.ndarray, float]:
    """Forward pass: log alpha_t(j) = log P(o_1..o_t, q_t = j) (T, N) and log P(O)."""
    log_startprob = np.ascontiguousarray(log_startprob, dtype=float)
    log_frameprob = _check(log_frameprob, len(log_startprob))
    log_alpha, ll = _forward(log_startprob, np.ascontiguousarray(transmat, float), log_frameprob)
    return log_alpha, float(ll)


def backward(transmat: np.ndarray, log_frameprob: np.ndarray) -> np.ndarray:
    """Backward pass: log beta_t(i) = log P(o_t+1..o_T | q_t = i), (T, N)."""
    transmat = np.ascontiguousarray(transmat, dtype=float)
    return _backward(transmat, _check(log_frameprob, len(transmat)))


def forward_scaling(
    startprob: np.ndarray, transmat: np.ndarray, frameprob: np.ndarray
) -> tuple[np.ndarray, np.ndarray, float]:
    """Scaled forward pass (Rabiner eqs. 91-92): alpha-hat (T, N), each row summing to one,
    the scale factors c_t = 1 / sum_j alpha-tilde_t(j) (T,) and log P(O) = -sum_t log c_t.

    Works on the frame likelihoods b_j(o_t) themselves (no logarithms): faster, but a frame
    unlikely under every state underflows to zero, which is refused (ValueError) -- the log
    recursions (:func:`forward`) have no such limit.
    """
    frameprob = np.ascontiguousarray(frameprob, dtype=float)
    startprob = np.ascontiguousarray(startprob, dtype=float)
    if frameprob.ndim != 2 or frameprob.shape[1] != len(startprob) or len(frameprob) == 0:
        raise ValueError(f"frameprob must be (T >= 1, {len(startprob)}), got {frameprob.shape}")
    alpha, scale, bad = _forward_scaling(
        startprob, np.ascontiguousarray(transmat, float), frameprob
    )
    if bad >= 0:
        raise ValueError(
            f"scaled forward pass underflowed at frame {bad} (every state's likelihood is 0); "
            "use implementation='log'"
        )
    return alpha, scale, float(-np.log(scale).sum())


def backward_scaling(transmat: np.ndarray, frameprob: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """Scaled backward pass with the forward pass's scale factors: beta-hat (T, N)."""
    return _backward_scaling(
        np.ascontiguousarray(transmat, dtype=float),
        np.ascontiguousarray(frameprob, dtype=float),
        np.ascontiguousarray(scale, dtype=float),
    )


def forward_backward(
    log_startprob: np.ndarray,
    transmat: np.ndarray,
    log_frameprob: np.ndarray,
    implementation: str = "log",
) -> tuple[float, np.ndarray, np.ndarray]:
    """E-step statistics of one sequence (Rabiner eqs. 27, 37-38).

    ``implementation``: ``"log"`` (log space, never underflows) or ``"scaling"`` (Rabiner's
    scaled recursions on exp(log_frameprob); ValueError when a frame underflows).

    Returns:
        log P(O); the state posteriors gamma (T, N); the expected transition
        counts sum_t xi_t(i, j) (N, N).
    """
    transmat = np.ascontiguousarray(transmat, dtype=float)
    if implementation == "scaling":
        frameprob = np.exp(_check(log_frameprob, len(transmat)))
        alpha, scale, ll = forward_scaling(np.exp(log_startprob), transmat, frameprob)
        beta = _backward_scaling(transmat, frameprob, scale)
        gamma = alpha * beta
        gamma /= gamma.sum(axis=1, keepdims=True)
        return ll, gamma, _transition_counts_scaling(alpha, beta, transmat, frameprob)
    if implementation != "log":
        raise ValueError(f"implementation must be 'log' or 'scaling', got {implementation!r}")
    log_alpha, ll = forward(log_startprob, transmat, log_frameprob)
    log_frameprob = np.ascontiguousarray(log_frameprob, dtype=float)
    log_beta = _backward(transmat, log_frameprob)
    log_gamma = log_alpha + log_beta
    log_gamma -= log_gamma.max(axis=1, keepdims=True)
    gamma = np.exp(log_gamma)
    gamma /= gamma.sum(axis=1, keepdims=True)
    xi = _transition_counts(log_alpha, log_beta, transmat, log_frameprob, ll)
    return ll, gamma, xi


def viterbi(
    log_startprob: np.ndarray, log_transmat: np.ndarray, log_frameprob: np.ndarray
) -> tuple[np.ndarray, float]:
    """The single best state sequence (Rabiner eqs. 32-35): path (T,) and its log probability.

    Ties go to the lowest state index.
    """
    log_startprob = np.ascontiguousarray(log_startprob, dtype=float)
    log_frameprob = _check(log_frameprob, len(log_startprob))
    log_transmat = np.ascontiguousarray(log_transmat, dtype=float)
    path, lp = viterbi_kernel(log_startprob, log_transmat, log_frameprob)
    return path, float(lp)
