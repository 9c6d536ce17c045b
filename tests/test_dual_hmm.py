"""Dual HMM: B generated from A (offline and online), model files, CLI, real salsa pairs."""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest
from conftest import make_skeleton
from scipy.spatial.transform import Rotation

from markovmotion import persist
from markovmotion.cli import main
from markovmotion.core.motion import Motion
from markovmotion.core.skeleton import Skeleton
from markovmotion.errors import ModelFormatError, SkeletonMismatchError
from markovmotion.evaluate.hmm import cross_validate, evaluate_pair, summarise
from markovmotion.io import write_motion
from markovmotion.models.hmm.dual import DualHMM, into_frame, out_of_frame

N_POSES = 4
RNG = np.random.default_rng(11)
POSES_A = RNG.uniform(-70, 70, (N_POSES, 5, 3))  # Euler degrees per joint
POSES_B = RNG.uniform(-70, 70, (N_POSES, 5, 3))
PLACE_B = np.array([[0, 900, 1500], [300, 900, 1200], [-400, 950, 1700], [100, 850, 900.0]])


def state_sequence(n_frames: int, seed: int) -> np.ndarray:
    """Sticky random walk over the poses: segments of 8-20 frames."""
    rng = np.random.default_rng(seed)
    out, state = [], int(rng.integers(N_POSES))
    while len(out) < n_frames:
        out += [state] * int(rng.integers(8, 21))
        state = int((state + rng.integers(1, N_POSES)) % N_POSES)
    return np.array(out[:n_frames])


def motion_of(poses: np.ndarray, states: np.ndarray, roots: np.ndarray, noise: float, seed: int):
    sk = make_skeleton()
    rng = np.random.default_rng(seed)
    angles = poses[states] + rng.normal(0, noise, (len(states), 5, 3))
    angles[:, 0] = 0.0  # the root does not turn: A's heading stays +Z
    quats = Rotation.from_euler("ZXY", angles.reshape(-1, 3), degrees=True).as_quat()
    quats = quats.reshape(len(states), 5, 4)
    quats[:, 4] = [0, 0, 0, 1]
    return Motion.from_rotations(sk, quats, roots, fps=30.0, name=f"synthetic{seed}")


def synthetic_pair(n_frames: int, seed: int) -> tuple[Motion, Motion, np.ndarray]:
    """A cycles through noisy poses; B's pose and place are a fixed function of A's pose."""
    states = state_sequence(n_frames, seed)
    a = motion_of(POSES_A, states, np.tile([0.0, 900.0, 0.0], (n_frames, 1)), 2.0, seed)
    b = motion_of(POSES_B, states, PLACE_B[states], 0.0, seed + 100)
    return a, b, states


@pytest.fixture(scope="module")
def training() -> list[tuple[Motion, Motion]]:
    return [synthetic_pair(n, seed)[:2] for n, seed in ((260, 1), (300, 2), (240, 3))]


@pytest.fixture(scope="module")
def model(training) -> DualHMM:
    return DualHMM(n_states=N_POSES, n_iter=20, window=6, placement_window=1).fit(training)


@pytest.mark.parametrize("observation", ["pose", "motion"])
@pytest.mark.parametrize("mode", ["paper", "joint"])
def test_generated_b_recovers_the_known_function_of_a_state(training, mode, observation):
    dual = DualHMM(
        n_states=N_POSES,
        mode=mode,
        observation=observation,
        n_iter=20,
        window=6,
        placement_window=1,  # B's place jumps with A's state here
    ).fit(training)
    a, b, states = synthetic_pair(200, 9)
    truth = b.positions()
    standard = dual.generate(a, "standard")
    windowed = dual.generate(a, "windowed")
    assert standard.n_frames == windowed.n_frames == a.n_frames
    assert standard.skeleton.same_topology(b.skeleton)
    err_std = np.linalg.norm(standard.positions() - truth, axis=-1).mean(axis=1)
    err_win = np.linalg.norm(windowed.positions() - truth, axis=-1).mean(axis=1)
    # Every frame of B right, pose and place (mm); frame 0 of the windowed decoder starts from
    # the paper's middle state (eq. 3). A's synthetic poses jump from one frame to the next, so
    # with A's motion in the observation a jump frame may still be answered from the state left.
    jumps = np.flatnonzero(np.diff(states)) + 1 if observation == "motion" else []
    assert err_std[np.setdiff1d(np.arange(200), jumps)].max() < 1.0
    assert err_win[np.setdiff1d(np.arange(1, 200), jumps)].max() < 1.0


