"""Variable-length Markov models (VLMM paper §3): suffix tree, automaton, behaviour model, E_T."""

from __future__ import annotations

import copy
import json
import shutil

import numpy as np
import pytest
from conftest import make_motion
from scipy.spatial.transform import Rotation

from markovmotion.algorithms.kinematics import fit_rotations, rotvec_positions
from markovmotion.data.splits import held_out_last
from markovmotion.evaluate.vlmm import HorizonCurve, ZeroVelocity, evaluate_horizon
from markovmotion.models.base import Model
from markovmotion.models.vlmm.behaviour import BehaviourModel, load_motions
from markovmotion.models.vlmm.prediction_suffix_tree import VLMM, prediction_suffix_tree


def variable_order_source(n: int, seed: int = 0) -> np.ndarray:
    """Tokens 0-4 where the next token needs 3 tokens of memory after ``0 1``, 1 elsewhere.

    0 -> 1; 1 -> 3 after ``2 0 1`` or ``4 0 1``, 2 after ``3 0 1``; 2 -> 0 (p .6)
    or 4 (p .4); 3 -> 0; 4 -> 0.
    """
    rng = np.random.default_rng(seed)
    s = [2, 0, 1]
    while len(s) < n:
        a = s[-1]
        if a == 0:
            s.append(1)
        elif a == 1:
            s.append({2: 3, 3: 2, 4: 3}[s[-3]])
        elif a == 2:
            s.append(0 if rng.random() < 0.6 else 4)
        else:
            s.append(0)
    return np.array(s)


#: The memories that source needs: every token alone, and the three contexts
#: of ``0 1`` (with ``0 1`` itself, uninformative but their common suffix).
TRUE_MEMORIES = {(), (0,), (1,), (2,), (3,), (4,), (0, 1), (2, 0, 1), (3, 0, 1), (4, 0, 1)}


def memories(model: VLMM, tree_only: bool = True) -> set[tuple[int, ...]]:
    out = set()
    for q in range(model.n_states):
        if tree_only and not model.in_suffix_tree_[q]:
            continue
        n = model.memory_lengths_[q]
        out.add(
            tuple(int(v) for v in model.memories_[q, model.memories_.shape[1] - n :]) if n else ()
        )
    return out


@pytest.fixture(scope="module")
def source_model() -> VLMM:
    x = variable_order_source(20000)
    return VLMM(max_memory=6, epsilon=1e-3).fit([x[:12000], x[12000:]])


# ----------------------------------------------------------------- the VLMM
def test_vlmm_recovers_exactly_the_memories_of_a_variable_order_source(source_model):
    assert memories(source_model) == TRUE_MEMORIES
    assert source_model.output_probs(memories_index(source_model, (3, 0, 1)))[2] == 1.0
    hist = source_model.memory_length_histogram()
    assert hist.sum() == source_model.n_states and len(hist) == 7


def memories_index(model: VLMM, memory: tuple[int, ...]) -> int:
    for q in range(model.n_states):
        n = model.memory_lengths_[q]
        if tuple(model.memories_[q, model.memories_.shape[1] - n :]) == memory and n == len(memory):
            return q
    raise KeyError(memory)


def test_kl_pruning_removes_a_memory_that_adds_no_information():
    x = variable_order_source(20000)
    levels, kept, gains = prediction_suffix_tree([x], 5, 3, 1e-3)
    # "2 0" is counted in the prefix tree, predicts exactly what "0" predicts (1) ...
    level2 = levels[2]
    zero = np.flatnonzero(levels[1].symbol == 0)[0]
    two_zero = np.flatnonzero((level2.parent == zero) & (level2.symbol == 2))[0]
    offset = len(levels[1].symbol)
    assert gains[offset + two_zero] == 0.0
    # ... so it is pruned, and so are all memories of a first-order chain beyond length 1
    assert not kept[2][two_zero]
    rng = np.random.default_rng(3)
    trans = rng.dirichlet(np.ones(4), size=4)
    chain = [0]
    for _ in range(20000):
        chain.append(rng.choice(4, p=trans[chain[-1]]))
    pruned = VLMM(max_memory=3, epsilon=1e-3).fit([np.array(chain)])
    assert pruned.memory_lengths_.max() == 1
    assert VLMM(max_memory=3, epsilon=0.0).fit([np.array(chain)]).memory_lengths_.max() == 3


def test_pfsa_output_distributions_sum_to_one_and_transitions_are_exact(source_model):
    m = source_model
    sums = np.add.reduceat(m.out_probs_, m.out_indptr_[:-1])
    assert np.allclose(sums, 1.0)
    assert m.start_probs_.sum() == pytest.approx(1.0)
    # delta(q, a) is the longest suffix of q a among the states (brute force)
    by_memory = {mem: q for q in range(m.n_states) for mem in [tuple(memories_of(m, q))]}
    rows = np.repeat(np.arange(m.n_states), np.diff(m.out_indptr_))
    for q, a, nxt in zip(rows, m.out_symbols_, m.next_state_, strict=True):
        s = tuple(memories_of(m, q)) + (int(a),)
        longest = next(s[i:] for i in range(len(s) + 1) if s[i:] in by_memory)
        assert by_memory[longest] == nxt
    # recognition predicts with the longest suffix of the whole history in the tree
    x = variable_order_source(300, seed=5)
    states = m.recognise(x)
    tree = memories(m)
    for t in range(10, 300, 7):
        hist = tuple(int(v) for v in x[: t + 1])
        longest = next(hist[i:] for i in range(len(hist) - 7, len(hist) + 1) if hist[i:] in tree)
        assert np.allclose(m.output_probs(states[t]), m.output_probs(by_memory[longest]))


