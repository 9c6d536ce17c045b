"""MediaPipe in every view: robust triangulation (``track --method triangulate``) and the guide
it gives the annealed particle filter (``track --guide mediapipe``)."""

from __future__ import annotations

import itertools
import json
import shutil

import numpy as np
import pytest
from scipy.optimize import least_squares

from markovmotion.cli import main
from markovmotion.data.index import data_root
from markovmotion.features.body_points import BODY_POINTS, body_points
from markovmotion.video.annealed_particle_filter import AnnealedParticleFilter, view_features
from markovmotion.video.cameras import ring_of_cameras
from markovmotion.video.monocular import LANDMARKS
from markovmotion.video.multiview import shaded_frames
from markovmotion.video.render import background
from markovmotion.video.triangulation import (
    GUIDE_POINTS,
    OUTLIER_ANGLE,
    SMOOTHING_TWO_VIEWS_S,
    Guide,
    ViewLandmarks,
    choose_smoothing,
    fit_state,
    landmarks_to_body_points,
    triangulate_points,
)


def _cameras(views: int = 4, size: tuple[int, int] = (272, 480)):
    return ring_of_cameras(np.array([0.0, 900.0, 0.0]), 3500.0, views, size)


def _project(cams, points: np.ndarray) -> np.ndarray:
    return np.stack([c.project(points)[0] for c in cams])


def test_triangulation_recovers_points_and_agrees_with_brute_force():
    """Exact projections give the points back; noisy ones give what minimising the
    reprojection error by brute force (nonlinear least squares from the truth) gives."""
    rng = np.random.default_rng(0)
    truth = rng.uniform([-600, 0, -600], [600, 1800, 600], (40, 3))
    cams = _cameras(4)
    pix = _project(cams, truth)
    pts, used, worst = triangulate_points(cams, pix, np.ones((4, 40)))
    assert np.allclose(pts, truth, atol=1e-3) and used.all() and worst.max() < 1e-3
    noisy = pix + rng.normal(0, 1.5, pix.shape)
    pts, used, _ = triangulate_points(cams, noisy, np.ones((4, 40)))
    assert used.all()  # 1.5 px of noise is no outlier
    best = np.array(
        [
            least_squares(lambda y, q=q: (_project(cams, y[None])[:, 0] - q).ravel(), x).x
            for x, q in zip(truth, noisy.transpose(1, 0, 2), strict=True)
        ]
    )
    apart = np.linalg.norm(pts - best, axis=1)
    assert apart.max() < 0.1  # mm, at 3.5 m; both about 18 mm from the truth
    # a point seen by one view only cannot be placed
    one = np.zeros((4, 40))
    one[0] = 1.0
    pts, used, _ = triangulate_points(cams, pix, one)
    assert np.isnan(pts).all() and not used.any()


@pytest.mark.parametrize("views", [3, 4])
def test_a_view_with_a_wrong_landmark_is_rejected(views):
    rng = np.random.default_rng(1)
    truth = rng.uniform([-400, 200, -400], [400, 1600, 400], (20, 3))
    cams = _cameras(views)
    pix = _project(cams, truth) + rng.normal(0, 0.5, (views, 20, 2))
    bad = pix.copy()
    bad[1, :, 0] += 60.0  # camera 1 puts every landmark 60 px to the side
    assert 60.0 > 2 * OUTLIER_ANGLE * min(c.focal for c in cams)
    pts, used, worst = triangulate_points(cams, bad, np.ones((views, 20)))
    assert not used[1].any() and used[[v for v in range(views) if v != 1]].all()
    assert np.linalg.norm(pts - truth, axis=1).max() < 30.0
    assert worst.max() < 5.0
    # without the rejection (everything an inlier) the wrong view pulls the points away
    pulled, used, _ = triangulate_points(cams, bad, np.ones((views, 20)), outlier_angle=1e6)
    assert used.all() and np.linalg.norm(pulled - truth, axis=1).mean() > 50.0


def test_body_points_of_landmarks_are_missing_only_where_their_landmarks_are():
    lm = np.random.default_rng(2).normal(0, 300, (len(LANDMARKS), 3))
    lm[LANDMARKS.index("left_wrist")] = np.nan
    pts = landmarks_to_body_points(lm)
    missing = {p for p, row in zip(BODY_POINTS, pts, strict=True) if np.isnan(row).any()}
    assert missing == {"left_wrist"}


def _guide_of(points: np.ndarray, cams, wrong_view: int | None = None) -> Guide:
    """MediaPipe as an oracle: the guide points where the true body points project; in
    ``wrong_view`` every landmark 80 px to the side, with weight 0 (as triangulation drops it)."""
    idx = [BODY_POINTS.index(p) for p in GUIDE_POINTS]
    pix = np.stack([c.project(points[:, idx])[0] for c in cams])  # (V, F, J, 2)
    w = np.ones(pix.shape[:3])
    if wrong_view is not None:
        pix[wrong_view, ..., 0] += 80.0
        w[wrong_view] = 0.0
    return Guide(list(cams), pix, w, points=points)


def test_guide_cost_is_least_at_the_truth_and_ignores_dropped_views(body, take):
    pts = body_points(take[0])[:2]
    cams = _cameras(3, (240, 180))
    guide = _guide_of(pts, cams, wrong_view=2)
    moved = pts[0].copy()
    moved[BODY_POINTS.index("left_wrist")] += [300.0, 0.0, 0.0]
    c = guide.cost(np.stack([pts[0], moved]), 0)
    assert c[0] < 1e-9 < c[1] <= 1.0
    assert guide.cost(pts[:1], 5) is None  # no landmarks for that frame: images alone


def test_fitted_state_reaches_the_points_of_a_known_pose(body, take):
    """The body model fitted to a captured pose's points, from the standing pose beside it."""
    truth = body.states_of(take[0].trim(0, 1))[0]
    pts = body.joint_positions(truth)[0]
    start = body.standing(truth[:3] + [80.0, 0.0, 50.0], truth[3] + 0.3)
    x = fit_state(body, pts, start)
    idx = [BODY_POINTS.index(p) for p in GUIDE_POINTS]
    err = np.linalg.norm(body.joint_positions(x)[0, idx] - pts[idx], axis=-1).mean()
    before = np.linalg.norm(body.joint_positions(start)[0, idx] - pts[idx], axis=-1).mean()
    assert err < 25.0 < before
    few = np.full_like(pts, np.nan)
    few[:3] = pts[:3]
    assert fit_state(body, few, start) is None


