"""Markers as input (issue #15, item 4): virtual markers, C3D writing, a dual HMM on markers."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

from markovmotion.cli import main
from markovmotion.core.markers import Markers
from markovmotion.errors import ModelFormatError, MotionFormatError, SkeletonMismatchError
from markovmotion.evaluate.hmm import evaluate_pair
from markovmotion.features.markers import (
    MarkerFeatures,
    heading_markers,
    marker_layout,
    out_of_marker_frame,
    virtual_marker_names,
    virtual_markers,
)
from markovmotion.io.bvh import write_bvh
from markovmotion.io.c3d import read_c3d, write_c3d
from markovmotion.models.base import Model
from markovmotion.models.hmm.dual import DualHMM
from tests.conftest import assert_seen_streams_as_stepped

FRAMES = 360  # of each real take used (120 fps: 3 s, 90 frames at the model's 30 fps)


@pytest.fixture(scope="module")
def takes(mocap):
    """The first seconds of the real interaction takes (A, B) of two labels, skeletons."""
    pairs = mocap.pairs(["handshake", "pull"], kind="skeleton")[:3]
    return [tuple(m.trim(0, FRAMES) for m in mocap.load_pair(a, b)) for a, b in pairs]


@pytest.fixture(scope="module")
def marker_takes(takes):
    """The same takes as 30 virtual markers per person (Markers pairs)."""
    return [(virtual_markers(a), virtual_markers(b)) for a, b in takes]


@pytest.fixture(scope="module")
def model(marker_takes) -> DualHMM:
    return DualHMM(n_states=6, n_iter=10, markers=30).fit(marker_takes[:2], ["handshake", "pull"])


def test_virtual_markers_move_rigidly_with_their_segments(takes):
    a = takes[0][0]
    for n in (13, 30, 50):
        markers = virtual_markers(a, n)
        assert markers.names == virtual_marker_names(n) and len(set(markers.names)) == n
        assert markers.positions.shape == (a.n_frames, n, 3) and markers.fps == a.fps
        rigid, _ = marker_layout(a.skeleton, n)
        dist = np.linalg.norm(markers.positions - a.positions()[:, rigid], axis=2)
        assert np.ptp(dist, axis=0).max() < 1e-6  # constant distance to its joint
        assert np.isfinite(markers.positions).all()
    assert virtual_marker_names(30)[:13] == virtual_marker_names(13)
    markers = virtual_markers(a)
    # markers on the front of the body are ahead of those on the back, by A's heading
    left, right = heading_markers(markers.names)
    assert [markers.names[i] for i in left] == ["L_SHOULDER", "L_HIP"]
    step = MarkerFeatures().fit([markers])
    pose = step.pose(markers)
    front, back = markers.names.index("STERNUM"), markers.names.index("C7")
    assert (pose[:, front, 2] > pose[:, back, 2]).all()
    with pytest.raises(ValueError, match="13 to 200"):
        virtual_markers(a, 12)


def test_virtual_markers_need_the_body_points(takes):
    from conftest import make_motion

    with pytest.raises(SkeletonMismatchError, match="body points"):
        virtual_markers(make_motion())


def test_c3d_round_trip(tmp_path):
    rng = np.random.default_rng(3)
    pos = rng.uniform(-2000, 2000, (40, 5, 3))
    pos[5, 2] = np.nan
    pos[7] = np.nan
    markers = Markers(("L_HIP", "R_HIP", "HEAD", "a_long_marker_name", "x"), pos, 120.0)
    path = tmp_path / "m.c3d"
    write_c3d(markers, path)
    back = read_c3d(path)
    assert back.names == markers.names and back.fps == 120.0
    assert np.array_equal(np.isnan(back.positions), np.isnan(pos))
    np.testing.assert_allclose(back.positions, pos.astype(np.float32), rtol=1e-6, atol=1e-3)
    with pytest.raises(MotionFormatError, match=r"\.c3d"):
        write_c3d(markers, tmp_path / "m.bvh")
    bad = Markers(("x" * 40,), pos[:, :1], 120.0)
    with pytest.raises(MotionFormatError, match="labels"):
        write_c3d(bad, path)
    assert read_c3d(path).names == markers.names  # the earlier file is untouched
    assert sorted(os.listdir(tmp_path)) == ["m.c3d"]  # no temporary left behind


def test_a_marker_model_reproduces_b_on_its_training_takes(model, marker_takes):
    assert model.uses_markers and model.marker_names_b_ == list(virtual_marker_names(30))
    frames = sum(model._rate(a).n_frames for a, _ in marker_takes[:2])
    assert model.train_a_.shape[0] == model.markers_b_.shape[0] == frames
    mean_b = model.training_b().positions.mean(axis=0)
    for a, b in marker_takes[:2]:
        out = model.respond(a)
        assert isinstance(out, Markers) and out.names == b.names and out.fps == model.fps
        truth = model.body_positions(model._rate(b))
        error = np.linalg.norm(model.body_positions(out) - truth, axis=2).mean()
        origin, yaw = model.place(model._rate(a))
        still = out_of_marker_frame(np.repeat(mean_b[None], len(yaw), axis=0), origin, yaw)
        baseline = np.linalg.norm(still - truth, axis=2).mean()
        assert error < 100.0, error  # mm per marker, on its training frames
        assert error < 0.5 * baseline, (error, baseline)


def test_a_motion_given_to_a_virtual_marker_model_gets_its_markers_first(model, takes):
    a, b = takes[0]
    assert np.array_equal(model.respond(a).positions, model.respond(virtual_markers(a)).positions)
    res = evaluate_pair(model, a, b, "take", "handshake")
    assert res.errors["standard"].mean() < res.errors["mean_pose"].mean()


def test_responds_to_a_c3d_file_and_saves_and_loads_to_identical_output(
    model, marker_takes, tmp_path
):
    a, _ = marker_takes[2]
    write_c3d(a, tmp_path / "a.c3d")
    a_file = read_c3d(tmp_path / "a.c3d")
    path = tmp_path / "model.npz"
    model.save(path)
    loaded = Model.load(path)
    assert isinstance(loaded, DualHMM) and loaded.uses_markers
    for method in ("standard", "windowed"):
        first, again = model.respond(a_file, method), loaded.respond(a_file, method)
        assert np.array_equal(first.positions, again.positions)
        assert first.n_frames == model._rate(a).n_frames
    assert loaded.score(a_file) == model.score(a_file)


def test_the_online_partner_streams_what_windowed_respond_gives(model, marker_takes, caplog):
    a = model._rate(marker_takes[2][0])
    k = model.held().frames  # a marker unseen: held for k frames, then missing observations
    a.positions[10 : 10 + k + 3, 4] = np.nan
    partner = model.partner()
    with caplog.at_level("WARNING", logger="markovmotion"):
        shown = [partner.step(a.trim(t, t + 1)) for t in range(a.n_frames)]
    shown = [s for s in shown if s is not None] + partner.finish()
    streamed = np.concatenate([s.positions for s in shown])
    whole = model.respond(a, "windowed")
    np.testing.assert_allclose(streamed, whole.positions, atol=1e-9)
    assert np.isfinite(whole.positions).all()
    assert f"frame {10 + k} of A is missing" in caplog.text


def test_markers_seen_at_once_stream_what_stepping_them_gives(model, marker_takes, capsys):
    a = model._rate(marker_takes[2][0])
    a.positions[10:13, 4] = np.nan
    assert_seen_streams_as_stepped(model, a)
    capsys.readouterr()


def test_marker_model_files_are_checked(model, tmp_path):
    from markovmotion import persist

    path = tmp_path / "model.npz"
    model.save(path)
    header, arrays = persist.load_npz(path)
    key = next(k for k in arrays if k.endswith("markers_b_"))
    arrays[key] = arrays[key][:, :-1]
    persist.save_npz(path, "dual_hmm", header, arrays)
    with pytest.raises(ModelFormatError, match="markers_b_"):
        Model.load(path)


def test_bad_inputs_are_one_line(model, marker_takes, takes, tmp_path, capsys):
    path = tmp_path / "model.npz"
    model.save(path)
    skeleton_model = tmp_path / "skeleton.npz"
    DualHMM(n_states=4, n_iter=3).fit(takes[:1]).save(skeleton_model)
    a_c3d = tmp_path / "a.c3d"
    write_c3d(marker_takes[2][0], a_c3d)
    a_bvh = tmp_path / "a.bvh"
    write_bvh(takes[2][0], a_bvh)
    other = marker_takes[2][0].select(virtual_marker_names(13))
    write_c3d(other, tmp_path / "few.c3d")
    cases = [
        (path, a_c3d, "b.bvh", "trained on markers"),
        (skeleton_model, a_c3d, "b.bvh", "trained on skeletons"),
        (skeleton_model, a_bvh, "b.c3d", "trained on skeletons"),
        (path, tmp_path / "few.c3d", "b.c3d", "markers not found: HEAD_BACK"),
    ]
    for model_file, a, out, message in cases:
        args = ["dualhmm", "respond", "--model", str(model_file), "--input", str(a)]
        with pytest.raises(SystemExit) as exc:
            main([*args, "--out", str(tmp_path / out)])
        err = capsys.readouterr().err.strip()
        assert exc.value.code == 2 and message in err and "\n" not in err, err
    # a BVH given to a model on virtual markers: its markers are placed first
    main(
        ["dualhmm", "respond", "--model", str(path), "--input", str(a_bvh)]
        + ["--out", str(tmp_path / "b.c3d")]
    )
    assert read_c3d(tmp_path / "b.c3d").names == virtual_marker_names(30)
    # a model learnt from C3D markers whose names are no body points cannot find them on a BVH
    c3d_model = DualHMM(n_states=4, n_iter=3).fit(marker_takes[:1])
    assert not c3d_model.markers and c3d_model.uses_markers
    with pytest.raises(SkeletonMismatchError, match="HEAD_BACK.*name no body point"):
        c3d_model.respond(takes[0][0])


#: An upper-body tracker's points (Bütepage's Kinect names) and the body points they name.
SENSOR_POINTS = {
    "TORSO": "spine",
    "HEAD": "head",
    "R_SHOULDER": "right_shoulder",
    "L_SHOULDER": "left_shoulder",
    "R_ELBOW": "right_elbow",
    "L_ELBOW": "left_elbow",
    "R_HAND": "right_wrist",
    "L_HAND": "left_wrist",
}
SENSOR_HEIGHT = 1100.0  # mm: the sensor's origin above the floor


def _sensor(motion, drop: float = SENSOR_HEIGHT) -> Markers:
    """A skeleton's body points as a depth sensor gives them: named, origin at its height."""
    from markovmotion.features.body_points import body_point_index

    index = body_point_index(motion.skeleton, list(SENSOR_POINTS.values()))
    pos = motion.positions()[:, index]
    pos[..., 1] -= drop
    return Markers(list(SENSOR_POINTS), pos, motion.fps, motion.name)