@pytest.mark.parametrize("placement_window", [1, 7, 15])
def test_partner_streams_what_windowed_generation_gives(model, placement_window, capsys):
    model = copy.copy(model).set_params(placement_window=placement_window)
    a, _, _ = synthetic_pair(90, 5)
    offline = model.generate(a, "windowed").positions()
    partner = model.partner()
    streamed = []
    for t in range(a.n_frames):
        out = partner.step(a.trim(t, t + 1))
        assert (out is None) == (t < partner.lag)
        if out is not None:
            streamed.append(out.positions()[0])
    streamed += [m.positions()[0] for m in partner.finish()]
    np.testing.assert_allclose(np.array(streamed), offline, atol=1e-6)
    assert partner.lag == model.window - 1
    assert capsys.readouterr().err == ""


@pytest.mark.parametrize("placement_window", [1, 9])
def test_a_window_as_long_as_the_take_gives_standard_generation(model, placement_window):
    a, _, _ = synthetic_pair(60, 8)
    model = copy.copy(model).set_params(placement_window=placement_window)
    long_window = copy.copy(model).set_params(window=a.n_frames, initial="prior")
    np.testing.assert_allclose(
        long_window.generate(a, "windowed").positions(),
        model.generate(a, "standard").positions(),
        atol=1e-9,
    )


def test_b_place_is_the_centred_mean_of_the_path_places(model):
    a, _, _ = synthetic_pair(80, 4)
    own = model.generate(a, "standard").translations[:, 0]
    smooth = copy.copy(model).set_params(placement_window=5).generate(a, "standard")
    # A stands still facing +Z, so B's place relative to A is its world place; 5 frames
    # centred, fewer at the ends.
    csum = np.vstack([np.zeros((1, 3)), np.cumsum(own, axis=0)])
    lo, hi = np.maximum(np.arange(80) - 2, 0), np.minimum(np.arange(80) + 3, 80)
    expected = (csum[hi] - csum[lo]) / (hi - lo)[:, None]
    np.testing.assert_allclose(smooth.translations[:, 0], expected, atol=1e-6)


def test_nested_cross_validation_picks_the_placement_window_on_the_other_takes():
    """B's place jumps with A's state here, so averaging it only blurs the jumps: every fold
    must pick 1 frame, from its own training takes alone, and say so."""
    takes = [
        (f"t{seed}", "toy", *synthetic_pair(n, seed)[:2])
        for n, seed in ((200, 1), (220, 2), (180, 3))
    ]
    model = DualHMM(n_states=N_POSES, n_iter=10, window=6)
    results, _ = cross_validate(takes, model, placement_windows=[9, 1])
    assert [r.chosen["placement_window"] for r in results] == [1] * 3
    chosen = summarise(results, model)["per_pair"]["t2"]["chosen"]
    assert chosen["placement_window"] == 1
    assert min(chosen["inner_mm"], key=chosen["inner_mm"].get) == "1"  # the pick is the best
    assert np.median(np.concatenate([r.errors["standard"] for r in results])) < 1.0


def test_missing_frames_are_skipped_with_a_warning(model, capsys):
    a, b, _ = synthetic_pair(90, 6)
    broken = a.copy()
    broken.rotations[40:43] = np.nan
    partner = model.partner()
    outputs = [partner.step(broken.trim(t, t + 1)) for t in range(broken.n_frames)]
    outputs = [o for o in outputs if o is not None] + partner.finish()
    assert len(outputs) == a.n_frames
    assert capsys.readouterr().err.count("skipped") == 3
    generated = model.generate(broken, "windowed").positions()
    assert np.isfinite(generated).all()
    err = np.linalg.norm(generated - b.positions(), axis=-1).mean(axis=1)
    assert np.median(err) < 1.0