def test_the_guided_filter_tracks_a_rendered_take_better(body, take):
    """Rendered from three cameras with a small search (60 particles x 3 layers): the filter
    guided by the true joints' projections (a view of them wrong and dropped) ends nearer the
    truth than the same filter unguided, for two seeds."""
    pts = body_points(take[0])[:6]
    cams = _cameras(3, (240, 180))
    bgs = [background((c.width, c.height), k) for k, c in enumerate(cams)]
    videos = [
        list(shaded_frames([pts], c, bg, 2.0, k))
        for k, (c, bg) in enumerate(zip(cams, bgs, strict=True))
    ]
    feats = [view_features([v[t] for v in videos], bgs, t) for t in range(len(pts))]

    def error(guide: Guide | None, seed: int) -> float:
        apf = AnnealedParticleFilter(body, cams, 60, 3, fps=30.0, seed=seed, guide=guide)
        x = np.array([apf.step(f)[0] for f in feats])
        return float(np.linalg.norm(body.joint_positions(x) - pts, axis=-1).mean())

    for seed in (0, 1):
        plain, guided = error(None, seed), error(_guide_of(pts, cams, wrong_view=1), seed)
        assert guided < 0.7 * plain, (seed, plain, guided)


@pytest.fixture(scope="module")
def real_video():
    return data_root().parent / "video" / "pose2sim_balancing"


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--method", "monocular", "--guide", "mediapipe"], "use it with --method apf"),
        (["--guide", "openpose"], "--guide"),
        (["--method", "triangulate", "--stature", "1700"], "--method monocular"),
        (["--method", "triangulate", "--out", "x.bvh"], "use a .c3d name"),
        (["--method", "triangulate", "--left-right", "facing"], "--method monocular"),
        (["--guide", "none", "--left-right", "mediapipe"], "--method monocular"),
        (["--method", "monocular", "--left-right", "both"], "--method triangulate"),
        (["--method", "monocular", "--left-right", "sideways"], "must be one of"),
        (["--method", "monocular", "--sides"], "--method apf"),
        (["--left-right", "facing", "--sides"], "facing is for --method monocular"),
        (["--method", "monocular", "--person", "cam0:10,10"], "--person"),
        (["--guide", "none", "--person", "cam0:10,10"], "--guide mediapipe"),
        (["--method", "triangulate", "--person", "cam7:10,10"], "no camera 'cam7'"),
        (["--method", "triangulate", "--person", "cam0:300,10"], "outside cam0's 272x480"),
        (["--method", "triangulate", "--views", "2", "--person", "cam3:1,1"], "no camera 'cam3'"),
        (["--views", "2", "--person", "cam3:1,1"], "no camera 'cam3'"),
        (["--stature", "1700"], "--method monocular"),
        (["--method", "triangulate", "--truth", "x.bvh"], "no such file (--truth)"),
        (["--truth", "x.bvh"], "no such file (--truth)"),
        (["--truth", "cameras.json"], "the rendered take's motion"),
        (["--guide", "mediapipe", "--views", "1"], "at least 2 views"),
        (["--method", "apf", "--smooth", "0.05"], "--method triangulate or monocular"),
        (["--method", "triangulate", "--smooth", "slow"], "auto or SECONDS"),
        (["--method", "triangulate", "--smooth", "-1"], "auto or SECONDS"),
    ],
)
def test_bad_guide_and_triangulate_options_are_one_line(
    real_video, tmp_path, capsys, extra, message
):
    extra = [str(tmp_path / e) if e.endswith(".bvh") else e for e in extra]
    extra = [str(real_video / e) if e == "cameras.json" else e for e in extra]
    with pytest.raises(SystemExit) as exc:
        main(["track", "--video", str(real_video), *extra])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1 and "Traceback" not in err


def test_triangulate_needs_every_camera(real_video, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["track", "--video", str(real_video / "cam0.mp4"), "--method", "triangulate"])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip()
    assert "every camera" in err and len(err.splitlines()) == 1


def _need_mediapipe() -> None:
    try:
        import mediapipe  # noqa: F401
    except ImportError:
        pytest.fail("these tests need MediaPipe: run scripts/install-camera", pytrace=False)


def test_triangulated_track_of_real_video(real_video, tmp_path, capsys):
    """MediaPipe in the 4 real views, triangulated: every frame placed, views consistent to a
    few pixels, within 110 mm of the reference (itself MediaPipe triangulated at full
    resolution, wrong for one side in frames 42-72) and within 60 mm of it in most frames."""
    _need_mediapipe()
    out = tmp_path / "a.c3d"
    main(["track", "--video", str(real_video), "--method", "triangulate", "--json",
          "--reference", str(real_video / "reference_mediapipe_triangulated_mm.csv"),
          "--out", str(out)])  # fmt: skip
    s = json.loads(capsys.readouterr().out)
    assert s["method"] == "triangulate" and s["views"] == 4
    assert s["frames"] == s["frames_placed"] == 100
    assert s["median_residual_px"] < 8.0 and 0 < s["landmark_views_dropped"]
    assert s["mean_mm"] <= 110.0
    assert out.is_file()
    # a landmark put on the other arm for a frame or two is taken out (Triangulated.despiked):
    # before, the right wrist left for frames 83-84 by 635-691 mm
    assert s["landmarks_despiked"] > 0
    # smoothed over time by the width the camera left out chose (choose_smoothing)
    assert s["smoothing_s"] > 0 and len(s["smoothing_left_out_px"]) == 8
    assert s["smoothing_chosen_by"] == "left-out cameras"
    assert not any("this camera's video" in n for n in s["notes"])  # every view agrees
    from markovmotion.io import read_c3d

    steps = np.linalg.norm(np.diff(read_c3d(out).positions, axis=0), axis=-1)
    assert np.nanmax(steps) < 300.0
    # one person in the room: no view is left out, and he stands where the cameras are aimed
    assert s["views_of_someone_else"] == 0 and s["from_capture_centre_m"] < 1.0


def test_mediapipe_tracks_are_measured_against_a_rendered_take(tmp_path, take, capsys):
    """``--truth`` works for every method: MediaPipe triangulated from 3 rendered views of
    the held-out pull, and one view placed by PnP, against the capture's 19 body points
    (frames aligned by the render's start frame; measured: triangulated 63 mm, one view 274,
    unaligned 263 mm)."""
    _need_mediapipe()
    out = tmp_path / "take"
    main(["video", "render", str(take[1]), "--out", str(out), "--views", "3",
          "--seconds", "1", "--start", "1", "--fps", "30"])  # fmt: skip
    capsys.readouterr()
    for method, bound in (("triangulate", 90.0), ("monocular", 350.0)):
        main(["track", "--video", str(out), "--method", method, "--truth", str(take[1]),
              "--json"])  # fmt: skip
        s = json.loads(capsys.readouterr().out)
        assert s["frames_compared"] == s["frames"] == 30 and len(s["per_joint_mm"]) == 19
        assert s["mpjpe_mm"] < bound, method
    # aligned by the render's start frame: against the take from its first frame, far worse
    from markovmotion.video.multiview import truth_errors
    from markovmotion.video.triangulation import track_triangulated_video

    tr, _ = track_triangulated_video(out)
    aligned = truth_errors(tr.points, tr.fps, take[1], out)["mpjpe_mm"]
    doc = json.loads((out / "cameras.json").read_text())
    assert doc.pop("start_frame") == 30
    (out / "cameras.json").write_text(json.dumps(doc))
    assert truth_errors(tr.points, tr.fps, take[1], out)["mpjpe_mm"] > aligned + 50.0
    # the truth of another take than the one rendered gets a note before any tracking
    from markovmotion.video.multiview import check_truth

    assert check_truth(take[1], out) is None
    other = next(p for p in take[1].parent.iterdir() if p.name != take[1].name)
    assert take[1].name in check_truth(other, out)


