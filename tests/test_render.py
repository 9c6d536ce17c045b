"""Rendering: GIF, MP4 and PNG strips of synthetic and real motion, the render command, the demo."""

from __future__ import annotations

import imageio_ffmpeg
import numpy as np
import pytest
from conftest import make_motion
from PIL import Image

from markovmotion import MarkovMotionError, read_motion
from markovmotion.cli import main
from markovmotion.core.markers import Markers
from markovmotion.demo.run import STEPS, WALK, run_demo
from markovmotion.video.demo import vlmm_contours
from markovmotion.viz import render, render_frames, save_line_plot
from markovmotion.viz.animation import COLOURS, _Stage, _tracks

REAL = {
    "cmu_bvh": "cmu/bvh/martial_03.bvh.gz",
    "bandai_bvh": "bandai/dataset-2/walk_normal_001.bvh.gz",
    "cmu_amc": WALK,
}


@pytest.fixture(scope="session")
def real(mocap):
    """One take of each source and format, read once."""
    return {key: mocap.load_motion(mocap.find(f)) for key, f in REAL.items()}


@pytest.fixture(scope="session")
def salsa(mocap):
    """Both partners of a salsa take, in their shared coordinate frame."""
    return mocap.load_pair(*mocap.pairs(label="salsa")[0])


def gif_frames(path) -> list[np.ndarray]:
    with Image.open(path) as im:
        out = []
        for k in range(im.n_frames):
            im.seek(k)
            out.append(np.asarray(im.convert("RGB")))
    return out


def mp4_frames(path) -> tuple[tuple[int, int], list[np.ndarray]]:
    reader = imageio_ffmpeg.read_frames(str(path))
    meta = next(reader)
    w, h = meta["size"]
    return (w, h), [np.frombuffer(f, np.uint8).reshape(h, w, 3) for f in reader]


def changed_pixels(a: np.ndarray, b: np.ndarray) -> int:
    """Pixels that differ by more than a compression artefact, below the clock (top 10%)."""
    top = a.shape[0] // 10
    return int((np.abs(a[top:].astype(int) - b[top:].astype(int)).max(axis=2) > 40).sum())


def colour_pixels(image: np.ndarray, colour: str) -> int:
    rgb = np.array([int(colour[i : i + 2], 16) for i in (1, 3, 5)])
    return int((np.abs(image[..., :3].astype(int) - rgb).max(axis=2) < 30).sum())


