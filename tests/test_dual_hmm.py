"""Dual HMM: B generated from A (offline and online), model files, CLI, real salsa pairs."""

from __future__ import annotations

import copy
import json
import shutil

import numpy as np
import pytest
from conftest import make_skeleton
from scipy.spatial.transform import Rotation

from markovmotion import persist
from markovmotion.cli import main
from markovmotion.core.markers import Markers
from markovmotion.core.motion import Motion
from markovmotion.core.skeleton import Skeleton
from markovmotion.data import MocapIndex
from markovmotion.errors import ModelFormatError, SkeletonMismatchError
from markovmotion.evaluate.hmm import cross_validate, evaluate_pair, summarise
from markovmotion.evaluate.takes import index_record
from markovmotion.io import write_motion
from markovmotion.models.base import KINDS, Model
from markovmotion.models.hmm.dual import DualHMM, into_frame, out_of_frame
from markovmotion.models.online import OnlinePartner, replay, run

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


#: The toy skeleton has no body points to find: the toy models see every joint, unblended.
TOY = {"points": "all", "blend_window": 1}


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
    return DualHMM(n_states=N_POSES, n_iter=20, window=6, placement_window=1, **TOY).fit(training)


@pytest.mark.parametrize("observation", ["pose", "motion"])
@pytest.mark.parametrize("mode", ["paper", "joint"])
def test_generated_b_recovers_the_known_function_of_a_state(training, mode, observation):
    dual = DualHMM(
        **TOY,
        n_states=N_POSES,
        mode=mode,
        observation=observation,
        n_iter=20,
        window=6,
        placement_window=1,  # B's place jumps with A's state here
    ).fit(training)
    a, b, states = synthetic_pair(200, 9)
    truth = b.positions()
    standard = dual.respond(a, "standard")
    windowed = dual.respond(a, "windowed")
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


@pytest.mark.parametrize(
    "kind, mode",
    [("diag", "paper"), ("diag", "joint"), ("tied", "paper"), ("tied", "joint")]
    + [("spherical", "paper")],  # joint: one variance for A's and B's features mixes them up
)
def test_every_covariance_type_recovers_b_and_round_trips(training, kind, mode, tmp_path):
    """Issue 26: the dual HMM on diagonal, spherical or tied Gaussians (the chains keep the
    type's compact form, so do their files)."""
    dual = DualHMM(
        **TOY, n_states=N_POSES, mode=mode, covariance_type=kind, n_iter=20, placement_window=1
    ).fit(training)
    assert dual.lambda_a_.covariance_type == dual.lambda_b_.covariance_type == kind
    ndim = {"diag": 2, "spherical": 1, "tied": 2}[kind]
    assert dual.lambda_a_._covars_.ndim == dual.lambda_b_._covars_.ndim == ndim
    a, b, states = synthetic_pair(200, 9)
    err = np.linalg.norm(dual.respond(a, "standard").positions() - b.positions(), axis=-1)
    jumps = np.flatnonzero(np.diff(states)) + 1
    assert err.mean(axis=1)[np.setdiff1d(np.arange(200), jumps)].max() < 1.0
    dual.save(tmp_path / "dual.npz")
    back = DualHMM.load(tmp_path / "dual.npz")
    np.testing.assert_array_equal(back.lambda_b_._covars_, dual.lambda_b_._covars_)
    np.testing.assert_allclose(
        back.respond(a, "windowed").positions(), dual.respond(a, "windowed").positions()
    )


@pytest.mark.parametrize("placement_window", [1, 7, 15])
def test_partner_streams_what_windowed_generation_gives(model, placement_window, capsys):
    model = copy.copy(model).set_params(placement_window=placement_window)
    a, _, _ = synthetic_pair(90, 5)
    offline = model.respond(a, "windowed").positions()
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
        long_window.respond(a, "windowed").positions(),
        model.respond(a, "standard").positions(),
        atol=1e-9,
    )


def test_b_place_is_the_centred_mean_of_the_path_places(model):
    a, _, _ = synthetic_pair(80, 4)
    own = model.respond(a, "standard").translations[:, 0]
    smooth = copy.copy(model).set_params(placement_window=5).respond(a, "standard")
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
    model = DualHMM(n_states=N_POSES, n_iter=10, window=6, **TOY)
    results, _ = cross_validate(
        takes, model, grid=[{"placement_window": 9}, {"placement_window": 1}]
    )
    assert [r.chosen["settings"]["placement_window"] for r in results] == [1] * 3
    chosen = summarise(results, model)["per_pair"]["t2"]["chosen"]
    assert chosen["settings"] == {"placement_window": 1}
    best = min(chosen["inner_mm"], key=chosen["inner_mm"].get)
    assert best == "placement_window=1"  # the pick is the best
    assert np.median(np.concatenate([r.errors["standard"] for r in results])) < 1.0


