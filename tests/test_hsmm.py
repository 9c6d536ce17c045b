"""Explicit-duration HSMM: forward-backward against brute force, EM recovery, clustering, CMLLR."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy.special import logsumexp

from markovmotion.algorithms.gaussian import log_gaussian_diag
from markovmotion.algorithms.hsmm_recursions import duration_log_pmf, forward_backward
from markovmotion.models.gait.adaptation import (
    METHODS,
    RegressionTree,
    adapt,
    adaptation_statistics,
    estimate_transforms,
    identity_transform,
    transform_blocks,
    walker_adaptive_training,
)
from markovmotion.models.gait.context_tree import cluster_state
from markovmotion.models.gait.hsmm import HSMM
from markovmotion.state import estimator_state, restore_estimator


def brute_force(log_b: np.ndarray, log_dur: np.ndarray):
    """Every way of splitting T frames among the N states in order, each 1..Dmax frames."""
    t_len, n = log_b.shape
    dmax = log_dur.shape[1]
    scores, paths = [], []
    for ds in itertools.product(range(1, dmax + 1), repeat=n):
        if sum(ds) != t_len:
            continue
        states = np.repeat(np.arange(n), ds)
        scores.append(
            sum(log_dur[k, d - 1] for k, d in enumerate(ds)) + log_b[np.arange(t_len), states].sum()
        )
        paths.append((ds, states))
    scores = np.array(scores)
    total = logsumexp(scores)
    gamma = np.zeros((t_len, n))
    dur_post = np.zeros((n, dmax))
    for w, (ds, states) in zip(np.exp(scores - total), paths, strict=True):
        gamma[np.arange(t_len), states] += w
        for k, d in enumerate(ds):
            dur_post[k, d - 1] += w
    return total, gamma, dur_post


@pytest.mark.parametrize(
    ("t_len", "n", "dmax", "seed"), [(9, 3, 5, 0), (7, 2, 6, 1), (10, 4, 4, 2)]
)
def test_forward_backward_equals_enumeration(t_len, n, dmax, seed):
    rng = np.random.default_rng(seed)
    log_b = rng.normal(size=(t_len, n))
    log_dur = np.log(rng.dirichlet(np.ones(dmax), size=n))
    ll, gamma, dur_post = forward_backward(log_b, log_dur)
    ref_ll, ref_gamma, ref_dur = brute_force(log_b, log_dur)
    assert ll == pytest.approx(ref_ll, abs=1e-10)
    np.testing.assert_allclose(gamma, ref_gamma, atol=1e-12)
    np.testing.assert_allclose(dur_post, ref_dur, atol=1e-12)
    np.testing.assert_allclose(gamma.sum(axis=1), 1.0)


def test_impossible_sequence_has_zero_likelihood():
    log_b = np.zeros((2, 3))  # three states cannot fit in two frames
    ll, gamma, _ = forward_backward(log_b, np.log(np.full((3, 4), 0.25)))
    assert ll == -np.inf and not gamma.any()


def test_duration_pmf_is_normalised_and_peaks_at_mean():
    logp = duration_log_pmf(np.array([3.0, 7.0]), np.array([1.0, 2.0]), 15)
    np.testing.assert_allclose(np.exp(logp).sum(axis=1), 1.0)
    assert list(logp.argmax(axis=1) + 1) == [3, 7]


def test_log_gaussian_matches_scipy():
    from scipy.stats import multivariate_normal

    rng = np.random.default_rng(3)
    x, mu, var = rng.normal(size=(5, 3)), rng.normal(size=(2, 3)), rng.uniform(0.2, 2, (2, 3))
    ref = np.column_stack([multivariate_normal(mu[p], np.diag(var[p])).logpdf(x) for p in range(2)])
    np.testing.assert_allclose(log_gaussian_diag(x, mu, var), ref)


def known_model() -> HSMM:
    """Three states, two contexts sharing the outputs but with their own first-state durations."""
    m = HSMM(n_states=3)
    m.means_ = np.array([[0.0, 0.0], [3.0, 0.0], [0.0, 3.0]])
    m.variances_ = np.full((3, 2), 0.5)
    m.dur_means_ = np.array([3.0, 6.0, 4.0, 8.0])
    m.dur_variances_ = np.array([1.0, 1.5, 1.0, 1.5])
    m.out_map_ = np.array([[0, 1, 2], [0, 1, 2]])
    m.dur_map_ = np.array([[0, 1, 2], [3, 1, 2]])
    m.max_duration_ = 14
    return m


def test_sampled_durations_follow_the_densities():
    """Drawn durations have the frequencies of the discretised densities; speed moves the total."""
    model = known_model()
    contexts = np.array([0, 1])
    rng = np.random.default_rng(4)
    draws = model.durations(np.tile(contexts, 20000), rng=rng).reshape(20000, -1)
    _, dur = model.chain(contexts)
    pmf = np.exp(duration_log_pmf(model.dur_means_, model.dur_variances_, model.max_duration_))
    for k, q in enumerate(dur):
        freq = np.bincount(draws[:, k] - 1, minlength=model.max_duration_) / len(draws)
        np.testing.assert_allclose(freq, pmf[q], atol=0.012)
    again = np.random.default_rng(4)
    np.testing.assert_array_equal(model.durations(contexts, rng=again), draws[0])
    # at speed 1 without rng: the means, rounded; faster and slower paces move the total
    assert list(model.durations(contexts)) == [3, 6, 4, 8, 6, 4]
    # fractional means: the rounded partial sums follow the real ones, so nothing drifts
    model.dur_means_ = np.array([3.3, 3.3, 3.3, 3.3])
    most_likely = model.durations(np.tile(contexts, 10))
    assert most_likely.sum() == 198 and set(most_likely) == {3, 4}  # 60 states x 3.3
    model.dur_means_ = np.array([3.0, 6.0, 4.0, 8.0])
    fast = model.durations(np.tile(contexts, 4000), 1.25, rng).reshape(4000, -1).sum(axis=1)
    slow = model.durations(np.tile(contexts, 4000), 0.8, rng).reshape(4000, -1).sum(axis=1)
    total = model.dur_means_[dur].sum()
    assert fast.mean() == pytest.approx(total / 1.25, abs=0.3)
    assert slow.mean() == pytest.approx(total / 0.8, abs=0.3)


@pytest.fixture(scope="module")
def sampled():
    rng = np.random.default_rng(0)
    true = known_model()
    xs, cs, bs = [], [], []
    for _ in range(40):
        c = rng.integers(0, 2, size=4)
        x, d = true.sample(c, rng)
        xs.append(x)
        cs.append(c)
        bs.append(np.r_[0, np.cumsum(d.reshape(4, 3).sum(axis=1))])
    return true, xs, cs, bs


def test_em_recovers_duration_means(sampled):
    true, xs, cs, bs = sampled
    questions = [np.array([True, False])]
    model = HSMM(n_states=3, n_iter=20, max_duration=14).fit(xs, cs, bs, 2, questions)
    # EM starts from an even split of each unit among its states (all durations equal)
    for ctx in (0, 1):
        est = model.dur_means_[model.dur_map_[ctx]]
        ref = true.dur_means_[true.dur_map_[ctx]]
        np.testing.assert_allclose(est, ref, atol=0.4)
    np.testing.assert_allclose(model.means_[model.out_map_[0]], true.means_, atol=0.15)
    # clustering keeps the two first-state durations apart, and ties the shared later ones
    assert model.dur_map_[0, 0] != model.dur_map_[1, 0]
    assert (model.dur_map_[0, 1:] == model.dur_map_[1, 1:]).all()
    assert np.all(np.diff(model.log_likelihood_[model.n_iter_untied :]) > -1e-6)


def test_state_round_trip(sampled):
    _, xs, cs, bs = sampled
    model = HSMM(n_states=3, n_iter=2).fit(xs[:5], cs[:5], bs[:5], 2)
    arrays: dict[str, np.ndarray] = {}
    back = restore_estimator(estimator_state(model, "m", arrays), arrays)
    assert back.score(xs[:3], cs[:3]) == model.score(xs[:3], cs[:3])


def test_clustering_splits_only_where_data_differ():
    rng = np.random.default_rng(4)
    occ = np.array([50.0, 50.0, 50.0, 0.0])  # context 3 never seen
    means = np.array([[0.0], [0.0], [5.0], [0.0]])
    x = [
        rng.normal(m, 1.0, size=(int(n), 1)) for m, n in zip(means, np.maximum(occ, 1), strict=True)
    ]
    sums = np.array([xi.sum(axis=0) if n else np.zeros(1) for xi, n in zip(x, occ, strict=True)])
    sumsq = np.array(
        [(xi**2).sum(axis=0) if n else np.zeros(1) for xi, n in zip(x, occ, strict=True)]
    )
    questions = [np.array([1, 0, 0, 0], bool), np.array([0, 0, 1, 1], bool)]
    leaf = cluster_state(occ, sums, sumsq, questions, np.array([1e-3]))
    assert leaf[0] == leaf[1] != leaf[2]
    assert leaf[3] == leaf[2]  # the unseen context follows the question's answer


# ------------------------------------------------------------------ adaptation (CMLLR)
def six_dim_model() -> HSMM:
    """Three states over 6 dims (two per static / delta / delta-delta block), one context."""
    m = HSMM(n_states=3)
    m.means_ = np.array([[0, 0, 1, 0, 0, 2], [3, 0, 0, 1, 2, 0], [0, 3, -1, 1, 0, -2]], dtype=float)
    m.variances_ = np.full((3, 6), 0.3)
    m.var_floor_ = np.full(6, 1e-4)
    m.dur_means_ = np.array([3.0, 5.0, 4.0])
    m.dur_variances_ = np.array([1.0, 1.0, 1.0])
    m.out_map_ = np.array([[0, 1, 2]])
    m.dur_map_ = np.array([[0, 1, 2]])
    m.max_duration_ = 14
    return m


def sample_model(model: HSMM, n: int, seed: int):
    rng = np.random.default_rng(seed)
    out = [model.sample(np.zeros(3, dtype=int), rng)[0] for _ in range(n)]
    return out, [np.zeros(3, dtype=int)] * n


def test_cmllr_on_matching_data_leaves_the_model_unchanged():
    model = six_dim_model()
    xs, cs = sample_model(model, 60, seed=1)
    blocks = transform_blocks(6, "stream")
    stats, _, _ = adaptation_statistics(model, xs, cs, blocks)
    root = RegressionTree(np.array([-1]), np.ones((1, 3), dtype=bool))
    w = estimate_transforms(stats, model.means_, model.variances_, blocks, root, 0.0, 1.0).w[0]
    np.testing.assert_allclose(w, identity_transform(6), atol=0.06)
    adapted = adapt(model, xs, cs, method="cmllr", map_step=False)
    np.testing.assert_allclose(adapted.means_, model.means_, atol=0.08)
    np.testing.assert_allclose(adapted.variances_, model.variances_, rtol=0.2)
    np.testing.assert_allclose(adapted.dur_means_, model.dur_means_, atol=0.3)


def test_cmllr_recovers_a_known_affine_shift():
    model = six_dim_model()
    shifted = six_dim_model()
    turn = np.array([[np.cos(0.4), -np.sin(0.4)], [np.sin(0.4), np.cos(0.4)]])
    a = np.zeros((6, 6))
    for k, block in enumerate(transform_blocks(6, "stream")):
        a[np.ix_(block, block)] = (1.0 + 0.2 * k) * turn
    c = np.array([1.0, -2.0, 0.5, 0.0, 1.5, -1.0])
    shifted.dur_means_ = model.dur_means_ + 2.0
    xs, cs = sample_model(shifted, 80, seed=2)
    xs = [x @ a.T + c for x in xs]  # the data are A x + c of the model's
    adapted = adapt(model, xs, cs, method="cmllr", map_step=False, n_iter=4)
    np.testing.assert_allclose(adapted.means_, model.means_ @ a.T + c, atol=0.12)
    np.testing.assert_allclose(adapted.dur_means_, shifted.dur_means_, atol=0.4)
    # CSMAPLR and MAP get there too; MAP moves the means further towards the data
    smap = adapt(model, xs, cs, method="csmaplr", tree_depth=1)
    np.testing.assert_allclose(smap.means_, model.means_ @ a.T + c, atol=0.12)


def test_adaptation_from_unit_boundaries_recovers_affine_durations():
    """Durations 1.5 d + 1 of the model's under data the unadapted model misaligns.

    The model's own first alignment puts frames in the wrong units, and the
    transforms fitted to it keep them there (duration variances of that
    alignment, not of the data); starting from the units' boundaries recovers
    the affine durations, variances 2.25 times the model's, and the outputs.
    """
    model = six_dim_model()
    true = six_dim_model()
    true.dur_means_ = 1.5 * model.dur_means_ + 1.0
    true.dur_variances_ = 2.25 * model.dur_variances_
    rng = np.random.default_rng(3)
    a, c = np.diag(rng.uniform(0.5, 2.0, 6)), rng.normal(0.0, 3.0, 6)
    xs, cs, bs = [], [], []
    for _ in range(12):
        units = np.zeros(4, dtype=int)
        x, d = true.sample(units, rng)
        xs.append(x @ a.T + c)
        cs.append(units)
        bs.append(np.r_[0, np.cumsum(d.reshape(4, 3).sum(axis=1))])
    target = model.means_ @ a.T + c
    for method in METHODS:
        adapted = adapt(
            model, xs, cs, method=method, map_step=False, max_duration=20, boundaries=bs
        )
        np.testing.assert_allclose(adapted.dur_means_, true.dur_means_, atol=0.6)
        np.testing.assert_allclose(adapted.dur_variances_, true.dur_variances_, rtol=0.5)
        np.testing.assert_allclose(adapted.means_, target, atol=0.15)
    lost = adapt(model, xs, cs, method="cmllr", map_step=False, max_duration=20)
    assert np.abs(lost.means_ - target).max() > 1.0


def test_few_data_stay_near_the_prior():
    """With two sequences, a strong CSMAPLR prior keeps the model close to where it was."""
    model = six_dim_model()
    xs, cs = sample_model(model, 2, seed=3)
    xs = [x + 5.0 for x in xs]
    weak = adapt(model, xs, cs, tau=1.0, map_step=False)
    strong = adapt(model, xs, cs, tau=1e6, map_step=False)
    assert np.abs(strong.means_ - model.means_).max() < 0.05
    assert np.abs(weak.means_ - model.means_).mean() > 3.0


def test_csmaplr_root_moves_on_fewer_frames_than_the_node_threshold():
    """One sequence (~9 frames) below min_occupancy: CSMAPLR's identity prior lets the root move, CMLLR stays."""
    model = six_dim_model()
    xs, cs = sample_model(model, 1, seed=5)
    xs = [x + 5.0 for x in xs]
    frames = sum(len(x) for x in xs)
    smap = adapt(model, xs, cs, tau=1.0, min_occupancy=10 * frames, map_step=False)
    cmllr = adapt(model, xs, cs, method="cmllr", min_occupancy=10 * frames, map_step=False)
    assert np.abs(smap.means_ - model.means_).mean() > 2.0
    np.testing.assert_allclose(cmllr.means_, model.means_)


