"""The structured two-level behaviour model (VLMM paper §4) on a routine with known structure."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import make_skeleton
from scipy.spatial.transform import Rotation

from markovmotion.core.motion import Motion
from markovmotion.errors import ModelFormatError
from markovmotion.evaluate.vlmm import evaluate_horizon
from markovmotion.models.base import Model
from markovmotion.models.vlmm.behaviour import BehaviourModel
from markovmotion.models.vlmm.structured import (
    StructuredBehaviourModel,
    key_positions,
    key_prototypes,
    load_behaviour,
    resample,
)

#: Spine and leg angles (degrees) of the three key poses; the routine rests in each.
POSES = np.array([[0.0, 0.0, 0.0], [60.0, 40.0, -30.0], [-50.0, -35.0, 45.0]])


def routine(n_moves: int, seed: int) -> tuple[Motion, list[int]]:
    """Poses 0 1 0 2 0 1 0 2 ...: after pose 0 comes 2 if 1 came before it, else 1.

    Each move eases between two poses in 14-22 frames, then rests 5 frames.
    """
    rng = np.random.default_rng(seed)
    order = [0]
    for k in range(n_moves):
        order.append(0 if order[-1] else (2 if k % 4 == 2 else 1))
    angles = [np.repeat(POSES[:1], 5, axis=0)]
    for a, b in zip(order[:-1], order[1:], strict=True):
        s = 0.5 - 0.5 * np.cos(np.linspace(0, np.pi, int(rng.integers(14, 23))))[1:]
        angles.append(POSES[a] + s[:, None] * (POSES[b] - POSES[a]))
        angles.append(np.repeat(POSES[b : b + 1], 5, axis=0))
    angles = np.vstack(angles) + rng.normal(scale=0.3, size=(1, 3))
    sk = make_skeleton()
    quats = np.tile([0.0, 0, 0, 1], (len(angles), sk.n_joints, 1))
    quats[:, 3] = Rotation.from_euler("X", angles[:, :1], degrees=True).as_quat()
    quats[:, 1] = Rotation.from_euler("Z", angles[:, 1:2], degrees=True).as_quat()
    quats[:, 2] = Rotation.from_euler("Z", angles[:, 2:3], degrees=True).as_quat()
    return Motion.from_rotations(sk, quats, np.tile([0, 900.0, 0], (len(angles), 1))), order


@pytest.fixture(scope="module")
def structured() -> StructuredBehaviourModel:
    motions = [routine(40, seed)[0] for seed in range(3)]
    base = BehaviourModel(n_prototypes=24, max_memory=3, lam=5.0)
    return StructuredBehaviourModel(base, max_memory=3, n_keys=3, cluster_distance=1.0).fit(motions)


def test_key_prototypes_are_frequent_slow_local_minima():
    speeds = np.array([0.1, 1.0, 0.2, 2.0, 0.05])
    seqs = [np.array([0, 1, 2, 3, 0, 1, 4, 3, 2]), np.array([1, 4, 1, 0, 3])]
    # minima: 0 (twice, below 0.5), 2 (once, below), 4 (twice); 2 at the end does not count
    assert key_prototypes(seqs, speeds, 0.5, 2).tolist() == [0, 4]
    assert key_prototypes(seqs, speeds, 0.15, 5).tolist() == [0, 4]
    assert key_positions(np.array([5, 0, 7, 0, 4, 4, 8, 0]), np.array([0, 4])).tolist() == [1, 4, 7]
    assert np.allclose(resample(np.array([[0.0], [2.0]]), 3)[:, 0], [0, 1, 2])


def test_keys_are_the_rest_poses_and_atomic_behaviours_the_moves(structured):
    s = structured
    assert len(s.keys_) == 3
    key_motion = s.prototype_model_.to_motion(s.prototype_model_.knots(s.keys_)[0])
    spine = np.degrees(Rotation.from_quat(key_motion.rotations[:, 3]).as_euler("XYZ")[:, 0])
    assert np.abs(np.sort(spine) - np.sort(POSES[:, 0])).max() < 8.0
    assert s.n_atomic_behaviours == 4  # 0->1, 1->0, 0->2, 2->0
    for pair in {tuple(p) for p in s.template_pairs_}:
        sel = np.all(s.template_pairs_ == pair, axis=1)
        assert s.template_probs_[sel].sum() == pytest.approx(1.0)
    for i in range(len(s.template_probs_)):
        tpl = s.template(i)
        assert tpl[0] == s.keys_[s.template_pairs_[i, 0]]
        assert tpl[-1] == s.keys_[s.template_pairs_[i, 1]]


def generated_keys(model: StructuredBehaviourModel, seed: int) -> list[int]:
    tokens = model.generate_tokens(40.0, np.random.default_rng(seed))
    return tokens[key_positions(tokens, model.keys_)].tolist()


def test_key_memory_captures_the_routine_order_and_first_order_does_not(structured):
    """Paper Fig. 9: with N = 1 the moves come in random order, with N = 3 in the learnt one."""
    middle = structured.keys_[structured.vlmm_.output_probs(0).argmax()]  # pose 0: most frequent
    for n, should_follow in ((3, True), (1, False)):
        keys = generated_keys(structured.with_key_memory(n), seed=1)
        triples = [tuple(keys[i : i + 3]) for i in range(len(keys) - 2) if keys[i + 1] == middle]
        alternates = all(a != c for a, _, c in triples)
        assert alternates == should_follow, (n, triples[:10])
    a = structured.generate(5.0)
    assert np.array_equal(a.rotations, structured.generate(5.0).rotations)


def test_prediction_uses_the_key_history(structured):
    test, _ = routine(16, seed=7)
    feats = structured.observe([test])
    kw = dict(horizon=45, fps=30.0, n_samples=5, stride=4)
    deep = evaluate_horizon(structured, feats, **kw)
    shallow = evaluate_horizon(structured.with_key_memory(1), feats, **kw)
    assert deep.at(1.5) < shallow.at(1.5)
    pred = structured.predict(test.trim(0, 100), 1.0)
    assert pred.n_frames == 130
    # predict matches templates at the last frame alone, as every frame's matching gives it
    every = structured.prepare(feats[0])
    some = structured.prepare(feats[0], [len(feats[0]) - 1, 5])
    assert set(some) == {len(feats[0]) - 1, 5}
    for t, (rest, state, key) in some.items():
        assert np.array_equal(rest, every[t][0]) and (state, key) == every[t][1:]


def test_structured_save_load_round_trip(structured, tmp_path):
    structured.save(tmp_path / "s.npz", held_out_files=["x.bvh"])
    loaded = StructuredBehaviourModel.load(tmp_path / "s.npz")
    assert type(Model.load(tmp_path / "s.npz")) is StructuredBehaviourModel
    assert type(load_behaviour(tmp_path / "s.npz")) is StructuredBehaviourModel
    assert loaded.held_out_files_ == ["x.bvh"] and len(loaded.train_files_) == 3
    with pytest.raises(ModelFormatError, match="is a 'structured_vlmm' model, expected 'vlmm'"):
        BehaviourModel.load(tmp_path / "s.npz")
    structured.prototype_model_.save(tmp_path / "b.npz")
    with pytest.raises(ModelFormatError, match="is a 'vlmm' model, expected 'structured_vlmm'"):
        StructuredBehaviourModel.load(tmp_path / "b.npz")
    assert np.array_equal(loaded.template_tokens_, structured.template_tokens_)
    rng = np.random.default_rng
    assert np.array_equal(
        loaded.generate_tokens(10.0, rng(3)), structured.generate_tokens(10.0, rng(3))
    )


def test_score_is_the_likelihood_of_the_key_sequence(structured):
    train = routine(40, seed=0)[0]
    assert np.array_equal(structured.key_tokens(train), structured.key_sequences()[0])
    test, _ = routine(16, seed=7)
    deep, shallow = structured.score([test]), structured.with_key_memory(1).score([test])
    assert shallow < deep < 0  # the key order needs memory (paper Fig. 9)


def test_a_structured_routine_past_the_frame_limit_is_one_line(structured):
    """As the VLMM's: seconds past the frame limit, or not a positive number, a LimitError."""
    from markovmotion.errors import LimitError

    for seconds in (1e9, 0.0, None):
        with pytest.raises(LimitError):
            structured.generate(seconds)