def test_missing_frames_are_skipped_with_a_warning(model, caplog):
    a, b, _ = synthetic_pair(90, 6)
    broken = a.copy()
    broken.rotations[40:43] = np.nan
    partner = model.partner()
    with caplog.at_level("WARNING", logger="markovmotion"):
        outputs = [partner.step(broken.trim(t, t + 1)) for t in range(broken.n_frames)]
    outputs = [o for o in outputs if o is not None] + partner.finish()
    assert len(outputs) == a.n_frames
    assert [r.getMessage() for r in caplog.records] == [
        "frame 40 of A is missing or holds NaN: skipped"  # once per stream
    ]
    generated = model.respond(broken, "windowed").positions()
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


def test_a_motion_seen_at_once_streams_what_stepping_it_gives(model, training, capsys):
    """The live page's path (:meth:`Partner.see`, then :meth:`Partner.step_seen` frame by
    frame: A's features, densities and places computed for the whole motion at once) gives
    B frame for frame as :meth:`Partner.step` of each one-frame motion, missing frames too."""
    a = turning(synthetic_pair(70, 12)[0])
    a.rotations[30:32] = np.nan
    stepped, streamed = model.partner(), model.partner()
    seen = streamed.see(a)
    assert not seen.log_b.flags.writeable  # shared by the sessions streaming the motion
    for t in range(a.n_frames):
        one, other = stepped.step(a.trim(t, t + 1)), streamed.step_seen(seen, t)
        assert (one is None) == (other is None) == (t < model.window - 1)
        if one is not None:
            np.testing.assert_allclose(other.positions(), one.positions(), atol=1e-9)
    assert [m.n_frames for m in streamed.finish()] == [m.n_frames for m in stepped.finish()]
    assert capsys.readouterr().err == ""  # step's warning is logged, see is quiet
    # A's features relative to A's running mean depend on the stream before: stepped
    person = DualHMM(n_states=N_POSES, n_iter=2, window=6, normalise="person", **TOY)
    assert person.fit(training[:1]).partner().see(a) is None


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
            loaded.respond(a, method).positions(), model.respond(a, method).positions()
        )
    header, _ = persist.load_npz(path, "dual_hmm")
    learnt = header["model"]["learnt"]
    assert "pipeline_a_" in learnt and "pipeline_b_" in learnt and "skeleton_b_" in learnt


def test_dual_hmm_follows_the_model_contract(model, training, tmp_path):
    assert KINDS["dual_hmm"] is DualHMM and DualHMM.VERBS == ("respond", "score", "partner")
    assert not hasattr(DualHMM, "generate")
    # Both people of every take are training files (in memory: hashed by their arrays).
    assert len(model.train_files_) == 2 * len(training)
    labelled = DualHMM(n_states=N_POSES, n_iter=2, window=6, **TOY).fit(
        training, ["toy", "b", "toy"]
    )
    assert labelled.labels_ == ["b", "toy"] and model.labels_ == []
    with pytest.raises(ValueError, match="2 labels for 3"):
        DualHMM(n_states=N_POSES, **TOY).fit(training, ["toy", "b"])
    labelled.save(tmp_path / "m.npz", source="toy data")
    loaded = Model.load(tmp_path / "m.npz")
    assert isinstance(loaded, DualHMM) and loaded.source_ == "toy data"
    assert loaded.labels_ == ["b", "toy"] and loaded.train_files_ == labelled.train_files_


def test_score_is_the_log_likelihood_of_a_under_lambda_a(model):
    a, _, _ = synthetic_pair(80, 7)
    xa, _ = model.features_a(a)
    assert model.score(a) == pytest.approx(model.lambda_a_.score(xa), rel=1e-12)
    shaken = a.copy()
    shaken.rotations[:, 1:] = Rotation.random(80 * 4, random_state=0).as_quat().reshape(80, 4, 4)
    assert model.score(shaken) < model.score(a) - 100  # a stranger's motion is unlikely
    broken = a.copy()
    broken.rotations[10:12] = np.nan  # missing frames: no observation, still a number
    assert np.isfinite(model.score(broken))