@pytest.fixture(scope="module")
def sensor_model(takes) -> DualHMM:
    """A dual HMM of sensor markers (vertical origin the sensor's), both roles."""
    pairs = [(_sensor(a), _sensor(b)) for a, b in takes[:2]]
    return DualHMM(n_states=5, n_iter=8).fit(pairs + [(b, a) for a, b in pairs])


def test_a_sensor_marker_model_answers_a_skeleton_at_its_height(sensor_model, takes, capsys):
    a, b = takes[2]
    assert sensor_model.lifts(a) and not sensor_model.lifts(_sensor(a))
    answer = sensor_model.respond(a, "windowed")
    assert answer.names == tuple(SENSOR_POINTS)
    # B stands at the skeleton's height, not the sensor's: the training pairs' centroids
    # are at the same height to within a few cm; the real B is at A's height here
    real_b = _sensor(b, drop=0.0).resample(30)
    gap = np.mean(answer.positions[..., 1]) - np.mean(real_b.positions[..., 1])
    assert abs(gap) < 150.0, gap
    # raising A raises B by as much, and nothing else changes
    raised = a.copy()
    raised.translations[:, 0, 1] += 500.0
    up = sensor_model.respond(raised, "windowed")
    np.testing.assert_allclose(up.positions[..., 1], answer.positions[..., 1] + 500.0, atol=1e-6)
    np.testing.assert_allclose(up.positions[..., [0, 2]], answer.positions[..., [0, 2]], atol=1e-6)
    # the online partner, frame by frame, gives the same B
    a30 = a.resample(30)
    partner = sensor_model.partner()
    frames = [f for t in range(a30.n_frames) if (f := partner.step(a30.trim(t, t + 1)))]
    frames += partner.finish()
    np.testing.assert_allclose(
        np.concatenate([f.positions for f in frames]), answer.positions, atol=1e-6
    )
    capsys.readouterr()