def memories_of(m: VLMM, q: int) -> list[int]:
    n = m.memory_lengths_[q]
    return [int(v) for v in m.memories_[q, m.memories_.shape[1] - n :]] if n else []


def test_unseen_event_backs_off_to_the_root(source_model):
    m = source_model
    q = memories_index(m, (0,))  # "0" is always followed by 1: 3 is unseen here
    assert m.transition(np.array([q]), np.array([3]))[0] == memories_index(m, (3,))


def test_generation_ml_is_deterministic_and_stochastic_follows_the_model(source_model):
    m = source_model
    assert np.array_equal(m.generate(50), m.generate(50))
    sample = m.generate(20000, np.random.default_rng(0))
    after_2 = sample[1:][sample[:-1] == 2]
    assert np.mean(after_2 == 0) == pytest.approx(0.6, abs=0.03)
    # every generated transition is one the source allows
    allowed = {(0, 1), (1, 2), (1, 3), (2, 0), (2, 4), (3, 0), (4, 0)}
    assert set(zip(sample[:-1].tolist(), sample[1:].tolist(), strict=True)) <= allowed


def test_log_likelihood_by_hand():
    m = VLMM(1, 0.0).fit([np.array([0, 1, 0, 1, 1]), np.array([1, 1, 0])], n_symbols=2)
    # P(0) = 3/8 at the root, P(1 | 0) = 1, P(1 | 1) = P(0 | 1) = 1/2
    assert m.log_likelihood([0, 1, 1, 0]) == pytest.approx(np.log(3 / 8) + 2 * np.log(0.5))
    assert m.log_likelihood([]) == 0.0
    # "0 0" is unseen after 0: backs off to the root's P(0)
    assert m.log_likelihood([0, 0]) == pytest.approx(2 * np.log(3 / 8))


def test_vlmm_save_load_round_trip(tmp_path, behaviour_model, exercise):
    path = tmp_path / "m.npz"
    behaviour_model.save(path, note="x")
    loaded = BehaviourModel.load(path)
    assert type(Model.load(path)) is BehaviourModel and loaded.note_ == "x"
    assert loaded.train_files_ == behaviour_model.train_files_
    assert [r["file"] for r in loaded.train_files_] == [m.name for m in exercise[0]]
    assert loaded.score(exercise[1]) == behaviour_model.score(exercise[1])
    assert np.array_equal(loaded.prototypes_, behaviour_model.prototypes_)
    assert np.array_equal(loaded.vlmm_.next_state_, behaviour_model.vlmm_.next_state_)
    a = behaviour_model.generate(3.0, np.random.default_rng(4))
    b = loaded.generate(3.0, np.random.default_rng(4))
    assert np.allclose(a.rotations, b.rotations)
    assert np.array_equal(
        loaded.vlmm_.recognise([1, 2, 3]), behaviour_model.vlmm_.recognise([1, 2, 3])
    )


# ------------------------------------------------------------------- E_T
class _Identity:
    """A predictor whose configurations are one 3-D point in mm (positions = C)."""

    n_dims = 3

    def __init__(self, offsets: np.ndarray):
        self.offsets = offsets  # (samples, 3): prediction = C_t + offset at every horizon

    def prepare(self, features):
        return None

    def predict_configurations(self, features, prepared, frames, horizon, n_samples, rng):
        c = features[frames, :3]
        return np.broadcast_to(
            c[:, None, None, :] + self.offsets[None, :, None, :],
            (len(frames), len(self.offsets), horizon, 3),
        )

    def configuration_positions(self, configs):
        return configs.reshape(-1, 1, 3)


def test_e_t_agrees_with_a_hand_computation():
    c = np.array([[0.0, 0, 0], [3, 4, 0], [3, 4, 0], [6, 8, 0]])
    feats = np.hstack([c, np.zeros_like(c)])
    zero = evaluate_horizon(ZeroVelocity(_Identity(np.zeros((1, 3)))), [feats], 2, 1.0, 1)
    # T = 1: |C_t - C_t+1| for t = 0, 1, 2 -> 5, 0, 5; T = 2: t = 0, 1 -> 5, 5
    assert zero.mean.tolist() == pytest.approx([10 / 3, 5.0])
    assert zero.mad.tolist() == pytest.approx([(5 / 3 + 10 / 3 + 5 / 3) / 3, 0.0])
    assert zero.count.tolist() == [3, 2]
    # two Monte Carlo samples per frame at +-(0, 0, 1): each trial error is hypot(d, 1)
    mc = evaluate_horizon(_Identity(np.array([[0, 0, 1.0], [0, 0, -1.0]])), [feats], 1, 1.0, 2)
    assert mc.mean[0] == pytest.approx((2 * np.hypot(5, 1) + 1) / 3)
    assert mc.count[0] == 6
    assert HorizonCurve.from_errors("x", 2.0, np.array([[1.0, np.nan], [3.0, 4.0]])).at(1.0) == 4.0


