"""E-steps mapped over chunks of sequences: the same fit whatever ``n_jobs`` and backend."""

from __future__ import annotations

import joblib
import numpy as np
import pytest
from test_hmm import known_model as known_hmm
from test_hsmm import known_model as known_hsmm

from markovmotion.algorithms.parallel import chunk_bounds, map_sequences
from markovmotion.models.gait.hsmm import HSMM
from markovmotion.models.hmm.gaussian import GaussianHMM
from markovmotion.state import estimator_state, restore_estimator


def test_chunks_are_contiguous_cover_every_sequence_and_balance_frames():
    sizes = [100, 5, 5, 5, 5, 100, 50, 50, 1, 1]
    bounds = chunk_bounds(sizes, 4)
    assert bounds[0][0] == 0 and bounds[-1][1] == len(sizes)
    assert all(a[1] == b[0] for a, b in zip(bounds, bounds[1:], strict=False))
    assert all(i < j for i, j in bounds)
    frames = [sum(sizes[i:j]) for i, j in bounds]
    assert max(frames) <= 120  # a quarter of 322 frames, up to one whole sequence more
    assert chunk_bounds([7], 8) == [(0, 1)]
    assert chunk_bounds([3, 3], 8) == [(0, 1), (1, 2)]


def test_one_job_calls_the_function_once_on_everything():
    calls = []
    values = list(range(10))

    def total(part):
        calls.append(len(part))
        return sum(part)

    def take(i, j):
        return (values[i:j],)

    assert map_sequences(total, sum, [1] * 10, take, n_jobs=1) == 45
    assert calls == [10]
    assert map_sequences(total, sum, [1] * 10, take, n_jobs=2) == 45
    assert len(calls) > 2 and sum(calls[1:]) == 10  # several chunks, each value once


def hmm_data():
    x, _ = known_hmm().sample(4000, random_state=3)
    lengths = np.random.default_rng(0).multinomial(4000 - 20 * 30, np.ones(20) / 20) + 30
    return x, lengths


def assert_same_hmm(a: GaussianHMM, b: GaussianHMM) -> None:
    assert a.n_iter_ == b.n_iter_
    for name in ("history_", "startprob_", "transmat_", "means_", "covars_"):
        np.testing.assert_allclose(getattr(a, name), getattr(b, name), rtol=1e-9, atol=1e-12)


@pytest.fixture(scope="module")
def hmm_serial():
    x, lengths = hmm_data()
    return x, lengths, GaussianHMM(3, n_iter=8, random_state=0).fit(x, lengths)


def test_gaussian_hmm_fits_the_same_with_two_jobs(hmm_serial):
    x, lengths, serial = hmm_serial
    threads = GaussianHMM(3, n_iter=8, random_state=0, n_jobs=2).fit(x, lengths)
    assert_same_hmm(threads, serial)
    np.testing.assert_allclose(threads.predict_proba(x, lengths), serial.predict_proba(x, lengths))
    with joblib.parallel_config(n_jobs=2):  # n_jobs=None follows the context
        assert_same_hmm(GaussianHMM(3, n_iter=8, random_state=0).fit(x, lengths), serial)


def test_gaussian_hmm_e_step_in_worker_processes(hmm_serial):
    x, lengths, serial = hmm_serial
    with joblib.parallel_config(backend="loky", n_jobs=2):
        assert serial.score(x, lengths) == pytest.approx(serial._e_step_chunk(x, lengths)[0])


@pytest.fixture(scope="module")
def walks():
    true = known_hsmm()  # two contexts with their own first-state durations
    rng = np.random.default_rng(0)
    xs, cs, bs = [], [], []
    for _ in range(24):
        c = rng.integers(0, 2, size=rng.integers(2, 6))
        x, d = true.sample(c, rng)
        xs.append(x)
        cs.append(c)
        bs.append(np.r_[0, np.cumsum(d.reshape(len(c), 3).sum(axis=1))])
    return xs, cs, bs


def test_hsmm_fits_the_same_with_two_jobs(walks):
    xs, cs, bs = walks
    questions = [np.array([True, False])]
    serial = HSMM(n_states=3, n_iter=5, max_duration=14).fit(xs, cs, bs, 2, questions)
    threads = HSMM(n_states=3, n_iter=5, max_duration=14, n_jobs=2).fit(xs, cs, bs, 2, questions)
    np.testing.assert_array_equal(threads.out_map_, serial.out_map_)
    np.testing.assert_array_equal(threads.dur_map_, serial.dur_map_)
    for name in ("log_likelihood_", "means_", "variances_", "dur_means_", "dur_variances_"):
        np.testing.assert_allclose(getattr(threads, name), getattr(serial, name), rtol=1e-9)


def test_models_saved_without_n_jobs_load_with_the_default(hmm_serial, walks):
    x, lengths, hmm = hmm_serial
    xs, cs, bs = walks
    hsmm = HSMM(n_states=3, n_iter=2, n_jobs=2).fit(xs, cs, bs, 2)
    for model, score in ((hmm, lambda m: m.score(x, lengths)), (hsmm, lambda m: m.score(xs, cs))):
        arrays: dict[str, np.ndarray] = {}
        state = estimator_state(model, "m", arrays)
        del state["params"]["n_jobs"]  # as written before n_jobs existed
        old = restore_estimator(state, arrays)
        assert old.n_jobs is None
        assert score(old) == pytest.approx(score(model), rel=1e-12)


def test_dask_through_joblib(hmm_serial):
    distributed = pytest.importorskip("distributed")
    x, lengths, serial = hmm_serial
    with (
        distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None
        ) as cluster,
        distributed.Client(cluster),
        joblib.parallel_config(backend="dask"),
    ):
        assert_same_hmm(GaussianHMM(3, n_iter=8, random_state=0).fit(x, lengths), serial)
