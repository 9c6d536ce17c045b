"""Monocular tracking: MediaPipe landmarks to body points and markers, placed by PnP, on real video."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from markovmotion.cli import main
from markovmotion.data.index import data_root
from markovmotion.features.body_points import BODY_POINTS, MARKER_POINTS
from markovmotion.io.c3d import read_c3d
from markovmotion.video.cameras import look_at
from markovmotion.video.monocular import (
    FEET,
    LANDMARK_WEIGHTS,
    LANDMARKS,
    START_UP_LINES,
    Landmarks,
    floor_scale,
    kabsch_align,
    monocular_markers,
    native_start_up_lines_held,
    place_body,
    to_body_points,
    to_world,
)
from markovmotion.video.render import read_frames


def test_only_mediapipes_start_up_lines_are_held_back(capfd):
    """Lines written to file descriptor 2 in the block (C++ and Python alike) come out after
    it, except MediaPipe's start-up lines; the descriptor is the terminal's again after."""
    import os
    import sys

    with native_start_up_lines_held():
        os.write(2, b"W0000 inference_feedback_manager.cc:114] Feedback manager requires\n")
        os.write(2, b"a real error from C++\n")
        print("a Python warning", file=sys.stderr)
        os.write(2, b"INFO: Created TensorFlow Lite XNNPACK delegate for CPU.\n")
        early = capfd.readouterr().err
        assert "real error" not in early  # held, not yet out
    os.write(2, b"after\n")
    err = early + capfd.readouterr().err
    assert err.endswith("a real error from C++\nafter\n") and "a Python warning" in err
    assert not any(line in err for line in START_UP_LINES)


@pytest.fixture(scope="module")
def real_video():
    return data_root().parent / "video" / "pose2sim_balancing"


def _standing_landmarks(rng: np.random.Generator, frames: int) -> np.ndarray:
    """(F, 33, 3) world landmarks (mm, Y up) of a person about 1.75 m tall, feet on Y = 0."""
    base = rng.uniform([-250, 100, -150], [250, 1700, 150], (len(LANDMARKS), 3))
    for n in FEET:
        base[LANDMARKS.index(n), 1] = 0.0
    out = base + rng.normal(0, 30, (frames, *base.shape))
    out[:, [LANDMARKS.index(n) for n in FEET], 1] = 0.0
    return out + [500.0, 0.0, -300.0]


def test_a_lens_over_the_real_video_is_undone_as_its_frames_are_read(real_video, tmp_path):
    """Camera 0's real frames seen through a barrel lens (k1 = -0.3, OpenCV's model; written
    losslessly), read with that camera's distortion in cameras.json, are the original frames
    again (within resampling), where read as they are they are not."""
    import cv2

    from markovmotion.video.cameras import load_cameras, save_cameras
    from markovmotion.video.render import write_video

    (cam, *_), doc = load_cameras(real_video)
    lens = replace(cam, distortion=(-0.3, 0.1, 0.0, 0.0, 0.0), background="", video="frames")
    w, h = cam.width, cam.height
    grid = np.stack(np.meshgrid(np.arange(w), np.arange(h)), -1).astype(np.float32)
    seen = cv2.undistortPoints(grid.reshape(-1, 1, 2), cam.K, np.array(lens.distortion), P=cam.K)
    maps = seen.reshape(h, w, 2)
    original = [f for _, f in zip(range(2), read_frames(real_video / cam.video), strict=False)]
    write_video([cv2.remap(f, maps[..., 0], maps[..., 1], cv2.INTER_LINEAR) for f in original],
                tmp_path / "frames", doc["fps"])  # fmt: skip
    save_cameras([lens], tmp_path / "cameras.json", doc["fps"])
    (back,), _ = load_cameras(tmp_path)
    centre = (slice(h // 6, 5 * h // 6), slice(w // 6, 5 * w // 6))
    for k, (fixed, raw) in enumerate(
        zip(read_frames(tmp_path / "frames", back), read_frames(tmp_path / "frames"), strict=True)
    ):
        truth = original[k].astype(float)[centre]
        assert np.abs(fixed.astype(float)[centre] - truth).mean() < 3.0
        assert np.abs(raw.astype(float)[centre] - truth).mean() > 6.0


def test_landmark_weights_make_the_named_points():
    assert LANDMARK_WEIGHTS.shape == (len(BODY_POINTS), len(LANDMARKS))
    assert np.allclose(LANDMARK_WEIGHTS.sum(axis=1), 1.0)
    lm = np.random.default_rng(0).normal(0, 500, (2, len(LANDMARKS), 3))
    bp = to_body_points(lm)
    at = {n: lm[:, i] for i, n in enumerate(LANDMARKS)}
    assert np.allclose(bp[:, BODY_POINTS.index("pelvis")], (at["left_hip"] + at["right_hip"]) / 2)
    assert np.allclose(bp[:, BODY_POINTS.index("left_toe")], at["left_foot_index"])
    assert np.allclose(bp[:, BODY_POINTS.index("right_knee")], at["right_knee"])
    neck = (at["left_shoulder"] + at["right_shoulder"]) / 2
    pelvis = bp[:, 0]
    assert np.allclose(bp[:, BODY_POINTS.index("chest")], pelvis + 2 / 3 * (neck - pelvis))


def test_markers_are_the_vlmm_points_by_name():
    pts = np.random.default_rng(1).normal(0, 300, (5, len(BODY_POINTS), 3))
    m = monocular_markers(pts, 30.0)
    assert m.n_markers == len(MARKER_POINTS) == 13
    assert np.allclose(m.positions[:, m.names.index("L_WRIST")], pts[:, 7])  # left_wrist
    assert np.allclose(m.positions[:, m.names.index("HEAD_FRONT")], pts[:, 4])  # head


def test_pnp_places_the_body_where_it_stands_and_the_floor_fixes_its_size():
    """The world landmarks, hip-centred and turned, placed back by PnP at their true depth;
    the same body 10 % too small lands nearer the camera, and the floor scale restores it."""
    rng = np.random.default_rng(3)
    truth = _standing_landmarks(rng, 6)
    cam = look_at(np.array([400.0, 1500.0, 3500.0]), np.array([0, 900, 0]), 272, 480, 420.0)
    pix, _ = cam.project(truth)
    hips = [LANDMARKS.index("left_hip"), LANDMARKS.index("right_hip")]
    turn = Rotation.from_rotvec(rng.normal(0, 1.0, (6, 3))).as_matrix()
    world = np.einsum("fij,flj->fli", turn, truth - truth[:, hips].mean(1, keepdims=True))
    vis = np.ones((6, len(LANDMARKS)))
    found = np.ones(6, dtype=bool)
    for size, want in ((1.0, 1.0), (0.9, 1 / 0.9)):
        placed_cam, placed = place_body(Landmarks(pix, world * size, vis, found), cam)
        assert placed.all()
        placed_world = to_world(placed_cam, cam)
        scale = floor_scale(placed_world, cam)
        assert scale == pytest.approx(want, rel=1e-3)
        rescaled = cam.centre + scale * (placed_world - cam.centre)
        assert np.abs(rescaled - truth).max() < 1.0


def test_kabsch_recovers_a_rigid_motion():
    rng = np.random.default_rng(4)
    fixed = rng.normal(0, 400, (3, 12, 3))
    rot = Rotation.random(3, random_state=5).as_matrix()
    moving = np.einsum("fij,fpj->fpi", rot, fixed) + rng.normal(0, 1000, (3, 1, 3))
    assert np.allclose(kabsch_align(moving, fixed), fixed, atol=1e-6)


def test_reference_errors_count_every_joint_known_in_both(tmp_path):
    """A joint unknown in one frame leaves only that joint out, not the frame; a frame with
    no joint known is counted as missing; the mean is over the joint-frames compared."""
    from markovmotion.features.body_points import BODY_POINTS
    from markovmotion.video.monocular import REFERENCE_JOINTS, reference_errors

    ref = np.arange(4 * 12 * 3, dtype=float).reshape(4, 12, 3)
    cols = [f"{j}_{a}" for j in REFERENCE_JOINTS for a in "xyz"]
    lines = ["frame," + ",".join(cols)]
    lines += [f"{f}," + ",".join(f"{v:g}" for v in ref[f].ravel()) for f in range(4)]
    path = tmp_path / "ref.csv"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    points = np.zeros((4, len(BODY_POINTS), 3))
    idx = [BODY_POINTS.index(j) for j in REFERENCE_JOINTS]
    points[:, idx] = ref + [0.0, 0.0, 10.0]  # 10 mm off everywhere
    points[1, idx[0]] = np.nan  # one joint unknown
    points[3] = np.nan  # nothing known
    errors = reference_errors(points, path)
    assert errors["frames_compared"] == 3 and errors["frames_missing"] == 1
    assert errors["joints_missing"] == 1 and errors["frames_aligned"] == 3
    assert errors["mean_mm"] == pytest.approx(10.0)
    assert errors["aligned_mean_mm"] == pytest.approx(0.0, abs=1e-6)
    # frames of 2 known joints count in the mean, not in the aligned one (no alignment on
    # 2 points: it had given NaN, which is not JSON)
    few = np.full_like(points, np.nan)
    few[:, idx[:2]] = points[:, idx[:2]]
    errors = reference_errors(few, path)
    assert errors["mean_mm"] == pytest.approx(10.0) and errors["frames_aligned"] == 0
    assert errors["aligned_mean_mm"] is None


def test_monocular_track_of_real_video(real_video, tmp_path, capfd):
    """One real camera (cam0 of the 4-view balancing trial), all 100 frames: within 130 mm of
    the triangulated reference after per-frame rigid alignment; the 13 markers written;
    MediaPipe's C++ start-up lines are not on the terminal (file descriptor 2)."""
    try:
        import mediapipe  # noqa: F401
    except ImportError:
        pytest.fail("these tests need MediaPipe: run scripts/install-camera", pytrace=False)
    out = tmp_path / "a.c3d"
    main(
        [
            "track",
            "--video",
            str(real_video / "cam0.mp4"),
            "--method",
            "monocular",
            "--reference",
            str(real_video / "reference_mediapipe_triangulated_mm.csv"),
            "--out",
            str(out),
            "--json",
        ]
    )
    printed = capfd.readouterr()
    summary = json.loads(printed.out)
    assert not any(line in printed.err for line in START_UP_LINES), printed.err
    assert summary["frames"] == summary["frames_placed"] == 100
    assert summary["aligned_mean_mm"] <= 130.0
    assert summary["aligned_mean_mm"] < summary["mean_mm"]
    assert 0.8 < summary["scale"] < 1.25  # the feet on the treadmill: a plausible size
    markers = read_c3d(out)
    assert markers.n_frames == 100 and "L_SHOULDER" in markers.names
    feet = markers.positions[:, [markers.names.index(n) for n in ("L_ANKLE", "R_ANKLE")], 1]
    assert 0.0 < np.median(feet.min(axis=1)) < 200.0  # ankles just above the floor
    at = {n: markers.positions[:, markers.names.index(n)] for n in markers.names}
    for upper, lower in (("L_ELBOW", "L_WRIST"), ("R_KNEE", "R_ANKLE")):  # constant bones
        length = np.linalg.norm(at[upper] - at[lower], axis=1)
        assert 150 < length.mean() < 600 and np.ptp(length) < 1e-3 * length.mean()
    # smoothed over time by the sigma chosen on rendered kinds (MONOCULAR_SMOOTHING_S): the
    # wrists' frame-to-frame jitter is lower than unsmoothed (--smooth 0), and so is the error
    assert summary["smoothing_s"] == round(1 / 15, 4)
    assert summary["smoothing_chosen_by"].startswith("fixed")
    main(["track", "--video", str(real_video / "cam0.mp4"), "--method", "monocular", "--smooth",
          "0", "--reference", str(real_video / "reference_mediapipe_triangulated_mm.csv"),
          "--out", str(tmp_path / "raw.c3d"), "--json"])  # fmt: skip
    raw = json.loads(capfd.readouterr().out)
    assert raw["smoothing_s"] == 0 and raw["aligned_mean_mm"] > summary["aligned_mean_mm"]
    rough = read_c3d(tmp_path / "raw.c3d")

    def jerk(m) -> float:  # second differences of the wrists (mm per frame squared)
        w = m.positions[:, [m.names.index(n) for n in ("L_WRIST", "R_WRIST")]]
        return float(np.nanmedian(np.linalg.norm(np.diff(w, 2, axis=0), axis=-1)))

    assert jerk(markers) < 0.5 * jerk(rough)


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--out", "x.bvh"], "use a .c3d name"),
        (["--reference", "missing.csv"], "no such reference file"),
        (["--stature", "90"], "--stature"),
    ],
)
def test_monocular_bad_options_are_one_line(real_video, tmp_path, capsys, extra, message):
    extra = [str(tmp_path / e) if e.endswith((".bvh", ".csv")) else e for e in extra]
    with pytest.raises(SystemExit) as exc:
        main(["track", "--video", str(real_video / "cam0.mp4"), "--method", "monocular", *extra])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1 and "Traceback" not in err