# ------------------------------------------------------- the behaviour model
@pytest.fixture(scope="module")
def exercise(mocap):
    """Three Indian-dance takes for training and one held out, at 15 fps."""
    entries = mocap.query(category="exercise", label="indian_dance")
    train, test = held_out_last(entries)
    assert [e.name for e in test] == ["indian_14"]
    motions, _ = load_motions(mocap, train[:3] + test, 15.0)
    return motions[:3], motions[3:]


@pytest.fixture(scope="module")
def behaviour_model(exercise) -> BehaviourModel:
    train, _ = exercise
    return BehaviourModel(n_prototypes=40, max_memory=5, fps=15.0, random_state=0).fit(train)


def test_behaviour_model_generates_ml_deterministically_and_writes_bvh(behaviour_model, tmp_path):
    from markovmotion.io import read_motion, write_motion

    a = behaviour_model.generate(4.0, stochastic=False)
    b = behaviour_model.generate(4.0, np.random.default_rng(9), stochastic=False)
    assert np.array_equal(a.rotations, b.rotations)
    c, d = behaviour_model.generate(4.0), behaviour_model.generate(4.0)  # random_state
    assert np.array_equal(c.rotations, d.rotations)
    assert a.n_frames == 61 and a.skeleton.same_topology(behaviour_model.skeleton_)
    write_motion(behaviour_model.generate(4.0, np.random.default_rng(1)), tmp_path / "g.bvh")
    assert read_motion(tmp_path / "g.bvh").n_frames == 61


def test_generated_motion_passes_through_the_prototypes(behaviour_model):
    m = behaviour_model
    tokens = m.generate_tokens(3.0, np.random.default_rng(2))
    configs = m.synthesize(tokens)
    c, dc = m.knots(tokens)
    times = np.r_[0, np.cumsum(m.intervals(c, dc))]
    at_knots = configs[np.round(times).astype(int)[np.isclose(times, np.round(times))]]
    assert np.allclose(at_knots, c[np.isclose(times, np.round(times))])
    assert np.allclose(configs[0], c[0])


def test_fk_of_configurations_matches_the_motion(behaviour_model, exercise):
    m = behaviour_model
    motion = exercise[1][0].trim(0, 40)
    feats = m.observe([motion])[0]
    pos = m.configuration_positions(feats[:, : m.n_dims])
    truth = m.to_motion(feats[:, : m.n_dims]).positions()[:, m.eval_joints_]
    assert np.allclose(pos, truth, atol=1e-6)
    rv = Rotation.from_quat(motion.rotations.reshape(-1, 4)).as_rotvec().reshape(40, -1, 3)
    assert np.allclose(
        rotvec_positions(motion.skeleton, rv, motion.translations[:, 0]), motion.positions()
    )
    assert np.allclose(
        fit_rotations(motion.skeleton, motion.positions()).positions(), motion.positions()
    )


def test_positions_configuration_goes_back_to_bvh_through_ik(exercise):
    train, test = exercise
    model = BehaviourModel(n_prototypes=20, max_memory=3, fps=15.0, configuration="positions")
    model.fit(train[:1])
    motion = model.generate(2.0, np.random.default_rng(0))
    assert motion.skeleton.same_topology(train[0].skeleton)
    # IK keeps the prototypes' joint directions: the fitted pose matches the
    # generated positions up to bone lengths
    feats = model.observe([test[0].trim(0, 10)])[0]
    target = model.pipeline_.inverse_transform([feats[:, : model.n_dims]])[0]
    fitted = model.to_motion(feats[:, : model.n_dims]).body_centred_positions()
    assert np.linalg.norm(fitted - target, axis=-1).mean() < 20.0


def test_prediction_beats_nothing_silly_on_held_out_dance(behaviour_model, exercise):
    """E_T on a held-out take: bounded, and the VLMM no worse than first order at 2 s."""
    m = behaviour_model
    feats = m.observe(exercise[1])
    kw = dict(horizon=30, fps=m.fps, n_samples=10, stride=10)
    vlmm = evaluate_horizon(m, feats, **kw)
    first = evaluate_horizon(m.with_vlmm(1, 0.0), feats, **kw)
    assert 10.0 < vlmm.at(1.0) < 400.0
    assert vlmm.at(2.0) < first.at(2.0) * 1.1
    pred = m.predict(exercise[1][0].trim(0, 60), 1.0)
    assert pred.n_frames == 60 + 15


def test_smooth_join_blends_the_paper_curve_with_the_observed_pose(behaviour_model, exercise):
    """continuation = w C0 + (1 - w) H with w = exp(-T / (join fps)); join 0 is the paper's H."""
    m = behaviour_model
    feats = m.observe(exercise[1])[0]
    c0, dc0 = m.start_knots(feats, np.array([20, 40]), 1)
    tokens = np.tile(m.generate_tokens(4.0, np.random.default_rng(3)), (2, 1))
    paper = m.continuation(tokens, c0, dc0, 30)
    joined = copy.copy(m)
    joined.join = 1.0
    w = np.exp(-np.arange(1, 31) / m.fps)[None, :, None]
    assert np.allclose(joined.continuation(tokens, c0, dc0, 30), w * c0[:, None] + (1 - w) * paper)
    assert np.array_equal(m.join_weights(30), np.zeros(30))
    with pytest.raises(ValueError, match="join"):
        BehaviourModel(join=-1.0).fit(exercise[0][:1])