def test_walker_adaptive_training_moves_unit_differences_into_transforms():
    """Two walkers offset from each other: WAT keeps the model's variances near the true ones."""
    model = six_dim_model()
    rng = np.random.default_rng(4)
    offset = np.array([1.5, -1.5, 0.0, 0.0, 0.0, 0.0])
    one = [np.zeros(1, dtype=int)] * 40  # one three-state unit per sequence
    xs = [model.sample(c, rng)[0] + offset * (i % 2) for i, c in enumerate(one)]
    units = ["a" if i % 2 == 0 else "b" for i in range(len(xs))]
    bounds = [np.array([0, len(x)]) for x in xs]
    plain = HSMM(n_states=3, n_iter=8, max_duration=14).fit(xs, one, bounds, 1)
    wat = HSMM(n_states=3, n_iter=8, max_duration=14).fit(xs, one, bounds, 1)
    transforms = walker_adaptive_training(wat, xs, one, units, n_rounds=3, tau=1.0)
    static = slice(0, 2)
    # the offset between walkers inflates the plain model's variance (true: 0.3)
    assert plain.variances_[:, static].mean() > 0.7
    assert wat.variances_[:, static].mean() < 0.45
    shift = transforms["b"][:, -1] - transforms["a"][:, -1]
    np.testing.assert_allclose(shift[static], -offset[static], atol=0.3)