@pytest.fixture(scope="module")
def partner_models(mocap, tmp_path_factory):
    """Small dual HMMs on the training handshake and pull takes, B placed by where A faces
    (``heading``) and along the capture room's axes (``world``)."""
    from markovmotion.data.splits import held_out_pairs
    from markovmotion.models.hmm.dual import DualHMM

    train, _ = held_out_pairs(mocap.pairs(label=["handshake", "pull"], kind="skeleton"))
    pairs = [mocap.load_pair(a, b) for a, b in train]
    out = {}
    for frame in ("heading", "world"):
        path = tmp_path_factory.mktemp("model") / f"{frame}.npz"
        DualHMM(n_states=4, n_iter=3, window=4, placement_window=3, frame=frame).fit(pairs).save(
            path
        )
        out[frame] = path
    return out


@pytest.mark.parametrize("frame", ["heading", "world"])
def test_respond_monocular_draws_the_partner_into_the_real_video(
    real_video, partner_models, tmp_path, capsys, frame
):
    """``dualhmm respond --video DIR --method monocular``: A tracked in camera 1 alone, B drawn
    into its real footage; a model placing B by its capture room's axes gets a note."""
    out = tmp_path / "composite.mp4"
    main(["dualhmm", "respond", "--model", str(partner_models[frame]), "--video",
          str(real_video), "--method", "monocular", "--view", "1", "--max-frames", "12",
          "--out", str(out)])  # fmt: skip
    frames = list(read_frames(out))
    original = list(read_frames(real_video / "cam1.mp4"))[:12]
    assert len(frames) == 12 and frames[0].shape == original[0].shape
    changed = [
        np.abs(f.astype(int) - o).max(axis=2) > 60 for f, o in zip(frames, original, strict=True)
    ]
    assert sum(c.sum() for c in changed) > 500  # B drawn (the rest: compression noise)
    err = capsys.readouterr().err
    assert "12 frames in camera 1 (cam1) (12 placed" in err
    assert ("--frame heading" in err) == (frame == "world")