def test_joined_prediction_beats_holding_still_on_held_out_dance(exercise):
    """The cross-validated settings (body-centred positions, lambda 100, join 2 s) predict
    a held-out take better than holding the last pose at 1, 2 and 3 s, and better than a
    first-order Markov model with the same join at 2 and 3 s."""
    train, test = exercise
    m = BehaviourModel(40, fps=15.0, configuration="positions", lam=100.0, join=2.0).fit(train)
    feats = m.observe(test)
    kw = dict(horizon=45, fps=m.fps, n_samples=10, stride=5)
    vlmm = evaluate_horizon(m, feats, **kw)
    zero = evaluate_horizon(ZeroVelocity(m), feats, **kw)
    first = evaluate_horizon(m.with_vlmm(1, 0.0), feats, **kw)
    for s in (1.0, 2.0, 3.0):
        assert vlmm.at(s) < zero.at(s)
    for s in (2.0, 3.0):
        assert vlmm.at(s) < first.at(s)


def test_score_is_the_vlmm_likelihood_of_the_prototype_sequences(behaviour_model, exercise):
    m = behaviour_model
    train = exercise[0]
    assert np.array_equal(m.tokens(train[0]), m.token_sequences()[0])
    total = sum(m.vlmm_.log_likelihood(t) for t in m.token_sequences())
    assert m.score(train) == pytest.approx(total)
    assert np.isfinite(m.score(exercise[1])) and m.score(exercise[1]) < 0


def test_cli_train_generate_predict_evaluate(tmp_path, mocap, capsys):
    from markovmotion.cli import main

    model = tmp_path / "m.npz"
    main(["vlmm", "train", "--label", "indian_dance", "--prototypes", "30", "--max-memory", "4",
          "--fps", "10", "--out", str(model)])  # fmt: skip
    main(["vlmm", "generate", "--model", str(model), "--seconds", "3", "--stochastic",
          "--out", str(tmp_path / "g.bvh")])  # fmt: skip
    assert (tmp_path / "g.bvh").is_file()
    take = mocap.find("cmu/bvh/indian_14.bvh.gz").path
    main(["vlmm", "predict", "--model", str(model), "--input", str(take), "--horizon", "1",
          "--out", str(tmp_path / "p.bvh"), "--animation", str(tmp_path / "p.png")])  # fmt: skip
    assert (tmp_path / "p.png").stat().st_size > 1000  # observed, then predicted in red
    capsys.readouterr()
    main(["vlmm", "evaluate", "--model", str(model), "--test", str(mocap.root), "--samples", "3",
          "--stride", "40", "--json", "--plot", str(tmp_path / "et.png")])  # fmt: skip
    result = json.loads(capsys.readouterr().out)
    for name in ("vlmm", "first_order", "zero_velocity"):
        for s in ("0.5", "1", "2", "3"):
            assert result[f"E_T_mm.{name}.{s}"] > 0
    # the shared index: the model's category and labels, its five training takes left out
    assert result["test_files"] == ["cmu/bvh/indian_14.bvh.gz"]
    assert len(result["left_out_training_files"]) == 5
    assert (tmp_path / "et.png").stat().st_size > 1000
    walk = mocap.find(mocap.query(source="bandai")[0].file).path  # another skeleton: named
    with pytest.raises(SystemExit) as info:
        main(["vlmm", "predict", "--model", str(model), "--input", str(walk),
              "--out", str(tmp_path / "w.bvh")])  # fmt: skip
    assert info.value.code == 2
    assert f"{walk}: the input's skeleton does not match" in capsys.readouterr().err


def test_the_plot_says_what_was_evaluated():
    """The E_T plot's frame count is at the model's rate (it gave a 120 fps take's frames,
    4 times those evaluated at 30), one curve asked for under two names shows both, and the
    legend reads as words."""
    from markovmotion.evaluate.vlmm import VlmmEvaluation, curve_label

    take = make_motion(n_frames=121, fps=120.0)  # 1 s
    curve = HorizonCurve("vlmm", 30.0, np.ones(3), np.zeros(3), np.ones(3))
    run = VlmmEvaluation({"vlmm": curve, "vlmm_N5": curve}, None, [take], 0.1, 5, 1)
    assert run.n_frames == 31
    near = make_motion(n_frames=146, fps=30.00003)  # kept as it is by resample, as evaluated
    run = VlmmEvaluation({"vlmm": curve}, None, [near], 0.1, 5, 1)
    assert run.n_frames == 146
    assert curve_label("vlmm = vlmm_N5") == "VLMM (the model) = VLMM, memory 5"
    assert curve_label("first_order").startswith("first-order Markov")
    assert curve_label("zero_velocity").startswith("zero velocity")