def test_duration_variances_keep_their_floor_in_training_and_adaptation():
    """Units of identical lengths (zero duration variance): training and CMLLR stop at the
    floor, CSMAPLR (prior towards the model's variances) above it; durations stay >= 1 frame."""
    true = six_dim_model()
    true.dur_variances_ = np.full(3, 1e-6)  # every state lasts exactly its mean
    rng = np.random.default_rng(6)
    xs, cs, bs = [], [], []
    for _ in range(10):
        x, d = true.sample(np.zeros(2, dtype=int), rng)
        xs.append(x)
        cs.append(np.zeros(2, dtype=int))
        bs.append(np.r_[0, np.cumsum(d.reshape(2, 3).sum(axis=1))])
    assert len({len(x) for x in xs}) == 1
    trained = HSMM(n_states=3, n_iter=3, dur_var_floor=0.05).fit(xs, cs, bs, 1)
    np.testing.assert_allclose(trained.dur_variances_, 0.05)
    model = six_dim_model()  # durations variance 1, floor 0.1 (the default)
    for method in METHODS:
        adapted = adapt(model, xs, cs, method=method, boundaries=bs)
        assert adapted.dur_var_floor == model.dur_var_floor == 0.1
        if method == "cmllr":
            np.testing.assert_allclose(adapted.dur_variances_, 0.1)
        assert np.all(adapted.dur_variances_ >= 0.1) and np.all(adapted.dur_variances_ < 0.8)
        np.testing.assert_allclose(adapted.dur_means_, true.dur_means_, atol=0.3)
        draws = adapted.durations(np.zeros(500, dtype=int), speed=2.5, rng=rng)
        assert draws.min() >= 1
    with pytest.raises(ValueError, match="dur_var_floor must be positive"):
        HSMM(n_states=3, dur_var_floor=0.0).fit(xs, cs, bs, 1)
