"""Multi-view video, calibrated cameras and the annealed particle filter tracker (dual-HMM §3)."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from markovmotion import read_motion
from markovmotion.cli import main
from markovmotion.errors import MotionFormatError
from markovmotion.features.body_points import BODY_POINTS, body_points
from markovmotion.video.annealed_particle_filter import (
    AnnealedParticleFilter,
    model_coverage,
    survival_beta,
    view_features,
)
from markovmotion.video.body_model import BODY_SHAPE
from markovmotion.video.cameras import load_cameras, look_at, ring_of_cameras, save_cameras
from markovmotion.video.monocular import LANDMARKS
from markovmotion.video.multiview import shaded_frames
from markovmotion.video.render import background, read_frames, silhouette_mask
from markovmotion.video.shading import CLOTHES, DepthCanvas, capsule_colours
from markovmotion.video.sides import SideCheck, SideView


def _cameras(points, views=3, size=(160, 120)):
    centre = points[:, 0].mean(axis=0)
    return ring_of_cameras(centre, 3500.0, views, size)


def test_camera_file_round_trip(tmp_path):
    cams = ring_of_cameras(np.array([100.0, 0.0, -300.0]), 4000.0, 3, (320, 240))
    path = save_cameras(cams, tmp_path / "cameras.json", 30.0, source="x.bvh")
    back, doc = load_cameras(tmp_path)
    assert doc["fps"] == 30.0 and doc["source"] == "x.bvh" and len(back) == 3
    pts = np.random.default_rng(0).normal(0, 500, (50, 3)) + [0, 900, 0]
    for a, b in zip(cams, back, strict=True):
        assert np.allclose(a.project(pts)[0], b.project(pts)[0])
        assert (a.name, a.video, a.width, a.height) == (b.name, b.video, b.width, b.height)
    assert path == tmp_path / "cameras.json"


def test_a_distorted_camera_reads_its_frames_as_its_pinhole_image(tmp_path):
    """Dots drawn where a lens with barrel distortion puts known points (OpenCV's model) are
    read back where the camera's pinhole projection puts them; the distortion survives
    cameras.json; a frame of another size is one error naming the video."""
    import cv2

    from markovmotion.video.render import read_frames, write_video

    (cam,) = ring_of_cameras(np.zeros(3), 3000.0, 1, (320, 240))
    dist = [-0.25, 0.08, 0.001, -0.002, 0.0]
    grid = [(u, v) for u in (30, 110, 210, 290) for v in (25, 120, 215)]  # out to the corners
    pts = np.array([cam.centre + 3000.0 * cam.ray(np.array(p, float)) for p in grid])
    seen, _ = cv2.projectPoints(pts, cv2.Rodrigues(cam.R)[0], cam.t, cam.K, np.array(dist))
    frame = np.zeros((240, 320, 3), np.uint8)
    for u, v in seen[:, 0]:
        cv2.circle(
            frame, (round(u * 16), round(v * 16)), 3 * 16, (255, 255, 255), -1, cv2.LINE_AA, 4
        )
    frames = tmp_path / "frames"
    write_video([frame, frame], frames, 25.0)  # PNG frames: lossless
    save_cameras([replace(cam, distortion=tuple(dist))], tmp_path / "cameras.json", 25.0)
    (back,), _ = load_cameras(tmp_path)
    assert back.distortion == pytest.approx(dist)
    got = next(read_frames(frames, back))[..., 0].astype(float)
    pinhole, _ = cam.project(pts)
    moved = np.linalg.norm(seen[:, 0] - pinhole, axis=1)
    assert moved.max() > 8  # the lens moves the dots, by up to this many pixels
    for (u, v), d in zip(pinhole, moved, strict=True):  # each dot's centre, back where it belongs
        x0, y0 = int(u) - 8, int(v) - 8
        patch = got[y0 : y0 + 17, x0 : x0 + 17]
        ys, xs = np.mgrid[y0 : y0 + 17, x0 : x0 + 17]
        centre = np.array([(xs * patch).sum(), (ys * patch).sum()]) / patch.sum()
        assert np.linalg.norm(centre - [u, v]) < 0.5, d
    small = tmp_path / "small"
    write_video([frame[:200]], small, 25.0)
    with pytest.raises(
        MotionFormatError, match="camera cam0 is 320x240 but frame 0 of its video is 320x200"
    ):
        next(read_frames(small, back))


def test_camera_looks_at_its_target():
    cam = look_at(np.array([0.0, 1500.0, -4000.0]), np.array([0.0, 900.0, 0.0]), 320, 240, 300.0)
    pix, depth = cam.project(np.array([[0.0, 900.0, 0.0], [0.0, 1900.0, 0.0]]))
    assert np.allclose(pix[0], [160, 120]) and depth[0] > 0
    assert pix[1, 1] < pix[0, 1]  # up in the world is up in the image


@pytest.mark.parametrize(
    "edit, problem",
    [
        (lambda d: d.update(cameras=3), "'cameras' must be a list"),
        (lambda d: d["cameras"][0].update(K=[[1, 0], [0, 1]]), "K must be"),
        (lambda d: d["cameras"][0].update(R=[[2, 0, 0], [0, 1, 0], [0, 0, 1]]), "not a rotation"),
        (lambda d: d["cameras"][0].update(distortion=[0.1, 0, 0]), "distortion must be a list"),
        (lambda d: d["cameras"][0].update(distortion=[0.1, 0, 0, "x"]), "distortion must be"),
        (lambda d: d["cameras"][0].update(distortion=[1e9, 0, 0, 0, 0]), "beyond"),
        (lambda d: d["cameras"][0].update(width=-5), "width and height"),
        (lambda d: d["cameras"][0].update(t=["a", 0, 0]), ".t must be"),
    ],
)
def test_bad_camera_file_is_one_error(tmp_path, edit, problem):
    save_cameras(ring_of_cameras(np.zeros(3), 4000.0, 1), tmp_path / "cameras.json", 25.0)
    doc = json.loads((tmp_path / "cameras.json").read_text())
    edit(doc)
    (tmp_path / "cameras.json").write_text(json.dumps(doc))
    with pytest.raises(MotionFormatError, match=problem):
        load_cameras(tmp_path)


def test_body_model_projection_agrees_with_rasterisers(body, take):
    """The tracker's capsule test, the silhouette renderer and the z-buffer agree on the body."""
    motion, _ = take
    pts = body_points(motion)
    cam = _cameras(pts, 1, (320, 240))[0]
    colours = capsule_colours(BODY_SHAPE, [str(i) for i in range(19)], CLOTHES["a"])
    for t in (0, len(pts) // 2):
        tracker = model_coverage(pts[t], cam)
        canvas = silhouette_mask(pts[t], cam, BODY_SHAPE) >= 128
        z = DepthCanvas(cam.width, cam.height, scale=1)
        z.body(pts[t], cam, BODY_SHAPE, colours)
        shaded = z.ident >= 0
        for other in (canvas, shaded):
            iou = (tracker & other).sum() / (tracker | other).sum()
            assert iou > 0.93
        assert tracker.sum() > 300


def test_depth_test_hides_the_farther_body(take):
    motion, _ = take
    p = body_points(motion)[0]
    cam = _cameras(body_points(motion), 1)[0]
    towards = cam.centre - p[0]
    towards[1] = 0
    near = p + 600 * towards / np.linalg.norm(towards)  # the same pose nearer the camera
    grey = np.zeros((19 + 2, 3))
    canvas = DepthCanvas(cam.width, cam.height)
    canvas.body(p, cam, BODY_SHAPE, grey, 0)
    canvas.body(near, cam, BODY_SHAPE, grey + 255, 1)
    behind = DepthCanvas(cam.width, cam.height)
    behind.body(near, cam, BODY_SHAPE, grey + 255, 1)
    behind.body(p, cam, BODY_SHAPE, grey, 0)
    assert (canvas.ident == 1).sum() == (behind.ident == 1).sum() > 0


def test_survival_rate_sets_beta():
    cost = np.random.default_rng(0).uniform(0.1, 0.5, 300)
    for alpha in (0.2, 0.5, 0.8):
        w = np.exp(-survival_beta(cost, alpha) * (cost - cost.min()))
        assert w.sum() ** 2 / (len(w) * (w**2).sum()) == pytest.approx(alpha, abs=0.01)


def test_body_model_rebuilds_capture(body, take):
    """The state of a captured pose rebuilds it closely, within the joint limits."""
    motion, _ = take
    x = body.states_of(motion)
    err = np.linalg.norm(body.joint_positions(x) - body_points(motion), axis=-1).mean()
    assert err < 40.0
    assert 24 <= body.n_dof <= 31
    inside = (x >= body.lower - 1e-9) & (x <= body.upper + 1e-9)
    assert inside.mean() > 0.97


def test_tracker_converges_on_a_known_pose(body, take):
    """Rendered from three cameras, the tracker finds a captured pose from a standing start."""
    motion, _ = take
    pts = body_points(motion)[:4]
    cams = _cameras(pts, 3, (240, 180))
    bgs = [background((c.width, c.height), k) for k, c in enumerate(cams)]
    videos = [
        list(shaded_frames([pts], c, bg, 2.0, k))
        for k, (c, bg) in enumerate(zip(cams, bgs, strict=True))
    ]
    apf = AnnealedParticleFilter(body, cams, particles=150, layers=8, fps=30.0, seed=1)
    errors, costs = [], []
    for t in range(len(pts)):
        feats = view_features([v[t] for v in videos], bgs, t)
        x, best = apf.step(feats)
        errors.append(np.linalg.norm(body.joint_positions(x)[0] - pts[t], axis=-1).mean())
        costs.append(best)
    assert errors[-1] < 120.0, errors
    assert np.mean(errors) < 130.0, errors
    assert all(0.0 <= c < 0.5 for c in costs)


def _sides(points: np.ndarray, cam, swap: bool = False) -> SideCheck:
    """MediaPipe's left and right as an oracle: its shoulders and hips where the true ones
    project (or each side at the other's, ``swap``)."""
    pixels = np.zeros((len(points), len(LANDMARKS), 2))
    vis = np.zeros((len(points), len(LANDMARKS)))
    for side, other in (("left", "right"), ("right", "left")):
        for part in ("shoulder", "hip"):
            k = LANDMARKS.index(f"{other if swap else side}_{part}")
            pixels[:, k] = cam.project(points[:, BODY_POINTS.index(f"{side}_{part}")])[0]
            vis[:, k] = 1.0
    return SideCheck([SideView(cam, pixels, vis)])


def _turned_round(points: np.ndarray) -> np.ndarray:
    """Body points (19, 3) turned by pi about the vertical through the pelvis."""
    out = points.copy()
    out[:, [0, 2]] = 2 * points[0, [0, 2]] - points[:, [0, 2]]
    return out


def test_side_check_tells_a_body_turned_round(take):
    motion, _ = take
    pts = body_points(motion)[:2]
    check = _sides(pts, _cameras(pts, 3)[1])  # camera 0 sees him edge on
    assert check.evidence(pts[0], 0) < -1.0 and not check.flipped(pts[0], 0)
    assert check.flipped(_turned_round(pts[0]), 0)
    assert check.evidence(pts[0], 2) is None  # no landmarks for that frame: cannot tell


def test_a_flip_is_searched_again_or_lowers_the_confidence(body, take):
    """Started turned round, the tracker keeps the flip without the side check; with it, the
    flip is found and searched again from the pose turned round; a flip it cannot undo costs
    the frame ``flip_cost``."""
    motion, _ = take
    pts = body_points(motion)[:2]
    cams = _cameras(pts, 3, (240, 180))
    bgs = [background((c.width, c.height), k) for k, c in enumerate(cams)]
    videos = [list(shaded_frames([pts], c, bg, 2.0, k)) for k, (c, bg) in enumerate(zip(cams, bgs, strict=True))]  # fmt: skip
    truth = body.states_of(motion.trim(0, 1))[0]
    flipped = truth.copy()
    flipped[3] += np.pi

    def run(sides):
        apf = AnnealedParticleFilter(
            body, cams, 100, 6, fps=30.0, seed=2, start=flipped, sides=sides
        )
        out = [apf.step(view_features([v[t] for v in videos], bgs, t)) for t in range(len(pts))]
        turn = abs(np.angle(np.exp(1j * (out[-1][0][3] - truth[3]))))
        return apf, turn, [best for _, best in out]

    plain, turn_plain, _ = run(None)
    checked, turn_checked, _ = run(_sides(pts, cams[1]))
    assert turn_plain > 2.0 and plain.flips == 0
    assert checked.flips >= 1 and turn_checked < 1.0 and checked.flipped == 0
    always = _sides(pts, cams[1])
    always.flipped = lambda points, frame: True  # a flip no search undoes
    stuck, _, costs = run(always)
    assert stuck.flips == stuck.flipped == len(pts)
    assert min(costs) >= stuck.flip_cost


@pytest.fixture(scope="module")
def rendered(tmp_path_factory, take):
    """Two cameras, 0.1 s of the held-out take at 30 fps, 96x72, by the command line."""
    _, path = take
    out = tmp_path_factory.mktemp("video") / "take"
    main(["video", "render", str(path), "--out", str(out), "--views", "2", "--seconds", "0.1",
          "--fps", "30", "--width", "96", "--height", "72"])  # fmt: skip
    return out


def test_video_render_writes_videos_and_cameras(rendered):
    cams, doc = load_cameras(rendered)
    assert len(cams) == 2 and doc["fps"] == 30.0 and doc["people"] == "a"
    assert all((rendered / c.video).is_file() and (rendered / c.background).is_file() for c in cams)
    assert all((c.width, c.height) == (96, 72) for c in cams)


def test_track_command_reports_error_against_truth(rendered, take, tmp_path, capsys):
    _, path = take
    capsys.readouterr()
    main(["track", "--video", str(rendered), "--truth", str(path), "--json",
          "--body-model", "interaction", "--particles", "20", "--layers", "2",
          "--out", str(tmp_path / "a.bvh")])  # fmt: skip
    summary = json.loads(capsys.readouterr().out)
    assert summary["views"] == 2 and summary["frames"] == 3
    assert {"mpjpe_mm", "per_joint_mm", "fps", "confidence"} <= summary.keys()
    assert summary["mpjpe_mm"] > 0 and len(summary["per_joint_mm"]) == 19
    tracked = read_motion(tmp_path / "a.bvh")
    assert tracked.n_frames == 3 and body_points(tracked).shape == (3, 19, 3)


def test_cameras_without_a_background_image_are_one_note(take, tmp_path, capsys):
    """Two of three cameras without an empty-scene image: the note on their backgrounds is
    one line naming them, printed once (it had been printed per camera), and the JSON's
    ``background`` holds that line."""
    folder = tmp_path / "take"
    main(["video", "render", str(take[1]), "--out", str(folder), "--views", "3", "--seconds",
          "0.1", "--fps", "30", "--width", "96", "--height", "72"])  # fmt: skip
    doc = json.loads((folder / "cameras.json").read_text())
    for cam in doc["cameras"][1:]:  # cam0 keeps its plate: someone is seen in the video
        (folder / cam.pop("background")).unlink()
    (folder / "cameras.json").write_text(json.dumps(doc))
    capsys.readouterr()
    main(["track", "--video", str(folder), "--json", "--body-model", "interaction",
          "--particles", "10", "--layers", "1", "--max-frames", "2", "--background", "median",
          "--out", str(tmp_path / "a.bvh")])  # fmt: skip
    run = capsys.readouterr()
    said = "note: cam1, cam2: median background (no empty-scene image), not checked for the person"
    assert json.loads(run.out)["background"] == [said]
    assert run.err.count("median background") == 1 and f"{said}\n" in run.err, run.err


def test_the_camera_file_is_read_once_per_command(
    rendered, take, body, dual_model, tmp_path, monkeypatch
):
    """``track`` (the method's choice, the filter, ``--truth`` before and after the tracking)
    and ``dualhmm respond --video`` read and check the camera file once, and hand what they
    read to every reader (it had been read five and two times); so does ``track_take`` given
    the file's path."""
    import markovmotion.video.cameras as cameras
    from markovmotion.video.multiview import track_take

    reads = []
    read = cameras.read_cameras

    def counted(path):
        reads.append(path)
        return read(path)

    monkeypatch.setattr(cameras, "read_cameras", counted)
    small = ["--body-model", "interaction", "--particles", "10", "--layers", "1"]
    main(["track", "--video", str(rendered), "--truth", str(take[1]), *small,
          "--out", str(tmp_path / "a.bvh")])  # fmt: skip
    assert len(reads) == 1
    main(["dualhmm", "respond", "--model", str(dual_model), "--video", str(rendered),
          "--method", "apf", *small, "--out", str(tmp_path / "c.mp4")])  # fmt: skip
    assert len(reads) == 2
    summary = track_take(rendered, body, rendered / "cameras.json", take[1], 10, 1)[2]
    assert len(reads) == 3 and "mpjpe_mm" in summary


def test_seed_changes_the_draw_and_the_same_seed_repeats_it(rendered, tmp_path):
    """The tracker's random draws come from ``--seed``: two seeds give two tracks, one seed
    the same track twice (issue 24: seeds 0 and 1 once gave byte-identical files)."""
    tracks = {}
    for name, seed in (("a", 0), ("b", 0), ("c", 1)):
        out = tmp_path / f"{name}.bvh"
        main(["track", "--video", str(rendered), "--body-model", "interaction",
              "--particles", "20", "--layers", "2", "--seed", str(seed),
              "--out", str(out)])  # fmt: skip
        tracks[name] = body_points(read_motion(out))
    assert np.array_equal(tracks["a"], tracks["b"])
    assert np.abs(tracks["a"] - tracks["c"]).max() > 1.0


@pytest.fixture(scope="module")
def dual_model(mocap, tmp_path_factory):
    """A small dual HMM on the training handshake and pull takes (A's skeleton: the template's)."""
    from markovmotion.data.splits import held_out_pairs
    from markovmotion.models.hmm.dual import DualHMM

    train, _ = held_out_pairs(mocap.pairs(label=["handshake", "pull"], kind="skeleton"))
    pairs = [mocap.load_pair(a, b) for a, b in train]
    model = DualHMM(n_states=4, n_iter=3, window=4, placement_window=3).fit(pairs)
    path = tmp_path_factory.mktemp("model") / "dual.npz"
    model.save(path)
    return path


@pytest.mark.parametrize("live", [False, True])
def test_respond_draws_the_partner_into_the_video(rendered, dual_model, tmp_path, capsys, live):
    out = tmp_path / "composite.mp4"
    args = ["dualhmm", "respond", "--model", str(dual_model), "--video", str(rendered),
            "--out", str(out), "--body-model", "interaction", "--particles", "20",
            "--layers", "2", "--view", "1"]  # fmt: skip
    main(args + (["--realtime"] if live else []))
    frames = list(read_frames(out))
    original = list(read_frames(rendered / "cam1.mp4"))
    assert len(frames) == len(original) == 3
    assert frames[0].shape == original[0].shape
    changed = [
        np.abs(f.astype(int) - o).max(axis=2) > 60 for f, o in zip(frames, original, strict=True)
    ]
    assert sum(c.sum() for c in changed) > 0  # the partner is drawn somewhere
    err = capsys.readouterr().err
    assert ("skipped" in err) == live


def test_respond_passes_the_guide_to_the_tracker(rendered, dual_model, tmp_path, monkeypatch):
    """``dualhmm respond --video DIR --guide mediapipe``: A is tracked with MediaPipe's guide
    (what ``track --guide`` does; the tracker itself is tested in test_triangulation)."""
    import inspect

    import markovmotion.video.composite as composite
    import markovmotion.video.multiview as multiview

    seen = []

    class Tracked(Exception):
        pass

    def spy(*args, **kwargs):
        seen.append(kwargs.get("guide"))
        # the background learnt, as track's default (--background learn) and track_take's
        default = inspect.signature(multiview.track_take).parameters["learn_background"].default
        assert kwargs.get("learn_background", default)
        raise Tracked

    monkeypatch.setattr(composite, "track_take", spy)
    args = ["dualhmm", "respond", "--model", str(dual_model), "--video", str(rendered),
            "--out", str(tmp_path / "c.mp4"), "--body-model", "interaction"]  # fmt: skip
    for extra in ([], ["--guide", "mediapipe"]):
        with pytest.raises(Tracked):
            main(args + extra)
    assert seen == [False, True]  # a rendered video: the default (auto) leaves it unguided


def test_respond_passes_the_person_named_to_the_tracker(
    rendered, dual_model, tmp_path, monkeypatch, capsys
):
    """``dualhmm respond --video DIR --guide mediapipe --person CAM:U,V``: the person reaches
    the tracker; without the guide, or without --video, it is one line."""
    import markovmotion.video.composite as composite

    seen = []

    class Tracked(Exception):
        pass

    def spy(*args, **kwargs):
        seen.append(kwargs.get("person"))
        raise Tracked

    monkeypatch.setattr(composite, "track_take", spy)
    args = ["dualhmm", "respond", "--model", str(dual_model), "--video", str(rendered),
            "--out", str(tmp_path / "c.mp4"), "--person", "0:10,10"]  # fmt: skip
    with pytest.raises(Tracked):
        main([*args, "--guide", "mediapipe"])
    assert seen == ["0:10,10"]
    capsys.readouterr()
    for extra in (["--method", "apf"], ["--realtime"]):  # the filter unguided (rendered video)
        with pytest.raises(SystemExit) as exc:
            main(args + extra)
        assert exc.value.code == 2
        err = capsys.readouterr().err.strip()
        assert "--person" in err and len(err.splitlines()) == 1
    with pytest.raises(SystemExit) as exc:
        main(["dualhmm", "respond", "--model", str(dual_model), "--input", str(rendered),
              "--out", str(tmp_path / "b.bvh"), "--person", "0:10,10"])  # fmt: skip
    assert exc.value.code == 2 and "--person" in capsys.readouterr().err


def test_one_view_is_said_once_after_the_work(dual_model, tmp_path, monkeypatch, capsys):
    """The particle filter on one view of real video: one note says what one view leaves it,
    printed once (``--guide auto``'s note and track's own had both been printed, each offering
    --method monocular), and after the work (``respond --video`` had printed it before)."""
    import markovmotion.video.composite as composite
    from markovmotion.data.index import data_root
    from markovmotion.video.multiview import ONE_VIEW_NOTE

    real = data_root().parent / "video" / "pose2sim_balancing"
    small = ["--particles", "10", "--layers", "1", "--max-frames", "2"]
    for video, extra in (
        (real, ["--views", "1"]),
        (real / "cam1.mp4", []),
        (real / "cam1.mp4", ["--guide", "none"]),
    ):
        capsys.readouterr()
        main(["track", "--video", str(video), *extra, *small, "--out", str(tmp_path / "a.bvh")])
        err = capsys.readouterr().err
        assert err.count("one view") == 1 and err.count("--method monocular") == 1, err
        assert f"{ONE_VIEW_NOTE}\n" in err, err

    track_take = composite.track_take

    def after(*args, **kwargs):  # nothing said of one view before the tracking
        assert "one view" not in capsys.readouterr().err
        return track_take(*args, **kwargs)

    monkeypatch.setattr(composite, "track_take", after)
    main(["dualhmm", "respond", "--model", str(dual_model), "--video", str(real / "cam1.mp4"),
          "--method", "apf", *small, "--out", str(tmp_path / "c.mp4")])  # fmt: skip
    err = capsys.readouterr().err
    assert err.count("one view") == 1 and f"{ONE_VIEW_NOTE}\n" in err, err


@pytest.mark.parametrize(
    "extra",
    [["--guide", "mediapipe", "--realtime"], ["--guide", "mediapipe", "--method", "monocular"]],
)
def test_respond_guide_only_with_the_whole_video_filter(
    rendered, dual_model, tmp_path, capsys, extra
):
    with pytest.raises(SystemExit) as exc:
        main(["dualhmm", "respond", "--model", str(dual_model), "--video", str(rendered),
              "--out", str(tmp_path / "c.mp4"), *extra])  # fmt: skip
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip()
    assert "--guide" in err and len(err.splitlines()) == 1


def test_respond_needs_one_source_of_a(dual_model, tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["dualhmm", "respond", "--model", str(dual_model), "--out", str(tmp_path / "c.mp4")])
    assert exc.value.code == 2
    assert "--input" in capsys.readouterr().err


def test_missing_or_bad_camera_file_exits_2(tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    with pytest.raises(SystemExit) as exc:
        main(["track", "--video", str(tmp_path / "empty")])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "cameras.json" in err and len(err.strip().splitlines()) == 1
    (tmp_path / "bad").mkdir()
    (tmp_path / "bad" / "cameras.json").write_text("{not json")
    with pytest.raises(SystemExit) as exc:
        main(["track", "--video", str(tmp_path / "bad")])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "not a JSON camera file" in err and len(err.strip().splitlines()) == 1


def test_lone_video_uses_its_camera(rendered, tmp_path, capsys):
    """One camera's video is tracked with the camera naming it; without a camera file: exit 2."""
    capsys.readouterr()
    main(["track", "--video", str(rendered / "cam1.mp4"), "--json", "--body-model", "interaction",
          "--particles", "10", "--layers", "1", "--max-frames", "1"])  # fmt: skip
    assert json.loads(capsys.readouterr().out)["views"] == 1
    lone = tmp_path / "lone.mp4"
    lone.write_bytes((rendered / "cam1.mp4").read_bytes())
    with pytest.raises(SystemExit) as exc:
        main(["track", "--video", str(lone)])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "no camera file" in err and len(err.strip().splitlines()) == 1


def test_given_start_pose_must_be_on_the_body_models_skeleton(rendered, mocap, capsys):
    salsa = mocap.root / mocap.pairs(label="salsa")[0][0].file
    with pytest.raises(SystemExit) as exc:
        main(["track", "--video", str(rendered), "--start", str(salsa), "--max-frames", "1"])
    assert exc.value.code == 2
    assert "not the body model's skeleton" in capsys.readouterr().err


def test_demo_video_step_composites_the_partner_into_the_handshake(mocap, tmp_path):
    """``markovmotion demo``'s video step: 2 s of the handshake rendered, A tracked, B put
    into camera 0's video: an MP4 of 60 frames that moves."""
    import cv2
    from rich.console import Console

    from markovmotion.video.demo import video_partner

    (path,) = video_partner(tmp_path, mocap, Console(quiet=True))
    cap = cv2.VideoCapture(str(path))
    frames = []
    ok, frame = cap.read()
    while ok:
        frames.append(frame)
        ok, frame = cap.read()
    assert len(frames) == 60 and not np.array_equal(frames[0], frames[-1])


def test_the_partner_has_a_frame_for_every_video_frame():
    """100 video frames at 60 fps are 50 partner frames at 30, which span 99 at 60: the last
    partner frame is held over the last video frame (it was left without a partner)."""
    from markovmotion.core.markers import Markers
    from markovmotion.video.composite import at_video_rate

    pos = np.arange(50, dtype=float)[:, None, None] * np.ones((1, 2, 3))
    b = at_video_rate(Markers(["P", "Q"], pos, 30.0, "B"), 60.0, 100)
    assert b.n_frames == 100 and b.fps == 60.0
    np.testing.assert_allclose(b.positions[:99, 0, 0], np.arange(99) / 2)
    np.testing.assert_allclose(b.positions[99], b.positions[98])
    same = at_video_rate(Markers(["P", "Q"], pos, 30.0, "B"), 30.0, 50)
    np.testing.assert_array_equal(same.positions, pos)


def test_respond_live_to_a_video_with_no_one_says_so(dual_model, tmp_path, capsys):
    """``respond --video --realtime`` on the empty scene (each camera's plate as a video):
    one line, as the whole video's tracking says it, and no composite of a partner answering
    no one (it tracked 3 of 40 frames and wrote one, exit 0)."""
    from conftest import empty_scene

    empty_scene(tmp_path, 6)
    out = tmp_path / "composite.mp4"
    with pytest.raises(SystemExit) as exit_:
        main(["dualhmm", "respond", "--model", str(dual_model), "--video", str(tmp_path),
              "--out", str(out), "--realtime", "--particles", "20", "--layers", "2"])  # fmt: skip
    assert exit_.value.code == 2
    assert "no person found in this video" in capsys.readouterr().err
    assert not out.exists()


def test_a_partner_outside_the_cameras_image_is_said_and_the_best_camera_named():
    """B standing beside one camera's field (the demo's 320x240 video cut B at its left edge
    in 53 of 60 frames): a note names the share of frames and the camera that shows B whole;
    B in view gives none."""
    from markovmotion.core.markers import Markers
    from markovmotion.video.composite import framing_notes, shown_share

    cams = ring_of_cameras(np.zeros(3), 3000.0, views=2, size=(320, 240))
    rest = np.array([[0, 1100, 0], [0, 1650, 0], [-180, 1400, 0], [180, 1400, 0.0]])
    names = ("TORSO", "HEAD", "R_SHOULDER", "L_SHOULDER")
    inside = Markers(names, np.repeat(rest[None], 20, axis=0), 30.0, "b")
    assert all(shown_share(c, inside.positions) == 1.0 for c in cams)
    assert framing_notes(cams, 0, inside) == []
    # moved far to the side of camera 0's view (along its image's horizontal axis)
    right = cams[0].R[0]  # camera 0's x axis in the world
    away = inside.positions + 2500.0 * right
    away[:5] = inside.positions[:5]  # in view for a quarter of the frames
    beside = Markers(names, away, 30.0, "b")
    share0, share1 = shown_share(cams[0], away), shown_share(cams[1], away)
    assert share0 == pytest.approx(0.25)
    (note,) = framing_notes(cams, 0, beside)
    assert "outside camera 0" in note and "75%" in note
    if share1 > share0:
        assert "--view 1" in note


def test_a_composite_says_which_figure_is_the_virtual_partner():
    """Every composite frame carries a caption naming B and its model (it said nothing of who
    is real and who is generated); without one, a frame passes unchanged."""
    from markovmotion.video.composite import partner_caption, with_caption

    frame = np.full((240, 320, 3), 200, np.uint8)
    np.testing.assert_array_equal(with_caption(frame, ""), frame)
    shown = with_caption(frame, partner_caption("models/shake.npz"))
    assert partner_caption("models/shake.npz") == "red: virtual partner (shake.npz)"
    changed = np.abs(shown.astype(int) - frame).max(axis=2) > 0
    assert changed[:20, :150].mean() > 0.5 and not changed[40:].any()  # top left only


def test_a_track_that_keeps_starting_again_is_said_to_be_doubtful():
    """A rendered two-person video tracked unguided restarted the search in 71 of 90 frames
    and was 1750 mm from the capture without a word (a new user's trial): more than a fifth
    of the frames restarted gets a note, which offers what the filter did not already use."""
    from markovmotion.video.multiview import RESTARTS_NOTED, restarts_note

    assert restarts_note(0, 100) == [] and restarts_note(int(RESTARTS_NOTED * 100), 100) == []
    assert restarts_note(3, 0) == []
    (line,) = restarts_note(71, 90)
    assert line.startswith("note: the filter started its search again in 71 of 90 frames")
    assert "--guide mediapipe" in line
    (guided,) = restarts_note(71, 90, guided=True)
    assert "--guide" not in guided and "--method triangulate" in guided