def copied_index(folder, rows) -> str:
    """An INDEX.csv in ``folder`` listing byte copies of shared takes under new names."""
    folder.mkdir()
    lines = ["file,source,subject,trial,category,label,partner_file,fps,frames,description"]
    for name, e in rows:
        shutil.copyfile(e.path, folder / name)
        lines.append(f"{name},{e.source},{e.subject},{e.trial},{e.category},{e.label},,"
                     f"{e.fps:g},{e.frames},a copy")  # fmt: skip
    (folder / "INDEX.csv").write_text("\n".join(lines) + "\n")
    return str(folder / "INDEX.csv")


def test_cli_evaluate_test_index_leaves_out_training_takes_by_content(
    tmp_path, mocap, behaviour_model, capsys
):
    """--test on any index: its takes whatever their names, minus copies of training takes."""
    from markovmotion.cli import main

    model = tmp_path / "m.npz"
    behaviour_model.save(model)  # trained on indian_04, 06 and 07
    take = {e.name: e for e in mocap.query(category="exercise", label="indian_dance")}
    walk = mocap.query(source="bandai")[0]
    index = copied_index(tmp_path / "other", [("dance_a.bvh.gz", take["indian_04"]),
                         ("dance_b.bvh.gz", take["indian_14"]), ("walk.bvh.gz", walk)])  # fmt: skip
    capsys.readouterr()
    main(["vlmm", "evaluate", "--model", str(model), "--test", index, "--samples", "2",
          "--stride", "60", "--horizon", "1", "--json"])  # fmt: skip
    result = json.loads(capsys.readouterr().out)
    assert result["test_files"] == ["dance_b.bvh.gz"]
    assert result["left_out_training_files"] == ["dance_a.bvh.gz"]
    assert result["left_out_other_skeleton"] == ["walk.bvh.gz"]
    for name in ("vlmm", "first_order", "zero_velocity"):
        assert result[f"E_T_mm.{name}.0.5"] > 0 and result[f"E_T_mm.{name}.1"] > 0
    # an index of training takes only: one line naming them, exit 2
    index = copied_index(tmp_path / "train", [("a.bvh.gz", take["indian_04"]),
                         ("b.bvh.gz", take["indian_06"])])  # fmt: skip
    with pytest.raises(SystemExit) as info:
        main(["vlmm", "evaluate", "--model", str(model), "--test", index, "--json"])
    assert info.value.code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "trained on: a.bvh.gz, b.bvh.gz" in err
    # an index of another skeleton alone: one line saying what differs
    index = copied_index(tmp_path / "walks", [("walk.bvh.gz", walk)])
    with pytest.raises(SystemExit) as info:
        main(["vlmm", "evaluate", "--model", str(model), "--test", index, "--json"])
    err = capsys.readouterr().err.strip()
    assert info.value.code == 2 and len(err.splitlines()) == 1
    assert "(walk.bvh.gz: (27 joints, the model's 57; the model's joints hip, abdomen" in err


def test_markers_source_learns_13_points_and_writes_c3d_and_point_lights(tmp_path, mocap, capsys):
    """--source markers: the paper's 13 body points from a skeleton, generation and prediction
    as C3D (read back: 13 named markers) or a point-light GIF, E_T in mm and in
    configuration space (eq. 9); a BVH output for a markers model is one line, exit 2."""
    from markovmotion.cli import main
    from markovmotion.features.body_points import MARKER_POINTS
    from markovmotion.io import read_c3d

    model = tmp_path / "m.npz"
    main(["vlmm", "train", "--source", "markers", "--label", "indian_dance", "--prototypes",
          "20", "--max-memory", "3", "--fps", "10", "--lam", "30", "--out", str(model)])  # fmt: skip
    main(["vlmm", "generate", "--model", str(model), "--seconds", "2", "--stochastic",
          "--out", str(tmp_path / "g.c3d")])  # fmt: skip
    markers = read_c3d(tmp_path / "g.c3d")
    assert markers.names == MARKER_POINTS and markers.n_frames == 21 and markers.fps == 10
    assert np.isfinite(markers.positions).all() and markers.positions[..., 1].min() >= -1e-3
    # head above the ankles, shoulders wider apart than nothing: a human-shaped cloud
    assert (markers.positions[:, 0, 1] > markers.positions[:, -1, 1] + 500).all()
    take = mocap.find("cmu/bvh/indian_14.bvh.gz").path
    main(["vlmm", "predict", "--model", str(model), "--input", str(take), "--horizon", "1",
          "--out", str(tmp_path / "p.gif")])  # fmt: skip
    assert (tmp_path / "p.gif").stat().st_size > 1000
    walk = mocap.query(source="bandai")[0].path  # another skeleton: its 13 points by name
    main(["vlmm", "predict", "--model", str(model), "--input", str(walk), "--horizon", "1",
          "--out", str(tmp_path / "w.c3d")])  # fmt: skip
    assert read_c3d(tmp_path / "w.c3d").names == MARKER_POINTS
    capsys.readouterr()
    for space in ("mm", "configuration"):
        main(["vlmm", "evaluate", "--model", str(model), "--samples", "3", "--stride", "40",
              "--space", space, "--json"])  # fmt: skip
        result = json.loads(capsys.readouterr().out)
        assert all(result[f"E_T_{space}.{n}.1"] > 0 for n in ("vlmm", "zero_velocity"))
    assert result["E_T_configuration.vlmm.1"] < 39**0.5  # within the diagonal of [0, 1]^39
    with pytest.raises(SystemExit) as info:
        main(["vlmm", "generate", "--model", str(model), "--out", str(tmp_path / "g.bvh")])
    assert info.value.code == 2
    assert "C3D" in capsys.readouterr().err