def test_guide_option_reaches_the_tracker(tmp_path, take, capsys):
    """``--guide mediapipe`` on a tiny rendered video: MediaPipe runs over every view before
    the clock (its time reported apart), the summary says so."""
    _need_mediapipe()
    out = tmp_path / "take"
    main(["video", "render", str(take[1]), "--out", str(out), "--views",
          "2", "--seconds", "0.1", "--fps", "30", "--width", "96", "--height", "72"])  # fmt: skip
    main(["track", "--video", str(out), "--json", "--particles", "10", "--layers", "2",
          "--guide", "mediapipe"])  # fmt: skip
    s = json.loads(capsys.readouterr().out)
    assert s["guide"] == "mediapipe" and s["guide_seconds"] >= 0.0
    assert s["views_of_someone_else"] >= 0
    assert 0.0 <= s["guide_seen"] <= 1.0
    assert s["frames"] == 3 and 0 < s["fps_with_guide"] <= s["fps"]


def test_the_guide_is_on_for_real_people_and_off_for_rendered_ones(
    real_video, tmp_path, take, capsys, monkeypatch
):
    """``--guide auto`` (the default): MediaPipe guides the filter on real video (a camera file
    from a calibration), not on ``video render``'s (its capsule people mislead MediaPipe; an
    older render is known by the take it names), and without MediaPipe it says so."""
    import markovmotion.video.monocular as monocular
    from markovmotion.video.cameras import load_cameras
    from markovmotion.video.multiview import resolve_guide

    _need_mediapipe()
    out = tmp_path / "take"
    main(["video", "render", str(take[1]), "--out", str(out), "--views", "2", "--seconds",
          "0.1", "--fps", "30", "--width", "96", "--height", "72"])  # fmt: skip
    rendered, real = load_cameras(out)[1], load_cameras(real_video)[1]
    assert rendered["rendered"] is True and "rendered" not in real
    older = {k: v for k, v in rendered.items() if k != "rendered"}
    assert [resolve_guide("auto", d) for d in (rendered, older, real)] == [
        (False, None), (False, None), (True, None),
    ]  # fmt: skip
    assert resolve_guide("none", real) == (False, None)
    assert resolve_guide("mediapipe", rendered) == (True, None)
    with pytest.raises(ValueError, match="guide"):
        resolve_guide("openpose", real)
    # the real video, defaults: guided
    main(["track", "--video", str(real_video), "--json", "--particles", "10", "--layers", "2",
          "--max-frames", "2"])  # fmt: skip
    assert json.loads(capsys.readouterr().out)["guide"] == "mediapipe"
    monkeypatch.setattr(monocular, "mediapipe_installed", lambda: False)
    guided, note = resolve_guide("auto", real)
    assert not guided and "scripts/install-camera" in note
    main(["track", "--video", str(real_video), "--json", "--particles", "10", "--layers", "2",
          "--max-frames", "2"])  # fmt: skip
    run = capsys.readouterr()
    assert "guide" not in json.loads(run.out) and "MediaPipe is not installed" in run.err
    monkeypatch.undo()
    # one view: nothing to triangulate, so not guided, and said (it had said "guided")
    assert resolve_guide("auto", real, views=1)[0] is False
    main(["track", "--video", str(real_video / "cam0.mp4"), "--json", "--particles", "10",
          "--layers", "2", "--max-frames", "2"])  # fmt: skip
    run = capsys.readouterr()
    assert "guide" not in json.loads(run.out) and "one view" in run.err


def test_a_video_that_ends_early_is_said(real_video, tmp_path, capsys):
    """A camera's video that ends before the others' (a recording cut short): the particle
    filter follows the frames the views have together, the triangulation carries on with the
    other views; both say which video ended, not silently."""
    import itertools

    from markovmotion.video.render import read_frames, shortest_note, write_video

    _need_mediapipe()
    doc = json.loads((real_video / "cameras.json").read_text())
    for cam in doc["cameras"]:
        cam.pop("background", None)
        if cam["name"] == "cam1":
            frames = list(itertools.islice(read_frames(real_video / cam["video"]), 4))
            write_video(frames, tmp_path / cam["video"], doc["fps"])
        else:
            shutil.copy(real_video / cam["video"], tmp_path / cam["video"])
    (tmp_path / "cameras.json").write_text(json.dumps(doc))
    said = "note: cam1.mp4 ended after 4 frames, before the other views: 4 frames tracked"
    assert shortest_note(["cam0.mp4", "cam1.mp4"], [100, 4]) == said
    assert shortest_note(["cam0.mp4", "cam1.mp4"], [4, 4]) is None
    main(["track", "--video", str(tmp_path), "--max-frames", "6", "--guide", "none",
          "--particles", "10", "--layers", "2", "--background", "median"])  # fmt: skip
    err = capsys.readouterr().err
    assert said in err and "tracked 4 frames" in err, err
    main(["track", "--video", str(tmp_path), "--max-frames", "6", "--method", "triangulate"])
    err = capsys.readouterr().err
    carry = "note: cam1.mp4 ended after 4 frames, before the other views: they carry on"
    assert f"{carry} without it over frames 4-5" in err and "tracked 6 frames" in err, err
    assert "by its header" not in err  # its header counts 4: not damaged
    main(["track", "--video", str(tmp_path), "--max-frames", "3", "--method", "triangulate"])
    assert "ended after" not in capsys.readouterr().err  # cut by --max-frames: nothing to say


def _damaged_copy(folder):
    """``real_copy`` with camera 2's file zeroed over 8000 bytes a third of the way in (a
    new user's trial: OpenCV then decodes 18 of the 100 frames its header counts)."""
    data = bytearray((folder / "cam2.mp4").read_bytes())
    at = len(data) // 3
    data[at : at + 8000] = bytes(8000)
    (folder / "cam2.mp4").unlink()  # the link, not the shared file
    (folder / "cam2.mp4").write_bytes(bytes(data))
    return folder


