"""Gaussian densities, written once for every model: full covariance through Cholesky
factors of the precision (Gaussian and dual HMMs, the dual HMM's trellis distances) and
diagonal (the gait HSMM's output densities); hmmlearn's four covariance types (``full``,
``diag``, ``spherical``, ``tied``) in their compact forms; the weighted M-step with
hmmlearn's conjugate priors, and a per-feature variance floor.
"""

from __future__ import annotations

from typing import Any

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


# ------------------------------------------------------------------ covariance types
COVARIANCE_TYPES = ("full", "diag", "spherical", "tied")


def check_covariance_type(covariance_type: str) -> str:
    """``covariance_type`` if it is one of :data:`COVARIANCE_TYPES`, else ValueError."""
    if covariance_type not in COVARIANCE_TYPES:
        raise ValueError(
            f"covariance_type must be one of {COVARIANCE_TYPES}, got {covariance_type!r}"
        )
    return covariance_type


def compact_covariances(covars: Any, covariance_type: str, n: int) -> np.ndarray:
    """Covariances in their stored (compact) form, checked as hmmlearn checks them: spherical
    (N,) positive variances, diag (N, D) positive, full (N, D, D) and tied (D, D) symmetric
    positive definite. A copy; ValueError naming the problem otherwise."""
    check_covariance_type(covariance_type)
    c = np.array(covars, dtype=float, copy=True)
    if covariance_type == "spherical":
        c = c.reshape(-1) if c.size == n else c
        if c.shape != (n,) or not np.all(c > 0):
            raise ValueError(f"'spherical' covars must be {n} positive variances, got {c.shape}")
        return c
    if covariance_type == "diag":
        if c.ndim != 2 or len(c) != n or not np.all(c > 0):
            raise ValueError(f"'diag' covars must be ({n}, n_features) positive variances")
        return c
    mats = c[None] if covariance_type == "tied" else c
    want = "(n_features, n_features)" if covariance_type == "tied" else f"({n}, D, D)"
    if c.ndim != (2 if covariance_type == "tied" else 3) or mats.shape[1] != mats.shape[2]:
        raise ValueError(f"'{covariance_type}' covars must have shape {want}, got {c.shape}")
    if covariance_type == "full" and len(c) != n:
        raise ValueError(f"'full' covars must have shape {want}, got {c.shape}")
    if not np.allclose(mats, np.swapaxes(mats, 1, 2)) or not np.all(np.linalg.eigvalsh(mats) > 0):
        raise ValueError(f"'{covariance_type}' covars must be symmetric positive definite")
    return c


def full_covariances(covars: np.ndarray, covariance_type: str, n: int, d: int) -> np.ndarray:
    """(N, D, D) covariance matrices from the compact form of ``covariance_type``."""
    if covariance_type == "full":
        return covars
    if covariance_type == "diag":
        return np.einsum("nd,de->nde", covars, np.eye(d))
    if covariance_type == "tied":
        return np.broadcast_to(covars, (n, d, d)).copy()
    return np.asarray(covars).reshape(-1)[:, None, None] * np.eye(d)


def compact_of_full(full: np.ndarray, covariance_type: str) -> np.ndarray:
    """The compact form of ``covariance_type`` nearest full (N, D, D) covariances: their
    diagonals (diag), mean diagonal (spherical), mean matrix (tied)."""
    if covariance_type == "full":
        return full
    diag = np.diagonal(full, axis1=1, axis2=2)
    if covariance_type == "diag":
        return diag.copy()
    if covariance_type == "spherical":
        return diag.mean(axis=1)
    return full.mean(axis=0)


