"""Interaction paper §2-5: joint shape vectors, decay operator, chain, extrapolation, CONDENSATION."""

from __future__ import annotations

import json
import shutil
from dataclasses import astuple

import numpy as np
import pytest
from conftest import make_skeleton

from markovmotion import read_motion
from markovmotion.cli import main
from markovmotion.core.motion import Motion
from markovmotion.defaults import DEFAULT_PLACE_WINDOW
from markovmotion.errors import ModelFormatError, SkeletonMismatchError
from markovmotion.evaluate.chain import evaluate_partner, pose_error_mm
from markovmotion.evaluate.takes import jump_sizes
from markovmotion.features.joint_shape import JointShape, Person, TwoPeople, joint_shape_pipeline
from markovmotion.models.base import Model
from markovmotion.models.chain.behaviour_chain import BehaviourChain, decay_behaviour, proximities
from markovmotion.models.chain.condensation import (
    DEFAULT_SIGMA,
    MultipleHypotheses,
    SingleHypothesis,
    hypersphere_mode,
    likelihood_weights,
    weighted_mean,
)
from markovmotion.models.chain.partner import PlaceAverage, VirtualPartner
from markovmotion.models.online import OnlinePartner, concatenate


# --------------------------------------------------------------- joint shape vectors
def random_people(dims: int, n: int = 30, seed: int = 0) -> TwoPeople:
    rng = np.random.default_rng(seed)
    k = 32 if dims == 2 else 5
    return TwoPeople(
        points=rng.normal(size=(n, 2, k, dims)) * 50,
        reference=rng.normal(size=(n, 2, dims)) * 300,
        height=rng.uniform(150, 200, (n, 2)),
        heading=rng.uniform(-np.pi, np.pi, (n, 2)) if dims == 3 else np.zeros((n, 2)),
        fps=25.0,
    )


@pytest.mark.parametrize("dims", [2, 3])
def test_partner_placed_back_exactly(dims):
    """Re-arranging eqs. 3-4 puts either person's partner back where it was."""
    p = random_people(dims)
    if dims == 3:
        p.reference[..., 1] = 0.0  # references on the floor
    js = JointShape().fit([p])
    c = js.transform([p])[0]
    assert c.shape == (p.n_frames, 2 * js.shape_size + (1 if dims == 2 else 4) + 1)
    for person in (0, 1):
        partner = js.place(c, person, p.person(person))
        truth = p.person(1 - person)
        np.testing.assert_allclose(partner.points[..., 0], truth.points[..., 0], atol=1e-9)
        np.testing.assert_allclose(partner.height, truth.height, rtol=1e-9)
        if dims == 3:
            np.testing.assert_allclose(partner.points, truth.points, atol=1e-9)


def test_state_vectors_in_unit_range_with_scaled_derivatives():
    p = random_people(2)
    pipe = joint_shape_pipeline([p], window=5, lam=10.0)
    f = pipe.fit_transform([p])[0]
    d = f.shape[1] // 2
    assert f[:, :d].min() == pytest.approx(0.0) and f[:, :d].max() == pytest.approx(1.0)
    # shape coordinates share one range: a shape's geometry is kept
    raw = pipe.steps[1].transform(pipe.steps[0].transform([p]))[0]
    shapes = slice(0, 2 * pipe.steps[0].shape_size)
    ratio = np.ptp(f[:, shapes], axis=0) / np.ptp(raw[:, shapes], axis=0)
    np.testing.assert_allclose(ratio, ratio[0])
    np.testing.assert_allclose(f[2:, d:], 10.0 * np.diff(f[1:, :d], axis=0))


# -------------------------------------------------------------- behaviour model
def test_proximity_falls_linearly_to_the_hypercube_diagonal():
    p = proximities(np.zeros((1, 2)), np.array([[0.0, 0.0], [1.0, 1.0], [0.5, 0.0]]))
    np.testing.assert_allclose(p, [[1.0, 0.0, 1.0 - 0.5 / np.sqrt(2)]])


def test_decay_operator_matches_eq10_by_hand():
    p = np.array([[0.5, 0.2], [0.3, 0.9], [0.1, 0.1], [0.2, 0.3]])
    # z0 = 0; z_t = p_t if p_t > gamma z_{t-1} else gamma z_{t-1}, gamma = 0.5
    expected = [[0.5, 0.2], [0.3, 0.9], [0.15, 0.45], [0.2, 0.3]]
    np.testing.assert_allclose(decay_behaviour(p, gamma=0.5), expected)


def hand_chain(prototypes: np.ndarray, labels: list[list[int]], **params) -> BehaviourChain:
    """A chain whose behaviour prototypes are the state prototypes themselves."""
    ch = BehaviourChain(calibrate_intervals=False, **params)
    ch.state_prototypes_ = np.asarray(prototypes, dtype=float)
    ch.behaviour_prototypes_ = np.eye(len(prototypes))
    ch.chain_prototype_ = np.arange(len(prototypes))
    return ch.fit_chain([np.array(lab) for lab in labels])