@pytest.mark.parametrize(
    ("method", "said"),
    [
        ("monocular", "12 frames in camera 0 (cam0)"),
        ("triangulate", "12 frames in 4 views, triangulated"),
    ],
)
def test_a_marker_partner_is_drawn_into_the_real_video_at_the_persons_height(
    mocap, real_video, tmp_path, capsys, method, said
):
    """A partner learnt from a depth sensor's 8 upper-body markers (the collection's
    handshakes) answers the man tracked by MediaPipe (camera 0 alone, or every camera
    triangulated) and is drawn into camera 0 as the body parts its markers name: its drawn
    pixels reach up to the man's head height and not to the floor."""
    from markovmotion.models.hmm.dual import DualHMM

    pairs = [mocap.load_pair(a, b) for a, b in mocap.pairs("handshake", kind="markers")[:4]]
    model = tmp_path / "sensor.npz"
    DualHMM(n_states=4, n_iter=3, window=4, frame="heading").fit(pairs).save(model)
    out = tmp_path / "composite.mp4"
    main(["dualhmm", "respond", "--model", str(model), "--video", str(real_video),
          "--method", method, "--max-frames", "12", "--out", str(out)])  # fmt: skip
    assert said in capsys.readouterr().err
    frames = list(read_frames(out))
    original = list(read_frames(real_video / "cam0.mp4"))[:12]
    changed = np.array(
        [np.abs(f.astype(int) - o).max(axis=2) > 60 for f, o in zip(frames, original, strict=True)]
    )
    rows = np.flatnonzero(changed.any(axis=(0, 2)))
    assert changed.sum() > 500  # B drawn
    height = original[0].shape[0]
    assert rows.min() < 0.4 * height and rows.max() < 0.8 * height  # upper body, no legs