def test_replay_drops_the_frames_that_fell_due_while_a_step_ran(model, monkeypatch):
    """On a clock where one step takes 2.5 frame periods, the frame that fell due and is
    already overtaken is dropped (skipped, never queued) and the next is stepped: B still
    has a frame for every frame of A, and the summary counts the one dropped."""
    import types

    import markovmotion.models.online as online

    clock = types.SimpleNamespace(now=0.0, steps=0)
    monkeypatch.setattr(online, "time", types.SimpleNamespace(
        perf_counter=lambda: clock.now, sleep=lambda s: setattr(clock, "now", clock.now + s)
    ))  # fmt: skip
    a, _, _ = synthetic_pair(40, 5)
    period = 1.0 / a.fps

    class Slow:
        def __init__(self):
            self.partner = model.partner()

        def __getattr__(self, name):
            return getattr(self.partner, name)

        def step(self, frame):
            clock.steps += 1
            if clock.steps == 12:  # the warm-up step, then frames 0-10: frame 10 is slow
                clock.now += 2.5 * period
            return self.partner.step(frame)

    played = replay(Slow, a)
    assert played.dropped == 1 and played.motion.n_frames == a.n_frames
    assert "dropped frames 1;" in played.summary()


def test_partner_is_an_online_partner_that_any_replay_takes(model, capsys):
    a, _, _ = synthetic_pair(40, 5)
    partner = model.partner()
    assert isinstance(partner, OnlinePartner)
    assert partner.fps == model.fps and partner.skeleton is model.skeleton_b_
    offline = model.respond(a, "windowed").positions()
    np.testing.assert_allclose(run(partner, a).positions(), offline, atol=1e-6)
    played = replay(model.partner, a)  # real time: 40 frames at 30 fps
    assert played.motion.n_frames == a.n_frames and played.lag == model.window - 1
    if played.dropped == 0:
        np.testing.assert_allclose(played.motion.positions(), offline, atol=1e-6)
    assert "dropped frames" in played.summary()
    assert capsys.readouterr().err == ""
    with pytest.raises(ValueError, match="stream is finished"):  # went on answering before
        partner.step(a.trim(0, 1))
    with pytest.raises(ValueError, match="stream is finished"):
        partner.finish()  # gave more frames a second time
    fresh = model.partner()
    with pytest.raises(ValueError, match="step takes one frame of A, got 5"):
        fresh.step(a.trim(0, 5))  # was taken as one frame, answered up to 700 mm off
    with pytest.raises(TypeError, match="not ndarray"):
        fresh.step(a.positions()[:1])


class _StoppedAt:
    """A partner whose ``step`` is interrupted (Ctrl-C) at its ``at``-th frame."""

    def __init__(self, partner, at):
        self.partner, self.at, self.count = partner, at, 0

    def __getattr__(self, name):
        return getattr(self.partner, name)

    def step(self, frame):
        self.count += 1
        if self.count == self.at:
            raise KeyboardInterrupt
        return self.partner.step(frame)


def test_an_interrupted_replay_keeps_what_was_answered(model, tmp_path, monkeypatch, capsys):
    """Ctrl-C during a real-time replay: B so far is kept (the partner's look-ahead flushed),
    ``respond --realtime`` writes it, says so and exits as interrupted (130); it kept nothing."""
    a, _, _ = synthetic_pair(40, 5)
    played = replay(lambda: _StoppedAt(model.partner(), 25), a)
    assert played.interrupted and played.streamed == 24
    assert played.motion.n_frames == 24  # the lag's frames come out of finish()
    if played.dropped == 0:  # in real time, as the whole offline answer to those frames
        offline = model.respond(a.trim(0, 24), "windowed").positions()
        np.testing.assert_allclose(played.motion.positions(), offline, atol=1e-6)
    write_motion(a, tmp_path / "a.bvh")
    model.save(tmp_path / "m.npz")
    own = DualHMM.partner
    monkeypatch.setattr(DualHMM, "partner", lambda self, *w: _StoppedAt(own(self, *w), 25))
    out = tmp_path / "b.bvh"
    with pytest.raises(SystemExit) as stopped:
        main(["dualhmm", "respond", "--model", str(tmp_path / "m.npz"), "--input",
              str(tmp_path / "a.bvh"), "--out", str(out), "--realtime"])  # fmt: skip
    assert stopped.value.code == 130
    assert "interrupted after 24 of 40 frames" in capsys.readouterr().err
    assert out.is_file()