def turning(a: Motion) -> Motion:
    """``a`` turning and walking about: its root yawed and moved frame by frame."""
    out = a.copy()
    t = np.arange(a.n_frames)
    yaw = Rotation.from_rotvec(np.outer(0.8 * np.sin(t / 9.0), [0.0, 1.0, 0.0]))
    out.rotations[:, 0] = (yaw * Rotation.from_quat(a.rotations[:, 0])).as_quat()
    out.translations[:, 0] += np.column_stack([15.0 * t, 0.0 * t, 400.0 * np.cos(t / 13.0)])
    return out


def test_partner_sees_a_as_the_offline_features_do(model, capsys):
    """The partner's features, built frame by frame from each frame's own forward kinematics
    and the last finite frame's, are the rows of the whole take's features."""
    a = turning(synthetic_pair(60, 9)[0])
    a.rotations[20:22] = np.nan
    offline, missing = model.features_a(a)
    partner = model.partner()
    seen, step_features = [], partner.step_features
    partner.step_features = lambda xa, place: seen.append(xa) or step_features(xa, place)
    for t in range(a.n_frames):
        partner.step(a.trim(t, t + 1))
    assert [x is None for x in seen] == missing.tolist()
    np.testing.assert_allclose(
        np.array([x for x in seen if x is not None]), offline[~missing], rtol=1e-12, atol=1e-9
    )
    assert capsys.readouterr().err.count("skipped") == 2


def test_into_and_out_of_a_ground_frame_turn_the_root_about_up():
    a = turning(synthetic_pair(40, 10)[0])
    rng = np.random.default_rng(0)
    origin, yaw = rng.normal(0, 500, (40, 3)), rng.uniform(-np.pi, np.pi, 40)
    out = out_of_frame(a, origin, yaw)
    turn = Rotation.from_rotvec(np.outer(yaw, [0.0, 1.0, 0.0]))
    expected = turn * Rotation.from_quat(a.rotations[:, 0])
    np.testing.assert_allclose(
        Rotation.from_quat(out.rotations[:, 0]).as_matrix(), expected.as_matrix(), atol=1e-12
    )
    np.testing.assert_allclose(
        out.translations[:, 0], turn.apply(a.translations[:, 0]) + origin, atol=1e-9
    )
    np.testing.assert_array_equal(out.rotations[:, 1:], a.rotations[:, 1:])
    back = into_frame(out, origin, yaw)
    np.testing.assert_allclose(back.rotations, a.rotations, atol=1e-12)
    np.testing.assert_allclose(back.translations, a.translations, atol=1e-9)


def test_save_load_round_trip(model, tmp_path):
    path = tmp_path / "dual.npz"
    model.save(path)
    loaded = DualHMM.load(path)
    a, _, _ = synthetic_pair(80, 7)
    for method in ("standard", "windowed"):
        np.testing.assert_allclose(
            loaded.generate(a, method).positions(), model.generate(a, method).positions()
        )
    header, _ = persist.load_npz(path, "dual_hmm")
    learnt = header["model"]["learnt"]
    assert "pipeline_a_" in learnt and "pipeline_b_" in learnt and "skeleton_b_" in learnt


def test_model_files_of_another_version_or_kind_are_refused(model, tmp_path, monkeypatch):
    monkeypatch.setattr(persist, "FORMAT_VERSION", 99)
    model.save(tmp_path / "future.npz")
    monkeypatch.undo()
    with pytest.raises(ModelFormatError, match="format version 99"):
        DualHMM.load(tmp_path / "future.npz")
    persist.save_npz(tmp_path / "other.npz", "vlmm", {}, {})
    with pytest.raises(ModelFormatError, match="'vlmm' model"):
        DualHMM.load(tmp_path / "other.npz")


def test_a_skeleton_that_is_not_the_models_is_a_clear_error(model):
    a, _, _ = synthetic_pair(30, 8)
    sk = a.skeleton
    other = Skeleton(("pelvis", *sk.names[1:]), sk.parents, sk.offsets, sk.channels, sk.end_site)
    stranger = Motion(other, a.rotations, a.translations, a.fps, name="stranger.bvh")
    with pytest.raises(SkeletonMismatchError, match="stranger.bvh: person A's skeleton"):
        model.generate(stranger)