def test_a_sensor_model_scored_on_skeletons_places_its_baselines_as_its_partner(
    sensor_model, takes
):
    """Evaluated on a skeleton pair (floor at 0), a sensor-marker model's baselines see A
    lifted as the partner does: raising both people by 500 mm changes no error, and the
    mean pose is within reach of the partner (not a metre off, the sensor's height)."""
    a, b = takes[2]
    res = evaluate_pair(sensor_model, a, b, "t", "handshake")
    up_a, up_b = a.copy(), b.copy()
    for m in (up_a, up_b):
        m.translations[:, 0, 1] += 500.0
    raised = evaluate_pair(sensor_model, up_a, up_b, "t", "handshake")
    for key in ("windowed", "mean_pose", "known_motion", "nearest_neighbour"):
        assert raised.errors[key].mean() == pytest.approx(res.errors[key].mean(), abs=0.5)
        assert raised.pose_errors[key].mean() == pytest.approx(res.pose_errors[key].mean(), abs=0.5)
    assert res.pose_errors["mean_pose"].mean() < 2 * res.pose_errors["windowed"].mean()
    # while B stands still (the take's first frames) the mean pose is as near as the partner
    assert res.errors["mean_pose"][:10].mean() < 1.5 * res.errors["windowed"][:10].mean()


def test_realtime_replays_a_marker_model_as_windowed_respond_answers(
    sensor_model, takes, tmp_path, capsys, monkeypatch
):
    """``respond --realtime`` with a marker model: A streamed at its rate, B's markers as
    the windowed decoder answers the whole take (C3D's float32 aside). On a clock that
    never falls behind: a frame the machine's load makes late is dropped, and B differs
    from then on, as it should (the test had failed so on a loaded machine)."""
    import types

    import markovmotion.models.online as online

    clock = types.SimpleNamespace(now=0.0)
    fake = types.SimpleNamespace(
        perf_counter=lambda: clock.now,
        sleep=lambda s: setattr(clock, "now", clock.now + s),
    )
    monkeypatch.setattr(online, "time", fake)
    a = _sensor(takes[2][0]).resample(30)
    model, given, out = tmp_path / "m.npz", tmp_path / "a.c3d", tmp_path / "b.c3d"
    sensor_model.save(model)
    write_c3d(a, given)
    main(["dualhmm", "respond", "--model", str(model), "--input", str(given), "--realtime"]
         + ["--out", str(out)])  # fmt: skip
    assert "dropped frames 0;" in capsys.readouterr().err
    whole = sensor_model.respond(read_c3d(given), "windowed")
    np.testing.assert_allclose(read_c3d(out).positions, whole.positions, atol=0.05)