def test_chain_counts_state_changes_and_ends():
    ch = hand_chain(np.zeros((3, 4)), [[0, 0, 1, 1, 2], [0, 2, 2]])
    np.testing.assert_allclose(
        ch.transmat_,
        [[0, 0.5, 0.5, 0], [0, 0, 1, 0], [0, 0, 0, 1], [0, 0, 0, 1]],
    )
    np.testing.assert_allclose(ch.startprob_, [1, 0, 0, 0])
    np.testing.assert_allclose(ch.occupancy_, [3 / 8, 2 / 8, 3 / 8, 0])


def test_fitted_chain_rows_sum_to_one():
    rng = np.random.default_rng(1)
    seqs = [np.cumsum(rng.normal(0, 0.02, (80, 6)), axis=0) + 0.5 for _ in range(3)]
    ch = BehaviourChain(n_state_prototypes=12, n_behaviour_prototypes=8, n_epochs=2).fit(seqs)
    assert ch.transmat_.shape == (9, 9)
    np.testing.assert_allclose(ch.transmat_.sum(axis=1), 1.0)
    assert ch.transmat_[ch.end_state, ch.end_state] == 1.0
    assert ch.startprob_.sum() == pytest.approx(1.0)
    assert ch.behaviour_vectors(seqs[0]).shape == (80, 12)


def line_chain() -> BehaviourChain:
    """Three prototypes on a line, visited 0 -> 1 -> 2 -> end, moving at 0.1 per frame."""
    c = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]])
    v = np.tile([0.1, 0.0], (3, 1))
    return hand_chain(np.hstack([c, 10 * v]), [[0, 1, 2]], lam=10.0)


def test_extrapolation_passes_the_prototypes_and_stops_at_the_end():
    ch = line_chain()
    out = ch.extrapolate(ch.state_prototypes_[0], 0)
    # eq. 15: |dC| = 1 at speed 0.1 per frame -> 10 frames per segment; ends still at prototype 2
    assert len(out) == 21
    np.testing.assert_allclose(out[[0, 10, 20], :2], ch.state_prototypes_[:, :2], atol=1e-12)
    np.testing.assert_allclose(out[1:, 2:], np.tile([1.0, 0.0], (20, 1)), atol=1e-9)  # lambda dC
    only = ch.extrapolate(ch.state_prototypes_[2], ch.end_state)
    np.testing.assert_allclose(only, ch.state_prototypes_[2:])


def test_branch_enumerates_every_successor_at_a_decision_point():
    c = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [1.0, -1.0]])
    ch = hand_chain(np.hstack([c, np.zeros_like(c)]), [[0, 1, 2], [0, 1, 3]], max_interval=4)
    h = ch.at(ch.state_prototypes_[[1]], [1])
    succ = ch.branch(h)
    assert sorted(succ.state.tolist()) == [2, 3]


# ------------------------------------------------------------------ CONDENSATION
def test_likelihood_and_hypersphere_mode():
    w = likelihood_weights(np.array([0.0, 0.05, 1.0]), sigma=0.05)
    np.testing.assert_allclose(w[:2] / w[0], [1.0, np.exp(-0.5)])
    assert w.sum() == pytest.approx(1.0) and w[2] < 1e-80
    pts = np.array([[0.0], [0.1], [0.15], [3.0], [3.05]])
    assert hypersphere_mode(pts, 0.12) == 1
    assert hypersphere_mode(pts) in (0, 1, 2)  # median distance: the dense cluster


def branching_chain() -> BehaviourChain:
    """A loop with a decision point: two branches look alike to the real person at first
    (prototypes 2 and 3) but the partner differs; they part for the real person later (4, 5).

    Columns of C: the real person (2), the partner (2).
    """
    c = np.array(
        [
            [0.0, 0.0, 0.0, 0.0],
            [0.5, 0.0, 0.5, 0.0],
            [1.0, 0.05, 1.0, 1.0],
            [1.0, -0.05, 1.0, -1.0],
            [0.5, 0.6, 0.5, 1.0],
            [0.5, -0.6, 0.5, -1.0],
        ]
    )
    ch = hand_chain(np.hstack([c, np.zeros_like(c)]), [[0, 1, 2, 4, 0, 1, 3, 5]], max_interval=8.0)
    ch.transmat_[:6] = 0.0  # a loop without end: 0 -> 1 -> (2 -> 4 | 3 -> 5) -> 0
    for a, b, p in (
        (0, 1, 1),
        (1, 2, 0.5),
        (1, 3, 0.5),
        (2, 4, 1),
        (3, 5, 1),
        (4, 0, 1),
        (5, 0, 1),
    ):
        ch.transmat_[a, b] = p
    return ch