def check_animation(motion, tmp_path, n_expected, **kwargs):
    gif, mp4, png = (tmp_path / f"out.{s}" for s in ("gif", "mp4", "png"))
    assert render(motion, gif, **kwargs) == gif
    render(motion, mp4, **kwargs)
    render(motion, png, **kwargs)

    frames = gif_frames(gif)
    assert len(frames) == n_expected
    assert changed_pixels(frames[0], frames[len(frames) // 2]) > 300  # the figure moves
    assert changed_pixels(frames[len(frames) // 2], frames[-1]) > 300
    assert colour_pixels(frames[0], COLOURS[0]) > 100  # a figure is drawn

    data = mp4.read_bytes()
    assert data[4:8] == b"ftyp"
    size, video = mp4_frames(mp4)
    assert size == (frames[0].shape[1], frames[0].shape[0])
    assert len(video) == n_expected
    assert changed_pixels(video[0], video[len(video) // 2]) > 300

    with Image.open(png) as im:
        assert im.format == "PNG" and im.size[0] <= 1920
        strip = np.asarray(im.convert("RGB"))
    assert colour_pixels(strip, COLOURS[0]) > 600  # six small figures
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.gif", "out.mp4", "out.png"]


def test_synthetic_motion_to_gif_mp4_png(tmp_path):
    motion = make_motion(n_frames=40, fps=30)  # 1.3 s: frames at 0, 1/15, ... 19/15 s
    check_animation(motion, tmp_path, 20, fps=15)


@pytest.mark.parametrize("key", list(REAL))
def test_real_motion_to_gif_mp4_png(real, key, tmp_path):
    check_animation(real[key], tmp_path, 24, fps=12, max_seconds=2)


def test_frame_rate_is_resampled_and_short_clips_hold(real, tmp_path):
    walk = real["cmu_amc"]  # 120 fps, 343 frames: 2.85 s
    render(walk, tmp_path / "w.gif", fps=10)
    assert len(gif_frames(tmp_path / "w.gif")) == int(2.85 * 10) + 1
    render([walk, walk.trim(0, 60)], tmp_path / "two.gif", fps=10, side_by_side=True)
    assert len(gif_frames(tmp_path / "two.gif")) == int(2.85 * 10) + 1


def test_two_people_share_a_scene_in_two_colours(salsa, tmp_path):
    render(list(salsa), tmp_path / "pair.gif", max_seconds=1)
    frame = gif_frames(tmp_path / "pair.gif")[0]
    assert colour_pixels(frame, COLOURS[0]) > 100
    assert colour_pixels(frame, COLOURS[1]) > 100
    render(list(salsa), tmp_path / "apart.gif", max_seconds=1, side_by_side=True)
    apart = gif_frames(tmp_path / "apart.gif")[0]
    assert apart.shape[1] > frame.shape[1]  # two panels side by side
    # each panel shows one person: the blue one on the left, the red one on the right
    half = apart.shape[1] // 2
    assert colour_pixels(apart[:, :half], COLOURS[0]) > 100
    assert colour_pixels(apart[:, :half], COLOURS[1]) == 0
    assert colour_pixels(apart[:, half:], COLOURS[1]) > 100


def test_render_frames_strip(real, tmp_path):
    walk = real["bandai_bvh"]
    path = render_frames(walk, [0, 30, 60, 90], tmp_path / "strip.png", title="walk")
    with Image.open(path) as im:
        image = np.asarray(im.convert("RGB"))
    assert colour_pixels(image, COLOURS[0]) > 400
    with pytest.raises(ValueError):
        render_frames(walk, [], tmp_path / "none.png")


def test_markers_are_drawn_as_points(tmp_path):
    motion = make_motion(n_frames=30)
    pos = motion.positions()
    pos[5:10, 2] = np.nan  # an occluded marker
    markers = Markers(tuple(f"m{k}" for k in range(pos.shape[1])), pos, motion.fps, "markers")
    render([motion, markers], tmp_path / "mix.gif")
    frames = gif_frames(tmp_path / "mix.gif")
    assert len(frames) == 15
    assert colour_pixels(frames[3], COLOURS[1]) > 20  # the marker dots, in the second colour


def test_camera_sees_a_walk_upright_from_the_side(real):
    walk = real["bandai_bvh"]
    stage = _Stage.build(_tracks(walk, None), side_by_side=False, end=walk.duration)
    times = np.arange(walk.n_frames) / walk.fps
    screen, floor, _ = stage.pose(0, times)
    names = walk.skeleton.names[walk.skeleton.body_root :]
    head, toe = names.index("Head_end"), names.index("Toes_L_end")
    assert np.all(screen[:, head, 1] - screen[:, toe, 1] > 1000)  # head well above the feet
    assert np.all(screen[..., 1] >= floor[..., 1] - 1e-6)  # every joint above its shadow
    pelvis_x = screen[:, 0, 0]
    assert pelvis_x[-1] - pelvis_x[0] > 0.8 * 9000  # a 10 m walk crosses the screen left to right


def test_unknown_suffix_is_an_error(tmp_path, capsys):
    with pytest.raises(MarkovMotionError, match="unknown output format"):
        render(make_motion(), tmp_path / "x.avi")
    with pytest.raises(SystemExit) as exc:  # checked before any input is read
        main(["render", str(tmp_path / "walk.bvh"), "--out", str(tmp_path / "x.webm")])
    assert exc.value.code == 2
    assert "unknown output format '.webm'" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_long_title_shrinks_to_fit_a_narrow_figure():
    from markovmotion.viz.animation import _figure

    fig, _ = _figure(1, 1, 0.7, "a title far too long for one narrow panel of one person", 5.0)
    fig.canvas.draw()
    assert fig.texts[0].get_window_extent().width <= fig.bbox.width
    # the demo's caption of numbers goes onto lines of its own, still readable: it had been
    # shrunk to about 5 pt in a 396-pixel GIF
    caption = (
        "new people (pair3, never seen): windowed 149 mm, mean pose 197; body-centred 113 vs 111 mm"
    )
    fig, _ = _figure(1, 1, 0.62, caption, 4.5)
    fig.canvas.draw()
    text = fig.texts[0]
    assert text.get_window_extent().width <= fig.bbox.width
    assert text.get_fontsize() >= 10 and "\n" in text.get_text()
    assert "body-centred" in text.get_text()  # not broken at its hyphen


def test_an_upper_body_of_markers_stands_on_a_floor_below_its_shoulders():
    """A depth sensor's 8 upper-body points: drawn joined as a person (the shoulders joined),
    over a floor a standing adult's shoulder height below the shoulders, not at an idle
    hand; the 13 markers of the VLMM paper get a trunk and a head joined to it."""
    from markovmotion.features.body_points import MARKER_POINTS, figure_bones
    from markovmotion.viz.animation import SHOULDER_HEIGHT

    names = ("TORSO", "HEAD", "R_SHOULDER", "L_SHOULDER", "R_ELBOW", "L_ELBOW", "R_HAND", "L_HAND")
    rest = np.array([[0, 1100, 0], [0, 1650, 0], [-180, 1400, 0], [180, 1400, 0],
                     [-200, 1100, 0], [200, 1100, 0], [-200, 850, 0], [200, 850, 0.0]])  # fmt: skip
    upper = Markers(names, np.repeat(rest[None], 10, axis=0), 30.0, "upper body")
    stage = _Stage.build(_tracks(upper, None), side_by_side=False, end=upper.duration)
    assert stage.ground == pytest.approx(1400.0 - SHOULDER_HEIGHT)
    drawn = {frozenset((names[a], names[b])) for a, b in stage.tracks[0].bones}
    assert frozenset(("R_SHOULDER", "L_SHOULDER")) in drawn
    # a whole body of markers stands on its own lowest point, as before
    whole = make_motion(n_frames=10)
    stage = _Stage.build(_tracks(whole, None), side_by_side=False, end=whole.duration)
    assert stage.ground == pytest.approx(np.nanmin(whole.positions()[..., 1]))
    lines = {
        frozenset((MARKER_POINTS[a], MARKER_POINTS[b])) for a, b in figure_bones(MARKER_POINTS)
    }
    for pair in (("left_shoulder", "right_shoulder"), ("left_hip", "right_hip"),
                 ("left_shoulder", "left_hip"), ("head", "right_shoulder")):  # fmt: skip
        assert frozenset(pair) in lines


def test_render_command(mocap, tmp_path):
    a, b = mocap.pairs(label="salsa")[0]
    out = tmp_path / "pair.png"
    main(["render", str(a.path), str(b.path), "--out", str(out), "--data-fps", "60"])
    assert out.stat().st_size > 0
    gif = tmp_path / "walk.gif"
    walk = mocap.find(REAL["bandai_bvh"]).path
    main(["render", str(walk), "--out", str(gif), "--fps", "10", "--max-seconds", "1.5"])
    assert len(gif_frames(gif)) == 15


def test_demo_writes_motion_animation_and_plot(mocap, real, tmp_path):
    out = tmp_path / "demo"
    run_demo(out, mocap.root, [*STEPS, vlmm_contours])  # as 'markovmotion demo' (video apart)
    for name in ("walk.bvh", "walk.gif", "pca-energy.png"):
        assert (out / name).stat().st_size > 0
    back = read_motion(out / "walk.bvh")
    walk = real["cmu_amc"]
    assert back.n_frames == walk.n_frames and back.fps == pytest.approx(walk.fps)
    np.testing.assert_allclose(back.positions(), walk.positions(), atol=1e-3)
    with Image.open(out / "pca-energy.png") as im:
        assert im.format == "PNG"
    # the trained models' outputs: motions that read back, animations that move
    bvhs = (
        "partner-virtual.bvh",
        "handshake-virtual.bvh",
        "vlmm-routine.bvh",
        "gait-elderly-synthesized.bvh",
        "chain-partner.bvh",
    )
    for name in bvhs:
        motion = read_motion(out / name)
        assert motion.n_frames > 30 and np.isfinite(motion.positions()).all()
    gifs = ("partner.gif", "handshake.gif", "vlmm-routine.gif", "gait-elderly.gif")
    for name in (*gifs, "chain-partner.gif"):
        frames = gif_frames(out / name)
        assert len(frames) > 10 and not np.array_equal(frames[0], frames[-1])
    # contour routines at memory 1 and 4 (paper Fig. 9), key and prototype memory: four rows
    with Image.open(out / "vlmm-contours-key-memory.png") as im:
        assert im.format == "PNG" and im.size[0] > 3 * im.size[1]
        strip = np.asarray(im.convert("L"))
    for row in np.array_split(strip, 4):
        dark = (row < 128).mean(axis=0)
        assert 0.02 < (row < 128).mean() < 0.5  # filled contours, not blank nor solid
        assert (np.convolve(dark > 0, np.ones(8), "same") == 0).sum() > 100  # gaps between


def test_line_plot_is_written_atomically(tmp_path):
    path = save_line_plot(
        tmp_path / "plots" / "errors.png",
        np.arange(1, 11),
        {"VLMM": np.linspace(10, 50, 10), "first-order": np.linspace(12, 90, 10)},
        xlabel="horizon (frames)",
        ylabel="error (mm)",
        logy=True,
        hlines={"chance": 80.0},
    )
    with Image.open(path) as im:
        assert im.format == "PNG" and im.size[0] > 300
    assert [p.name for p in path.parent.iterdir()] == ["errors.png"]


def test_gif_keeps_its_frame_rate(tmp_path):
    """GIF delays are centiseconds: 15 fps must not play as 1000 // 15 // 10 = 6 cs (10 % fast)."""
    render(make_motion(n_frames=60, fps=30), tmp_path / "w.gif", fps=15)  # 30 frames: 2 s
    with Image.open(tmp_path / "w.gif") as im:
        delays = []
        for k in range(im.n_frames):
            im.seek(k)
            delays.append(im.info["duration"])
    assert sum(delays) == 2000
    assert set(delays) <= {60, 70}


def test_an_animation_beyond_the_frame_limit_is_refused_before_any_work(tmp_path):
    """``render walk.bvh --data-fps 1e-2``: 2 s of frames become hours of animation; refused in
    one line naming the output and the limit (issue 22), in the real process, in under 10 s of
    CPU (``check_clean``), before anything is drawn."""
    from hostile_corpus import check_clean, run_cli, small_bvh

    take = tmp_path / "walk.bvh"
    take.write_text(small_bvh(60))  # 60 frames: 5,900 s at 0.01 fps, 88,501 frames at 15 fps
    out = tmp_path / "o.gif"
    run = run_cli(["render", str(take), "--out", str(out), "--data-fps", "1e-2"], timeout=30)
    check_clean(run, "o.gif", "88501 frames", "MARKOVMOTION_MAX_ANIMATION_FRAMES")
    assert not out.exists()
    # the limit is the declared one: raised above the animation's length, the same is drawn
    run = run_cli(
        ["render", str(take), "--out", str(out), "--data-fps", "1e-2", "--max-seconds", "1"],
        env={"MARKOVMOTION_MAX_ANIMATION_FRAMES": "10"},
    )
    check_clean(run, "o.gif", "15 frames", "MARKOVMOTION_MAX_ANIMATION_FRAMES")
    # a GIF is held whole in memory until written: its own, lower limit, naming .mp4
    run = run_cli(
        ["render", str(take), "--out", str(out), "--data-fps", "1e-2", "--max-seconds", "1"],
        env={"MARKOVMOTION_MAX_GIF_FRAMES": "10"},
    )
    check_clean(run, "o.gif", "15 frames", "MARKOVMOTION_MAX_GIF_FRAMES")
    assert ".mp4" in run.stderr and not out.exists()
    # a strip draws a few frames whatever the take's length: not refused
    strip = tmp_path / "o.png"
    run = run_cli(["render", str(take), "--out", str(strip), "--data-fps", "1e-2"], timeout=60)
    assert run.code == 0, run.stderr
    assert strip.stat().st_size > 0


def test_a_capture_with_every_marker_occluded_is_one_line(tmp_path, capsys):
    """A C3D whose markers are never seen: render says there is nothing to draw, exit 2
    (it was a traceback from the camera's placement)."""
    from markovmotion.io import write_c3d

    path = tmp_path / "occluded.c3d"
    write_c3d(Markers(("A", "B"), np.full((10, 2, 3), np.nan), 30.0, "occluded"), path)
    with pytest.raises(SystemExit) as stop:
        main(["render", str(path), "--out", str(tmp_path / "o.png")])
    err = capsys.readouterr().err
    assert stop.value.code == 2 and "nothing to draw" in err and len(err.strip().splitlines()) == 1


def test_a_finished_motion_and_a_cut_clip_are_said(tmp_path, monkeypatch):
    """Of two motions, the one that is over holds its last pose faded and the clock says
    when it ended (a 2.9 s walk stood still until 't = 9.07 s' beside a longer one); a clip
    cut by max_seconds says so in its title (the demo showed 10 s of a 35.7 s take)."""
    import matplotlib.text

    from markovmotion.viz import animation

    said, titles = [], []
    own_set_text, own_figure = matplotlib.text.Text.set_text, animation._figure
    monkeypatch.setattr(
        matplotlib.text.Text,
        "set_text",
        lambda self, s: (said.append(str(s)), own_set_text(self, s))[1],
    )
    monkeypatch.setattr(
        animation, "_figure", lambda *a, **k: (titles.append(a[3]), own_figure(*a, **k))[1]
    )
    short, long = make_motion(n_frames=31), make_motion(n_frames=91, seed=1)  # 1 s, 3 s at 30
    short.name, long.name = "short", "long"
    render([short, long], tmp_path / "two.gif", fps=10.0, max_seconds=2.0, title="two")
    assert titles[-1] == "two (first 1.9 s of 3 s)"
    assert any("short ended at 1.0 s" in s for s in said)
    assert not any("long ended" in s for s in said)
    # cut to the frames shown, a motion still playing is not over (the cut end of a take at
    # 30.00003 fps fell just before the last time shown)
    said.clear()
    render([short, long], tmp_path / "two.png", strip_frames=4)  # cells at 0, 1, 2, 3 s
    ended = [s for s in said if "ended" in s]
    assert len(ended) == 2 and all(s.startswith("short ended") for s in ended)
    cut = _tracks(long, None)[0].until(1.0)
    assert not cut.over(1.0) and cut.over(3.1) and cut.end_time == pytest.approx(3.0)


def test_a_prediction_is_drawn_from_where_it_starts(tmp_path, monkeypatch):
    """``render_continuation``: the observed frames (the last seconds of them), then the
    prediction as a figure of its own that appears where the observation ended."""
    from markovmotion.viz import animation

    drawn = {}
    monkeypatch.setattr(animation, "render", lambda items, path, **k: drawn.update(items=items))
    motion = make_motion(n_frames=90)  # 3 s at 30 fps, the last 1 s "predicted"
    animation.render_continuation(motion, 60, tmp_path / "p.gif", seconds_before=1.0)
    observed, predicted = drawn["items"]
    assert observed.n_frames == 30 and predicted.n_frames == 60  # from frame 30 on
    pos = predicted.positions()
    assert np.isnan(pos[:29]).all() and np.isfinite(pos[29:]).all()
    np.testing.assert_allclose(pos[29:], motion.positions()[59:])
    with pytest.raises(ValueError, match="first frame"):
        animation.render_continuation(motion, 0, tmp_path / "p.gif")


def test_a_strip_of_a_walk_follows_the_walker(real):
    """A walk across the room: each cell of a strip is a window on the walker at that time
    (each person was about 70 pixels tall in a window holding the whole 10 m), at one
    scale; a motion on the spot keeps the one window."""
    from markovmotion.viz.animation import _follow_window

    walk = real["bandai_bvh"]
    stage = _Stage.build(_tracks(walk, None), side_by_side=False, end=walk.duration)
    times = np.linspace(0, walk.duration, 6)
    follow = _follow_window(stage, times)
    assert follow is not None and follow.half[0] < stage.panels[0].half[0] / 2
    half = follow.half
    for t in times:  # the walker inside that window wherever the cell is centred
        screen, floor, _ = stage.pose(0, np.array([t]))
        pts = np.vstack([screen[0], floor[0]])
        assert np.all(pts.max(0) - pts.min(0) <= 2 * half)
    still = make_motion(n_frames=60)
    still.translations[:, 0] = still.translations[0, 0]  # on the spot
    stage = _Stage.build(_tracks(still, None), side_by_side=False, end=still.duration)
    assert _follow_window(stage, np.linspace(0, still.duration, 6)) is None


def test_an_animation_of_a_walk_follows_the_walker(real, tmp_path):
    """A GIF of a walk across the room: the window glides with the walker, who stays large
    and near the middle of every frame (in one window holding the whole walk the walker
    crossed it, about 70 pixels tall)."""
    from PIL import Image, ImageSequence

    from markovmotion.viz.animation import COLOURS

    walk = real["bandai_bvh"]
    path = render(walk, tmp_path / "walk.gif", fps=5)
    colour = np.array([int(COLOURS[0][k : k + 2], 16) for k in (1, 3, 5)])
    with Image.open(path) as gif:
        frames = [np.asarray(f.convert("RGB"), dtype=int) for f in ImageSequence.Iterator(gif)]
    assert len(frames) >= 10
    heights, middles = [], []
    for f in frames:
        ys, xs = np.nonzero(np.abs(f - colour).sum(axis=-1) < 60)
        heights.append((ys.max() - ys.min()) / f.shape[0])
        middles.append(xs.mean() / f.shape[1])
    assert min(heights) > 0.3
    assert 0.2 < min(middles) and max(middles) < 0.8


def test_blitting_restores_every_column_of_the_frame():
    """A figure 4.02 in wide at 100 dpi is 402 px, but its bbox is 401.99...: restoring that
    left the last column holding every frame's pixels (a grey line at a video's right edge)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from markovmotion.viz.animation import _whole

    fig = Figure(figsize=(4.02, 4.5), dpi=100)
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    assert canvas.copy_from_bbox(fig.bbox).get_extents() == (0, 0, 401, 450)  # the trap
    assert canvas.copy_from_bbox(_whole(canvas)).get_extents() == (0, 0, 402, 450)


def test_the_demo_on_a_users_own_walks_runs_what_it_can_and_says_what_it_skipped(
    mocap, tmp_path, capsys
):
    """``demo --data`` on a user's index of three walks (no CMU takes, no partners): the
    captured walk is the index's first walk, the PCA is of its walks, and every step that
    needs takes it does not hold is skipped and named after the table; an index with
    nothing a step can use is one line."""
    import shutil

    from markovmotion.errors import DataNotFoundError

    mine = tmp_path / "mine"
    (mine / "w").mkdir(parents=True)
    rows = ["file,source,subject,trial,category,label,partner_file,fps,frames,description"]
    for k, e in enumerate(mocap.query(source="bandai", label="normal")[:3]):
        shutil.copyfile(e.path, mine / "w" / f"{k}.bvh.gz")
        rows.append(f"w/{k}.bvh.gz,lab,me,{k},walk,normal,,{e.fps:g},{e.frames},my walk")
    (mine / "INDEX.csv").write_text("\n".join(rows) + "\n")
    capsys.readouterr()
    run_demo(tmp_path / "out", mine)
    assert (
        read_motion(tmp_path / "out" / "walk.bvh").n_frames
        == mocap.query(source="bandai", label="normal")[0].frames
    )
    assert (tmp_path / "out" / "pca-energy.png").stat().st_size > 0
    err = capsys.readouterr().err
    skipped = [ln for ln in err.splitlines() if ln.startswith("note: skipped on")]
    assert len(skipped) == len(STEPS) - 2 and all("mine/INDEX.csv" in ln for ln in skipped)
    from rich.console import Console

    from markovmotion.data import MocapIndex

    with pytest.raises(DataNotFoundError) as no_exercise:  # not "labelled None"
        vlmm_contours(tmp_path / "c", MocapIndex.load(mine), Console())
    assert str(no_exercise.value).startswith("exercise takes, at least 2: 0 in")
    (mine / "INDEX.csv").write_text(rows[0] + "\n")
    with pytest.raises(DataNotFoundError, match="no step of the demo.*the first: A captured"):
        run_demo(tmp_path / "none", mine)
    assert not (tmp_path / "none").exists()  # no empty folder left