def test_a_sensor_marker_model_names_the_body_points_a_skeleton_lacks(sensor_model, takes):
    import dataclasses

    from markovmotion.core.motion import Motion

    a = takes[2][0]
    names = ["noggin" if n.lower() == "head" else n for n in a.skeleton.names]
    skeleton = dataclasses.replace(a.skeleton, names=tuple(names))
    headless = Motion(skeleton, a.rotations, a.translations, a.fps, name="headless")
    with pytest.raises(SkeletonMismatchError, match="headless.*head"):
        sensor_model.check_input(headless)


def test_lift_online_equals_whole_take():
    from markovmotion.features.markers import Lift

    rng = np.random.default_rng(0)
    pos = rng.normal(0.0, 100.0, (40, 3, 3))
    pos[..., 1] += 1200.0
    pos[5] = np.nan  # a frame with nothing seen keeps the last lift
    markers = Markers(["a", "b", "c"], pos, 30.0)
    lifted, lift = Lift(-50.0)(markers)
    centre = pos[..., 1].mean(axis=1)  # NaN in frame 5
    seen = np.isfinite(centre)
    expected = [-50.0 - np.mean(centre[: t + 1][seen[: t + 1]]) for t in range(40)]
    np.testing.assert_allclose(lift, expected)
    online = Lift(-50.0)
    steps = [online.step(markers.trim(t, t + 1)) for t in range(40)]
    np.testing.assert_allclose([s for _, s in steps], lift)
    np.testing.assert_allclose(
        np.concatenate([m.positions for m, _ in steps]), lifted.positions, equal_nan=True
    )


def test_cli_trains_on_c3d_pairs_of_an_index_and_responds_with_c3d(marker_takes, tmp_path, capsys):
    data = tmp_path / "data"
    rows = ["file,source,subject,trial,category,label,partner_file,fps,frames,description"]
    for k, (a, b) in enumerate(marker_takes, start=1):
        for who, m, partner in (("a", a, "b"), ("b", b, "a")):
            write_c3d(m, data / f"{who}{k}.c3d")
            rows.append(
                f"{who}{k}.c3d,test,,{k},interaction,meet,{partner}{k}.c3d,120,{m.n_frames},"
            )
    (data / "INDEX.csv").write_text("\n".join(rows) + "\n")
    model = tmp_path / "m.npz"
    main(
        ["dualhmm", "train", "--data", str(data), "--out", str(model), "--states", "5"]
        + ["--n-iter", "5", "--test-trials", "3"]
    )
    assert "30 markers" in capsys.readouterr().err
    out = tmp_path / "b.c3d"
    main(
        ["dualhmm", "respond", "--model", str(model), "--input", str(data / "a3.c3d")]
        + ["--out", str(out), "--standard"]
    )
    b = read_c3d(out)
    assert b.names == virtual_marker_names(30) and b.n_frames == FRAMES // 4
    main(["dualhmm", "evaluate", "--model", str(model), "--json"])
    report = json.loads(capsys.readouterr().out)
    assert report["overall"]["frames"] == FRAMES // 4
    assert report["overall"]["standard_mm"] < report["overall"]["mean_pose_mm"] * 2
    # the reference of B's real motion on the mean pose: never above the mean pose itself,
    # body-centred (per point, the mean distance to the frames >= the distance to their mean)
    body = report["overall"]["body_centred"]
    assert 0 < body["known_motion_mm"] <= body["mean_pose_mm"] + 0.05
    # the world error split into B's place and the rest: moved onto the real B's centroid,
    # each partner is no further from it than its world error allows (triangle inequality)
    place = report["overall"]["place"]
    for key in ("windowed", "mean_pose"):
        world = report["overall"][f"{key}_mm"]
        assert place[f"{key}_at_true_place_mm"] <= world + place[f"{key}_centroid_mm"] + 0.1
        assert place[f"{key}_centroid_mm"] <= world + 0.1