def test_model_files_of_another_version_or_kind_are_refused(model, tmp_path, monkeypatch):
    monkeypatch.setattr(persist, "FORMAT_VERSION", 99)
    model.save(tmp_path / "future.npz")
    monkeypatch.undo()
    with pytest.raises(ModelFormatError, match="format version 99"):
        DualHMM.load(tmp_path / "future.npz")
    persist.save_npz(tmp_path / "other.npz", "vlmm", {}, {})
    with pytest.raises(ModelFormatError, match="'vlmm'"):  # unknown kind, or not a dual HMM
        DualHMM.load(tmp_path / "other.npz")


def test_a_skeleton_that_is_not_the_models_is_a_clear_error(model):
    a, _, _ = synthetic_pair(30, 8)
    sk = a.skeleton
    other = Skeleton(("pelvis", *sk.names[1:]), sk.parents, sk.offsets, sk.channels, sk.end_site)
    stranger = Motion(other, a.rotations, a.translations, a.fps, name="stranger.bvh")
    with pytest.raises(SkeletonMismatchError, match="stranger.bvh: person A's skeleton"):
        model.respond(stranger)
    # markers to a model of skeletons: the same line online as respond's (it was a TypeError
    # from inside the features)
    markers = Markers(("a", "b", "c"), np.zeros((1, 3, 3)), a.fps, "x.c3d")
    with pytest.raises(SkeletonMismatchError, match="x.c3d: markers") as online:
        model.partner().step(markers)
    with pytest.raises(SkeletonMismatchError) as whole:
        model.respond(markers)
    assert str(online.value) == str(whole.value)


def test_a_take_with_nothing_recorded_is_refused_not_answered(model):
    """NaN frames are missing observations, but a take of nothing else was answered with an
    invented B and scored as certain (log P = 0)."""
    a, _, _ = synthetic_pair(30, 9)
    empty = a.copy()
    empty.rotations[:] = np.nan
    for verb in (model.respond, model.score):
        with pytest.raises(ValueError, match="every one of its 30 frames"):
            verb(empty)
    with pytest.raises(ValueError, match="its one frame"):
        model.score(empty.trim(0, 1))
    empty.rotations[5:] = a.rotations[5:]  # some frames recorded: answered
    assert np.isfinite(model.score(empty)) and model.respond(empty).n_frames == 30


def test_a_refit_refused_for_its_takes_leaves_the_model_as_it_was(model, training):
    """A pair of joints with a NaN frame is refused before anything learnt is dropped."""
    again = copy.deepcopy(model)
    a, b = training[0]
    broken = a.copy()
    broken.rotations[3] = np.nan
    with pytest.raises(ValueError, match=r"take 0 \(A\).*1 frame \(first 3"):
        again.fit([(broken, b)])
    np.testing.assert_array_equal(again.respond(a).positions(), model.respond(a).positions())


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
    args += ["--points", "all", "--blend-window", "1"]
    main([*args, "--states", "4", "--window", "6", "--placement-window", "1", "--out", str(model)])
    assert model.exists()

    # A file with a broken frame (NaN values) is refused as every command refuses it ...
    lines = (data / "a4.bvh").read_text().splitlines()
    n_channels = len(lines[-1].split())
    lines[-20] = " ".join(["nan"] * n_channels)
    stream = tmp_path / "stream.bvh"
    stream.write_text("\n".join(lines) + "\n")
    out = tmp_path / "b.bvh"
    with pytest.raises(SystemExit) as refused:
        main(
            ["dualhmm", "respond", "--model", str(model), "--input", str(stream)]
            + ["--out", str(out), "--realtime"]
        )
    assert refused.value.code == 2 and not out.exists()
    assert "NaN or infinite" in capsys.readouterr().err
    # ... and a whole one is replayed in real time
    main(
        ["dualhmm", "respond", "--model", str(model), "--input", str(data / "a4.bvh")]
        + ["--out", str(out), "--realtime"]
    )
    err = capsys.readouterr().err
    assert "p99" in err and "dropped frames" in err
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
    assert report["test_files"] == ["a4.bvh", "b4.bvh"]
    assert report["left_out_training_files"] == []

    # Without --test: the takes held out at training (recorded in the model file); without
    # --plots, nothing is written beside the model
    before = set(tmp_path.iterdir())
    main(["dualhmm", "evaluate", "--model", str(model), "--json"])
    assert set(tmp_path.iterdir()) == before
    again = json.loads(capsys.readouterr().out)
    assert again["test_files"] == ["a4.bvh", "b4.bvh"]
    assert again["overall"]["standard_mm"] == overall["standard_mm"]

    main(
        ["dualhmm", "crossval", "--data", str(data), "--states", "4", "--window", "6"]
        + ["--n-iter", "5", "--placement-window", "1", "--points", "all", "--json"]
    )
    folds = json.loads(capsys.readouterr().out)
    assert folds["overall"]["pairs"] == 4 and len(folds["test_files"]) == 8
    assert folds["overall"]["standard_mm"] < 0.1 * folds["overall"]["mean_pose_mm"]

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