def test_a_video_damaged_in_its_middle_is_said_and_the_other_views_carry_on(real_copy, capsys):
    """Camera 2's video damaged in its middle: OpenCV stops there as at an end. Monocular had
    tracked 18 frames without a word, the triangulation only 18 of 100 frames; now each says
    which video ended, after how many frames, and what its header counts, and the
    triangulation carries on over the frames the other three views have, placing them all."""
    import subprocess
    import sys

    _need_mediapipe()
    folder = _damaged_copy(real_copy)
    # FFmpeg's lines on the damaged frames are held back although the camera file's reading
    # opens the videos first (a new process: OpenCV reads the setting once)
    read = subprocess.run(
        [sys.executable, "-c", "import sys; from markovmotion.video.cameras import load_cameras; "
         "load_cameras(sys.argv[1]); from markovmotion.video.render import read_frames; "
         "print(sum(1 for _ in read_frames(sys.argv[1] + '/cam2.mp4')))", str(folder)],
        capture_output=True, text=True, check=True,
    )  # fmt: skip
    assert read.stdout.strip() == "18" and "h264" not in read.stderr, read.stderr
    said = "cam2.mp4 ended after 18 frames (100 frames by its header: damaged or cut short?)"
    main(["track", "--video", str(folder / "cam2.mp4"), "--method", "monocular", "--json",
          "--max-frames", "30"])  # fmt: skip
    run = capsys.readouterr()
    s = json.loads(run.out)
    assert s["frames"] == 18 and s["notes"] == [f"note: {said}"] and said in run.err
    main(["track", "--video", str(folder), "--method", "triangulate", "--json", "--max-frames",
          "30"])  # fmt: skip
    s = json.loads(capsys.readouterr().out)
    assert s["frames"] == s["frames_placed"] == 30
    assert f"note: {said}, before the other views: they carry on without it over frames " \
        "18-29" in s["notes"], s["notes"]  # fmt: skip
    main(["track", "--video", str(folder), "--max-frames", "30", "--guide", "none",
          "--particles", "10", "--layers", "1", "--json"])  # fmt: skip
    s = json.loads(capsys.readouterr().out)  # the particle filter stops, and says why
    assert s["frames"] == 18
    assert f"note: {said}, before the other views: 18 frames tracked" in s["notes"]


def _wrist_unsure(noise: float):
    """3 cameras, 12 frames of a standing person's landmarks (seed 5), pixels with
    ``noise``, every landmark seen surely but the left wrist, unsure (0.2) in views 1-2."""
    rng = np.random.default_rng(5)
    cams = _cameras(3)
    pts = _standing_landmarks(12)
    pix = _project(cams, pts.reshape(-1, 3)).reshape(3, 12, -1, 2)
    pix = pix + rng.normal(0.0, noise, pix.shape)
    vis = np.ones(pix.shape[:3])
    vis[1:, :, LANDMARKS.index("left_wrist")] = 0.2
    return cams, pts, pix, vis


def test_views_dropped_are_views_seen_surely_and_not_used(tmp_path, monkeypatch):
    """``landmark_views_dropped`` was the views seen surely less the views used, and the
    views used include those of landmarks filled from unsure views (Triangulated.filled):
    -58 and -203 in a new user's trial. A wrist seen surely by one of three views, unsurely
    by two, is filled from all three; one view's elbow is put 60 px off, and only that is
    dropped."""
    from markovmotion.video.cameras import save_cameras
    from markovmotion.video.triangulation import PersonViews, track_triangulated_video

    cams, pts, pix, vis = _wrist_unsure(noise=0.5)
    elbow = LANDMARKS.index("right_elbow")
    pix[0, :, elbow] += 60.0
    views = ViewLandmarks(cams, pix, vis)
    save_cameras(cams, tmp_path / "cameras.json", 30.0)
    for c in cams:
        (tmp_path / c.video).write_bytes(b"")  # named, never read: MediaPipe is replaced
    monkeypatch.setattr(
        "markovmotion.video.triangulation.person_views",
        lambda *args, **kwargs: PersonViews(views, views, None, 0, []),
    )
    _, s = track_triangulated_video(tmp_path, smooth=0.0)
    assert s["landmarks_filled_low_visibility"] == 12
    assert s["landmark_views_dropped"] == 12  # the elbow's view, in every frame


def test_a_reference_of_another_length_than_the_track_is_said(tmp_path):
    """A 100-row reference at 60 fps against a 50-frame track of the same take at 30 fps was
    compared frame by frame without a word (264.7 mm): a note gives both lengths and, when
    they differ by more than a tenth, the rate the reference would have over the same time.
    None when they match, or when --max-frames cut the track and the reference goes on."""
    from markovmotion.video.monocular import REFERENCE_JOINTS, reference_note

    cols = [f"{j}_{a}" for j in REFERENCE_JOINTS for a in "xyz"]
    lines = ["frame," + ",".join(cols)] + [
        f"{f}," + ",".join(["1"] * len(cols)) for f in range(100)
    ]
    ref = tmp_path / "ref.csv"
    ref.write_text("\n".join(lines) + "\n", encoding="utf-8")
    said = reference_note(ref, 50, 30.0)
    assert said.startswith("note: the reference ref.csv has 100 rows and the track 50 frames")
    assert "row k is compared with frame k, its last 50 rows with none" in said
    assert "if both span the same time, the reference is at 60 fps and the video at 30" in said
    assert reference_note(ref, 100, 60.0) is None
    assert reference_note(ref, 97, 60.0, first_frame=3) is None  # skip_frames 3: 97 rows on
    assert reference_note(ref, 30, 60.0, max_frames=30) is None  # --max-frames 30
    shorter = reference_note(ref, 120, 60.0, max_frames=120)  # cut, and the reference too
    assert "has 100 rows and the track 120 frames" in shorter and "fps" not in shorter
    longer = reference_note(ref, 104, 60.0)
    assert "has 100 rows and the track 104 frames" in longer and "fps" not in longer
    assert "the track's last 4 with none" in longer


def test_a_view_of_another_size_is_one_line(real_video, tmp_path, capsys):
    """A camera's video of another size than the camera (a copy made smaller) is refused by
    the triangulation as by the particle filter, not triangulated with the wrong pixels."""

    from markovmotion.video.render import read_frames, write_video

    for k in range(4):
        for name in (f"cam{k}.mp4", f"cam{k}_background.png"):
            shutil.copy(real_video / name, tmp_path / name)
    shutil.copy(real_video / "cameras.json", tmp_path / "cameras.json")
    frames = [f[:, :240] for f in itertools.islice(read_frames(real_video / "cam1.mp4"), 3)]
    write_video(frames, tmp_path / "cam1.mp4", 60.0)
    for extra in (["--method", "triangulate"], ["--guide", "none"]):
        with pytest.raises(SystemExit) as exc:
            main(["track", "--video", str(tmp_path), "--max-frames", "3", *extra])
        assert exc.value.code == 2
        err = capsys.readouterr().err.strip()
        assert "camera cam1 is 272x480" in err and "240x480" in err, err
        assert len(err.splitlines()) == 1