def test_marker_shape_joins_the_named_body_points_and_refuses_unnamed_markers():
    from markovmotion.errors import SkeletonMismatchError
    from markovmotion.video.body_model import marker_shape

    names = ["TORSO", "HEAD", "R_SHOULDER", "L_SHOULDER", "R_ELBOW", "L_ELBOW", "R_HAND", "L_HAND"]
    shape, points = marker_shape(names)
    assert points[0] == "spine" and points[6] == "right_wrist"
    joined = {tuple(sorted((names[a], names[b]))) for a, b in shape.capsules}
    assert ("R_ELBOW", "R_HAND") in joined and ("HEAD", "TORSO") in joined
    assert len(joined) == 7  # every marker hangs from its parent on the body's tree
    assert {names[b[0]] for b in shape.balls} == {"HEAD", "R_HAND", "L_HAND"}
    with pytest.raises(SkeletonMismatchError, match="nothing to draw"):
        marker_shape(["M1", "M2", "M3"])


def test_live_respond_answers_a_video_at_twice_the_models_rate(
    real_video, partner_models, tmp_path, capsys
):
    """``respond --video --realtime`` on the real 60 fps video with a 30 fps partner: the
    partner sees every other frame and B, resampled to 60 fps, is drawn into the footage."""
    out = tmp_path / "live.mp4"
    main(["dualhmm", "respond", "--model", str(partner_models["heading"]), "--video",
          str(real_video), "--realtime", "--max-frames", "12", "--particles", "20",
          "--layers", "2", "--out", str(out)])  # fmt: skip
    assert "live: 12 frames" in capsys.readouterr().err
    frames = list(read_frames(out))
    original = list(read_frames(real_video / "cam0.mp4"))[:12]
    assert len(frames) == 12
    changed = [
        (np.abs(f.astype(int) - o).max(axis=2) > 60).sum()
        for f, o in zip(frames, original, strict=True)
    ]
    assert sum(changed) > 500  # B drawn over the frames it answers (after the lag)


