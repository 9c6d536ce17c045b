"""A partner for people the model has never seen (issue #23): person normalisation, both
roles, the frame chosen by leaving people out, and cross-validation by pairs of people, on
the collection's real markers-only handshakes (Bütepage: several pairs of people)."""

from __future__ import annotations

import numpy as np
import pytest

from markovmotion.core.markers import Markers
from markovmotion.evaluate import hmm as evaluation
from markovmotion.features.person import RunningCentre, on_average_body
from markovmotion.models.base import Model
from markovmotion.models.hmm.dual import DualHMM, choose_frame

FRAMES = 120  # of each real take (30 fps: 4 s)


@pytest.fixture(scope="module")
def people(mocap):
    """(subject, A, B) of the markers handshakes, first seconds; at least two pairs of people."""
    pairs = mocap.pairs("handshake", kind="markers")
    takes = [(a.subject, *(m.trim(0, FRAMES) for m in mocap.load_pair(a, b))) for a, b in pairs]
    assert len({s for s, _, _ in takes}) >= 2
    return takes


# ------------------------------------------------------------------ the steps
def test_running_centre_is_causal_and_the_same_online():
    rng = np.random.default_rng(0)
    train = [rng.normal(size=(50, 3)) + 5, rng.normal(size=(30, 3)) - 1]
    step = RunningCentre(prior=10).fit(train)
    np.testing.assert_allclose(step.mean_, np.vstack(train).mean(0))
    x = rng.normal(size=(40, 3)) + 3
    whole = step.transform([x])[0]
    online = step.online()
    np.testing.assert_allclose(np.array([online(row) for row in x]), whole, atol=1e-12)
    # brute force: row t minus the mean of (prior copies of mean_) and rows 0..t
    for t in (0, 7, 39):
        pool = np.vstack([np.repeat(step.mean_[None], 10, 0), x[: t + 1]])
        np.testing.assert_allclose(whole[t], x[t] - pool.mean(0), atol=1e-12)
    # a person standing differently: the offset is gone once the running mean has seen it
    shifted = step.transform([x + 100.0])[0]
    assert np.abs(shifted[-1] - whole[-1]).max() < 100.0 * 10 / 50 + 1e-9


def test_on_average_body_keeps_the_motion_and_shares_the_shape():
    rng = np.random.default_rng(1)
    takes = [rng.normal(size=(20, 8, 3)) * 10 + rng.normal(size=(1, 8, 3)) * 200 for _ in range(3)]
    moved = on_average_body(takes)
    shapes = [m - m.mean(axis=1, keepdims=True) for m in moved]
    for s in shapes[1:]:
        np.testing.assert_allclose(s.mean(0), shapes[0].mean(0), atol=1e-9)
    for before, after in zip(takes, moved, strict=True):
        np.testing.assert_allclose(after.mean(axis=1), before.mean(axis=1), atol=1e-9)
        # the shape's change over the take is the take's own
        np.testing.assert_allclose(np.diff(after, axis=0), np.diff(before, axis=0), atol=1e-9)


def test_the_frame_is_chosen_by_leaving_people_out():
    """B stands 1 m in front of A in every take; the takes of each pair of people come from
    a sensor placed differently, so the room's axes agree within a pair and not across."""
    rng = np.random.default_rng(2)
    heading, world, groups = [], [], []
    for g, turn in enumerate((0.0, 2.0, 4.0)):
        for _ in range(2):
            front = np.array([0.0, 0.0, 1000.0]) + rng.normal(size=(30, 1, 3)) * 40
            heading.append(front)
            c, s = np.cos(turn), np.sin(turn)
            world.append(front @ np.array([[c, 0, -s], [0, 1, 0], [s, 0, c]]).T)
            groups.append(f"pair{g}")
    takes = {"heading": heading, "world": world}
    assert choose_frame(takes.__getitem__, groups) == "heading"
    same_room = {"heading": world, "world": heading}  # the other way round: world agrees
    assert choose_frame(same_room.__getitem__, groups) == "world"


# ------------------------------------------------------------------ the model
@pytest.fixture(scope="module")
def normalised(people) -> DualHMM:
    pairs = [(a, b) for _, a, b in people]
    groups = [s for s, _, _ in people]
    return DualHMM(n_states=6, n_iter=10, normalise="person").fit(pairs, groups=groups)


def test_a_normalised_model_streams_what_windowed_respond_gives(normalised, people):
    a = normalised._rate(people[-1][1])
    partner = normalised.partner()
    shown = [partner.step(a.trim(t, t + 1)) for t in range(a.n_frames)]
    shown = [s for s in shown if s is not None] + partner.finish()
    streamed = np.concatenate([s.positions for s in shown])
    np.testing.assert_allclose(streamed, normalised.respond(a, "windowed").positions, atol=1e-9)


def test_a_normalised_model_saves_and_loads(normalised, people, tmp_path):
    path = tmp_path / "m.npz"
    normalised.save(path)
    loaded = Model.load(path)
    assert loaded.normalise == "person"
    a = people[0][1]
    np.testing.assert_array_equal(
        loaded.respond(a, "windowed").positions, normalised.respond(a, "windowed").positions
    )