def test_videos_given_for_the_wrong_cameras_are_named(real_video, tmp_path, capsys):
    """Two cameras' videos swapped (as a calibration naming its cameras by serial number
    invites): the triangulation says which views the others disagree with, and which video
    each was given; it had said only that 'camera frames showed no one or someone else'."""
    _need_mediapipe()
    doc = json.loads((real_video / "cameras.json").read_text(encoding="utf-8"))
    one, two = doc["cameras"][1], doc["cameras"][2]
    one["video"], two["video"] = two["video"], one["video"]
    for k in range(4):
        (tmp_path / f"cam{k}.mp4").symlink_to(real_video / f"cam{k}.mp4")
    (tmp_path / "cameras.json").write_text(json.dumps(doc), encoding="utf-8")
    main(["track", "--video", str(tmp_path), "--method", "triangulate", "--max-frames", "30",
          "--json"])  # fmt: skip
    notes = [n for n in json.loads(capsys.readouterr().out)["notes"] if "this camera's" in n]
    assert len(notes) == 2
    assert notes[0].startswith("note: cam1:") and "is cam2.mp4 this camera's video" in notes[0]
    assert notes[1].startswith("note: cam2:") and "is cam1.mp4 this camera's video" in notes[1]


def test_a_camera_that_alone_sees_the_person_for_a_while_is_not_named():
    """A person out of one camera's field for part of a take (an ordinary take) leaves the
    other camera's landmarks untriangulable there, which says nothing of that camera: no
    note (it had asked whether cam0.mp4 was cam0's video)."""
    from markovmotion.video.triangulation import ViewLandmarks, lone_views, triangulate_views

    rng = np.random.default_rng(0)
    cams = ring_of_cameras(np.array([0.0, 900.0, 0.0]), 3500.0, 2, (272, 480))
    truth = rng.uniform([-300, 100, -300], [300, 1700, 300], (60, 33, 3))
    visibility = np.ones((2, 60, 33))
    visibility[1, 24:] = 0.0  # out of camera 1's field after 24 frames
    views = ViewLandmarks(cams, np.stack([c.project(truth)[0] for c in cams]), visibility)
    assert lone_views(views, triangulate_views(views)) == []


@pytest.mark.parametrize("n_views", [3, 4])
def test_of_three_views_the_one_that_disagrees_is_not_blamed(n_views):
    """Of three views, two cameras each given another camera's video can agree with one
    another, and the one right camera had been asked whether its video was its own (a new
    user's renumbered videos: "is cam0.mp4 this camera's video"). With three views or fewer
    the note says that the view disagrees with the others, not which side is wrong; with
    more, the others' agreement names the view, as before."""
    from markovmotion.video.triangulation import ViewLandmarks, lone_views, triangulate_views

    rng = np.random.default_rng(0)
    cams = ring_of_cameras(np.array([0.0, 900.0, 0.0]), 3500.0, n_views, (272, 480))
    truth = rng.uniform([-300, 100, -300], [300, 1700, 300], (60, 33, 3))
    pixels = np.stack([c.project(truth)[0] for c in cams])
    pixels[0] = cams[0].project(truth[::-1] + [400.0, 0.0, 0.0])[0]  # another moment's video
    views = ViewLandmarks(cams, pixels, np.ones((n_views, 60, 33)))
    notes = lone_views(views, triangulate_views(views))
    assert len(notes) == 1 and notes[0].startswith("note: cam0"), notes
    if n_views == 3:
        assert "cam0 disagrees with the other views" in notes[0]
        assert "either its video (cam0.mp4) or theirs is not the camera's" in notes[0]
        assert "is cam0.mp4 this camera's video" not in notes[0]
    else:
        assert "is cam0.mp4 this camera's video" in notes[0]


def test_the_guided_filter_says_whom_it_followed(real_video, capsys):
    """The guided particle filter's summary says whom MediaPipe followed, as the
    triangulation's does; a pixel with no one at it is said on stderr, with --json too."""
    _need_mediapipe()
    args = ["track", "--video", str(real_video), "--max-frames", "4", "--particles", "10",
            "--layers", "2", "--json"]  # fmt: skip
    main(args)
    s = json.loads(capsys.readouterr().out)
    assert s["from_capture_centre_m"] < 1.0 and "from_person_m" not in s
    main([*args, "--person", "cam0:5,5"])  # a corner of the room
    run = capsys.readouterr()
    assert json.loads(run.out)["from_person_m"] > 0.5
    assert "from the ray of --person" in run.err


def _standing_landmarks(frames: int) -> np.ndarray:
    """(F, 33, 3) mm: a person's landmarks, left at +x and right at -x of their middle line,
    each pair at its own height, walking slowly along z."""
    from markovmotion.video.left_right import SIDE_GROUPS, landmark_pair

    pts = np.zeros((frames, len(LANDMARKS), 3))
    pts[:, LANDMARKS.index("nose")] = [0.0, 1650.0, 80.0]
    height = 1600.0
    for stems in SIDE_GROUPS:
        for stem in stems:
            left, right = landmark_pair(stem)
            width = 120.0 + 60.0 * np.sin(height)  # pairs of differing widths
            pts[:, left] = [width, height, 0.0]
            pts[:, right] = [-width, height, 0.0]
            height -= 1500.0 / 26
    pts[..., 2] += np.linspace(0.0, 300.0, frames)[:, None]
    return pts


def test_landmarks_seen_unsurely_are_filled_from_every_view():
    """A wrist MediaPipe is sure of in one view only (visibility 0.9) and unsure of in the
    others (0.2): left out at first, then triangulated from all three by their visibility,
    near the truth; the landmarks seen surely are not changed."""
    from markovmotion.video.triangulation import triangulate_views

    cams, pts, pix, vis = _wrist_unsure(noise=1.0)
    wrist = LANDMARKS.index("left_wrist")
    vis[2, :4, wrist] = 0.0  # and not found at all in one view for a while
    views = ViewLandmarks(cams, pix, vis)
    tri = triangulate_views(views)
    assert np.isnan(tri.landmarks[:, wrist]).all()
    full, n = tri.filled(views)
    assert n == 12 and np.isfinite(full.landmarks).all()
    assert np.linalg.norm(full.landmarks[:, wrist] - pts[:, wrist], axis=-1).max() < 40.0
    others = np.arange(len(LANDMARKS)) != wrist
    np.testing.assert_array_equal(full.landmarks[:, others], tri.landmarks[:, others])
    assert full.filled(views)[1] == 0  # nothing left to fill