@pytest.mark.parametrize("method", ["monocular", "triangulate"])
def test_respond_by_mediapipe_is_not_live(real_video, partner_models, tmp_path, capsys, method):
    with pytest.raises(SystemExit) as exc:
        main(["dualhmm", "respond", "--model", str(partner_models["heading"]), "--video",
              str(real_video), "--method", method, "--realtime",
              "--out", str(tmp_path / "c.mp4")])  # fmt: skip
    assert exc.value.code == 2
    assert f"no --method {method}" in capsys.readouterr().err


def test_respond_triangulate_needs_every_camera(real_video, partner_models, tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["dualhmm", "respond", "--model", str(partner_models["heading"]), "--video",
              str(real_video / "cam0.mp4"), "--method", "triangulate",
              "--out", str(tmp_path / "c.mp4")])  # fmt: skip
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "needs the folder of every camera" in err and len(err.strip().splitlines()) == 1
    # the camera file names every camera as well as its folder does
    main(["dualhmm", "respond", "--model", str(partner_models["heading"]), "--video",
          str(real_video / "cameras.json"), "--method", "triangulate", "--max-frames", "5",
          "--out", str(tmp_path / "c.mp4")])  # fmt: skip
    assert "5 frames in 4 views, triangulated" in capsys.readouterr().err


def test_respond_auto_says_how_respond_asks_for_the_filter(
    real_video, partner_models, tmp_path, capsys
):
    """``respond --video`` without ``--method`` triangulates, and its note names how
    ``respond`` asks for the particle filter (``--method apf``, ``--realtime``), not track's
    ``.bvh --out``: respond's ``--out`` is the composite video."""
    main(["dualhmm", "respond", "--model", str(partner_models["heading"]), "--video",
          str(real_video), "--max-frames", "3", "--out", str(tmp_path / "c.mp4")])  # fmt: skip
    err = capsys.readouterr().err
    note = next(line for line in err.splitlines() if "--method auto chose" in line)
    assert "chose triangulate" in note and "--realtime" in note and ".bvh" not in note