REAL, PARTNER = slice(0, 2), slice(2, 4)


@pytest.fixture(scope="module")
def noisy_branching() -> list[tuple[np.ndarray, np.ndarray]]:
    """Six traversals of :func:`branching_chain`: true C (T, 4), real person seen with noise 0.15."""
    ch = branching_chain()
    runs = []
    for seed in range(6):
        rng = np.random.default_rng(seed)
        truth = ch.extrapolate(ch.state_prototypes_[0], 0, max_frames=150, rng=rng)[:, :4]
        runs.append((truth, truth[:, REAL] + rng.normal(0, 0.15, (len(truth), 2))))
    return runs


def partner_errors(make, runs) -> np.ndarray:
    """Per-frame partner errors (all runs) of the propagators ``make(seed)``."""
    out = []
    for seed, (truth, observed) in enumerate(runs):
        shapes, _, _ = make(seed).run(observed)
        out.append(np.linalg.norm(shapes[:, PARTNER] - truth[:, PARTNER], axis=1))
    return np.concatenate(out)


def test_condensation_beats_single_hypothesis_on_noisy_observations(noisy_branching):
    ch = branching_chain()
    paper = partner_errors(
        lambda s: SingleHypothesis(ch, [REAL], float("inf"), seed=s), noisy_branching
    )
    resynchronised = partner_errors(
        lambda s: SingleHypothesis(ch, [REAL], 0.0, seed=s), noisy_branching
    )
    multiple = partner_errors(
        lambda s: MultipleHypotheses(ch, [REAL], 200, sigma=0.15, response="ml", seed=s),
        noisy_branching,
    )
    # the paper's single hypothesis keeps a wrong branch to its end; re-entering the
    # chain where the real person says so leaves it, and many hypotheses do better still
    assert multiple.mean() < 0.5 * paper.mean()
    assert resynchronised.mean() < 0.5 * paper.mean()
    assert multiple.mean() < resynchronised.mean()


def test_weighted_mean_response_has_lower_squared_error_where_branches_look_alike(
    noisy_branching,
):
    """Where the real person cannot yet tell the branches apart, the ML hypothesis bets on
    one partner, the posterior mean (Isard and Blake's estimate) hedges between them."""
    ch = branching_chain()
    sq = {
        r: (
            partner_errors(
                lambda s, r=r: MultipleHypotheses(ch, [REAL], 200, 0.15, response=r, seed=s),
                noisy_branching,
            )
            ** 2
        ).mean()
        for r in ("ml", "mean")
    }
    assert sq["mean"] < 0.8 * sq["ml"]


def test_weighted_mean_averages_within_the_heaviest_role():
    c = np.array([[0.0, 2.0], [2.0, 4.0], [10.0, 10.0]])
    shape, role = weighted_mean(c, np.array([0, 0, 1]), np.array([0.3, 0.1, 0.6]))
    # role 0 weighs 0.4 < 0.6: the mean is the lone hypothesis of role 1
    assert role == 1 and np.allclose(shape, [10.0, 10.0])
    shape, role = weighted_mean(c, np.array([0, 0, 1]), np.array([0.3, 0.1, 0.2]))
    assert role == 0 and np.allclose(shape, [0.5, 2.5])


# ---------------------------------------------------------------------- real data
@pytest.fixture(scope="session")
def salsa_take(mocap) -> TwoPeople:
    a, b = mocap.pairs(label="salsa")[0]
    return TwoPeople.from_motions(*mocap.load_pair(a, b), fps=25.0)


def test_real_take_joint_shapes_and_placement(salsa_take):
    p = salsa_take
    assert p.fps == 25.0 and p.points.shape[1:] == (2, 19, 3)
    js = JointShape().fit([p])
    c = js.transform([p])[0]
    partner = js.place(c, 0, p.person(0))
    np.testing.assert_allclose(partner.points, p.points[:, 1], atol=1e-6)


@pytest.fixture(scope="session")
def small_partner(salsa_take) -> VirtualPartner:
    train = salsa_take.trim(0, 600)
    return VirtualPartner(n_state_prototypes=40, n_behaviour_prototypes=30, n_epochs=3).fit([train])