def test_place_split_separates_where_b_stands_from_its_pose():
    from markovmotion.evaluate.hmm import place_split
    from markovmotion.evaluate.vlmm import trial_errors

    rng = np.random.default_rng(5)
    truth = rng.normal(size=(30, 6, 3)) * 100
    pose_error = rng.normal(size=(30, 6, 3)) * 20
    pose_error -= pose_error.mean(axis=1, keepdims=True)  # leaves every centroid in place
    offset = rng.normal(size=(30, 1, 3)) * 300
    split = place_split(truth + pose_error + offset, truth)
    np.testing.assert_allclose(split["centroid"], np.linalg.norm(offset[:, 0], axis=-1))
    np.testing.assert_allclose(split["at_true_place"], trial_errors(truth + pose_error, truth))
    # B in the right place with the right pose: nothing left to split
    exact = place_split(truth, truth)
    assert np.abs(exact["centroid"]).max() < 1e-9 and np.abs(exact["at_true_place"]).max() < 1e-9


def test_known_motion_is_the_real_motion_about_the_mean_pose():
    from markovmotion.evaluate.hmm import known_motion
    from markovmotion.evaluate.vlmm import trial_errors

    rng = np.random.default_rng(3)
    truth = rng.normal(size=(40, 5, 3)) * 30 + rng.normal(size=(1, 5, 3)) * 200
    mean = rng.normal(size=(5, 3)) * 200
    shown = known_motion(mean, truth)
    np.testing.assert_allclose(shown.mean(axis=0), mean, atol=1e-9)
    np.testing.assert_allclose(np.diff(shown, axis=0), np.diff(truth, axis=0), atol=1e-9)
    # its error is the same in every frame: the posture's offset, the motion being exact
    err = trial_errors(shown, truth)
    np.testing.assert_allclose(err, np.linalg.norm(mean - truth.mean(0), axis=-1).mean())
    assert err.mean() <= trial_errors(np.broadcast_to(mean, truth.shape), truth).mean()
    placed = mean + rng.normal(size=(40, 1, 3)) * 50  # a mean pose placed frame by frame
    np.testing.assert_allclose(known_motion(placed, truth).mean(0), placed.mean(0), atol=1e-9)


def test_the_live_page_draws_a_marker_partner_as_a_stick_figure(model, takes):
    from markovmotion.features.body_points import point_bones
    from markovmotion.web.live import ModelPartner

    a = model._rate(takes[0][0])
    live = ModelPartner(model, a)
    assert len(live.parents) == 30 and live.lag == model.window - 1
    # the markers named as body points joined along the body; the others drawn as points
    bones = point_bones(model.marker_names_b_)
    assert len(bones) >= 5
    assert {(c, p) for c, p in enumerate(live.parents) if p >= 0} == set(map(tuple, bones.tolist()))
    shown = [live.step(a.trim(t, t + 1)) for t in range(live.lag + 2)]
    assert shown[0] is None and shown[-1].shape == (30, 3)


def test_heading_from_named_markers_or_the_markers_spread():
    left, right = heading_markers(["LASI", "RASI", "LSHO", "RSHO", "CLAV", "LKNE"])
    assert left.tolist() == [0, 2] and right.tolist() == [1, 3]
    left, right = heading_markers(["ShoulderLeft", "ShoulderRight", "HipLeft"])
    assert left.tolist() == [0] and right.tolist() == [1]  # hips only on one side: not used
    # no names to go by: a body 400 mm wide and 200 mm deep, turning slowly
    rng = np.random.default_rng(0)
    base = rng.uniform(0, 1, (5, 3)) * [200.0, 800.0, 100.0]
    body = np.concatenate([base * [sx, 1, sz] for sx in (-1, 1) for sz in (-1, 1)])  # symmetric
    yaw = np.linspace(0.2, 2.5, 30)
    s, c = np.sin(yaw)[:, None], np.cos(yaw)[:, None]
    x, z = body[None, :, 0], body[None, :, 2]
    pos = np.stack([c * x + s * z, np.broadcast_to(body[:, 1], (30, 20)), c * z - s * x], -1)
    markers = Markers([f"m{k}" for k in range(20)], pos + [500.0, 0.0, -300.0], 30.0)
    step = MarkerFeatures().fit([markers])
    assert len(step.left_) == 0
    origin, found = step.place(markers.positions)
    np.testing.assert_allclose(np.angle(np.exp(1j * (found - yaw))), 0.0, atol=1e-9)
    np.testing.assert_allclose(origin[:, [0, 2]], pos.mean(axis=1)[:, [0, 2]] + [500, -300])


def test_markers_are_found_whatever_the_case_of_their_labels(marker_takes):
    """Marker labels that differ from the model's only in case (``r_hand``, ``Head``) are
    the same markers: a take so labelled is answered exactly as the original; a label that
    two markers share whatever the case, or none has, is not found."""
    from markovmotion.core.markers import find_markers

    assert find_markers(("R_Hand", "HEAD", "head"), ["R_HAND", "HEAD", "Head", "TOE"]) == (
        [0, 1],
        ["Head", "TOE"],
    )
    model = DualHMM(n_states=4, n_iter=3).fit(marker_takes[:2])
    a = marker_takes[2][0]
    relabelled = Markers(
        tuple(n.lower() if k % 2 else n.title() for k, n in enumerate(a.names)),
        a.positions, a.fps, a.name,
    )  # fmt: skip
    assert relabelled.names != a.names
    model.check_input(relabelled)
    np.testing.assert_array_equal(model.respond(relabelled).positions, model.respond(a).positions)