def _frame_folders(real_video, folder, frames: int = 3):
    """The real cameras with each camera's video a folder of ``frames`` PNG frames
    (``camK/frame_N.png``, its cameras.json naming the folders), as a new user made them."""
    import itertools

    import cv2

    doc = json.loads((real_video / "cameras.json").read_text(encoding="utf-8"))
    for k, camera in enumerate(doc["cameras"]):
        (folder / f"cam{k}").mkdir(parents=True)
        for i, f in enumerate(itertools.islice(read_frames(real_video / f"cam{k}.mp4"), frames)):
            cv2.imwrite(str(folder / f"cam{k}" / f"frame_{i}.png"), f[..., ::-1])
        camera["video"] = f"cam{k}"
    (folder / "cameras.json").write_text(json.dumps(doc), encoding="utf-8")
    return folder


def test_a_folder_of_one_cameras_frames_is_that_cameras_video(
    real_video, partner_models, tmp_path, capsys
):
    """``--video FRAMES/cam2 --cameras FRAMES/cameras.json`` had been taken for the folder of
    every camera and camera 0's video tracked in its place, without a word (without
    ``--cameras``: "no camera file" in the frames' folder). A folder of image frames is one
    camera's video, the camera whose ``video`` names it, as a video file is."""
    folder = _frame_folders(real_video, tmp_path / "frames")
    cam2 = str(folder / "cam2")
    for cameras in (["--cameras", str(folder / "cameras.json")], []):
        main(["track", "--video", cam2, "--method", "monocular", "--max-frames", "3", "--json",
              *cameras])  # fmt: skip
        assert json.loads(capsys.readouterr().out)["camera"] == "cam2", cameras
    main(["dualhmm", "respond", "--model", str(partner_models["heading"]), "--video", cam2,
          "--cameras", str(folder / "cameras.json"), "--method", "monocular", "--max-frames",
          "3", "--out", str(tmp_path / "c.mp4")])  # fmt: skip
    assert "3 frames in camera 2 " in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:  # one camera's frames: not every camera's
        main(["track", "--video", cam2, "--method", "triangulate"])
    assert exc.value.code == 2
    assert "needs the folder of every camera" in capsys.readouterr().err


def test_an_output_that_cannot_be_written_is_refused_before_the_tracking(
    real_video, partner_models, tmp_path, capsys, monkeypatch
):
    """``--out /sys/a.c3d`` (or a folder, or a path under a file) had been found after all
    the tracking (11 s); ``dualhmm respond --video --out /sys/c.mp4`` then printed FFmpeg's
    lines and its command around "Broken pipe", and an existing folder as ``--out`` was
    named by the temporary file. Now one line naming the output, exit 2, before any
    tracking; the mp4 writer and ``atomic_write`` name it too."""
    import markovmotion.video.composite as composite
    import markovmotion.video.monocular as monocular
    import markovmotion.video.multiview as multiview
    import markovmotion.video.triangulation as triangulation
    from markovmotion.io.files import atomic_write
    from markovmotion.viz.video import write_mp4

    def never(*args, **kwargs):
        raise AssertionError("tracked before the output was checked")

    for module, name in ((monocular, "track_monocular_video"), (monocular, "track_monocular"),
                         (triangulation, "track_triangulated_video"), (multiview, "track_take"),
                         (composite, "track_take")):  # fmt: skip
        monkeypatch.setattr(module, name, never)
    (tmp_path / "a_folder.c3d").mkdir()
    (tmp_path / "a_folder.mp4").mkdir()
    (tmp_path / "a_file").write_text("")
    video = str(real_video / "cam0.mp4")
    cases = [
        (["track", "--video", video, "--method", "monocular"], "/proc/a.c3d",
         "cannot write into the folder /proc"),
        (["track", "--video", str(real_video), "--method", "triangulate"],
         str(tmp_path / "a_folder.c3d"), "is a folder"),
        (["track", "--video", video], str(tmp_path / "a_file" / "x" / "a.bvh"),
         f"cannot write: {tmp_path / 'a_file'} is a file, not a folder"),
        (["dualhmm", "respond", "--model", str(partner_models["heading"]), "--video", video,
          "--method", "monocular"], "/sys/c.mp4", "cannot write into the folder /sys"),
        (["dualhmm", "respond", "--model", str(partner_models["heading"]), "--video", video],
         str(tmp_path / "a_folder.mp4"), "is a folder"),
    ]  # fmt: skip
    for args, out, said in cases:
        with pytest.raises(SystemExit) as exc:
            main([*args, "--out", out])
        assert exc.value.code == 2, args
        err = capsys.readouterr().err
        lines = [line for line in err.splitlines() if not line.startswith("note:")]
        assert len(lines) == 1 and lines[0].startswith(f"error: {out}: {said}"), err
        assert ".tmp" not in err and "Traceback" not in err
    frame = np.zeros((16, 16, 3), np.uint8)
    with pytest.raises(OSError, match="cannot write into the folder /sys") as exc:
        write_mp4([frame] * 3, "/sys/c.mp4", 10.0)
    assert exc.value.filename == "/sys/c.mp4"
    with pytest.raises(IsADirectoryError, match="is a folder") as exc:
        with atomic_write(tmp_path / "a_folder.c3d") as fh:
            fh.write("x")
    assert exc.value.filename == str(tmp_path / "a_folder.c3d")
    assert [p.name for p in tmp_path.iterdir() if ".tmp" in p.name] == []