def test_real_partner_follows_and_round_trips(small_partner, salsa_take, tmp_path):
    test = salsa_take.trim(600)
    real = test.person(0)
    resp = small_partner.respond_shapes(real, 0, n_hypotheses=50)
    assert resp.partner.points.shape == test.points[:, 1].shape
    assert np.all(np.isfinite(resp.partner.points))
    # the partner stands within arm's reach of where it was, its joints within 0.3 m
    err = np.linalg.norm(resp.partner.points - test.points[:, 1], axis=-1).mean()
    assert err < 1000.0
    small_partner.save(tmp_path / "m.npz")
    back = VirtualPartner.load(tmp_path / "m.npz")
    assert back.source == "mocap"
    again = back.respond_shapes(real, 0, n_hypotheses=50)
    np.testing.assert_allclose(again.partner.points, resp.partner.points)
    with pytest.raises(ModelFormatError):
        VirtualPartner.load(tmp_path / "missing.npz")


def test_partner_of_the_second_person_is_the_first(small_partner, salsa_take):
    """With person 1 real, the partner is the model's person-0 half, placed from person 1."""
    seen = salsa_take.trim(0, 200)  # training frames: the chain knows them
    for person in (0, 1):
        resp = small_partner.respond_shapes(seen.person(person), person, n_hypotheses=50)
        assert np.all(resp.roles == person)
        to_partner = pose_error_mm(small_partner, resp.partner, seen.person(1 - person))
        to_real = pose_error_mm(small_partner, resp.partner, seen.person(person))
        assert to_partner < 0.8 * to_real


def test_evaluation_reports_every_error_and_the_cli_writes_a_partner(
    small_partner, salsa_take, mocap, tmp_path
):
    take = salsa_take.trim(600, 700)
    copy = (take.person(1), take.person(0))  # a "model" that answers each person with itself
    result = evaluate_partner(small_partner, [take], "mocap", 30, "map", others={"copy": [copy]})
    responses = [f"multiple_hypotheses_{r}" for r in ("ml", "map", "mean")]
    for key in ("single_hypothesis", "single_hypothesis_paper", "mean_shape", *responses):
        assert 0 < result[key] < 1000 and 0 < result["placement_mm"][key] < 5000
    assert result["multiple_hypotheses_response"] == "map" and result["sigma"] == DEFAULT_SIGMA
    assert result["multiple_hypotheses"] == result["multiple_hypotheses_map"]
    assert result["copy"] == 0.0 and result["placement_mm"]["copy"] == 0.0
    # the paper's single hypothesis (§5.1) is the re-synchronised one that never re-enters
    paper = evaluate_partner(small_partner, [take], "mocap", 30, "map", resync=np.inf)
    assert paper["single_hypothesis"] == paper["single_hypothesis_paper"]
    assert paper["single_hypothesis_paper"] == result["single_hypothesis_paper"]
    assert result["unit"] == "mm" and set(result["per_frame_ms"]) == {
        "single_hypothesis",
        "single_hypothesis_paper",
        "multiple_hypotheses",
        *responses,
    }
    by_person = result["by_real_person"]
    assert np.mean([p["mean_shape"] for p in by_person]) == pytest.approx(result["mean_shape"])
    # how much each partner jumps, the dual HMM's measure, beside the real partner's: the
    # copy answers with the real partner, so it jumps as much
    jumps = result["jump_p90_mm"]
    assert set(jumps) == {"mean_shape", "single_hypothesis", "single_hypothesis_paper",
                          "multiple_hypotheses", "copy", "real", *responses}  # fmt: skip
    steps = np.concatenate([jump_sizes(take.person(p).points) for p in (0, 1)])
    assert jumps["real"] == jumps["copy"] == round(float(np.percentile(steps, 90)), 1)
    assert jumps["multiple_hypotheses"] == jumps["multiple_hypotheses_map"]
    assert all(0 < v < 2000 for v in jumps.values())
    assert by_person[0]["jump_p90_mm"]["real"] == round(
        float(np.percentile(jump_sizes(take.person(1).points), 90)), 1
    )
    small_partner.save(tmp_path / "m.npz")
    a, _ = mocap.pairs(label="salsa")[0]
    out = tmp_path / "partner.bvh"
    argv = ["chain", "respond", "--model", str(tmp_path / "m.npz"), "--input", str(a.path)]
    main([*argv, "--out", str(out), "--hypotheses", "20", "--sigma", "0.1"])
    partner = read_motion(out)
    assert partner.n_frames == salsa_take.n_frames and partner.skeleton.n_joints == 19


def silhouette_take(n: int, swapping: bool) -> TwoPeople:
    """Two ellipse 'silhouettes' (image pixels, y down) dancing about x = 320; person 0 is the
    left-hand individual, or (``swapping``) an identity that changes sides."""
    t = np.arange(n)
    middle = 320 + 60 * np.sin(t / 50)
    side = np.sign(np.sin(t / 30) + 1e-9) if swapping else np.ones(n)
    angle = np.linspace(0, 2 * np.pi, 32, endpoint=False) - np.pi / 2  # from the top
    points, reference = [], []
    for person, width in ((0, 25.0), (1, 35.0)):
        x = middle + (2 * person - 1) * side * 40
        px = x[:, None] + width * np.cos(angle)[None]
        py = 240 + 90 * np.sin(angle)[None].repeat(n, 0)
        points.append(np.stack([px, py], axis=-1))
        reference.append(np.column_stack([x, np.full(n, 150.0)]))
    return TwoPeople(
        np.stack(points, axis=1),
        np.stack(reference, axis=1),
        np.full((n, 2), 180.0),
        np.zeros((n, 2)),
        25.0,
        "ellipses",
    )