def test_labels_with_a_subjects_prefix_are_the_markers_and_a_refusal_shows_the_takes_labels(
    marker_takes,
):
    """Vicon's ``Subject:Marker`` labels (``P1:R_HAND``) are the model's markers when one label
    alone matches without its prefix: answered exactly as the original; a take lacking
    markers is refused naming them and showing the labels it has."""
    from markovmotion.core.markers import find_markers
    from markovmotion.errors import MarkovMotionError

    assert find_markers(("P1:HEAD", "P2:HEAD", "P1:TOE"), ["HEAD", "TOE"]) == ([2], ["HEAD"])
    model = DualHMM(n_states=4, n_iter=3).fit(marker_takes[:2])
    a = marker_takes[2][0]
    prefixed = Markers(tuple(f"P1:{n}" for n in a.names), a.positions, a.fps, a.name)
    np.testing.assert_array_equal(model.respond(prefixed).positions, model.respond(a).positions)
    other = Markers(tuple(f"X{k}" for k in range(len(a.names))), a.positions, a.fps, "odd")
    with pytest.raises(MarkovMotionError) as exc:
        model.check_input(other)
    assert f"markers not found: {a.names[0]}" in str(exc.value)
    assert "(the take has X0, X1, X2" in str(exc.value)


def test_a_marker_never_seen_is_left_out_of_every_take_whatever_its_case():
    """One take labels its markers in capitals, the other in lower case and never sees
    ``rwra``: ``RWRA`` is left out of both (it had been left out of one only, and the two
    takes, alike whatever the case, then failed as "not markers like" each other)."""
    from markovmotion.features.markers import seen_in_every

    rng = np.random.default_rng(0)
    names = ("HEAD", "LSHO", "RSHO", "LWRA", "RWRA")
    a = Markers(names, rng.normal(size=(20, 5, 3)), 30.0, "a")
    positions = rng.normal(size=(20, 5, 3))
    positions[:, 4] = np.nan
    b = Markers(tuple(n.lower() for n in names), positions, 30.0, "b")
    kept = seen_in_every([a, b])
    assert kept[0].names == names[:4] and kept[1].names == tuple(n.lower() for n in names[:4])


def test_a_take_learnt_in_both_roles_is_named_once_where_a_marker_is_never_seen(capsys):
    """``--roles both`` gives each take twice: the note naming where a marker is never seen
    names each take once (it had said 'never seen in b.c3d, b.c3d')."""
    from markovmotion.features.markers import seen_in_every

    rng = np.random.default_rng(0)
    a = Markers(("HEAD", "RWRA"), rng.normal(size=(20, 2, 3)), 30.0, "a.c3d")
    b = Markers(("HEAD", "RWRA"), rng.normal(size=(20, 2, 3)), 30.0, "b.c3d")
    b.positions[:, 1] = np.nan
    kept = seen_in_every([a, b, b, a])
    assert [t.names for t in kept] == [("HEAD",)] * 4
    assert "RWRA (never seen in b.c3d)" in capsys.readouterr().err


def test_unseen_markers_in_a_take_are_left_out_of_its_errors_not_a_crash(model, marker_takes):
    """A held-out take with points unseen (NaN: occlusion) in A and in B: a new user's
    evaluation died in the observer's logistic regression after every fold had run (and its
    errors would have been NaN). Each frame's errors are over B's points seen in it, a frame
    with none is left out, and A's unseen frames are answered as respond answers them (the
    last seen frame held)."""
    from markovmotion.evaluate.hmm import Baselines, summarise

    a, b = (m.copy() for m in marker_takes[2])
    clean = evaluate_pair(model, a, b, "clean", "handshake")
    b.positions[40:60, 0] = np.nan  # one marker of B unseen for 20 frames (at 120 fps)
    b.positions[200:240] = np.nan  # all of B unseen
    a.positions[100:120] = np.nan  # all of A unseen
    res = evaluate_pair(model, a, b, "take", "handshake")
    truth = model.body_positions(model._rate(b), body_centred=True)
    some = np.isfinite(truth).any(axis=(1, 2))
    part = some & ~np.isfinite(truth).all(axis=(1, 2))
    assert 0 < (~some).sum() < 20 and part.any() and len(res.errors["windowed"]) == some.sum()
    for key in ("windowed", "mean_pose", "nearest_neighbour", "known_motion"):
        assert np.isfinite(res.errors[key]).all() and np.isfinite(res.pose_errors[key]).all()
    f = np.flatnonzero(part)[0]  # a frame with a marker unseen: the others' mean error
    seen = np.isfinite(truth[f]).all(axis=1)
    mean_pose = Baselines(model).mean_pose
    expected = np.linalg.norm(mean_pose[seen] - truth[f, seen], axis=1).mean()
    got = res.pose_errors["mean_pose"][np.searchsorted(np.flatnonzero(some), f)]
    assert got == pytest.approx(expected)
    assert np.isfinite(res.jumps["real"]).all() and len(res.jumps["real"]) < len(
        clean.jumps["real"]
    )
    # where B is seen and A was before, nothing moved
    np.testing.assert_allclose(res.pose_errors["mean_pose"][:5], clean.pose_errors["mean_pose"][:5])
    report = summarise([res, clean], model)["overall"]
    assert all(np.isfinite(report[k]) for k in ("windowed_mm", "mean_pose_mm", "observer_accuracy"))