def test_respond_composites_into_any_camera_of_six(real_copy, partner_models, tmp_path, capsys):
    """``--view`` had stopped at 3 though a camera file holds up to 6 cameras (MAX_CAMERAS):
    camera 4 of five is taken, and named by its name as well as its number."""
    from markovmotion.defaults import MAX_CAMERAS

    doc = json.loads((real_copy / "cameras.json").read_text(encoding="utf-8"))
    doc["cameras"].append({**doc["cameras"][3], "name": "side", "video": "cam4.mp4"})
    (real_copy / "cameras.json").write_text(json.dumps(doc), encoding="utf-8")
    (real_copy / "cam4.mp4").symlink_to((real_copy / "cam3.mp4").resolve())
    main(["dualhmm", "respond", "--model", str(partner_models["heading"]), "--video",
          str(real_copy), "--method", "monocular", "--view", "4", "--max-frames", "3",
          "--out", str(tmp_path / "c.mp4")])  # fmt: skip
    assert "tracked A over 3 frames in camera 4 (side) (3 placed" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        main(["dualhmm", "respond", "--model", str(partner_models["heading"]), "--video",
              str(real_copy), "--view", str(MAX_CAMERAS), "--out", str(tmp_path / "c.mp4")])  # fmt: skip
    assert exc.value.code == 2
    assert f"from 0 to {MAX_CAMERAS - 1}, got {MAX_CAMERAS}" in capsys.readouterr().err


@pytest.mark.parametrize("frame", ["heading", "world"])
def test_serve_says_a_partner_placing_b_by_its_rooms_axes(
    partner_models, tmp_path, capsys, monkeypatch, frame
):
    """``serve --partner`` with a dual HMM of frame 'world' (as ``--frame auto`` may pick)
    had said nothing at start-up, where ``dualhmm respond --video`` says it places B along
    its capture room's axes: the same note now (the server itself stubbed out)."""
    import markovmotion.web.server as server

    class Stopped:
        def run(self, sockets):
            return None

    monkeypatch.setattr(server, "uvicorn_server", lambda app: Stopped())
    (tmp_path / "lib").mkdir()
    main(["serve", "--library", str(tmp_path / "lib"), "--port", "0", "--partner",
          str(partner_models[frame])])  # fmt: skip
    err = capsys.readouterr().err
    said = f"{partner_models[frame]} places B along its capture room's axes from A"
    assert (said in err) == (frame == "world"), err
    assert ("train it with --frame heading" in err) == (frame == "world")


def test_composite_hides_the_partner_behind_the_person_and_not_where_none_is_found():
    from markovmotion.core.motion import Motion
    from markovmotion.features.body_points import POINT_SKELETON
    from markovmotion.video.composite import composite_frames

    rest = Motion.from_rotations(POINT_SKELETON, np.tile([0.0, 0, 0, 1], (1, 19, 1)))
    body = rest.positions()[0]
    cam = look_at(np.array([0.0, 1000.0, 4000.0]), np.array([0, 900, 0]), 160, 120, 150.0)
    frame = np.full((120, 160, 3), 30, np.uint8)
    b = np.array([body + [0, 0, -800.0]] * 3)  # B behind A, seen through the same pixels
    a = np.array([body + [0, 0, 300.0], body + [0, 0, -1600.0], np.full_like(body, np.nan)])
    drawn = [
        (np.abs(f.astype(int) - frame).max(axis=2) > 10).sum()
        for f in composite_frames(iter([frame] * 3), cam, a, b)
    ]
    assert drawn[0] < drawn[1] / 3  # A in front hides most of B
    assert drawn[1] == drawn[2] > 0  # A behind B, or not found: all of B


