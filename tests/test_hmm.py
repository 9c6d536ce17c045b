"""Gaussian HMM, its recursions and the windowed Viterbi decoder."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment
from scipy.special import logsumexp

from markovmotion.algorithms.gaussian import floor_covariances
from markovmotion.algorithms.hmm_recursions import forward, forward_backward, viterbi
from markovmotion.algorithms.windowed_viterbi import (
    WindowedViterbi,
    leavable,
    one_hot_log,
    start_distribution,
    windowed_viterbi,
)
from markovmotion.models.hmm.gaussian import GaussianHMM


def random_chain(rng: np.random.Generator, n: int, stay: float = 0.0):
    start = rng.dirichlet(np.ones(n))
    trans = rng.dirichlet(np.ones(n), size=n) + stay * np.eye(n)
    return start, trans / trans.sum(axis=1, keepdims=True)


def brute_force(log_pi, log_t, log_b):
    """Every state path of a tiny model: (best path, its log probability, log P(O), posteriors)."""
    n_t, n = log_b.shape
    paths = np.array(list(itertools.product(range(n), repeat=n_t)))
    scores = log_pi[paths[:, 0]] + log_b[np.arange(n_t), paths].sum(axis=1)
    scores += log_t[paths[:, :-1], paths[:, 1:]].sum(axis=1)
    ll = logsumexp(scores)
    weights = np.exp(scores - ll)
    gamma = np.stack([np.bincount(paths[:, t], weights, n) for t in range(n_t)])
    return paths[np.argmax(scores)], scores.max(), ll, gamma


def known_model() -> GaussianHMM:
    hmm = GaussianHMM(3)
    hmm.startprob_ = np.array([0.6, 0.3, 0.1])
    hmm.transmat_ = np.array([[0.9, 0.08, 0.02], [0.05, 0.9, 0.05], [0.1, 0.1, 0.8]])
    hmm.means_ = np.array([[0.0, 0.0], [5.0, 5.0], [-5.0, 6.0]])
    hmm.covars_ = np.array(
        [[[1.0, 0.3], [0.3, 0.5]], [[0.6, -0.2], [-0.2, 1.2]], [[2.0, 0.0], [0.0, 0.3]]]
    )
    return hmm


@pytest.mark.parametrize("seed", range(4))
def test_viterbi_forward_and_posteriors_equal_brute_force(seed):
    rng = np.random.default_rng(seed)
    n, n_t = 3, 6
    pi, trans = random_chain(rng, n)
    log_b = rng.normal(0, 2, (n_t, n))
    best, best_lp, ll, gamma = brute_force(np.log(pi), np.log(trans), log_b)
    path, lp = viterbi(np.log(pi), np.log(trans), log_b)
    np.testing.assert_array_equal(path, best)
    assert lp == pytest.approx(best_lp, rel=1e-12)
    assert forward(np.log(pi), trans, log_b)[1] == pytest.approx(ll, rel=1e-12)
    ll_fb, post, xi = forward_backward(np.log(pi), trans, log_b)
    np.testing.assert_allclose(post, gamma, atol=1e-12)
    assert xi.sum() == pytest.approx(n_t - 1)


def test_em_recovers_the_parameters_it_sampled_from():
    truth = known_model()
    x, _ = truth.sample(6000, random_state=1)
    lengths = [1500, 2500, 2000]
    hmm = GaussianHMM(3, n_iter=100, tol=1e-4, random_state=0).fit(x, lengths)
    assert np.all(np.diff(hmm.history_) > -1e-6)  # EM never loses likelihood
    assert hmm.converged_
    dist = np.linalg.norm(truth.means_[:, None] - hmm.means_[None], axis=-1)
    rows, order = linear_sum_assignment(dist)
    np.testing.assert_allclose(hmm.means_[order], truth.means_, atol=0.15)
    np.testing.assert_allclose(hmm.covars_[order], truth.covars_, atol=0.15)
    np.testing.assert_allclose(hmm.transmat_[np.ix_(order, order)], truth.transmat_, atol=0.03)
    assert hmm.score(x, lengths) >= truth.score(x, lengths) - 1.0


def test_fit_is_reproducible_with_a_seed():
    x, _ = known_model().sample(800, random_state=2)
    a = GaussianHMM(3, n_iter=5, random_state=7).fit(x)
    b = GaussianHMM(3, n_iter=5, random_state=7).fit(x)
    np.testing.assert_array_equal(a.means_, b.means_)
    np.testing.assert_array_equal(a.history_, b.history_)


def test_variance_floor_keeps_covariances_positive_definite():
    rng = np.random.default_rng(0)
    x = np.column_stack([rng.normal(size=500), np.full(500, 3.0)])  # one constant dimension
    hmm = GaussianHMM(2, n_iter=5, var_floor=1e-2).fit(x)
    assert np.linalg.eigvalsh(hmm.covars_).min() >= hmm.covar_floor_.min() * (1 - 1e-9)
    assert np.isfinite(hmm.history_).all()
    floored = floor_covariances(np.array([np.diag([4.0, 1e-9])]), 0.5)
    np.testing.assert_allclose(np.linalg.eigvalsh(floored[0]), [0.5, 4.0])


def test_no_underflow_on_100000_frames():
    hmm = known_model()
    x, states = hmm.sample(100_000, random_state=3)
    ll = hmm.score(x)
    assert np.isfinite(ll) and ll < -1e5
    gamma = hmm.predict_proba(x)
    np.testing.assert_allclose(gamma.sum(axis=1), 1.0)
    lp, path = hmm.decode(x)
    assert np.isfinite(lp) and lp <= ll
    assert np.mean(path == states) > 0.97


def test_bad_lengths_are_refused():
    x = np.zeros((10, 2))
    with pytest.raises(ValueError, match="lengths"):
        GaussianHMM(2).fit(x, [4, 4])


@pytest.mark.parametrize("width", [1, 3, 7])
@pytest.mark.parametrize("method", ["score", "decode", "predict_proba", "log_frameprob"])
def test_input_of_another_width_than_the_model_is_refused(method, width):
    """With more columns than the model, the compiled density read past its arrays."""
    hmm = known_model()
    x = np.random.default_rng(0).normal(size=(20, width))
    with pytest.raises(ValueError, match=f"X has {width} features, but GaussianHMM is expecting 2"):
        getattr(hmm, method)(x)


@pytest.mark.parametrize("extra", [0, 5])
def test_windowed_viterbi_with_a_whole_sequence_window_is_standard_viterbi(extra):
    rng = np.random.default_rng(4)
    pi, trans = random_chain(rng, 6, stay=3.0)
    log_b = rng.normal(0, 3, (40, 6))
    standard, _ = viterbi(np.log(pi), np.log(trans), log_b)
    windowed = windowed_viterbi(np.log(pi), np.log(trans), log_b, window=len(log_b) + extra)
    np.testing.assert_array_equal(windowed, standard)


def test_windowed_viterbi_follows_the_paper_slice_by_slice():
    """Each decided state is q2 of Viterbi on its slice started one-hot on the previous q2."""
    rng = np.random.default_rng(5)
    n, window = 5, 4
    pi, trans = random_chain(rng, n, stay=1.0)
    log_b = rng.normal(0, 2, (30, n))
    start = np.log(pi)
    decoder = WindowedViterbi(start, np.log(trans), window)
    states = []
    for t, row in enumerate(log_b):
        decided = decoder.push(row)
        assert len(decided) == (2 if t == window - 1 else int(t >= window - 1))
        states.extend(decided)
    states.extend(decoder.flush())
    assert len(states) == len(log_b) and decoder.lag == window - 2
    first, _ = viterbi(start, np.log(trans), log_b[:window])
    assert states[:2] == first[:2].tolist()
    for w in range(1, len(log_b) - window + 1):
        pi_w = np.full(n, -np.inf)
        pi_w[states[w]] = 0.0  # eq. 4
        path, _ = viterbi(pi_w, np.log(trans), log_b[w : w + window])
        assert states[w + 1] == path[1]
    assert states[-(window - 2) :] == path[2:].tolist()


def test_a_state_seen_only_at_the_ends_is_made_leavable_for_the_windowed_decoder():
    rng = np.random.default_rng(3)
    centres = np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 10.0]])
    seqs = []
    for _ in range(4):
        labels = np.r_[np.tile(np.repeat([0, 1], 15), 4), np.full(20, 2)]  # ends in state 2
        seqs.append(centres[labels] + rng.normal(0, 0.5, (len(labels), 2)))
    hmm = GaussianHMM(3, n_iter=30, random_state=0).fit(np.vstack(seqs), [140] * 4)
    end = int(np.argmin(np.linalg.norm(hmm.means_ - centres[2], axis=1)))
    assert hmm.transmat_[end, end] > 1 - 1e-6  # nothing ever left it
    absorbing = hmm.transmat_.copy()
    absorbing[end] = np.eye(3)[end]  # EM's limit
    log_b = hmm.log_frameprob(seqs[0])
    with np.errstate(divide="ignore"):
        stuck = windowed_viterbi(one_hot_log(3, end), np.log(absorbing), log_b, 10)
    assert (stuck == end).all()
    fixed = leavable(absorbing)
    np.testing.assert_allclose(fixed.sum(axis=1), 1.0)
    states = windowed_viterbi(one_hot_log(3, end), np.log(fixed), log_b, 10)
    assert (states[1:120] != end).all()
    assert (states[120:] == end).all()


def test_windowed_decoder_from_the_learnt_pi_follows_viterbi_where_eq3_is_trapped():
    # two recordings' worth of chain that never meet (states 0-1 and 2-3), every sampled
    # sequence starting in the first: the middle state (eq. 3) is in the other part
    pi = np.array([0.5, 0.5, 0.0, 0.0])
    trans = np.array(
        [[0.9, 0.1, 0, 0], [0.1, 0.9, 0, 0], [0, 0, 0.9, 0.1], [0, 0, 0.1, 0.9]], dtype=float
    )
    hmm = GaussianHMM(4)
    hmm.startprob_, hmm.transmat_ = pi, trans
    hmm.means_ = np.array([[0.0], [4.0], [0.5], [4.5]])  # the parts look alike
    hmm.covars_ = np.ones((4, 1, 1))
    x, _ = hmm.sample(400, random_state=0)
    log_b = hmm.log_frameprob(x)
    with np.errstate(divide="ignore"):
        log_pi, log_t = np.log(pi), np.log(trans)
    best = viterbi(log_pi, log_t, log_b)[0]
    assert set(best) <= {0, 1}
    prior = windowed_viterbi(start_distribution(log_pi, "prior"), log_t, log_b, 10)
    middle = windowed_viterbi(start_distribution(log_pi, "middle"), log_t, log_b, 10)
    assert (prior == best).mean() > 0.95
    assert set(middle) <= {2, 3}  # never leaves the part it was started in


def numpy_viterbi(log_pi: np.ndarray, log_a: np.ndarray, log_b: np.ndarray) -> np.ndarray:
    """Textbook Viterbi in NumPy (Rabiner eqs. 32-35), ties to the lowest predecessor."""
    delta = log_pi + log_b[0]
    back = []
    for row in log_b[1:]:
        scores = delta[:, None] + log_a  # (from i, to j)
        back.append(np.argmax(scores, axis=0))
        delta = scores.max(axis=0) + row
    path = [int(np.argmax(delta))]
    for b in reversed(back):
        path.append(int(b[path[-1]]))
    return np.array(path[::-1])


@pytest.mark.parametrize("n", [64, 256])
@pytest.mark.parametrize("ties", [False, True])
def test_viterbi_kernel_equals_numpy_viterbi_on_windows(n, ties):
    """The max-plus kernel on 10-frame windows started one-hot (eq. 4) or from a full pi,
    on random models, gives the textbook recursion's states, ties included (integer log
    probabilities make many)."""
    rng = np.random.default_rng(n)
    pi, trans = random_chain(rng, n)
    log_a, log_pi = np.log(trans), np.log(pi)
    if ties:
        log_a = -rng.integers(0, 3, (n, n)).astype(float)
        log_a[rng.random((n, n)) < 0.3] = -np.inf  # forbidden transitions too
    for w in range(20):
        log_b = rng.integers(-4, 0, (10, n)).astype(float) if ties else rng.normal(0, 5, (10, n))
        start = log_pi if w == 0 else one_hot_log(n, int(rng.integers(n)))
        path, lp = viterbi(start, log_a, log_b)
        expected = numpy_viterbi(start, log_a, log_b)
        np.testing.assert_array_equal(path, expected)
        score = start[path[0]] + log_b[0, path[0]]
        score += sum(log_a[path[t - 1], path[t]] + log_b[t, path[t]] for t in range(1, 10))
        assert lp == pytest.approx(score, rel=1e-12)