def test_silhouette_baseline_picks_the_side_without_being_told():
    model = VirtualPartner(n_state_prototypes=8, n_behaviour_prototypes=8, random_state=0)
    model.fit([silhouette_take(300, False), silhouette_take(250, False)])
    assert model.centre_ == pytest.approx(320, abs=5)
    test = silhouette_take(200, True)
    real = test.person(0)
    true_roles = (real.reference[:, 0] > test.reference[:, 1, 0]).astype(int)
    guessed = model.centre_roles(real)
    assert 0.5 < (guessed == true_roles).mean() < 1.0  # the middle drifts: some guesses fail
    result = evaluate_partner(model, [test], "silhouette", 20, "ml")
    assert result["unit"] == "fraction of body height"
    assert result["mean_shape_true_side"] < result["mean_shape"]
    right = model.mean_partner(real, true_roles)
    err = np.linalg.norm(right.points - test.points[:, 1], axis=-1).mean(axis=1) / 180.0
    assert err.mean() < 0.05  # the true side with the mean shape: the partner's own ellipse


# ------------------------------------------------- the contract: pairs in, online partner
@pytest.fixture(scope="session")
def pair_partner(mocap) -> VirtualPartner:
    """A small chain fitted on the contract's input: (Motion A, Motion B) pairs (10 s)."""
    a, b = mocap.load_pair(*mocap.pairs(label="salsa")[0])
    model = VirtualPartner(n_state_prototypes=12, n_behaviour_prototypes=10, n_epochs=2)
    return model.fit([(a.trim(0, 600), b.trim(0, 600))])


def test_fit_on_pairs_records_both_files_and_loads_alone(pair_partner, mocap, tmp_path):
    a, b = mocap.pairs(label="salsa")[0]
    assert [r["file"] for r in pair_partner.train_files_] == [a.path.name, b.path.name]
    assert pair_partner.skeletons_[1].n_joints == 19 and pair_partner.fps_ == 25.0
    pair_partner.save(tmp_path / "m.npz", source="mocap", labels=["salsa"])
    back = Model.load(tmp_path / "m.npz")
    assert isinstance(back, VirtualPartner) and back.source_ == "mocap"
    assert back.labels_ == ["salsa"] and back.train_files_ == pair_partner.train_files_


def test_online_partner_answers_frame_by_frame_as_respond(pair_partner, mocap):
    a = mocap.load_motion(mocap.pairs(label="salsa")[0][0]).trim(600, 720)
    whole = pair_partner.respond(a, n_hypotheses=20)
    partner = pair_partner.partner(n_hypotheses=20)
    assert isinstance(partner, OnlinePartner)
    assert partner.lag == 2 and partner.fps == 25.0 and partner.skeleton.n_joints == 19
    a25 = a.resample(partner.fps)
    out = [partner.step(a25.trim(t, t + 1)) for t in range(a25.n_frames)]
    assert out[:2] == [None, None] and all(f.n_frames == 1 for f in out[2:])
    streamed = concatenate([f for f in out if f is not None] + partner.finish(), 25.0)
    assert streamed.n_frames == whole.n_frames == a25.n_frames
    # the same frames to the bit (B's place averaged over its last place_window frames too)
    np.testing.assert_array_equal(streamed.rotations, whole.rotations)
    np.testing.assert_array_equal(streamed.translations, whole.translations)
    with pytest.raises(ValueError, match="stream is finished"):  # went on answering before
        partner.step(a25.trim(0, 1))
    partner = pair_partner.partner(n_hypotheses=20)
    with pytest.raises(SkeletonMismatchError):
        partner.step(
            Motion.from_rotations(make_skeleton(), np.tile([0.0, 0, 0, 1], (1, 5, 1)), fps=25.0)
        )
    with pytest.raises(ValueError, match="resample A to the partner's rate"):
        partner.step(a.trim(0, 1))  # A at its own 60 fps: was answered in slow motion
    with pytest.raises(ValueError, match="step takes one frame of A, got 5"):
        partner.step(a25.trim(0, 5))  # was taken, and crashed near the end
    with pytest.raises(TypeError, match="not ndarray"):
        partner.step(a25.positions()[:1])