def test_the_webcam_trackers_causal_left_right_is_the_offline_one_on_real_camera_1(
    real_video, needs_mediapipe
):
    """MediaPipe swaps the man's sides in camera 1 (a second person behind him): the webcam
    tracker's causal relabelling, frame by frame as the camera page runs it, undoes the
    swaps as the offline decoder does over the whole video."""
    from markovmotion.video.left_right import consistent_sides
    from markovmotion.video.monocular import detect_landmarks
    from markovmotion.video.webcam import FoundLandmarks, WebcamTracker

    lm = detect_landmarks(read_frames(real_video / "cam1.mp4"))
    offline, _, _, swapped = consistent_sides(lm.pixels, lm.world, lm.visibility)
    assert swapped.any(axis=1).sum() >= 10  # MediaPipe's labels do jump here
    with WebcamTracker(graphs=1) as live, WebcamTracker(graphs=1, left_right="mediapipe") as raw:
        for t in np.nonzero(lm.found)[0]:
            found = FoundLandmarks(lm.pixels[t], lm.world[t], lm.visibility[t], (272, 480), 0.0)
            got, kept = live.place(found), raw.place(found)
            if got is not None:
                np.testing.assert_allclose(got.pixels, offline[t])
                assert np.allclose(kept.pixels, lm.pixels[t])


def test_a_person_small_in_the_image_is_said():
    """One camera at half size (the person 80-95 px tall) was 336 mm from the reference
    against 148 at full size (160-190 px) without a word: the summary gives the person's
    height in pixels and a note below :data:`SMALL_PERSON_PX`."""
    from markovmotion.video.monocular import SMALL_PERSON_PX, person_pixels, small_person_note

    pixels = np.full((4, 33, 2), np.nan)
    pixels[:3, :, 1] = np.linspace(100.0, 190.0, 33)  # 90 px tall in three frames
    assert person_pixels(pixels) == pytest.approx(90.0)
    assert person_pixels(np.full((2, 33, 2), np.nan)) is None
    (line,) = small_person_note(90.0, "cam0")
    assert "90 px tall in cam0's image" in line
    assert small_person_note(SMALL_PERSON_PX, "cam0") == small_person_note(None, "cam0") == []


def test_a_small_frame_is_shown_to_mediapipe_enlarged_and_answered_in_its_own_pixels(
    real_video,
):
    """``frame_landmarks`` shows MediaPipe a frame whose longer side is under
    ``MEDIAPIPE_SIDE`` enlarged to it (bicubic), and gives the landmarks in the frame's own
    pixels: the real camera 0 (272x480) answers as that frame enlarged by hand to 544x960
    does, its pixels halved (pixel centres at integers); a frame already that large is not
    resized."""
    import cv2

    from markovmotion.video.monocular import MEDIAPIPE_SIDE, frame_landmarks, pose_estimator

    rgb = next(iter(read_frames(real_video / "cam0.mp4")))
    h, w = rgb.shape[:2]
    assert max(h, w) * 2 == MEDIAPIPE_SIDE
    big = cv2.resize(rgb, (2 * w, 2 * h), interpolation=cv2.INTER_CUBIC)
    with pose_estimator(static=True) as est:
        small_px, small_world, small_vis = frame_landmarks(est, rgb)
    with pose_estimator(static=True) as est:
        big_px, big_world, big_vis = frame_landmarks(est, big)
    np.testing.assert_allclose(small_px, (big_px + 0.5) / 2 - 0.5, atol=1e-3)
    np.testing.assert_allclose(small_world, big_world, atol=1e-3)
    np.testing.assert_allclose(small_vis, big_vis, atol=1e-6)
    # the person where MediaPipe saw him in the frame's own pixels: inside the frame
    assert (small_px[small_vis > 0.5] >= 0).all() and (small_px[small_vis > 0.5, 0] < w).all()