def test_b_frames_are_on_one_body(normalised):
    """Every training take of B has the same mean shape about its centroid."""
    b = normalised.markers_b_.astype(float)
    cut = np.cumsum(normalised.train_lengths_)[:-1]
    means = [p - p.mean(1, keepdims=True) for p in np.split(b, cut)]
    for m in means[1:]:
        np.testing.assert_allclose(m.mean(0), means[0].mean(0), atol=1e-2)


def test_crossval_leaves_one_pair_of_people_out(people, monkeypatch):
    seen = []
    fit = evaluation._fit_on

    def spy(model, takes, groups=None):
        seen.append(set(groups))
        return fit(model, takes, groups)

    monkeypatch.setattr(evaluation, "_fit_on", spy)
    takes = [(f"t{i}", "handshake", a, b) for i, (_, a, b) in enumerate(people)]
    groups = [s for s, _, _ in people]
    model = DualHMM(n_states=4, n_iter=5)
    results, _ = evaluation.cross_validate(takes, model, people=groups, roles="both")
    assert len(seen) == len(set(groups))  # one fit per pair of people
    for r in results:  # never trained on the people it answers
        fold = next(s for s in seen if r.people not in s)
        assert fold == set(groups) - {r.people}
    report = evaluation.summarise(results, model)
    assert set(report["per_people"]) == set(groups)
    assert sum(v["frames"] for v in report["per_people"].values()) == report["overall"]["frames"]


def test_both_roles_swaps_a_and_b():
    a = Markers(("x",), np.zeros((3, 1, 3)), 30.0, "a")
    b = Markers(("x",), np.ones((3, 1, 3)), 30.0, "b")
    (one, two) = evaluation.both_roles([("t", "wave", a, b)])
    assert one[2] is a and one[3] is b and two[2] is b and two[3] is a


# ------------------------------------------------------------------ output="regression"
def test_state_regressions_are_ridge_regressions_per_state():
    from sklearn.linear_model import Ridge

    from markovmotion.algorithms.gaussian import state_regressions

    rng = np.random.default_rng(4)
    x = rng.normal(size=(300, 3))
    state = (x[:, 0] > 0).astype(int)
    true = np.stack([rng.normal(size=(2, 3)) for _ in range(2)])
    y = np.einsum("tij,tj->ti", true[state], x) + 5 * state[:, None]
    gamma = np.eye(2)[state]
    mx, my, gains = state_regressions(x, y, gamma, ridge=0.0)
    for k in range(2):  # no ridge, no noise: the true maps come back
        np.testing.assert_allclose(gains[k], true[k], atol=1e-8)
        pred = my[k] + (x[state == k] - mx[k]) @ gains[k].T
        np.testing.assert_allclose(pred, y[state == k], atol=1e-8)
    _, _, gains = state_regressions(x, y, gamma, ridge=0.5)
    v = x.var(axis=0).mean()
    for k in range(2):
        n = int((state == k).sum())
        ridge = Ridge(alpha=0.5 * v * n).fit(x[state == k], y[state == k])
        np.testing.assert_allclose(gains[k], ridge.coef_, atol=1e-8)


@pytest.fixture(scope="module")
def regression(people) -> DualHMM:
    pairs = [(a, b) for _, a, b in people]
    return DualHMM(n_states=6, n_iter=10, normalise="person", output="regression").fit(pairs)


def test_regression_output_streams_what_windowed_respond_gives(regression, people, tmp_path):
    a = regression._rate(people[-1][1])
    partner = regression.partner()
    shown = [partner.step(a.trim(t, t + 1)) for t in range(a.n_frames)]
    shown = [s for s in shown if s is not None] + partner.finish()
    streamed = np.concatenate([s.positions for s in shown])
    whole = regression.respond(a, "windowed")
    np.testing.assert_allclose(streamed, whole.positions, atol=1e-9)
    assert whole.n_frames == a.n_frames and np.isfinite(whole.positions).all()
    path = tmp_path / "r.npz"
    regression.save(path)
    loaded = Model.load(path)
    for method in ("standard", "windowed"):
        np.testing.assert_array_equal(
            loaded.respond(a, method).positions, regression.respond(a, method).positions
        )


def test_regression_output_on_its_training_take_beats_the_mean_pose(regression, people):
    """On a take it learnt from, the regression answers B closer than B's mean pose."""
    _, a, b = people[0]
    res = evaluation.evaluate_pair(regression, a, b, "t", "handshake")
    for method in ("standard", "windowed"):
        assert res.errors[method].mean() < res.errors["mean_pose"].mean()
        assert res.pose_errors[method].mean() < res.pose_errors["mean_pose"].mean()


def test_regression_output_needs_markers(people):
    from conftest import make_motion

    from markovmotion.errors import SkeletonMismatchError

    m = make_motion(30)
    with pytest.raises(SkeletonMismatchError, match="regression"):
        DualHMM(n_states=2, output="regression").fit([(m, m)])