def test_respond_refuses_markers_it_cannot_answer_from_in_one_line(
    model, marker_takes, tmp_path, capsys
):
    """A tracker that never saw one of the model's markers (or never all at once, even held
    for a moment) gave a take of frames each missing a marker: the dual HMM treats such a
    frame as missing, and ``respond`` answered every frame from nothing (B 2.5 m from the
    real B on a Bütepage handshake) under a warning. Now one line, exit 2, naming the
    marker; a take with some frames whole, or each frame missing a marker seen a moment
    before (held: HeldMarkers), is answered."""
    path = tmp_path / "model.npz"
    model.save(path)
    a = marker_takes[2][0]
    never, halves, scattered, some = a.copy(), a.copy(), a.copy(), a.copy()
    never.positions[:, 3] = np.nan
    half = a.n_markers // 2  # each frame shows one half: no marker seen with the others
    halves.positions[::2, :half] = np.nan
    halves.positions[1::2, half:] = np.nan
    for t in range(a.n_frames):
        scattered.positions[t, t % a.n_markers] = np.nan
    some.positions[10:20] = np.nan
    args = ["dualhmm", "respond", "--model", str(path), "--out", str(tmp_path / "b.c3d")]
    for take, words in (
        (never, f"{a.names[3]} never seen"),
        (halves, f"no frame shows all {a.n_markers} of the model's markers, even with"),
    ):
        write_c3d(take, tmp_path / "a.c3d")
        with pytest.raises(SystemExit) as exc:
            main([*args, "--input", str(tmp_path / "a.c3d")])
        err = capsys.readouterr().err.strip()
        assert exc.value.code == 2 and words in err and "\n" not in err, err
        assert not (tmp_path / "b.c3d").exists()
    for take in (some, scattered):
        write_c3d(take, tmp_path / "a.c3d")
        main([*args, "--input", str(tmp_path / "a.c3d")])
        assert np.isfinite(read_c3d(tmp_path / "b.c3d").positions).all()


def test_evaluate_table_shows_the_body_centred_baselines_its_aims_cite(model, marker_takes, capsys):
    """The aims line compares the body-centred error with nearest neighbour and GMR: their
    numbers are in the table it follows (a new user's table showed standard, windowed and
    mean pose alone, and the aims cited a 121.1 mm found nowhere), and the known-motion and
    true-place columns are said what they are."""
    from markovmotion.cli.hmm import _print_table
    from markovmotion.evaluate.hmm import summarise

    report = summarise([evaluate_pair(model, *marker_takes[2], "take", "handshake")], model)
    _print_table(report)
    out, err = capsys.readouterr()
    head, overall = out.splitlines()[1].split(","), out.splitlines()[2].split(",")
    body = report["overall"]["body_centred"]
    column = next(i for i, h in enumerate(head) if h.startswith("body-centred"))
    names = head[column].removeprefix("body-centred ").split("/")
    keys = {"std": "standard_mm", "win": "windowed_mm", "mean": "mean_pose_mm",
            "nn": "nearest_neighbour_mm", "gmr": "gmr_mm"}  # fmt: skip
    assert names[:4] == ["std", "win", "mean", "nn"]
    assert overall[column] == "/".join(f"{body[keys[n]]:.1f}" for n in names)
    said = " ".join(err.split())
    assert "known motion: the real B's motion moved onto the training people's mean" in said
    assert "at true place: the world error with B moved onto the real B's centroid" in said


def test_a_marker_never_seen_is_refused_by_the_model_and_left_out_of_evaluate(
    model, marker_takes, tmp_path, capsys
):
    """A take whose person A never shows one of the model's markers cannot be answered (each
    frame is a missing observation): ``DualHMM.respond`` refuses it naming the marker, and
    ``dualhmm evaluate`` leaves it out, listed with why, and scores the others (a new user's
    evaluation had scored such a take at 2.5 m and pulled the overall to 1.3 m)."""
    from markovmotion.errors import SkeletonMismatchError

    a, b = marker_takes[2]
    never = a.copy()
    never.positions[:, 3] = np.nan
    with pytest.raises(SkeletonMismatchError, match=f"{a.names[3]} never seen"):
        model.respond(never, "windowed")
    data = tmp_path / "data"
    rows = ["file,source,subject,trial,category,label,partner_file,fps,frames,description"]
    for k, take in ((1, a), (2, never)):
        write_c3d(take, data / f"a{k}.c3d")
        write_c3d(b, data / f"b{k}.c3d")
        rows += [f"a{k}.c3d,test,p{k},{k},interaction,handshake,b{k}.c3d,120,{a.n_frames},"]
        rows += [f"b{k}.c3d,test,p{k},{k},interaction,handshake,a{k}.c3d,120,{a.n_frames},"]
    (data / "INDEX.csv").write_text("\n".join(rows) + "\n")
    path = tmp_path / "m.npz"
    model.save(path)
    main(["dualhmm", "evaluate", "--model", str(path), "--test", str(data / "INDEX.csv")]
         + ["--json"])  # fmt: skip
    report = json.loads(capsys.readouterr().out)
    assert f"a2.c3d (marker {a.names[3]} never seen)" in report["left_out_other_skeleton"]
    assert report["test_files"] and all("a2.c3d" not in f for f in report["test_files"])
    assert report["overall"]["windowed_mm"] < 1000