# ------------------------------------------------------------------ evaluation on any index
INDEX_HEADER = "file,source,subject,trial,category,label,partner_file,fps,frames,description"


def pair_rows(fa: str, fb: str, source: str, trial: str, label: str, fps: float) -> list[str]:
    return [
        f"{fa},{source},1,{trial},interaction,{label},{fb},{fps:g},0,",
        f"{fb},{source},1,{trial},interaction,{label},{fa},{fps:g},0,",
    ]


def test_evaluate_on_another_index_leaves_out_training_takes_by_content(mocap, tmp_path, capsys):
    """A model trained on one salsa take (copied files) is evaluated on another index:
    the same take under other names is left out by content, a take of another label is
    not a candidate, a new take is evaluated; the training index exits 2 in one line."""
    (a12, b12), (a03, b03) = (
        next(p for p in mocap.pairs("salsa") if p[0].trial == t) for t in ("12", "03")
    )
    train, other = tmp_path / "train", tmp_path / "other"
    train.mkdir()
    other.mkdir()
    rows = [INDEX_HEADER]
    for e in (a12, b12):  # byte copies, not links: the same content under another path
        shutil.copyfile(e.path, train / e.path.name)
    rows += pair_rows(a12.path.name, b12.path.name, "cmu", "12", "salsa", a12.fps)
    (train / "INDEX.csv").write_text("\n".join(rows) + "\n")
    shutil.copyfile(a12.path, other / "leader.bvh.gz")
    shutil.copyfile(b12.path, other / "follower.bvh.gz")
    rows = [INDEX_HEADER] + pair_rows(
        "leader.bvh.gz", "follower.bvh.gz", "cmu", "x1", "salsa", a12.fps
    )
    a, b = mocap.load_pair(a03, b03)
    for motion, name in ((a.trim(0, 120), "a3.bvh"), (b.trim(0, 120), "b3.bvh")):
        write_motion(motion, other / name)
    rows += pair_rows("a3.bvh", "b3.bvh", "test", "3", "salsa", a.fps)
    for motion, name in ((a.trim(200, 230), "c.bvh"), (b.trim(200, 230), "d.bvh")):
        write_motion(motion, other / name)
    rows += pair_rows("c.bvh", "d.bvh", "test", "4", "pull", a.fps)  # not a label it knows
    (other / "INDEX.csv").write_text("\n".join(rows) + "\n")

    # Trained as ``dualhmm train --data TRAIN`` does, on the first 10 s (the files' hashes).
    index = MocapIndex.load(train)
    (pair,) = index.pairs()
    motions = [m.trim(0, 600) for m in index.load_pair(*pair)]
    dual = DualHMM(n_states=3, n_iter=3, window=4, candidates=3).fit([motions], ["salsa"])
    model = tmp_path / "m.npz"
    dual.save(model, data_index=index_record(index), held_out_files=[])
    main(
        ["dualhmm", "evaluate", "--model", str(model), "--test", str(other / "INDEX.csv")]
        + ["--json", "--plots", str(tmp_path / "plots")]
    )
    report = json.loads(capsys.readouterr().out)
    assert report["test_files"] == ["a3.bvh", "b3.bvh"]
    assert report["left_out_training_files"] == ["leader.bvh.gz", "follower.bvh.gz"]
    assert list(report["per_pair"]) == ["a3+b3"] and report["overall"]["frames"] == 60
    for key in ("standard_mm", "windowed_mm", "mean_pose_mm"):
        assert report["per_pair"]["a3+b3"][key] > 0 and report["overall"][key] > 0

    # the training index, and its held-out takes (none: the model learnt every take)
    for args, words in (
        (["--test", str(train)], ("salsa_12.bvh.gz", "salsa_27.bvh.gz", "trained on")),
        ([], ("the model held no take out at training", "give --test INDEX")),
    ):
        with pytest.raises(SystemExit) as exit_info:
            main(["dualhmm", "evaluate", "--model", str(model), *args])
        assert exit_info.value.code == 2
        err = capsys.readouterr().err
        assert all(w in err for w in words) and len(err.strip().splitlines()) == 1, err
