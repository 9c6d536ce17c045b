"""MLPG (gait paper eqs. 10-11) against the dense solution; global variance (eqs. 12-15)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import solveh_banded

from markovmotion.algorithms.mlpg import (
    _ldl_banded,
    _ldl_solve,
    _normal_equations,
    global_variance,
    mlpg,
    mlpg_gv,
)
from markovmotion.features import add_deltas, delta_matrix


def random_case(t_len: int, dims: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    return rng.normal(size=(t_len, 3 * dims)), rng.uniform(0.1, 2.0, size=(t_len, 3 * dims))


def dense_mlpg(means: np.ndarray, variances: np.ndarray) -> np.ndarray:
    """(W' S^-1 W)^-1 W' S^-1 mu per dimension, with W of eq. (4) as a dense matrix."""
    t_len, three_d = means.shape
    dims = three_d // 3
    w = delta_matrix(t_len).toarray()
    out = np.empty((t_len, dims))
    for d in range(dims):
        mu = means[:, [d, dims + d, 2 * dims + d]].ravel()  # rows [c_t, dc_t, d2c_t] per frame
        prec = np.diag(1.0 / variances[:, [d, dims + d, 2 * dims + d]].ravel())
        out[:, d] = np.linalg.solve(w.T @ prec @ w, w.T @ prec @ mu)
    return out


@pytest.mark.parametrize(("t_len", "dims"), [(1, 1), (2, 2), (5, 1), (17, 3)])
def test_mlpg_equals_dense_solve(t_len, dims):
    means, variances = random_case(t_len, dims, seed=t_len)
    np.testing.assert_allclose(mlpg(means, variances), dense_mlpg(means, variances), atol=1e-10)


def test_banded_factorisation_matches_scipy():
    means, variances = random_case(40, 4, seed=7)
    band, rhs = _normal_equations(means, variances)
    ours = _ldl_solve(*_ldl_banded(band), rhs)
    ref = np.column_stack([solveh_banded(band[:, :, d], rhs[:, d]) for d in range(4)])
    np.testing.assert_allclose(ours, ref, atol=1e-12)


def test_huge_delta_variances_give_the_static_means():
    means, variances = random_case(30, 3, seed=2)
    variances[:, 3:] = 1e12
    np.testing.assert_allclose(mlpg(means, variances), means[:, :3], atol=1e-9)


def test_consistent_means_are_reproduced():
    """Means that are the deltas of a trajectory give that trajectory back."""
    rng = np.random.default_rng(5)
    c = np.cumsum(rng.normal(size=(50, 2)), axis=0)
    np.testing.assert_allclose(mlpg(add_deltas(c), np.ones((50, 6))), c, atol=1e-9)


def test_global_variance_reaches_its_target():
    rng = np.random.default_rng(1)
    t = np.arange(200)
    smooth = np.column_stack([np.sin(t / 8.0), np.cos(t / 5.0)])
    means = add_deltas(smooth)
    variances = np.hstack([np.full((200, 2), 1.0), np.full((200, 4), 0.01)])
    means[:, :2] += rng.normal(scale=0.3, size=(200, 2))
    ml = mlpg(means, variances)
    target = 1.5 * global_variance(ml)
    gv = mlpg_gv(means, variances, target, 1e-4 * target**2)
    np.testing.assert_allclose(global_variance(gv), target, rtol=0.02)
    # the shape of the ML trajectory is kept: strongly correlated with it
    for d in range(2):
        assert np.corrcoef(gv[:, d], ml[:, d])[0, 1] > 0.95


def test_gv_at_the_ml_variance_changes_nothing():
    means, variances = random_case(60, 2, seed=9)
    ml = mlpg(means, variances)
    gv = mlpg_gv(means, variances, global_variance(ml), np.ones(2))
    np.testing.assert_allclose(gv, ml, atol=1e-6)


def test_bad_shapes_are_refused():
    with pytest.raises(ValueError, match="3D"):
        mlpg(np.zeros((4, 5)), np.ones((4, 5)))