def test_held_markers_move_with_the_others_whole_and_frame_by_frame():
    """A marker unseen for at most ``frames`` frames is where it last was, moved by the mean
    move of the markers seen then and now (brute force); longer, or with nothing seen, it
    stays unseen; a whole take and frame-by-frame steps give the same frames."""
    from markovmotion.features.markers import HeldMarkers

    rng = np.random.default_rng(3)
    pos = np.cumsum(rng.normal(0, 5, (30, 4, 3)), axis=0) + [0.0, 1000.0, 0.0]
    pos[5:8, 1] = np.nan  # three frames: held
    pos[6, 3] = np.nan  # another at the same time: held, from frame 5
    pos[12:20, 2] = np.nan  # eight frames: the last three stay unseen
    pos[25] = np.nan  # nothing seen: nothing to hold by
    markers = Markers(["a", "b", "c", "d"], pos, 30.0)
    whole = HeldMarkers(5)(markers)
    for t, m, last in ((5, 1, 4), (7, 1, 4), (6, 3, 5), (16, 2, 11)):
        both = np.isfinite(pos[t]).all(axis=1) & np.isfinite(pos[last]).all(axis=1)
        expected = pos[last, m] + (pos[t, both] - pos[last, both]).mean(axis=0)
        np.testing.assert_allclose(whole.positions[t, m], expected)
    assert np.isnan(whole.positions[17:20, 2]).all() and np.isnan(whole.positions[25]).all()
    seen = np.isfinite(pos)
    np.testing.assert_array_equal(whole.positions[seen], pos[seen])  # the seen, as they were
    online = HeldMarkers(5)
    steps = np.concatenate([online.step(markers.trim(t, t + 1)).positions for t in range(30)])
    np.testing.assert_array_equal(steps, whole.positions)


def test_short_occlusions_of_a_marker_are_held_not_answered_from_nothing(
    model, marker_takes, monkeypatch
):
    """A's markers unseen for a few frames at a time (a lab's occlusions, here in 40 % of
    the frames): held, the partner answers them as it answers the whole take; without
    the hold each such frame was a missing observation, and B strayed further."""
    import markovmotion.models.hmm.dual as dual

    a = model._rate(marker_takes[2][0])
    rng = np.random.default_rng(0)
    occluded = a.copy()
    for start in range(0, a.n_frames - 6, 10):  # 4 frames of every 10, a random marker
        occluded.positions[start : start + 4, rng.integers(a.n_markers)] = np.nan
    clean = model.respond(a, "windowed").positions
    held = model.respond(occluded, "windowed").positions
    monkeypatch.setattr(dual, "HOLD_SECONDS", 0.0)
    dropped = model.respond(occluded, "windowed").positions
    far = [np.linalg.norm(x - clean, axis=-1).mean() for x in (held, dropped)]
    assert far[0] < 0.5 * far[1], far


def test_evaluate_without_a_test_set_of_a_model_that_held_none_out_says_so(
    marker_takes, tmp_path, capsys
):
    """``dualhmm train`` learns every take unless told: its ``evaluate`` without ``--test``
    says in one line that nothing was held out and what to give (it had listed every
    training take of the index as the reason)."""
    data = tmp_path / "data"
    rows = ["file,source,subject,trial,category,label,partner_file,fps,frames,description"]
    for k, (a, b) in enumerate(marker_takes, start=1):
        for who, m, partner in (("a", a, "b"), ("b", b, "a")):
            write_c3d(m, data / f"{who}{k}.c3d")
            rows.append(f"{who}{k}.c3d,test,,{k},interaction,meet,{partner}{k}.c3d,120,,")
    (data / "INDEX.csv").write_text("\n".join(rows) + "\n")
    path = tmp_path / "m.npz"
    main(["dualhmm", "train", "--data", str(data), "--out", str(path)]
         + ["--states", "3", "--n-iter", "2"])  # fmt: skip
    capsys.readouterr()
    with pytest.raises(SystemExit) as exc:
        main(["dualhmm", "evaluate", "--model", str(path)])
    err = capsys.readouterr().err.strip()
    assert exc.value.code == 2 and "\n" not in err
    assert "the model held no take out at training" in err and "give --test INDEX" in err
