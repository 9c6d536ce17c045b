"""Gaussian densities, written once for every model: full covariance through Cholesky
factors of the precision (Gaussian and dual HMMs, the dual HMM's trellis distances) and
diagonal (the gait HSMM's output densities), plus the weighted M-step and variance floor.
"""

from __future__ import annotations

import numba
import numpy as np

LOG_2PI = np.log(2.0 * np.pi)


def precision_cholesky(covars: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Upper-triangular P_k with P_k P_k' = inv(Sigma_k), and log det P_k, for (N, D, D) covariances.

    ``(x - mu_k) @ P_k`` whitens a frame, so its squared norm is the squared
    Mahalanobis distance under state k.
    """
    chol = np.linalg.cholesky(covars)
    prec = np.swapaxes(np.linalg.inv(chol), -1, -2)
    return np.ascontiguousarray(prec), -np.log(np.diagonal(chol, axis1=1, axis2=2)).sum(axis=1)


@numba.njit(cache=True, nogil=True)
def _quad_forms(x, means, prec):  # pragma: no cover - numba
    n_t, d = x.shape
    n = means.shape[0]
    out = np.empty((n_t, n))
    diff = np.empty(d)
    for t in range(n_t):
        for k in range(n):
            for a in range(d):
                diff[a] = x[t, a] - means[k, a]
            q = 0.0
            for b in range(d):
                y = 0.0
                for a in range(b + 1):
                    y += diff[a] * prec[k, a, b]
                q += y * y
            out[t, k] = q
    return out


def gaussian_log_density(
    x: np.ndarray, means: np.ndarray, prec: np.ndarray, log_det_prec: np.ndarray
) -> np.ndarray:
    """(T, N) log N(x_t; mu_k, Sigma_k) from :func:`precision_cholesky`'s factors."""
    quad = _quad_forms(np.ascontiguousarray(x, dtype=float), means, np.ascontiguousarray(prec))
    return -0.5 * quad + (log_det_prec - 0.5 * means.shape[1] * LOG_2PI)


def floor_covariances(covars: np.ndarray, floor: float) -> np.ndarray:
    """Covariances (N, D, D) with every eigenvalue raised to at least ``floor`` (a variance floor)."""
    covars = 0.5 * (covars + np.swapaxes(covars, -1, -2))
    vals, vecs = np.linalg.eigh(covars)
    vals = np.maximum(vals, floor)
    return np.einsum("nij,nj,nkj->nik", vecs, vals, vecs)


def weighted_gaussians(
    x: np.ndarray, weights: np.ndarray, floor: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Means (N, D), floored covariances (N, D, D) and masses (N,) of ``x`` under ``weights`` (T, N).

    The M-step of a Gaussian HMM (Rabiner eqs. 52-53 with full covariances);
    also B's state Gaussians from A's posteriors in the dual HMM.
    """
    d = x.shape[1]
    centre = x.mean(axis=0)
    x0 = x - centre
    mass = weights.sum(axis=0)
    safe = np.maximum(mass, 1e-300)[:, None]
    means0 = (weights.T @ x0) / safe
    second = (weights.T @ (x0[:, :, None] * x0[:, None, :]).reshape(len(x), d * d)) / safe
    covars = second.reshape(-1, d, d) - means0[:, :, None] * means0[:, None, :]
    return means0 + centre, floor_covariances(covars, floor), mass


def log_gaussian_diag(x: np.ndarray, means: np.ndarray, variances: np.ndarray) -> np.ndarray:
    """(T, P) log densities of frames x (T, O) under P diagonal Gaussians (P, O)."""
    prec = 1.0 / variances
    quad = (x**2) @ prec.T - 2.0 * x @ (means * prec).T + np.sum(means**2 * prec, axis=1)
    return -0.5 * (quad + np.sum(np.log(variances), axis=1) + x.shape[1] * LOG_2PI)


def state_regressions(
    x: np.ndarray, y: np.ndarray, gamma: np.ndarray, ridge: float = 1.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per state k, the linear regression of ``y`` on ``x`` under the state's weights: the
    conditional mean of a Gaussian over [x, y], E[y | x, k] = mu_y,k + G_k (x - mu_x,k) with
    G_k = S_yx,k (S_xx,k + ridge * v I)^-1, v the mean variance of ``x`` (Gaussian mixture
    regression, as HSMM-GMR in learning from demonstration, one component per state).

    Args:
        x: (T, Dx) inputs; y: (T, Dy) outputs; gamma: (T, K) state posteriors of the frames.
        ridge: the ridge, in units of x's mean variance, that keeps G_k small where a state
            holds few frames.

    Returns:
        means_x (K, Dx), means_y (K, Dy), gains (K, Dy, Dx).
    """
    w = gamma / np.maximum(gamma.sum(axis=0), 1e-300)
    means_x, means_y = w.T @ x, w.T @ y
    lift = ridge * float(x.var(axis=0).mean()) * np.eye(x.shape[1])
    gains = np.empty((len(means_x), y.shape[1], x.shape[1]))
    for k in range(len(means_x)):
        dx, dy = x - means_x[k], y - means_y[k]
        sxx = (dx * w[:, k, None]).T @ dx + lift
        syx = (dy * w[:, k, None]).T @ dx
        gains[k] = np.linalg.solve(sxx, syx.T).T
    return means_x, means_y, gains