def floor_covariances(covars: np.ndarray, floor: Any, covariance_type: str = "full") -> np.ndarray:
    """Covariances (compact form) floored feature by feature at ``floor`` (scalar or (D,)).

    Diagonal: each variance at least its feature's floor; spherical: at least the mean floor;
    full and tied: Sigma seen in units of the floor, F^-1/2 Sigma F^-1/2 with F = diag(floor),
    has every eigenvalue raised to at least 1 (so the variance along any direction u is at
    least u'Fu, and a scalar floor is the plain eigenvalue floor).
    """
    if covariance_type == "diag":
        return np.maximum(covars, floor)
    if covariance_type == "spherical":
        return np.maximum(covars, float(np.mean(floor)))
    mats = covars[None] if covariance_type == "tied" else covars
    scale = np.sqrt(np.broadcast_to(np.asarray(floor, dtype=float), mats.shape[-1:]))
    rel = mats / scale[:, None] / scale[None, :]
    rel = 0.5 * (rel + np.swapaxes(rel, -1, -2))
    vals, vecs = np.linalg.eigh(rel)
    rel = np.einsum("nij,nj,nkj->nik", vecs, np.maximum(vals, 1.0), vecs)
    out = rel * scale[:, None] * scale[None, :]
    return out[0] if covariance_type == "tied" else out


def gaussian_m_step(
    x: np.ndarray,
    weights: np.ndarray,
    covariance_type: str = "full",
    means_prior: Any = 0.0,
    means_weight: Any = 0.0,
    covars_prior: Any = 0.0,
    covars_weight: Any = 0.0,
    means: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """MAP means (N, D), compact covariances and state masses (N,) of ``x`` under ``weights``
    (T, N): Rabiner eqs. 52-53 with hmmlearn's conjugate priors (a normal prior of mean
    ``means_prior`` and weight ``means_weight`` on the means; inverse gamma on diagonal or
    spherical variances, inverse Wishart on full or tied ones, of scale ``covars_prior`` and
    weight ``covars_weight``). With zero priors these are the weighted maximum-likelihood
    Gaussians. The scatter is taken about each state's own mean (no cancellation when the
    means lie far from the origin). ``means`` given: the covariances are taken about them
    and returned as the means (hmmlearn's M-step when the means are not re-estimated).
    """
    d = x.shape[1]
    mass = weights.sum(axis=0)
    denom = mass[:, None]
    if means is None:
        means = (means_weight * np.asarray(means_prior) + weights.T @ x) / (means_weight + denom)
    meandiff = means - means_prior
    if covariance_type in ("diag", "spherical"):
        scatter = np.stack([w @ (x - m) ** 2 for w, m in zip(weights.T, means, strict=True)])
        c_n = means_weight * meandiff**2 + scatter
        c_d = max(covars_weight - 1, 0) + denom
        covars = (covars_prior + c_n) / np.maximum(c_d, 1e-5)
        return means, covars.mean(axis=1) if covariance_type == "spherical" else covars, mass
    scatter = np.empty((len(means), d, d))
    for k, (w, m) in enumerate(zip(weights.T, means, strict=True)):
        diff = x - m
        scatter[k] = (diff * w[:, None]).T @ diff
    c_n = means_weight * np.asarray(meandiff)[:, :, None] * meandiff[:, None, :] + scatter
    c_n = np.broadcast_to(c_n, (len(means), d, d))
    extra = max(covars_weight - d, 0)
    if covariance_type == "tied":
        return means, (covars_prior + c_n.sum(axis=0)) / (extra + mass.sum()), mass
    return means, (covars_prior + c_n) / (extra + mass[:, None, None]), mass


def covariance_floor(x: np.ndarray, min_covar: float, var_floor: float) -> np.ndarray:
    """Per-feature variance floor (D,): ``max(min_covar, var_floor * Var(x[:, j]))`` -- absolute,
    or relative to each feature's own variance (never to the mean over features)."""
    spread = np.var(x, axis=0) if len(x) > 1 else np.zeros(x.shape[1])
    return np.maximum(float(min_covar), float(var_floor) * spread)


def log_density(
    x: np.ndarray, means: np.ndarray, covars: np.ndarray, covariance_type: str
) -> np.ndarray:
    """(T, N) log N(x_t; mu_k, Sigma_k) for compact covariances of any type."""
    if covariance_type in ("diag", "spherical"):
        var = covars if covariance_type == "diag" else covars[:, None] * np.ones(means.shape[1])
        return log_gaussian_diag(x, means, var)
    full = full_covariances(covars, covariance_type, len(means), means.shape[1])
    return gaussian_log_density(x, means, *precision_cholesky(full))