def test_markers_read_from_c3d_files_go_through_train_generate_predict_evaluate(
    tmp_path, exercise, capsys
):
    """A markers-only capture: C3D files of an index (30 named markers, none of them the 13
    body points), learnt as named; generation and prediction come out as the same markers,
    E_T is measured on the held-out C3D take, and a BVH where a C3D is wanted is one line."""
    from markovmotion.cli import main
    from markovmotion.features.markers import virtual_marker_names, virtual_markers
    from markovmotion.io import read_c3d, write_c3d

    train, test = exercise
    data = tmp_path / "c3d"
    rows = ["file,source,subject,trial,category,label,partner_file,fps,frames,description"]
    for k, motion in enumerate([*train, *test], start=1):
        markers = virtual_markers(motion, 30)
        markers.positions[5:8, 3] = np.nan  # a marker unseen for three frames
        write_c3d(markers, data / f"take{k}.c3d")
        rows.append(f"take{k}.c3d,test,,{k},exercise,dance,,15,{markers.n_frames},")
    (data / "INDEX.csv").write_text("\n".join(rows) + "\n")
    model = tmp_path / "m.npz"
    main(["vlmm", "train", "--source", "markers", "--data", str(data), "--prototypes", "20",
          "--max-memory", "3", "--fps", "15", "--lam", "30", "--out", str(model)])  # fmt: skip
    assert "held out: take4.c3d" in " ".join(capsys.readouterr().err.split())
    main(["vlmm", "generate", "--model", str(model), "--seconds", "2", "--stochastic",
          "--out", str(tmp_path / "g.c3d")])  # fmt: skip
    generated = read_c3d(tmp_path / "g.c3d")
    assert generated.names == virtual_marker_names(30) and generated.n_frames == 31
    assert np.isfinite(generated.positions).all()
    spread = np.ptp(generated.positions[..., 1], axis=1)
    assert (spread > 1000).all()  # a standing body's height, every frame
    main(["vlmm", "predict", "--model", str(model), "--input", str(data / "take4.c3d"),
          "--horizon", "1", "--out", str(tmp_path / "p.c3d")])  # fmt: skip
    predicted = read_c3d(tmp_path / "p.c3d")
    assert predicted.n_frames == test[0].n_frames + 15 and predicted.names == generated.names
    capsys.readouterr()
    main(["vlmm", "evaluate", "--model", str(model), "--test", str(data), "--samples", "3",
          "--stride", "20", "--json"])  # fmt: skip
    result = json.loads(capsys.readouterr().out)
    assert result["test_files"] == ["take4.c3d"]
    # on markers that move, predicting beats nothing: below twice holding still
    assert 0 < result["E_T_mm.vlmm.1"] < 2 * result["E_T_mm.zero_velocity.1"]
    with pytest.raises(SystemExit) as info:
        main(["vlmm", "predict", "--model", str(model), "--input", str(tmp_path / "x.bvh"),
              "--out", str(tmp_path / "q.c3d")])  # fmt: skip
    assert info.value.code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "learnt markers" in err


def test_a_renamed_skeleton_says_which_joint_names_are_the_models(
    tmp_path, mocap, behaviour_model, capsys
):
    """``vlmm predict`` of a take whose joints are renamed (as 3ds Max's ``Bip01 ``; a
    namespace alone, Mixamo's ``mixamorig:``, is the same skeleton: test_mixed_collection):
    the line said "(57 joints, expected 57; joints differ: abdomen, chest, ... and 99 more)",
    both sides' names mixed, end sites among them; now which are the model's, which the
    input's, in skeleton order, end sites (named after their joints) left out."""
    from dataclasses import replace

    from markovmotion.cli import main
    from markovmotion.io import write_motion

    dance = mocap.load_motion(mocap.find("cmu/bvh/indian_14.bvh.gz")).trim(0, 30)
    sk = dance.skeleton
    renamed = replace(sk, names=tuple(f"Bip01 {n}" for n in sk.names))
    take = tmp_path / "renamed.bvh"
    write_motion(replace(dance, skeleton=renamed), take)
    model = tmp_path / "m.npz"
    behaviour_model.save(model)
    with pytest.raises(SystemExit) as info:
        main(["vlmm", "predict", "--model", str(model), "--input", str(take),
              "--out", str(tmp_path / "p.bvh")])  # fmt: skip
    err = capsys.readouterr().err.strip()
    joints = [n for n, end in zip(sk.names, sk.end_site, strict=True) if not end]
    assert info.value.code == 2 and err == (
        f"error: {take}: the input's skeleton does not match (57 joints, the model's 57; the "
        f"model's joints {', '.join(joints[:5])} (and {len(joints) - 5} more) are not in the "
        f"input, which has {', '.join('Bip01 ' + n for n in joints[:5])} "
        f"(and {len(joints) - 5} more) instead)"
    )
    assert "_end" not in err