@pytest.mark.parametrize("noise", [0.0, 3.0])
def test_the_smoothing_is_chosen_by_the_camera_left_out(noise):
    """A person swaying fast (1.5 Hz, 250 mm) seen by 4 cameras at 60 fps: with exact
    landmarks smoothing only blurs the motion and none is chosen; with 3 px of detection
    noise the width chosen is (within 10 %) the one that brings the track nearest the
    truth. Two cameras leave no view out: the documented width."""
    from markovmotion.video.triangulation import triangulate_views

    rng = np.random.default_rng(1)
    frames, fps = 120, 60.0
    pts = _standing_landmarks(frames)
    pts[..., 0] += 250.0 * np.sin(2 * np.pi * 1.5 * np.arange(frames) / fps)[:, None]
    cams = _cameras(4)
    pix = _project(cams, pts.reshape(-1, 3)).reshape(4, frames, -1, 2)
    pix = pix + rng.normal(0.0, noise, pix.shape)
    views = ViewLandmarks(cams, pix, np.ones(pix.shape[:3]))
    chosen = choose_smoothing(views, fps)
    assert len(chosen.errors_px) == 8 and chosen.errors_px[chosen.seconds] == min(
        chosen.errors_px.values()
    )
    tri = triangulate_views(views)
    if noise == 0.0:
        assert chosen.seconds == 0.0
    else:  # the width nearest the truth (33 ms: 17 mm from it, 38 mm unsmoothed, 57 at 0.1 s)
        true = {
            w: np.linalg.norm(tri.smoothed(w, fps).landmarks - pts, axis=-1).mean()
            for w in chosen.errors_px
        }
        assert true[chosen.seconds] < 1.1 * min(true.values()) < 0.6 * true[0.0]
    two = choose_smoothing(ViewLandmarks(cams[:2], pix[:2], views.visibility[:2]), fps)
    assert two.seconds == SMOOTHING_TWO_VIEWS_S and two.errors_px == {}


def test_views_sides_undoes_swaps_injected_into_some_views():
    """MediaPipe's swaps injected into one view (the whole body, as seen from behind) and
    another (the knees alone) are undone, view by view and group by group, and the triangulated
    landmarks come back; MediaPipe's labels alone leave them wrong."""
    from markovmotion.video.left_right import SIDE_GROUPS, landmark_pair
    from markovmotion.video.triangulation import (
        ViewLandmarks,
        consistent_views,
        triangulate_views,
        views_sides,
    )

    cams = _cameras(4)
    truth = _standing_landmarks(40)
    pixels = np.stack([c.project(truth.reshape(-1, 3))[0].reshape(40, -1, 2) for c in cams])
    given = pixels.copy()
    expected = np.zeros((4, 40, len(SIDE_GROUPS)), bool)
    everything = [landmark_pair(s) for stems in SIDE_GROUPS for s in stems]
    li, ri = (list(x) for x in zip(*everything, strict=True))
    given[0][10:30][:, li + ri] = pixels[0][10:30][:, ri + li]
    expected[0, 10:30] = True
    knee = SIDE_GROUPS.index(("knee",))
    kl, kr = landmark_pair("knee")
    given[2][5:9][:, [kl, kr]] = pixels[2][5:9][:, [kr, kl]]
    expected[2, 5:9, knee] = True
    views = ViewLandmarks(cams, given, np.full((4, 40, len(LANDMARKS)), 0.9))
    fixed, swapped = views_sides(views)
    np.testing.assert_array_equal(swapped, expected)
    np.testing.assert_allclose(fixed.pixels, pixels)
    tri = triangulate_views(consistent_views(views, "views"))
    np.testing.assert_allclose(tri.landmarks, truth, atol=1.0)
    assert tri.used.all()  # every view agrees now
    raw = triangulate_views(consistent_views(views, "mediapipe"))
    assert not raw.used[0, 10:30].all()  # MSAC drops the swapped view where pairs lie apart
    with pytest.raises(ValueError, match="world points"):
        consistent_views(views, "continuity")
    with pytest.raises(ValueError, match="left_right"):
        consistent_views(views, "sideways")


def test_views_sides_keeps_the_majority_over_time_not_frame_by_frame():
    """Three views; the middle one swapped throughout (the person's back to it) and, for three
    frames, another too: the majority that frame says mirror, continuity of the triangulated
    points says not; the labels of the frames around win."""
    from markovmotion.video.left_right import SIDE_GROUPS, landmark_pair
    from markovmotion.video.triangulation import ViewLandmarks, views_sides

    cams = _cameras(3)
    truth = _standing_landmarks(30)
    pixels = np.stack([c.project(truth.reshape(-1, 3))[0].reshape(30, -1, 2) for c in cams])
    given = pixels.copy()
    everything = [landmark_pair(s) for stems in SIDE_GROUPS for s in stems]
    li, ri = (list(x) for x in zip(*everything, strict=True))
    given[1][:, li + ri] = pixels[1][:, ri + li]
    given[2][12:15][:, li + ri] = pixels[2][12:15][:, ri + li]
    views = ViewLandmarks(cams, given, np.full((3, 30, len(LANDMARKS)), 0.9))
    fixed, swapped = views_sides(views)
    np.testing.assert_allclose(fixed.pixels, pixels)
    _, frame_by_frame = views_sides(views, over_time=False)
    assert frame_by_frame[0, 12:15].all()  # the majority alone mirrors those frames


def test_views_that_see_different_things_never_break_the_triangulation():
    """Pixels that no one point explains (two people, one per view) give points in front of
    every camera used, or NaN: no error, no point behind a camera or at infinity."""
    rng = np.random.default_rng(5)
    cams = _cameras(4, (1088, 1920))
    n = 4000
    pix = rng.uniform([-200, -200], [1300, 2100], (4, n, 2))
    w = rng.uniform(0.0, 1.0, (4, n)) * (rng.random((4, n)) < 0.8)
    pts, used, _ = triangulate_points(cams, pix, w)
    placed = np.isfinite(pts).all(axis=1)
    assert placed.any() and not placed.all()
    for v, cam in enumerate(cams):
        depth = (pts[placed & used[v]] @ cam.R.T + cam.t)[:, 2]
        assert (depth > 0).all()