def test_the_partners_place_is_averaged_over_its_last_frames(pair_partner, mocap):
    """``place_window``: where B stands on the floor and faces is averaged over its last
    frames and its body moved and turned with it, its pose unchanged. The response
    hops from hypothesis to hypothesis and where B stands hops with it (the held-out salsa
    take 15: 130 of 891 steps over 200 mm); averaged, B jumps far less. Frames given one at
    a time are those given at once, to the bit (the online partner's)."""
    import copy

    a, b = mocap.load_pair(*mocap.pairs(label="salsa")[0])
    take = pair_partner.two_people(a.trim(600, 1200), b.trim(600, 1200))
    real = take.person(0)
    assert pair_partner.place_window == DEFAULT_PLACE_WINDOW == 20
    paper = copy.deepcopy(pair_partner).set_params(place_window=1)
    hopping = paper.respond_shapes(real, 0, n_hypotheses=50, rng=0).partner
    steady = pair_partner.respond_shapes(real, 0, n_hypotheses=50, rng=0).partner
    t, w = 30, pair_partner.place_window
    on_floor = hopping.reference[t - w + 1 : t + 1, [0, 2]].mean(0)
    np.testing.assert_allclose(steady.reference[t, [0, 2]], on_floor)
    np.testing.assert_array_equal(steady.reference[:, 1], hopping.reference[:, 1])
    turn = np.exp(1j * hopping.heading[t - w + 1 : t + 1]).mean()
    assert steady.heading[t] == pytest.approx(np.angle(turn))
    assert pose_error_mm(pair_partner, steady, hopping) < 1e-6  # the body as it was
    p90 = [np.percentile(jump_sizes(p.points), 90) for p in (hopping, steady)]
    assert p90[1] < 0.6 * p90[0]
    at_once = PlaceAverage(w)(hopping)
    by_frame = PlaceAverage(w)
    frames = [by_frame(Person(*(x[i : i + 1] for x in astuple(hopping))))
              for i in range(real.n_frames)]  # fmt: skip
    np.testing.assert_array_equal(np.concatenate([f.points for f in frames]), at_once.points)
    assert PlaceAverage(1)(hopping) is hopping
    for wrong in (0, 1.5, True, 1001):
        with pytest.raises(ValueError, match="place_window must be 1 to 1000 frames"):
            VirtualPartner(place_window=wrong).check_params()


def test_frames_before_a_is_first_seen_are_the_mean_shape_and_leave_the_stream_alone(
    pair_partner, mocap
):
    """A stream that starts with frames missing (a camera that sees no one yet): each is
    answered in its turn with the same frame, the mean shape beside a stand-in A at the
    origin (200 hypotheses had been re-drawn on a constant input, B flickering 150-470 mm a
    frame), and nothing is propagated: from A's first frame B is respond's for A alone, to
    the bit (the stand-in had been pushed through the propagation, and B jumped when A
    came). N calls and finish() give N frames, in order."""
    a = mocap.load_motion(mocap.pairs(label="salsa")[0][0]).trim(600, 720).resample(25.0)
    whole = pair_partner.respond(a, n_hypotheses=20)
    partner = pair_partner.partner(n_hypotheses=20)
    out = [partner.step(None) for _ in range(7)]
    out += [partner.step(a.trim(t, t + 1)) for t in range(a.n_frames)]
    assert out[:2] == [None, None] and all(f is not None for f in out[2:])
    shown = concatenate([f for f in out if f is not None] + partner.finish(), 25.0)
    assert shown.n_frames == 7 + a.n_frames
    before = shown.positions()[:7]
    assert all(np.array_equal(f, before[0]) for f in before)
    stand_in = partner.unseen()  # at the origin, facing +Z, as the training people stand
    np.testing.assert_array_equal(stand_in.reference[0], [0.0, pair_partner.stance_[0, 1], 0.0])
    assert stand_in.heading[0] == 0.0 and stand_in.height[0] == pair_partner.stance_[0, 0]
    mean = pair_partner.mean_partner(stand_in, np.zeros(1, dtype=int))
    np.testing.assert_allclose(before[0][0, [0, 2]], mean.reference[0, [0, 2]])  # the pelvis
    np.testing.assert_array_equal(shown.rotations[7:], whole.rotations)
    np.testing.assert_array_equal(shown.translations[7:], whole.translations)


def test_a_file_saved_before_the_place_window_answers_as_it_was_saved(small_partner):
    """A parameter added since a file was saved takes the value the file answered with
    (``PARAMS_OF_OLDER_FILES``): a chain saved before ``place_window`` placed B unaveraged."""
    from markovmotion.state import estimator_state, restore_estimator

    arrays: dict = {}
    state = estimator_state(small_partner, "model", arrays)
    assert state["params"]["place_window"] == DEFAULT_PLACE_WINDOW > 1
    del state["params"]["place_window"]
    assert restore_estimator(state, arrays).place_window == 1