def test_one_take_is_said_in_the_singular(tmp_path, mocap, capsys):
    """``vlmm train`` on one take said "trained on 1 takes"; ``generate`` and ``evaluate``
    count the same way."""
    from markovmotion.cli import main

    dance, other = mocap.query(category="exercise", label="indian_dance")[:2]
    index = copied_index(tmp_path / "one", [("a.bvh.gz", dance)])
    test = copied_index(tmp_path / "test", [("b.bvh.gz", other)])
    model = tmp_path / "m.npz"
    main(["vlmm", "train", "--data", index, "--no-hold-out", "--prototypes", "10",
          "--max-memory", "2", "--fps", "10", "--out", str(model)])  # fmt: skip
    err = capsys.readouterr().err
    assert "trained on 1 take (" in err and "1 takes" not in err
    main(["vlmm", "evaluate", "--model", str(model), "--test", test, "--samples", "1",
          "--stride", "50", "--horizon", "1"])  # fmt: skip
    out = capsys.readouterr().out
    assert "1 prediction per frame" in " ".join(out.split())


def test_a_markers_model_observes_any_skeleton_with_the_13_points(mocap):
    """A ``configuration="markers"`` model learnt from CMU dances finds its 13 body points by
    name on a Bandai walk's skeleton (another topology) and predicts it; a skeleton model
    does not take it, and says which joints differ."""
    dances = [mocap.load_motion(e).trim(0, 240) for e in mocap.query(label="indian_dance")[:2]]
    walk = mocap.load_motion(mocap.query(source="bandai")[0]).trim(0, 120)
    assert not walk.skeleton.same_topology(dances[0].skeleton)
    model = BehaviourModel(n_prototypes=12, max_memory=2, fps=15.0, configuration="markers")
    model.fit(dances)
    assert model.fits(walk)
    (features,) = model.observe([walk])
    assert features.shape[0] == walk.resample(15.0).n_frames and np.isfinite(features).all()
    future = model.predict(walk, seconds=0.5, rng=np.random.default_rng(0))
    assert future.names == tuple(model.marker_names) and np.isfinite(future.positions).all()
    rotations = BehaviourModel(n_prototypes=12, max_memory=2, fps=15.0).fit(dances)
    assert not rotations.fits(walk) and "are not in the take, which has" in rotations.why_not(walk)


def test_evaluate_names_the_takes_too_short_for_the_horizons(
    tmp_path, mocap, behaviour_model, capsys, recwarn
):
    """Test takes shorter than the horizons: all of them shorter than the shortest is one
    line naming them, exit 2, no plot (it printed tables of NaN, NumPy's "Mean of empty
    slice" and an empty plot, exit 0); some horizons out of reach is a note naming them
    and the takes, those horizons "-" (null in JSON), no NumPy warning either way."""
    from markovmotion.cli import main
    from markovmotion.io import write_motion

    dance = mocap.load_motion(mocap.find("cmu/bvh/indian_14.bvh.gz"))
    model = tmp_path / "m.npz"
    behaviour_model.save(model)  # 15 fps

    def index(folder, takes):
        folder.mkdir()
        lines = ["file,source,subject,trial,category,label,partner_file,fps,frames,description"]
        for name, motion in takes:
            write_motion(motion, folder / name)
            lines.append(f"{name},lab,s1,1,exercise,indian_dance,,{motion.fps:g},"
                         f"{motion.n_frames},short")  # fmt: skip
        (folder / "INDEX.csv").write_text("\n".join(lines) + "\n")
        return str(folder)

    short = dance.resample(15.0).trim(0, 4)  # 4 frames at 15 fps: 0.2 s
    plot = tmp_path / "et.png"
    with pytest.raises(SystemExit) as info:
        main(["vlmm", "evaluate", "--model", str(model), "--test",
              index(tmp_path / "short", [("short.bvh", short)]), "--samples", "2",
              "--plot", str(plot), "--json"])  # fmt: skip
    out = capsys.readouterr()
    assert info.value.code == 2 and out.out == "" and not plot.exists()
    assert out.err.strip() == (
        "error: short.bvh: 4 frames, shorter than the 0.5 s horizon: nothing to evaluate"
    )
    medium = dance.resample(15.0).trim(0, 20)  # 19 frames after the first: 0.5 and 1 s
    shorter = dance.resample(15.0).trim(20, 30)  # 0.5 s only
    main(["vlmm", "evaluate", "--model", str(model), "--test",
          index(tmp_path / "medium", [("medium.bvh", medium), ("shorter.bvh", shorter)]),
          "--samples", "2", "--stride", "3", "--json"])  # fmt: skip
    out = capsys.readouterr()
    result = json.loads(out.out)
    assert result["E_T_mm.vlmm.0.5"] > 0 and result["E_T_mm.vlmm.1"] > 0
    assert result["E_T_mm.vlmm.2"] is None and result["E_T_mm.zero_velocity.3"] is None
    notes = [line for line in out.err.splitlines() if line.startswith("note: ")]
    assert notes == [
        "note: no test take is as long as the 2 and 3 s horizons (the longest, medium.bvh, "
        "has 20 frames): E_T not measured there",
        "note: shorter than some horizons, which are measured on the other takes only: "
        "shorter.bvh (10 frames: 1 s)",
    ]
    assert result["notes"] == [n.removeprefix("note: ") for n in notes]
    assert not [w for w in recwarn if issubclass(w.category, RuntimeWarning)]