def test_cli_train_respond_evaluate(tmp_path, capsys):
    data = tmp_path / "data"
    rows = ["file,source,subject,trial,category,label,partner_file,fps,frames,description"]
    for trial, (n, seed) in enumerate(((200, 1), (220, 2), (200, 3), (60, 4)), start=1):
        a, b, _ = synthetic_pair(n, seed)
        fa, fb = f"a{trial}.bvh", f"b{trial}.bvh"
        write_motion(a, data / fa)
        write_motion(b, data / fb)
        rows += [
            f"{fa},test,1,{trial},interaction,toy,{fb},30,{n},",
            f"{fb},test,1,{trial},interaction,toy,{fa},30,{n},",
        ]
    (data / "INDEX.csv").write_text("\n".join(rows) + "\n")
    model = tmp_path / "m.npz"
    args = ["dualhmm", "train", "--data", str(data), "--test-trials", "4"]
    main([*args, "--states", "4", "--window", "6", "--placement-window", "1", "--out", str(model)])
    assert model.exists()

    # A stream with a broken frame (NaN values) replayed in real time.
    lines = (data / "a4.bvh").read_text().splitlines()
    n_channels = len(lines[-1].split())
    lines[-20] = " ".join(["nan"] * n_channels)
    stream = tmp_path / "stream.bvh"
    stream.write_text("\n".join(lines) + "\n")
    out = tmp_path / "b.bvh"
    main(
        ["dualhmm", "respond", "--model", str(model), "--input", str(stream)]
        + ["--out", str(out), "--realtime"]
    )
    err = capsys.readouterr().err
    assert "skipped" in err and "p99" in err and "dropped frames" in err
    assert out.exists()

    main(
        ["dualhmm", "evaluate", "--model", str(model), "--test", str(data)]
        + ["--test-trials", "4", "--json", "--plots", str(tmp_path / "plots")]
    )
    report = json.loads(capsys.readouterr().out)
    for group in (report["overall"], report["per_label"]["toy"]):
        for key in ("standard_mm", "windowed_mm", "mean_pose_mm", "nearest_neighbour_mm"):
            assert group[key] >= 0
        assert set(group["latency_us"]) >= {"median", "p99"}
    overall = report["overall"]
    assert overall["standard_mm"] < 0.1 * overall["mean_pose_mm"]
    assert len(list((tmp_path / "plots").glob("*.png"))) == 1

    sk = make_skeleton()
    other = Skeleton(("pelvis", *sk.names[1:]), sk.parents, sk.offsets, sk.channels, sk.end_site)
    a, _, _ = synthetic_pair(30, 8)
    write_motion(Motion(other, a.rotations, a.translations, 30.0), tmp_path / "x.bvh")
    with pytest.raises(SystemExit) as exit_info:
        main(
            ["dualhmm", "respond", "--model", str(model), "--input", str(tmp_path / "x.bvh")]
            + ["--out", str(tmp_path / "y.bvh")]
        )
    assert exit_info.value.code == 2
    assert "x.bvh: person A's skeleton" in capsys.readouterr().err


# ------------------------------------------------------------------ real salsa pairs
HELD_OUT = ("03", "09", "13")  # the fixed split of the README's evaluation


@pytest.fixture(scope="session")
def salsa(mocap):
    pairs = mocap.pairs(label="salsa")
    load = {e.trial: mocap.load_pair(e, p) for e, p in pairs}
    return {t: (a.resample(30.0), b.resample(30.0)) for t, (a, b) in load.items()}


def test_real_salsa_held_out_pairs_beat_the_mean_pose(salsa):
    train = [pair for trial, pair in salsa.items() if trial not in HELD_OUT]
    dual = DualHMM(n_states=16, n_iter=20).fit(train)
    results = [evaluate_pair(dual, *salsa[t], t, "salsa") for t in HELD_OUT]
    mean = {k: np.concatenate([r.errors[k] for r in results]).mean() for k in results[0].errors}
    assert mean["windowed"] < 0.9 * mean["mean_pose"]
    assert mean["standard"] < 0.9 * mean["mean_pose"]
    assert abs(mean["windowed"] - mean["standard"]) < 0.1 * mean["standard"]