def _copy_index(root, mocap, trials: dict[str, str]) -> None:
    """An INDEX.csv of COPIES of salsa takes under other names: ``{new name: trial}``."""
    rows = ["file,source,subject,trial,category,label,partner_file,fps,frames,description"]
    by_trial = {e.trial: (e, p) for e, p in mocap.pairs(label="salsa")}
    (root / "takes").mkdir(parents=True)
    for name, trial in trials.items():
        for person, entry in zip("ab", by_trial[trial], strict=True):
            shutil.copyfile(entry.path, root / "takes" / f"{name}_{person}.bvh.gz")
        for me, other in ("ab", "ba"):
            rows.append(
                f"takes/{name}_{me}.bvh.gz,mine,,{name},interaction,salsa,"
                f"takes/{name}_{other}.bvh.gz,60,,a dance"
            )
    (root / "INDEX.csv").write_text("\n".join(rows) + "\n")


def test_evaluate_on_any_index_leaves_training_takes_out(pair_partner, mocap, tmp_path, capsys):
    model = tmp_path / "m.npz"
    pair_partner.save(model, source="mocap", labels=["salsa"])
    train_trial = mocap.pairs(label="salsa")[0][0].trial
    _copy_index(tmp_path / "mine", mocap, {"seen": train_trial, "new": "12"})
    argv = ["chain", "evaluate", "--model", str(model), "--hypotheses", "4", "--json"]
    main([*argv, "--test", str(tmp_path / "mine" / "INDEX.csv")])
    result = json.loads(capsys.readouterr().out)
    assert result["test_files"] == ["takes/new_a.bvh.gz", "takes/new_b.bvh.gz"]
    assert result["left_out_training_files"] == ["takes/seen_a.bvh.gz", "takes/seen_b.bvh.gz"]
    assert 0 < result["single_hypothesis"] < 1000 and 0 < result["mean_shape"] < 1000
    main([*argv[:-1], "--test", str(tmp_path / "mine" / "INDEX.csv")])  # the table names them
    err = capsys.readouterr().err
    (named,) = [ln for ln in err.splitlines() if ln.startswith("test takes: ")]
    assert named == f"test takes: {', '.join(result['takes'])}" and "seen" not in named
    # only training takes (the ZeroDivisionError of old), or none that fit: one line, exit 2
    _copy_index(tmp_path / "seen", mocap, {"seen": train_trial})
    (tmp_path / "none").mkdir()
    (tmp_path / "none" / "INDEX.csv").write_text(
        "file,source,subject,trial,category,label,partner_file,fps,frames,description\n"
    )
    for index, words in (("seen", "one it trained on: takes/seen_a"), ("none", "no two-person")):
        with pytest.raises(SystemExit) as info:
            main([*argv, "--test", str(tmp_path / index / "INDEX.csv")])
        err = capsys.readouterr().err
        assert info.value.code == 2 and words in err
        assert "Traceback" not in err and len(err.strip().splitlines()) == 1


def test_evaluation_table_lists_partners_not_parameters(capsys):
    from markovmotion.cli.chain import _print_errors

    errors = {"mean_shape": 97.8, "multiple_hypotheses_ml": 96.3}
    result = {
        **errors,
        "multiple_hypotheses": 96.3,
        "placement_mm": {"mean_shape": 590.6, "multiple_hypotheses_ml": 584.0},
        "per_frame_ms": {"multiple_hypotheses_ml": 0.4},
        "jump_p90_mm": {"mean_shape": 108.4, "multiple_hypotheses_ml": 385.8, "real": 37.9},
        "sigma": 0.15,
        "resync": 0.0,
    }
    _print_errors(result, "virtual partner", "ml")
    out = capsys.readouterr().out
    assert "mean_shape" in out and "multiple_hypotheses_ml *" in out and "584" in out
    assert "sigma" not in out and "resync" not in out
    assert "jump p90" in out and "385.8" in out and "real partner" in out and "37.9" in out
    # each row and measure is said under the table (a new user saw single_hypothesis_paper
    # and body-centred without a word on what they were)
    said = " ".join(out.split())
    assert "mean_shape: the training people's mean shape" in said
    assert "body-centred: each person about its own centroid" in said
    assert "single_hypothesis:" not in said  # no row, no word on it
    result["single_hypothesis_paper"] = 99.0
    result["placement_mm"]["single_hypothesis_paper"] = 600.0
    _print_errors(result, "virtual partner", "ml")
    said = " ".join(capsys.readouterr().out.split())
    assert "single_hypothesis_paper: one hypothesis never re-synchronised" in said