def test_the_take_held_out_is_one_of_the_skeleton_learnt(tmp_path, mocap, capsys):
    """An index whose last take of a label is on another skeleton: that take is left out as
    of another skeleton, and the last take on the skeleton learnt is the one held out (it
    had been held out itself, leaving the model nothing to be evaluated on); ``vlmm
    evaluate`` without ``--test`` answers it from that index, not the shared one."""
    from markovmotion.data import MocapIndex
    from markovmotion.models.vlmm.behaviour import fit_index

    take = {e.name: e for e in mocap.query(category="exercise", label="indian_dance")}
    walk = mocap.query(source="bandai")[0]
    folder = tmp_path / "mine"
    folder.mkdir()
    lines = ["file,source,subject,trial,category,label,partner_file,fps,frames,description"]
    for name, e in (("a.bvh.gz", take["indian_04"]), ("b.bvh.gz", take["indian_06"]),
                    ("c.bvh.gz", take["indian_07"]), ("z.bvh.gz", walk)):  # fmt: skip
        shutil.copyfile(e.path, folder / name)
        lines.append(f"{name},lab,s1,1,exercise,dance,,{e.fps:g},{e.frames},mine")
    (folder / "INDEX.csv").write_text("\n".join(lines) + "\n")
    capsys.readouterr()
    fit = fit_index(
        BehaviourModel(n_prototypes=20, max_memory=3, fps=10.0, random_state=0),
        MocapIndex.load(folder), "exercise",
    )  # fmt: skip
    assert fit.model.held_out_files_ == ["c.bvh.gz"]
    assert [e.file for e in fit.used] == ["a.bvh.gz", "b.bvh.gz"]
    assert [e.file for e in fit.other_skeleton] == ["z.bvh.gz"]
    # trained on this index, evaluate without --test answers its held-out take, from it
    from markovmotion.cli import main

    model = tmp_path / "m.npz"
    main(["vlmm", "train", "--data", str(folder), "--prototypes", "20", "--max-memory", "3",
          "--fps", "10", "--out", str(model)])  # fmt: skip
    capsys.readouterr()
    main(["vlmm", "evaluate", "--model", str(model), "--samples", "2", "--stride", "60",
          "--horizon", "1", "--json"])  # fmt: skip
    assert json.loads(capsys.readouterr().out)["test_files"] == ["c.bvh.gz"]
    folder.rename(tmp_path / "moved")  # the index gone: said, and its takes not found
    with pytest.raises(SystemExit) as info:
        main(["vlmm", "evaluate", "--model", str(model), "--json"])
    err = capsys.readouterr().err
    assert info.value.code == 2 and f"the index the model was trained on ({folder})" in err


def test_generate_takes_any_length_within_the_limit_in_linear_memory(behaviour_model):
    """``generate(seconds)`` from Python: past the frame limit, or not a positive number, is
    one LimitError (a day of routine had hung, and 1e5 s asked for 1.5 TiB); within it, the
    samples are found by binary search, the curve the same as the all-pairs count gave."""
    from markovmotion.algorithms.hermite import hermite_sample
    from markovmotion.errors import LimitError

    for seconds in (1e9, -1.0, float("nan"), None, "3"):
        with pytest.raises(LimitError):
            behaviour_model.generate(seconds)
    assert behaviour_model.generate(600.0).n_frames == 600 * 15 + 1
    rng = np.random.default_rng(0)
    knots, tangents = rng.normal(size=(7, 3)), rng.normal(size=(7, 3))
    times = np.cumsum(rng.uniform(0.5, 2.0, 7))
    at = np.linspace(times[0] - 1, times[-1] + 1, 200)
    two = hermite_sample(knots[None], tangents[None], times[None], at[None])[0]  # all pairs
    np.testing.assert_allclose(hermite_sample(knots, tangents, times, at), two, atol=1e-12)


def test_a_skeleton_without_a_body_point_is_one_balanced_line(mocap, tmp_path, capsys):
    """``vlmm predict`` of a markers model on a skeleton lacking a body point: the line
    names the point and closes every bracket it opens (it had cut the reason's own closing
    bracket: "does not match (its skeleton: ... head (looked for head ...)")."""
    from dataclasses import replace

    from markovmotion.cli import main
    from markovmotion.io import write_motion

    dances = [mocap.load_motion(e).trim(0, 240) for e in mocap.query(label="indian_dance")[:2]]
    model = tmp_path / "m.npz"
    BehaviourModel(n_prototypes=8, max_memory=2, fps=15.0, configuration="markers").fit(
        dances
    ).save(model)
    walk = mocap.load_motion(mocap.query(source="bandai")[0]).trim(0, 60)
    names = tuple("noggin" if n.lower() == "head" else n for n in walk.skeleton.names)
    write_motion(replace(walk, skeleton=replace(walk.skeleton, names=names)), tmp_path / "w.bvh")
    with pytest.raises(SystemExit) as info:
        main(["vlmm", "predict", "--model", str(model), "--input", str(tmp_path / "w.bvh"),
              "--out", str(tmp_path / "p.c3d")])  # fmt: skip
    err = capsys.readouterr().err.strip()
    assert info.value.code == 2 and len(err.splitlines()) == 1
    assert "head (looked for head" in err and err.count("(") == err.count(")")