def _two_people(frames: int = 30, mirror_view: int | None = None):
    """Landmarks of person P and of Q 1.2 m to the side, walking on, in 5 cameras."""
    from markovmotion.video.left_right import landmark_pair

    rng = np.random.default_rng(6)
    body = rng.uniform([-250, 0, -150], [250, 1750, 150], (len(LANDMARKS), 3))
    walk = np.linspace(0, 300, frames)[:, None, None] * np.array([0.0, 0.0, 1.0])
    p = body[None] + walk
    q = body[None] + walk + np.array([1200.0, 0.0, 300.0])
    cams = _cameras(5, (1088, 1920))
    pixels = np.stack([np.stack([c.project(x)[0] for x in p]) for c in cams])
    other = np.stack([np.stack([c.project(x)[0] for x in q]) for c in cams])
    if mirror_view is not None:  # that camera's MediaPipe swaps every left and right
        for stem in ("shoulder", "elbow", "wrist", "hip", "knee", "ankle", "ear"):
            a, b = landmark_pair(stem)
            pixels[mirror_view][:, [a, b]] = pixels[mirror_view][:, [b, a]]
    return cams, pixels, other, np.ones((5, frames, len(LANDMARKS)))


@pytest.mark.parametrize("mirror_view", [None, 1])
def test_one_person_drops_the_views_of_someone_else_and_keeps_to_one_person(mirror_view):
    """Views 0-3 see P and view 4 sees Q; then, for 10 frames, views 2-4 see Q: the person
    the views followed is kept (a view that mirrors P included) and every view of Q dropped.
    Landmark by landmark, the triangulation alone takes Q where more views see Q."""
    from markovmotion.video.triangulation import ViewLandmarks, one_person, triangulate_views

    cams, pixels, other, vis = _two_people(mirror_view=mirror_view)
    seen = pixels.copy()
    seen[4] = other[4]
    seen[2:4, 20:] = other[2:4, 20:]
    views = ViewLandmarks(cams, seen, vis)
    agreed, kept = one_person(views, fps=30.0)
    expected = np.ones((5, 30), bool)
    expected[4] = False
    expected[2:4, 20:] = False
    assert (kept == expected).all()
    assert (agreed.visibility[~expected] == 0).all()
    alone = triangulate_views(ViewLandmarks(cams, pixels, vis)).points
    if mirror_view is None:
        got = triangulate_views(agreed).points
        assert np.nanmax(np.linalg.norm(got - alone, axis=-1)) < 1.0
    mixed = triangulate_views(views).points
    assert np.nanmean(np.linalg.norm(mixed[20:] - alone[20:], axis=-1)) > 1000.0


def test_the_crop_around_a_person_is_a_square_with_a_margin_inside_the_image():
    from markovmotion.video.triangulation import CROP_MARGIN, _crop_box

    xy = np.array([[500.0, 200.0], [540.0, 400.0]])
    x0, y0, x1, y1 = _crop_box(xy, 1000, 1000)
    side = (1 + 2 * CROP_MARGIN) * 200
    assert (x1 - x0, y1 - y0) == (int(520 + side / 2) - int(520 - side / 2),) * 2
    assert x0 <= 500 and x1 >= 540 and y0 <= 200 and y1 >= 400
    assert _crop_box(xy, 600, 1000)[2] == 600  # cut to the image
    assert _crop_box(np.array([[5.0, 5.0], [6.0, 6.0]]), 100, 100) is None  # too small


def test_of_two_people_seen_alike_the_one_the_cameras_aim_at_is_kept_even_when_lost():
    """Two views see P (where the ring of cameras is aimed) and two see Q, 1.2 m out; for 5
    frames no view finds P: P is followed throughout (no one in those frames), never Q.
    Without "no one" holding where P was lost, coming back to anyone would be free."""
    from markovmotion.video.triangulation import ViewLandmarks, capture_centre, one_person

    cams, pixels, other, vis = _two_people()
    cams, pixels, other, vis = cams[:4], pixels[:4], other[:4], vis[:4]
    assert np.linalg.norm(capture_centre(cams) - [0.0, 900.0, 0.0]) < 1.0
    seen = pixels.copy()
    seen[:2] = other[:2]
    vis = vis.copy()
    vis[2:, 10:15] = 0.0  # P lost
    _, kept = one_person(ViewLandmarks(cams, seen, vis), fps=30.0)
    expected = np.zeros((4, 30), bool)
    expected[2:] = True
    expected[2:, 10:15] = False
    assert (kept == expected).all()


def test_the_person_named_by_a_pixel_is_followed_where_the_cameras_aim_elsewhere():
    """Two views see P (where the cameras are aimed) and two see Q, 1.2 m out: by default P is
    followed; ``--person`` at Q's pixel in camera 0 (which sees P) follows Q throughout, also
    after Q has walked off that pixel's ray; at P's pixel, P. The named person is where they
    stood over the first half second: later, Q is kept as P was, by the views and continuity."""
    from markovmotion.video.triangulation import ViewLandmarks, one_person, person_ray

    cams, pixels, other, vis = _two_people(frames=60)
    cams, pixels, other, vis = cams[:4], pixels[:4], other[:4], vis[:4]
    seen = pixels.copy()
    seen[:2] = other[:2]
    views = ViewLandmarks(cams, seen, vis)
    p_views = np.zeros((4, 60), bool)
    p_views[2:] = True
    assert (one_person(views, fps=30.0)[1] == p_views).all()
    for who, points, expected in (("Q", other, ~p_views), ("P", pixels, p_views)):
        u, v = np.median(points[0, 0], axis=0)  # camera 0, frame 0: the pixel a user clicks
        aim = person_ray(cams, f"{cams[0].name}:{u:.0f},{v:.0f}", fps=30.0)
        assert aim.frames == 15
        _, kept = one_person(views, fps=30.0, aim=aim)
        assert (kept == expected).all(), who


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("cam0", "is not CAMERA:U,V"),
        ("10,10", "is not CAMERA:U,V"),
        ("cam0:1,2,3", "is not CAMERA:U,V"),
        ("cam9:10,10", "no camera 'cam9'"),
        ("7:10,10", "no camera '7'"),
        ("cam0:-1,10", "outside cam0's"),
        ("cam0:10,nan", "outside cam0's"),
    ],
)
def test_a_bad_person_pixel_is_one_line(text, message):
    from markovmotion.video.triangulation import person_ray

    with pytest.raises(ValueError, match=message):
        person_ray(_cameras(2), text)
    assert person_ray(_cameras(2), "1:10,20").origin == pytest.approx(_cameras(2)[1].centre)


def test_a_person_alone_far_from_where_the_cameras_aim_keeps_every_view():
    """One person 4 m from where three cameras are aimed (a runner crossing the room): the
    distance only ranks people against each other, so every view is kept."""
    from markovmotion.video.triangulation import ViewLandmarks, capture_centre, one_person

    cams = ring_of_cameras(np.array([0.0, 900.0, 0.0]), 12000.0, 3, (1088, 1920))
    rng = np.random.default_rng(7)
    body = rng.uniform([-250, 0, -150], [250, 1750, 150], (len(LANDMARKS), 3))
    far = body + np.array([3200.0, 0.0, 2600.0])
    assert np.linalg.norm(far.mean(axis=0) - capture_centre(cams)) > 3900.0
    for c in cams:  # in every image
        xy, _ = c.project(far)
        assert ((xy > 0) & (xy < [c.width, c.height])).all()
    pixels = np.stack([np.stack([c.project(far)[0]] * 10) for c in cams])
    _, kept = one_person(ViewLandmarks(cams, pixels, np.ones((3, 10, len(LANDMARKS)))), 30.0)
    assert kept.all()