def test_a_skeleton_is_matched_by_its_joint_names_not_their_count(pair_partner, mocap):
    """A skeleton with as many joints under other names is refused, the joints named (it
    was once answered by position in the list, exit 0); the same skeleton is observed."""
    import dataclasses

    from markovmotion.errors import SkeletonMismatchError

    a, _ = mocap.load_pair(*mocap.pairs(label="salsa")[0])
    a = a.trim(0, 30)
    pair_partner.check_input(a)
    learnt = pair_partner.shape_names
    assert learnt and len(learnt) == pair_partner.shape_step.n_points_
    renamed = [("Joint" + n if n in learnt[:2] else n) for n in a.skeleton.names]
    other = dataclasses.replace(a, skeleton=dataclasses.replace(a.skeleton, names=tuple(renamed)))
    with pytest.raises(SkeletonMismatchError, match=f"lacks the joints {learnt[0]}, {learnt[1]}"):
        pair_partner.check_input(other)
    with pytest.raises(SkeletonMismatchError, match="matched by name"):
        pair_partner.respond(other)
    assert pair_partner.person(a).points.shape[1] == len(learnt)


def test_a_skeleton_exported_with_a_namespace_is_the_same_skeleton(pair_partner, mocap):
    """Mixamo's ``mixamorig:hip`` is ``hip`` (as a marker's ``P1:R_HAND`` is ``R_HAND``): the
    same take with its joints so named is answered as the take (it was refused, every joint
    named lacking), and a model learnt with the namespace finds the joints without it."""
    import dataclasses

    from markovmotion.features.joint_shape import shape_joints

    a, _ = mocap.load_pair(*mocap.pairs(label="salsa")[0])
    a = a.trim(600, 660)
    names = tuple(f"mixamorig:{n}" for n in a.skeleton.names)
    other = dataclasses.replace(a, skeleton=dataclasses.replace(a.skeleton, names=names))
    pair_partner.check_input(other)
    np.testing.assert_array_equal(pair_partner.person(other).points, pair_partner.person(a).points)
    mine = pair_partner.respond(a, n_hypotheses=1)
    theirs = pair_partner.respond(other, n_hypotheses=1)
    np.testing.assert_allclose(theirs.positions(), mine.positions())
    learnt = pair_partner.shape_names
    assert shape_joints(a.skeleton, [f"mixamorig:{n}" for n in learnt]) == shape_joints(
        a.skeleton, learnt
    )
    assert shape_joints(other.skeleton) == shape_joints(a.skeleton)  # the major joints


def test_a_response_holds_its_own_shape_not_the_frames_hypotheses():
    """A response's shape was a row of the frame's (hypotheses, d) array, which it kept
    alive: a 100,000-frame take at 200 hypotheses held every frame's (8 GB for 42,000
    frames at 25 fps, a new user's trial); now each response holds its own d numbers."""
    from markovmotion.models.chain.condensation import Response

    hypotheses = np.arange(200 * 119, dtype=float).reshape(200, 119)
    r = Response(hypotheses[17], 0, 0.5)
    assert r.shape.base is None and r.shape.nbytes == 119 * 8
    np.testing.assert_array_equal(r.shape, hypotheses[17])


def test_evaluate_without_test_answers_the_takes_held_out_of_the_index_learnt(
    mocap, tmp_path, capsys
):
    """A chain trained on a user's own index holds out a trial there; ``chain evaluate``
    without ``--test`` answers that trial's take from that index (it had answered the
    shared collection's held-out takes, which the user never gave it)."""
    trials = [a.trial for a, _ in mocap.pairs(label="salsa")][:3]
    _copy_index(tmp_path / "own", mocap, dict(zip(("x", "y", "z"), trials, strict=True)))
    model = tmp_path / "m.npz"
    main(["chain", "train", "--data", str(tmp_path / "own"), "--label", "salsa", "--epochs", "1",
          "--prototypes", "4", "--behaviours", "4", "--test-trials", "z", "--out", str(model)])  # fmt: skip
    assert VirtualPartner.load(model).held_out_files_ == ["takes/z_a.bvh.gz", "takes/z_b.bvh.gz"]
    capsys.readouterr()
    main(["chain", "evaluate", "--model", str(model), "--hypotheses", "4", "--json"])
    assert json.loads(capsys.readouterr().out)["test_files"] == [
        "takes/z_a.bvh.gz",
        "takes/z_b.bvh.gz",
    ]


def test_a_3d_partner_of_either_person_is_refused_in_one_line(pair_partner, mocap):
    """``respond(person=None)`` on motion capture: a ValueError saying 0 or 1 (the partner
    is written on the other's skeleton), not a TypeError from inside."""
    a, _ = mocap.load_pair(*mocap.pairs(label="salsa")[-1])
    with pytest.raises(ValueError, match=r"person must be 0 \(A\) or 1 \(B\) for a 3-D partner"):
        pair_partner.respond(a.trim(0, 30), person=None)
