"""Feature steps and the pipeline: inverses, paper equations, persistence."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import make_motion
from scipy.spatial.transform import Rotation

from markovmotion.errors import ModelFormatError
from markovmotion.features import (
    PCA,
    AugmentedConfiguration,
    Deltas,
    ExpMaps,
    FeaturePipeline,
    JointPositions,
    TemporalSmoothing,
    add_deltas,
    continuous_rotvec,
    delta_matrix,
)
from markovmotion.features.body_motion import BodyMotion, ground_frame, ground_travel
from markovmotion.features.smoothing import despike, smooth_gaps
from markovmotion.persist import FORMAT_VERSION, load_npz, save_npz


def test_expmap_round_trip_gives_the_same_motion():
    m = make_motion(n_frames=50)
    step = ExpMaps(root_position="full")
    x = step.fit_transform([m])
    back = step.inverse_transform(x)[0]
    np.testing.assert_allclose(back.positions(), m.positions(), atol=1e-8)


def test_continuous_rotvec_removes_the_flip_through_pi():
    angles = np.linspace(2.5, 3.8, 40)  # a turn about Z through pi
    rv = Rotation.from_rotvec(angles[:, None] * [0, 0, 1]).as_rotvec()
    assert np.abs(np.diff(rv, axis=0)).max() > 6  # SciPy flips to the short form
    smooth = continuous_rotvec(rv)
    np.testing.assert_allclose(smooth[:, 2], angles, atol=1e-9)
    np.testing.assert_allclose(
        Rotation.from_rotvec(smooth).as_quat()
        * np.sign(Rotation.from_rotvec(smooth).as_quat()[:, 3:]),
        Rotation.from_rotvec(rv).as_quat() * np.sign(Rotation.from_rotvec(rv).as_quat()[:, 3:]),
        atol=1e-12,
    )


def test_continuous_rotvec_keeps_short_form_near_rest():
    rv = np.array([[0.1, 0, 0], [-0.05, 0.02, 0], [0.0, -0.1, 0.01]])
    np.testing.assert_array_equal(continuous_rotvec(rv), rv)


def test_pca_keeps_the_energy_fraction():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(500, 6)) * [10, 5, 2, 0.1, 0.1, 0.1]
    pca = PCA(energy=0.95).fit([x[:200], x[200:]])
    ratio = np.cumsum(pca.explained_variance_ratio_)
    k = pca.n_components_
    assert ratio[k - 1] >= 0.95 > ratio[k - 2]
    assert k == 2
    full = PCA(energy=1.0).fit([x])
    np.testing.assert_allclose(full.inverse_transform(full.transform([x]))[0], x, atol=1e-9)


def test_augmented_configuration_eqs_1_to_4():
    c = np.array([[0.0, 10], [1, 10], [3, 20], [4, 30]])
    step = AugmentedConfiguration(lam=10).fit([c])
    f = step.transform([c])[0]
    scaled = np.array([[0, 0], [0.25, 0], [0.75, 0.5], [1, 1]])
    np.testing.assert_allclose(f[:, :2], scaled)
    np.testing.assert_allclose(f[1:, 2:], 10 * np.diff(scaled, axis=0))
    np.testing.assert_allclose(f[0, 2:], f[1, 2:])
    assert f[:, :2].min() == 0 and f[:, :2].max() == 1
    np.testing.assert_allclose(step.inverse_transform([f])[0], c)


def test_deltas_match_eqs_2_to_4():
    rng = np.random.default_rng(1)
    c = rng.normal(size=(12, 3))
    o = add_deltas(c)
    t = 5
    np.testing.assert_allclose(o[t, 3:6], 0.5 * (c[t + 1] - c[t - 1]))
    np.testing.assert_allclose(o[t, 6:], 0.25 * (c[t + 2] - 2 * c[t] + c[t - 2]))
    w = delta_matrix(12).toarray()
    for d in range(3):
        np.testing.assert_allclose(w @ c[:, d], o[:, [d, 3 + d, 6 + d]].ravel(), atol=1e-12)
    assert np.allclose(add_deltas(np.ones((6, 2)))[:, 2:], 0)
    np.testing.assert_array_equal(Deltas().inverse_transform([o])[0], c)


def test_smoothing_is_a_centred_moving_average():
    x = np.arange(10.0)[:, None] ** 2
    y = TemporalSmoothing(window=3).transform([x])[0]
    np.testing.assert_allclose(y[4], (9 + 16 + 25) / 3)


def test_despike_takes_out_a_glitch_and_leaves_real_motion_alone():
    """A Hampel filter: a wrist that leaves its path by 400 mm for two frames (60 fps) is put
    back within 40 mm (the window's median of a turning path); a point moving as fast as a hand can (2 m/s, turning) and one unseen
    in some frames are left as they are."""
    fps = 60.0
    t = np.arange(120) / fps
    path = np.stack([400 * np.cos(5 * t), 300 * np.sin(5 * t), 100 * t], axis=1)  # 2 m/s
    points = np.stack([path, path + 200.0], axis=1)  # (F, 2, 3)
    points[40:42, 0] += [400.0, 0.0, 0.0]
    points[70:75, 1] = np.nan
    out, spiked = despike(points, fps)
    assert spiked.sum() == 2 and spiked[40:42, 0].all()
    assert np.linalg.norm(out[40:42, 0] - path[40:42], axis=-1).max() < 40.0
    untouched = ~spiked
    untouched[70:75, 1] = False
    np.testing.assert_array_equal(out[untouched], points[untouched])
    assert np.isnan(out[70:75, 1]).all()
    assert despike(points[:2], fps)[1].sum() == 0  # too short to judge
    # a good point beside a glitch at a clip's edge or a gap is not judged against the mean
    # of itself and the glitch (25 fps: a window of 3)
    still = np.zeros((12, 1, 3))
    still[1, 0, 0] = still[7, 0, 0] = 500.0
    still[5] = np.nan
    out, spiked = despike(still, 25.0)
    assert spiked[:, 0].tolist() == [i in (1, 7) for i in range(12)]
    assert np.abs(out[[0, 2, 3, 4, 6, 8], 0]).max() == 0.0


def test_smooth_gaps_lowers_noise_keeps_gaps_and_agrees_with_brute_force():
    """Gaussian smoothing of a noisy path: nearer the truth than the noise; a point unseen
    stays unseen and its neighbours average only what was seen (brute-force weighted mean
    of the seen frames with Gaussian weights, away from the edges); sigma 0 changes nothing."""
    rng = np.random.default_rng(3)
    fps = 60.0
    t = np.arange(240) / fps
    path = np.stack([300 * np.cos(3 * t), 200 * np.sin(3 * t), 50 * t], axis=1)[:, None]
    noisy = path + rng.normal(0.0, 10.0, path.shape)
    noisy[100:104] = np.nan
    out = smooth_gaps(noisy, 2.0)
    seen = np.isfinite(noisy).all(-1)
    assert np.isnan(out[~seen]).all() and np.isfinite(out[seen]).all()
    raw = np.linalg.norm(noisy - path, axis=-1)[seen].mean()
    assert np.linalg.norm(out - path, axis=-1)[seen].mean() < 0.7 * raw
    frames = np.arange(len(t))
    for f in (20, 98, 105, 150):  # beside the gap too
        w = np.exp(-0.5 * ((frames - f) / 2.0) ** 2) * seen[:, 0]
        brute = np.nansum(w[:, None] * np.nan_to_num(noisy[:, 0]), axis=0) / w.sum()
        np.testing.assert_allclose(out[f, 0], brute, atol=1e-3)
    np.testing.assert_array_equal(smooth_gaps(noisy, 0.0), noisy)


def test_despike_leaves_real_motion_capture_alone():
    """The threshold is what real people do: on a captured take (the collection's first
    skeleton take) it replaces next to nothing."""
    from markovmotion.data.index import MocapIndex

    entry = next(e for e in MocapIndex.load() if e.kind == "skeleton")
    motion = entry.read()
    _, spiked = despike(motion.positions()[:, :20], motion.fps)
    assert spiked.mean() < 1e-3


def test_pipeline_saves_and_loads_without_pickle(tmp_path):
    motions = [make_motion(seed=s) for s in range(3)]
    pipe = FeaturePipeline([JointPositions(), TemporalSmoothing(3), PCA(0.9)])
    x = pipe.fit_transform(motions)
    arrays: dict = {}
    save_npz(tmp_path / "p.npz", "pipeline-test", {"pipeline": pipe.to_state(arrays)}, arrays)
    header, loaded = load_npz(tmp_path / "p.npz", "pipeline-test")
    back = FeaturePipeline.from_state(header["pipeline"], loaded)
    for a, b in zip(back.transform(motions), x, strict=True):
        np.testing.assert_allclose(a, b)
    assert back.steps[0].skeleton_.names == motions[0].skeleton.names


def test_model_file_errors(tmp_path):
    save_npz(tmp_path / "m.npz", "kind-a", {}, {"x": np.zeros(3)})
    with pytest.raises(ModelFormatError, match="expected 'kind-b'"):
        load_npz(tmp_path / "m.npz", "kind-b")
    (tmp_path / "junk.npz").write_bytes(b"not a zip")
    with pytest.raises(ModelFormatError, match="junk.npz: not a markovmotion model"):
        load_npz(tmp_path / "junk.npz")
    np.savez(tmp_path / "plain.npz", x=np.zeros(2))
    with pytest.raises(ModelFormatError, match="no header"):
        load_npz(tmp_path / "plain.npz")
    with pytest.raises(ModelFormatError, match="no such model file"):
        load_npz(tmp_path / "missing.npz")
    (tmp_path / "walk.bvh").write_text("HIERARCHY\n")  # a text file is not taken for a pickle
    with pytest.raises(ModelFormatError, match="walk.bvh: not a markovmotion model file \\(not an"):
        load_npz(tmp_path / "walk.bvh")
    with pytest.raises(ModelFormatError, match="m.txt: models are written as .npz"):
        save_npz(tmp_path / "m.txt", "kind-a", {}, {})
    assert not (tmp_path / "m.txt").exists()


def test_model_file_from_another_version(tmp_path, monkeypatch):
    import markovmotion.persist as persist

    monkeypatch.setattr(persist, "FORMAT_VERSION", FORMAT_VERSION + 1)
    save_npz(tmp_path / "new.npz", "k", {}, {})
    monkeypatch.setattr(persist, "FORMAT_VERSION", FORMAT_VERSION)
    with pytest.raises(ModelFormatError, match="format version 2.*retrain"):
        load_npz(tmp_path / "new.npz", "k")


def test_positions_on_real_data_are_body_centred(mocap):
    a, b = mocap.load_pair(*mocap.pairs(label="salsa")[0])
    assert a.n_frames == b.n_frames and a.fps == b.fps == 60
    x = JointPositions().fit_transform([a])[0].reshape(a.n_frames, -1, 3)
    pelvis = a.skeleton.body_root
    np.testing.assert_allclose(x[:, pelvis], 0, atol=1e-9)
    hips = a.hip_joints()
    lateral = x[:, hips[0]] - x[:, hips[1]]
    np.testing.assert_allclose(lateral[:, 2], 0, atol=1e-6)  # hips across, facing +Z
    assert np.all(lateral[:, 0] > 0)


# ------------------------------------------------------------------ A's pose and motion
def _moved(motion, yaw: float, shift) -> object:
    """``motion`` turned by ``yaw`` about the vertical and moved by ``shift`` (a rigid move)."""
    turn = Rotation.from_rotvec([0.0, yaw, 0.0])
    out = motion.copy()
    out.rotations[:, 0] = (turn * Rotation.from_quat(motion.rotations[:, 0])).as_quat()
    out.translations[:, 0] = turn.apply(motion.translations[:, 0]) + shift
    return out


def test_body_motion_ignores_where_the_body_is_and_uses_no_future_frames():
    m = make_motion(60, seed=4)
    step = BodyMotion().fit([m])
    x = step.transform([m])[0]
    assert x.shape == (60, 6 * m.skeleton.n_joints + 3)
    moved = step.transform([_moved(m, 2.1, [3000.0, 0.0, -500.0])])[0]
    np.testing.assert_allclose(moved, x, atol=1e-6)
    np.testing.assert_allclose(step.transform([m.trim(0, 25)])[0], x[:25], atol=1e-9)
    np.testing.assert_allclose(x[0, 3 * m.skeleton.n_joints :], 0.0)


def test_body_motion_measures_travel_in_the_bodys_own_frame():
    m = make_motion(30, seed=5)
    m.rotations[:, 0] = m.rotations[:1, 0]  # the pelvis keeps its heading h
    h = m.heading()[0]
    t = np.arange(30)[:, None]
    m.translations[:, 0] = [0.0, 900.0, 0.0] + t * 12.0 * np.array([np.sin(h), 0.0, np.cos(h)])
    step = BodyMotion(horizon=0.5, travel_horizon=1.0).fit([m])
    travel = step.transform([m])[0][1:, -3:] / (1.0 * m.fps)
    np.testing.assert_allclose(travel, np.tile([0.0, 12.0, 0.0], (29, 1)), atol=1e-6)
    np.testing.assert_allclose(
        ground_travel(*ground_frame(m))[1:], np.tile([0.0, 12.0, 0.0], (29, 1)), atol=1e-9
    )
    turned = ground_travel(np.zeros((3, 3)), np.array([3.1, -3.1, -3.0]))[1:, 2]
    np.testing.assert_allclose(turned, [2 * np.pi - 6.2, 0.1])  # the short way round
