"""Maximum-likelihood parameter generation with global variance (gait paper eqs. 10-15).

Given per-frame Gaussian means and variances of the observations
``o_t = [c_t, dc_t, d2c_t]`` (the layout of :func:`~markovmotion.features.add_deltas`),
:func:`mlpg` finds the static trajectory C maximising ``P(WC | q, lambda)``
(eq. 11, with W of eq. 4 from :func:`delta_matrix`):
``C = (W' S^-1 W)^-1 W' S^-1 mu``. The matrix ``W' S^-1 W`` is banded (half
bandwidth 4, from the delta-delta window), so each dimension is one banded
Cholesky (LDL') solve, O(T) in frames; all dimensions are factored in one
compiled pass (the same factorisation as :func:`scipy.linalg.cholesky_banded`,
which the tests use as the reference).

:func:`mlpg_gv` also maximises the likelihood of the trajectory's global
variance (eqs. 12-15; Toda & Tokuda 2007): ``omega log P(O | q) + log
P(v(C) | lambda_gv)``, by Newton-preconditioned gradient ascent started from
the ML trajectory scaled to the target variance. (The paper's eqs. 12-13
print 1/54 where the average over the T frames, 1/T, is meant.)
"""

from __future__ import annotations

from functools import lru_cache

import numba
import numpy as np
from scipy import sparse

#: Half bandwidth of W' S^-1 W: the widest window (delta-delta) reaches 2 frames each way.
BANDWIDTH = 4


#: Regression windows of eqs. (2) and (3): offsets -> weights.
DELTA_WINDOW = {-1: -0.5, 1: 0.5}
DELTA2_WINDOW = {-2: 0.25, 0: -0.5, 2: 0.25}


def delta_matrix(n_frames: int) -> sparse.csr_matrix:
    """W of eq. (4) for one dimension: (3T, T) with rows [c_t, dc_t, d2c_t] per frame t.

    Frames outside the sequence take the value of the nearest edge frame, so a
    constant sequence has zero deltas everywhere.
    """
    rows, cols, vals = [], [], []
    for t in range(n_frames):
        for block, window in enumerate(({0: 1.0}, DELTA_WINDOW, DELTA2_WINDOW)):
            for off, w in window.items():
                rows.append(3 * t + block)
                cols.append(min(max(t + off, 0), n_frames - 1))
                vals.append(w)
    return sparse.csr_matrix((vals, (rows, cols)), shape=(3 * n_frames, n_frames))


@numba.njit(cache=True)
def _ldl_banded(band):  # pragma: no cover - numba
    """LDL' of D symmetric banded systems at once; band (u+1, T, D) upper form.

    Returns ``low`` (u+1, T, D) with ``low[k, j] = L[j + k, j]`` and ``diag`` (T, D).
    """
    u1, n, dims = band.shape
    u = u1 - 1
    low = np.zeros((u1, n, dims))
    diag = np.empty((n, dims))
    for j in range(n):
        for d in range(dims):
            acc = band[u, j, d]
            for k in range(1, min(u, j) + 1):
                acc -= low[k, j - k, d] ** 2 * diag[j - k, d]
            diag[j, d] = acc
        for k in range(1, u + 1):
            if j + k >= n:
                break
            for d in range(dims):
                acc = band[u - k, j + k, d]
                for m in range(1, u - k + 1):
                    if j - m < 0:
                        break
                    acc -= low[k + m, j - m, d] * low[m, j - m, d] * diag[j - m, d]
                low[k, j, d] = acc / diag[j, d]
    return low, diag


@numba.njit(cache=True)
def _ldl_solve(low, diag, rhs):  # pragma: no cover - numba
    """Solve L D L' x = rhs (T, D) with the factors of :func:`_ldl_banded`."""
    u1, n, dims = low.shape
    u = u1 - 1
    x = rhs.copy()
    for i in range(n):
        for k in range(1, min(u, i) + 1):
            for d in range(dims):
                x[i, d] -= low[k, i - k, d] * x[i - k, d]
    for i in range(n):
        for d in range(dims):
            x[i, d] /= diag[i, d]
    for i in range(n - 1, -1, -1):
        for k in range(1, min(u, n - 1 - i) + 1):
            for d in range(dims):
                x[i, d] -= low[k, i, d] * x[i + k, d]
    return x


@lru_cache(maxsize=8)
def _band_operators(n_frames: int) -> tuple[sparse.csr_matrix, sparse.csr_matrix]:
    """W' (T, 3T) and the map M (3T, 5T) from precisions to upper-band entries of W' S^-1 W.

    Column ``(u + i - j) * T + j`` of M is band entry (i, j), i <= j, in the
    upper form of :func:`scipy.linalg.solveh_banded`; row r of M holds
    ``W[r, i] * W[r, j]``, so that ``band = precision @ M``.
    """
    w = delta_matrix(n_frames).tocsr()
    w.sort_indices()
    u, n = BANDWIDTH, n_frames
    counts = np.diff(w.indptr)
    width = int(counts.max())
    rows = np.repeat(np.arange(w.shape[0]), counts)
    slot = np.arange(len(w.indices)) - np.repeat(w.indptr[:-1], counts)
    cols = np.full((w.shape[0], width), -1)
    vals = np.zeros((w.shape[0], width))
    cols[rows, slot] = w.indices
    vals[rows, slot] = w.data
    a, b = np.meshgrid(np.arange(width), np.arange(width), indexing="ij")
    ci, cj = cols[:, a.ravel()], cols[:, b.ravel()]
    keep = (ci >= 0) & (cj >= 0) & (ci <= cj)
    r = np.broadcast_to(np.arange(w.shape[0])[:, None], ci.shape)[keep]
    flat = (u + ci[keep] - cj[keep]) * n + cj[keep]
    val = (vals[:, a.ravel()] * vals[:, b.ravel()])[keep]
    m = sparse.csr_matrix((val, (r, flat)), shape=(w.shape[0], (u + 1) * n))
    return w.T.tocsr(), m