def test_mediapipe_says_nothing_on_the_terminal(real_video, tmp_path):
    """A fresh process (MediaPipe's TensorFlow Lite says its start-up line once a process):
    ``track --method triangulate`` writes only its own lines; the line came after the graph's
    creation, from its own threads, before this was held."""
    import subprocess
    import sys

    _need_mediapipe()
    run = subprocess.run(
        [sys.executable, "-m", "markovmotion", "track", "--video", str(real_video),
         "--method", "triangulate", "--max-frames", "3", "--out", str(tmp_path / "a.c3d")],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert run.returncode == 0, run.stderr
    assert run.stderr.splitlines() == [
        f"wrote {tmp_path / 'a.c3d'}",
        "tracked 3 frames (3 with all 19 body points) of 4 views, smoothed over sigma 33.3 ms "
        "(fixed: too few frames to choose) at " + run.stderr.split(" at ")[-1].strip(),
    ]


def test_whom_notes_say_when_the_person_followed_may_not_be_the_one_meant():
    """A track near where the cameras are aimed says nothing; far from it, or far from the
    ray of a person named, or with views of someone else left out, one line each."""
    from markovmotion.video.triangulation import FAR_FROM_CENTRE_M, FAR_FROM_RAY_M, whom_notes

    near = {"from_capture_centre_m": FAR_FROM_CENTRE_M - 0.1, "views_of_someone_else": 0}
    assert whom_notes(near) == []
    far = {**near, "from_capture_centre_m": FAR_FROM_CENTRE_M + 0.2}
    assert len(whom_notes(far)) == 1 and "1.2 m from where the cameras" in whom_notes(far)[0]
    named = {**far, "from_person_m": FAR_FROM_RAY_M + 0.1}
    (line,) = whom_notes(named, named=True)  # the ray decides, not the centre
    assert "ray of --person" in line
    assert whom_notes({**named, "from_person_m": FAR_FROM_RAY_M - 0.1}, named=True) == []
    lines = whom_notes({**near, "views_of_someone_else": 3})
    assert len(lines) == 1 and lines[0].startswith("note: 3 camera frames")


def test_every_track_method_gives_the_reference_errors_under_reference(real_video, capsys):
    """``track --json --reference``: the particle filter, triangulate and monocular all give
    ``reference.mean_mm`` (the last two also flat, as before)."""
    _need_mediapipe()
    ref = str(real_video / "reference_mediapipe_triangulated_mm.csv")
    base = ["track", "--video", str(real_video), "--max-frames", "3", "--reference", ref, "--json"]
    for extra in (["--particles", "10", "--layers", "2"], ["--method", "triangulate"],
                  ["--method", "monocular"]):  # fmt: skip
        main([*base, *extra])
        s = json.loads(capsys.readouterr().out)
        assert s["reference"]["mean_mm"] > 0, extra


def test_a_video_with_no_one_in_it_says_so(tmp_path, capsys):
    """Each camera's empty-scene plate as a video: the particle filter reported a pose at
    confidence 0.40 in every frame and triangulation a NaN summary, exit 0 (a new user's
    trial); both now stop in one line, and so does ``--method monocular`` (which had written
    a track of no frame placed, exit 0: a later trial). (With the person gone
    from some frames only, those frames get confidence 0 and a note: 15 of 40 frames of the
    trial's clip, checked by hand.)"""
    from conftest import empty_scene

    from markovmotion.cli import main

    empty_scene(tmp_path, 4)
    for method, out in (("apf", "x.bvh"), ("triangulate", "x.c3d"), ("monocular", "x.c3d")):
        with pytest.raises(SystemExit) as exit_:
            main(["track", "--video", str(tmp_path), "--method", method, "--particles", "50",
                  "--layers", "2", "--out", str(tmp_path / out)])  # fmt: skip
        assert exit_.value.code == 2, method
        assert "no person found in this video" in capsys.readouterr().err, method
        assert not (tmp_path / out).exists()


def test_method_auto_picks_the_most_accurate_tracker_for_what_is_asked(monkeypatch):
    """``resolve_method``: ``auto`` is MediaPipe triangulated for two views or more and
    monocular for one; the particle filter when its own options or a skeleton are asked
    for, or MediaPipe is not installed; a method named is kept."""
    import markovmotion.video.monocular as monocular
    from markovmotion.video.multiview import resolve_method

    monkeypatch.setattr(monocular, "mediapipe_installed", lambda: True)
    chosen, note = resolve_method("auto", 4)
    assert chosen == "triangulate" and "auto chose triangulate" in note and "4 views" in note
    assert resolve_method("auto", 1)[0] == "monocular"
    assert resolve_method("auto", 3, filter_asked=True) == ("apf", None)
    for named in ("apf", "triangulate", "monocular"):
        assert resolve_method(named, 4) == (named, None)
    monkeypatch.setattr(monocular, "mediapipe_installed", lambda: False)
    assert resolve_method("auto", 4) == ("apf", None)
    with pytest.raises(ValueError, match="method must be one of"):
        resolve_method("kalman", 2)


def test_track_by_default_triangulates_and_a_skeleton_asks_for_the_filter(
    real_video, tmp_path, capsys
):
    """``track`` without ``--method`` on the real 4-view video triangulates MediaPipe (the
    note and the summary say so); a .bvh ``--out`` or a particle-filter option given makes
    it the particle filter, which writes the skeleton."""
    _need_mediapipe()
    base = ["track", "--video", str(real_video), "--max-frames", "3", "--json"]
    main(base)
    captured = capsys.readouterr()
    summary = json.loads(captured.out)
    assert summary["method"] == "triangulate" and summary["views"] == 4
    assert "note: --method auto chose triangulate" in captured.err
    main([*base, "--particles", "10", "--layers", "1", "--out", str(tmp_path / "a.bvh")])
    captured = capsys.readouterr()
    summary = json.loads(captured.out)
    assert "confidence" in summary and (tmp_path / "a.bvh").is_file()
    assert summary["method"] == "apf"  # the summary says which ran, whichever it was
    assert "auto chose" not in captured.err
    main([*base, "--layers", "1", "--particles", "10"])  # no --out: the filter's option
    assert "auto chose" not in capsys.readouterr().err
