"""Closed uniform cubic B-splines approximating silhouette boundaries (interaction paper, §2, eq. 1).

A shape is the n control points Q_0 .. Q_{n-1} of a closed uniform cubic
B-spline; the curve at parameter s in [0, n) is

    r(s) = sum_j b_j(s - k) Q_{(k - 1 + j) mod n},   k = floor(s),

with the uniform cubic basis b_0..b_3. Boundary samples evenly spaced in arc
length from the reference point are given parameters evenly spaced in [0, n),
so sample 0 (the reference point) sits at s = 0 and the control points are
evenly spaced around the silhouette and ordered from it; the control points
are the least-squares fit (Baumberg and Hogg).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np


def _basis(u: np.ndarray) -> np.ndarray:
    """(len(u), 4) uniform cubic B-spline basis values at local parameters u in [0, 1)."""
    u = np.asarray(u, dtype=float)[:, None]
    return np.hstack(
        [
            (1 - u) ** 3 / 6,
            (3 * u**3 - 6 * u**2 + 4) / 6,
            (-3 * u**3 + 3 * u**2 + 3 * u + 1) / 6,
            u**3 / 6,
        ]
    )


@lru_cache(maxsize=16)
def basis_matrix(n_samples: int, n_control: int) -> np.ndarray:
    """(M, n) matrix mapping control points to M curve points at s = n i / M (read-only)."""
    s = n_control * np.arange(n_samples) / n_samples
    k = np.floor(s).astype(int)
    b = _basis(s - k)
    out = np.zeros((n_samples, n_control))
    for j in range(4):
        np.add.at(out, (np.arange(n_samples), (k - 1 + j) % n_control), b[:, j])
    out.setflags(write=False)
    return out


@lru_cache(maxsize=16)
def _fit_matrix(n_samples: int, n_control: int) -> np.ndarray:
    out = np.linalg.pinv(basis_matrix(n_samples, n_control))
    out.setflags(write=False)
    return out


def fit_closed_bspline(samples: np.ndarray, n_control: int = 32) -> np.ndarray:
    """(n, 2) control points of the closed uniform cubic B-spline nearest ``samples`` (M, 2).

    ``samples`` are boundary points evenly spaced in arc length, the first at
    the reference point; least squares over all of them.
    """
    samples = np.asarray(samples, dtype=float)
    return _fit_matrix(len(samples), n_control) @ samples


def evaluate_closed_bspline(control: np.ndarray, n_samples: int = 256) -> np.ndarray:
    """(..., M, 2) curve points at M evenly spaced parameters of control points (..., n, 2)."""
    control = np.asarray(control, dtype=float)
    return basis_matrix(n_samples, control.shape[-2]) @ control


def resample_closed(points: np.ndarray, n_samples: int, start: int = 0) -> np.ndarray:
    """(M, 2) points evenly spaced in arc length around the closed polygon ``points``,
    the first at vertex ``start``."""
    p = np.roll(np.asarray(points, dtype=float), -start, axis=0)
    closed = np.vstack([p, p[:1]])
    seg = np.linalg.norm(np.diff(closed, axis=0), axis=1)
    cum = np.r_[0.0, np.cumsum(seg)]
    t = np.arange(n_samples) * cum[-1] / n_samples
    return np.column_stack([np.interp(t, cum, closed[:, 0]), np.interp(t, cum, closed[:, 1])])