def _interleave(x: np.ndarray) -> np.ndarray:
    """(T, 3D) [c, dc, d2c] blocks -> (3T, D) rows ordered as W's rows (frame-major)."""
    t, three_d = x.shape
    return x.reshape(t, 3, three_d // 3).reshape(3 * t, three_d // 3)


def _normal_equations(means: np.ndarray, variances: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Upper bands (u+1, T, D) of W' S^-1 W and right-hand sides W' S^-1 mu (T, D)."""
    means = np.asarray(means, dtype=float)
    variances = np.asarray(variances, dtype=float)
    if means.ndim != 2 or means.shape[1] % 3 or means.shape != variances.shape:
        raise ValueError("means and variances must both be (T, 3D) [static, delta, delta-delta]")
    n = len(means)
    wt, m = _band_operators(n)
    prec = _interleave(1.0 / variances)
    rhs = wt @ (prec * _interleave(means))
    band = np.ascontiguousarray((m.T @ prec).reshape(BANDWIDTH + 1, n, -1))
    return band, rhs


def mlpg(means: np.ndarray, variances: np.ndarray) -> np.ndarray:
    """Static trajectory (T, D) maximising the likelihood of [c, dc, d2c] (eqs. 10-11).

    Args:
        means, variances: (T, 3D) per-frame Gaussian parameters of the
            observation vectors, static block first (diagonal covariances).
    """
    band, rhs = _normal_equations(means, variances)
    return _ldl_solve(*_ldl_banded(band), rhs)


def _band_matvec(band: np.ndarray, c: np.ndarray) -> np.ndarray:
    """P c for symmetric P stored as upper bands (u+1, T, D), c (T, D)."""
    u = band.shape[0] - 1
    out = band[u] * c
    for k in range(1, u + 1):
        upper = band[u - k, k:]
        out[:-k] += upper * c[k:]
        out[k:] += upper * c[:-k]
    return out


def global_variance(c: np.ndarray) -> np.ndarray:
    """v(C) of eqs. 12-14: the variance over frames of each static dimension."""
    return np.var(np.asarray(c, dtype=float), axis=0)


def mlpg_gv(
    means: np.ndarray,
    variances: np.ndarray,
    gv_mean: np.ndarray,
    gv_var: np.ndarray,
    weight: float | None = None,
    n_iter: int = 20,
) -> np.ndarray:
    """Static trajectory (T, D) maximising ``omega log P(WC | q) + log N(v(C); gv_mean, gv_var)`` (eq. 15).

    Args:
        means, variances: (T, 3D) as for :func:`mlpg`.
        gv_mean, gv_var: (D,) Gaussian of the global variance (eq. 14) over
            training sequences.
        weight: omega; by default 1 / (3T), the ratio of the dimensions of
            v(C) and O (Toda & Tokuda).
        n_iter: gradient steps, each a banded solve per dimension with step
            halving wherever the objective would fall.
    """
    band, rhs = _normal_equations(means, variances)
    n, dims = rhs.shape
    omega = 1.0 / (3 * n) if weight is None else weight
    gv_mean = np.asarray(gv_mean, dtype=float)
    gv_prec = 1.0 / np.asarray(gv_var, dtype=float)
    factors = _ldl_banded(band)

    def solve(x: np.ndarray) -> np.ndarray:
        return _ldl_solve(*factors, x)

    def objective(c: np.ndarray) -> np.ndarray:
        hmm = -0.5 * np.sum(c * _band_matvec(band, c), axis=0) + np.sum(rhs * c, axis=0)
        return omega * hmm - 0.5 * gv_prec * (global_variance(c) - gv_mean) ** 2

    c_ml = solve(rhs)
    centre = c_ml.mean(axis=0)
    v_ml = global_variance(c_ml)
    scale = np.sqrt(np.divide(gv_mean, v_ml, out=np.ones(dims), where=v_ml > 1e-12))
    c = centre + scale * (c_ml - centre)
    value = objective(c)
    step = np.ones(dims)
    for _ in range(n_iter):
        dev = c - c.mean(axis=0)
        grad = (
            omega * (rhs - _band_matvec(band, c))
            - (gv_prec * (global_variance(c) - gv_mean) * 2.0 / n) * dev
        )
        direction = solve(grad) / omega
        for _ in range(8):
            trial = c + step * direction
            new = objective(trial)
            better = new >= value
            if better.all():
                break
            step = np.where(better, step, 0.5 * step)
        c = np.where(better, trial, c)
        value = np.where(better, new, value)
        step = np.minimum(2.0 * step, 1.0)
    return c
