"""Shared algorithms: Hermite interpolation, vector quantisation, DTW, batched kinematics."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from conftest import make_motion
from scipy.spatial.transform import Rotation

from markovmotion.algorithms.dtw import (
    dtw_distance,
    dtw_distance_matrix,
    dtw_path,
    open_end_dtw,
)
from markovmotion.algorithms.hermite import constant_acceleration_intervals, hermite_sample
from markovmotion.algorithms.kinematics import fit_rotations, rotvec_positions
from markovmotion.algorithms.vector_quantisation import (
    collapse_repeats,
    competitive_learning,
    kmeans_prototypes,
    nearest_prototype,
)


# ------------------------------------------------------------------ Hermite
def test_hermite_passes_through_knots_with_given_tangents():
    rng = np.random.default_rng(0)
    knots, tangents = rng.normal(size=(5, 3)), rng.normal(size=(5, 3))
    times = np.cumsum(np.r_[0.0, rng.uniform(0.5, 2.0, 4)])
    assert np.allclose(hermite_sample(knots, tangents, times, times), knots)
    h = 1e-6
    slope = (
        hermite_sample(knots, tangents, times, times[1:-1] + h)
        - hermite_sample(knots, tangents, times, times[1:-1] - h)
    ) / (2 * h)
    assert np.allclose(slope, tangents[1:-1], atol=1e-5)


def test_hermite_reproduces_a_cubic_and_works_on_batches():
    poly = np.poly1d([0.5, -1.0, 2.0, 3.0])
    times = np.array([0.0, 1.0, 2.5, 4.0])
    knots, tangents = poly(times)[:, None], poly.deriv()(times)[:, None]
    t = np.linspace(0, 4, 41)
    assert np.allclose(hermite_sample(knots, tangents, times, t)[:, 0], poly(t))
    batch = hermite_sample(
        np.stack([knots, 2 * knots]), np.stack([tangents, 2 * tangents]), np.stack([times] * 2), t
    )
    assert np.allclose(batch[1], 2 * batch[0])


def test_constant_acceleration_intervals_eq8():
    c = np.array([[0.0, 0.0], [3.0, 4.0], [3.0, 4.0]])
    dc = np.array([[1.0, 0.0], [0.0, 4.0], [0.0, 0.0]])
    tau = constant_acceleration_intervals(c, dc, min_interval=0.0, max_interval=100.0)
    assert tau[0] == pytest.approx(2 * 5 / (1 + 4))
    assert tau[1] == 0.0  # no distance to travel
    assert constant_acceleration_intervals(c[[0, 0]] + [[0, 0], [1, 0]], 0 * dc[:2])[0] == np.inf


# ------------------------------------------------------- vector quantisation
def test_collapse_repeats():
    tokens, starts = collapse_repeats(np.array([3, 3, 1, 1, 1, 3, 2, 2]))
    assert tokens.tolist() == [3, 1, 3, 2]
    assert starts.tolist() == [0, 2, 5, 6]


@pytest.mark.parametrize("method", ["kmeans", "competitive"])
def test_prototypes_find_separated_clusters(method):
    rng = np.random.default_rng(1)
    centres = np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 10.0], [10.0, 10.0]])
    x = np.vstack([c + rng.normal(scale=0.3, size=(200, 2)) for c in centres])
    if method == "kmeans":
        protos = kmeans_prototypes(x, 4)
    else:
        protos = competitive_learning(x, 4, n_epochs=3)
    assert np.abs(np.sort(protos, axis=0) - np.sort(centres, axis=0)).max() < 0.5
    tokens = nearest_prototype(x, protos)
    assert len(np.unique(tokens)) == 4
    assert all(len(np.unique(tokens[i * 200 : (i + 1) * 200])) == 1 for i in range(4))


# ---------------------------------------------------------------------- DTW
def _brute_force_dtw(a: np.ndarray, b: np.ndarray) -> float:
    """Least cost over every monotone path, by enumerating step sequences."""
    n, m = len(a), len(b)
    best = np.inf
    steps = [(1, 0), (0, 1), (1, 1)]
    for k in range(max(n, m) - 1, n + m - 1):
        for seq in itertools.product(steps, repeat=k):
            i = j = 0
            cost = np.linalg.norm(a[0] - b[0])
            for di, dj in seq:
                i, j = i + di, j + dj
                if i >= n or j >= m:
                    break
                cost += np.linalg.norm(a[i] - b[j])
            else:
                if (i, j) == (n - 1, m - 1):
                    best = min(best, cost)
    return best


def test_dtw_agrees_with_brute_force():
    rng = np.random.default_rng(2)
    a, b = rng.normal(size=(4, 2)), rng.normal(size=(3, 2))
    assert dtw_distance(a, b) == pytest.approx(_brute_force_dtw(a, b))
    cost, path = dtw_path(a, b)
    assert cost == pytest.approx(dtw_distance(a, b))
    assert path[0].tolist() == [0, 0] and path[-1].tolist() == [3, 2]
    assert cost == pytest.approx(sum(np.linalg.norm(a[i] - b[j]) for i, j in path))


def test_open_end_dtw_finds_the_matching_prefix():
    template = np.arange(10.0)
    observed = np.array([0.0, 1.0, 1.0, 2.0, 3.0, 4.0])  # the template up to 4, slowed
    cost, tau = open_end_dtw(observed, template)
    assert cost == 0.0 and tau == 5
    d = dtw_distance_matrix([template, observed, template + 1])
    # shifting by one costs only the two unmatched ends once warping is allowed
    assert d[0, 0] == 0 and d[0, 1] == d[1, 0] and d[0, 2] == pytest.approx(2.0)


# --------------------------------------------------------------- kinematics
def test_batched_fk_and_ik_agree_with_motion():
    m = make_motion(30)
    pos = m.positions()
    rv = Rotation.from_quat(m.rotations.reshape(-1, 4)).as_rotvec().reshape(30, -1, 3)
    assert np.allclose(rotvec_positions(m.skeleton, rv, m.translations[:, 0]), pos, atol=1e-9)
    part = rotvec_positions(m.skeleton, rv, m.translations[:, 0], joints=np.array([4, 1]))
    assert np.allclose(part, pos[:, [4, 1]], atol=1e-9)
    assert np.allclose(fit_rotations(m.skeleton, pos, m.fps).positions(), pos, atol=1e-6)
