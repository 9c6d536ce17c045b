"""Cameras from a Pose2Sim / Anipose calibration (Calib.toml) for the real 4-view video."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from markovmotion.cli import main
from markovmotion.data.index import data_root
from markovmotion.errors import MotionFormatError
from markovmotion.video.calibration import UP_AXES, cameras_from_toml
from markovmotion.video.cameras import load_cameras

FULL = (1088, 1920)  # the size the real cameras were calibrated at (4x the videos)
LENS = [-0.000721609375, 0.002187234375, 9.5e-06, 1.078125e-05]


@pytest.fixture(scope="module")
def real_video():
    return data_root().parent / "video" / "pose2sim_balancing"


def _toml(cameras, fisheye: bool = False) -> str:
    """A Pose2Sim Calib.toml of ``cameras`` (the project's), as Pose2Sim writes it: Z up,
    metres, intrinsics of the full-size images, OpenCV's Rodrigues rotation."""
    out = []
    for k, c in enumerate(cameras):
        s = np.array([FULL[0] / c.width, FULL[1] / c.height])
        K = c.K.copy()
        K[:2, :2] *= s[:, None]
        K[:2, 2] = (K[:2, 2] + 0.5) * s - 0.5
        rvec = cv2.Rodrigues(c.R @ UP_AXES["z"])[0].ravel()
        out += [
            f"[cam_{k + 1:02d}]",
            f'name = "cam_{k + 1:02d}"',
            f"size = [{FULL[0]:.1f}, {FULL[1]:.1f}]",
            f"matrix = {K.tolist()}",
            f"distortions = {LENS}",
            f"rotation = {rvec.tolist()}",
            f"translation = {(c.t / 1000).tolist()}",
            f"fisheye = {'true' if fisheye else 'false'}",
            "",
        ]
    return "\n".join(out + ["[metadata]", "adjusted = false", "error = 0.0", ""])


def _videos(real_video, tmp_path, n: int = 4):
    videos = []
    for k in range(n):
        (tmp_path / f"cam{k}.mp4").symlink_to(real_video / f"cam{k}.mp4")
        videos.append(tmp_path / f"cam{k}.mp4")
    return videos


def test_a_pose2sim_calibration_gives_the_cameras_of_the_real_video(real_video, tmp_path):
    """The real video's cameras written as Pose2Sim writes them (full-size intrinsics, Z up,
    metres, a Rodrigues rotation) come back as the same cameras for the quarter-size videos:
    the same pixels for every point, the lens kept; `video cameras` writes them beside the
    videos, and replaces a camera file only with --force."""
    truth, _ = load_cameras(real_video)
    calib = tmp_path / "Calib.toml"
    calib.write_text(_toml(truth))
    videos = _videos(real_video, tmp_path)
    got = cameras_from_toml(calib, videos)
    pts = np.random.default_rng(0).uniform([-800, 0, -800], [800, 1900, 800], (200, 3))
    for a, b in zip(truth, got, strict=True):
        assert (b.width, b.height) == (a.width, a.height) and b.video == a.video
        assert np.abs(a.project(pts)[0] - b.project(pts)[0]).max() < 1e-6
        assert b.distortion == pytest.approx(LENS)
    main(["video", "cameras", str(calib), *map(str, videos)])
    written, doc = load_cameras(tmp_path)
    assert doc["fps"] == 60.0 and [c.name for c in written] == [f"cam_0{k}" for k in range(1, 5)]
    with pytest.raises(SystemExit) as stop:  # nothing is lost: the file is there
        main(["video", "cameras", str(calib), *map(str, videos)])
    assert stop.value.code == 2
    main(["video", "cameras", str(calib), *map(str, videos), "--force", "--fps", "30"])
    assert load_cameras(tmp_path)[1]["fps"] == 30.0


def test_videos_given_in_another_order_than_the_cameras_are_refused(real_video, tmp_path, capsys):
    """Cameras cam_01 ... cam_04 with videos cam1.mp4 ... cam4.mp4 given as 2, 1, 3, 4: one
    line naming the order that matches, exit 2, nothing written; in their order, written."""
    truth, _ = load_cameras(real_video)
    calib = tmp_path / "Calib.toml"
    calib.write_text(_toml(truth))
    videos = []
    for k in range(4):
        (tmp_path / f"cam{k + 1}.mp4").symlink_to(real_video / f"cam{k}.mp4")
        videos.append(tmp_path / f"cam{k + 1}.mp4")
    swapped = [videos[1], videos[0], *videos[2:]]
    with pytest.raises(SystemExit) as stop:
        main(["video", "cameras", str(calib), *map(str, swapped)])
    err = capsys.readouterr().err
    assert stop.value.code == 2 and len(err.strip().splitlines()) == 1
    assert "another order" in err and "cam1.mp4 cam2.mp4 cam3.mp4 cam4.mp4" in err
    assert not (tmp_path / "cameras.json").exists()
    main(["video", "cameras", str(calib), *map(str, videos)])
    assert [c.name for c in load_cameras(tmp_path)[0]] == [f"cam_0{k}" for k in range(1, 5)]


@pytest.mark.parametrize(
    ("edit", "n_videos", "message"),
    [
        (lambda t: t, 3, "4 cameras but 3 videos"),
        (lambda t: t.replace("fisheye = false", "fisheye = true"), 4, "fisheye"),
        (lambda t: t.replace("1088.0, 1920.0", "1920.0, 1088.0"), 4, "another shape"),
        (lambda t: t.replace("translation = [", "translation = [1, "), 4, "translation must be"),
        (lambda t: t + "[[[", 4, "not a TOML"),
        (lambda t: t.replace("distortions = [", "distortions = [1, 2, "), 4, "distortions must be"),
    ],
)
def test_a_bad_calibration_is_one_line(real_video, tmp_path, edit, n_videos, message):
    truth, _ = load_cameras(real_video)
    calib = tmp_path / "Calib.toml"
    calib.write_text(edit(_toml(truth)))
    with pytest.raises(MotionFormatError, match=message):
        cameras_from_toml(calib, _videos(real_video, tmp_path)[:n_videos])


def test_a_calibration_that_is_not_a_file_is_one_line_not_a_hang(tmp_path, capsys):
    """A pipe, a folder or a huge file named as the calibration: exit 2, one line."""
    import os

    os.mkfifo(tmp_path / "pipe.toml")
    (tmp_path / "big.toml").write_bytes(b"#" * 2_000_000)
    for name, message in (("pipe.toml", "no such calibration file"), (".", "no such calibration"),
                          ("big.toml", "larger than")):  # fmt: skip
        with pytest.raises(SystemExit) as stop:
            main(["video", "cameras", str(tmp_path / name), str(tmp_path / "v.mp4")])
        err = capsys.readouterr().err
        assert stop.value.code == 2 and message in err and "Traceback" not in err


def _qca(cameras, serials, extra: str = "") -> str:
    """A Qualisys .qca.txt of ``cameras`` (the project's) as QTM writes it: sub-pixel units
    (1/64 px) of the full-size images, each camera's position (mm) and orientation in a Z-up
    world, camera axes OpenCV's turned half a turn about x; ``extra``: more camera elements."""
    cams = []
    for c, serial in zip(cameras, serials, strict=True):
        s = np.array([FULL[0] / c.width, FULL[1] / c.height])
        K = c.K.copy()
        K[:2, :2] *= s[:, None]
        K[:2, 2] = (K[:2, 2] + 0.5) * s - 0.5
        r = c.R @ UP_AXES["z"]  # Z-up world to OpenCV's camera axes
        m = np.diag([1.0, -1.0, -1.0]) @ r
        pos = -r.T @ c.t
        rot = " ".join(f'r{i + 1}{j + 1}="{float(m[i, j])!r}"' for i in range(3) for j in range(3))
        lens = (
            f'radialDistortion1="{LENS[0] * 64}" radialDistortion2="{LENS[1] * 64}" '
            f'radialDistortion3="0" tangentalDistortion1="{LENS[2] * 64}" '
            f'tangentalDistortion2="{LENS[3] * 64}"'
        )
        cams.append(
            f'<camera active="1" model="Miqus Video" serial="{serial}">'
            f'<fov_video left="0" top="0" right="{FULL[0] - 1}" bottom="{FULL[1] - 1}"/>'
            f'<transform {rot} x="{float(pos[0])!r}" y="{float(pos[1])!r}" z="{float(pos[2])!r}"/>'
            f'<intrinsic focalLengthU="{float(K[0, 0] * 64)!r}" focalLengthV="{float(K[1, 1] * 64)!r}" '
            f'centerPointU="{float(K[0, 2] * 64)!r}" centerPointV="{float(K[1, 2] * 64)!r}" {lens}/>'
            "</camera>"
        )
    return (
        "<?xml version='1.0' encoding='ASCII'?><calibration><cameras>"
        + extra + "".join(cams) + "</cameras></calibration>"
    )  # fmt: skip


def test_a_qualisys_calibration_gives_the_cameras_of_the_real_video(real_video, tmp_path):
    """The real video's cameras written as Qualisys writes them (the file its calibration
    came from) come back as the same cameras: marker-only cameras skipped, the video cameras
    in the natural order of their serials (cam2 before cam10), the lens as Pose2Sim reads it."""
    from markovmotion.video.calibration import cameras_from_qca

    truth, _ = load_cameras(real_video)
    marker_only = '<camera active="1" model="Miqus M3" serial="m1"/>'
    calib = tmp_path / "Calib.qca.txt"
    # written out of order: the reader sorts cam2, cam3, cam4 before cam10
    order = ["cam10", "cam2", "cam3", "cam4"]
    calib.write_text(_qca([truth[3], truth[0], truth[1], truth[2]], order, marker_only))
    videos = _videos(real_video, tmp_path)
    got = cameras_from_qca(calib, [videos[1], videos[2], videos[3], videos[0]])
    assert [c.name for c in got] == ["cam2", "cam3", "cam4", "cam10"]
    pts = np.random.default_rng(0).uniform([-800, 0, -800], [800, 1900, 800], (200, 3))
    for a, b in zip([truth[0], truth[1], truth[2], truth[3]], got, strict=True):
        assert (b.width, b.height) == (a.width, a.height)
        assert np.abs(a.project(pts)[0] - b.project(pts)[0]).max() < 1e-6
        assert b.distortion == pytest.approx(LENS)
    main(["video", "cameras", str(calib), *map(str, [videos[1], videos[2], videos[3], videos[0]])])
    assert len(load_cameras(tmp_path)[0]) == 4


@pytest.mark.parametrize(
    ("text", "says"),
    [
        ("<calibration><cameras>", "not a Qualisys calibration file"),
        ("", "not a Qualisys calibration file"),  # empty: told by its name, not as a TOML
        ('<?xml version="1.0"?><!DOCTYPE c [<!ENTITY a "aaaa">]><calibration/>', "DOCTYPE"),
        ('<calibration><cameras><camera serial="c1"/></cameras></calibration>', "needs fov_video"),
        ("<calibration><cameras></cameras></calibration>", "0 video cameras"),
    ],
)
def test_a_bad_qualisys_calibration_is_one_line(real_video, tmp_path, capsys, text, says):
    calib = tmp_path / "Calib.qca.txt"
    calib.write_text(text)
    videos = _videos(real_video, tmp_path, 1)
    with pytest.raises(SystemExit) as stop:
        main(["video", "cameras", str(calib), str(videos[0])])
    err = capsys.readouterr().err.strip()
    assert stop.value.code == 2 and says in err and "Traceback" not in err
    assert len(err.splitlines()) == 1


def test_a_missing_video_is_named(real_video, tmp_path, capsys):
    truth, _ = load_cameras(real_video)
    calib = tmp_path / "Calib.qca.txt"
    calib.write_text(_qca(truth[:1], ["cam1"]))
    with pytest.raises(SystemExit) as stop:
        main(["video", "cameras", str(calib), str(tmp_path / "nope.mp4")])
    err = capsys.readouterr().err.strip()
    assert stop.value.code == 2 and err.endswith("nope.mp4: no such video file")


def test_a_video_stretched_to_another_width_is_said(real_video, tmp_path, capsys):
    """A video of a slightly other shape than its calibration (Pose2Sim's cam01/cam02 are
    1080x1920 against a calibration at 1088x1920) is taken, its intrinsics scaled along each
    axis, and said; the same shape is not."""
    truth, _ = load_cameras(real_video)
    calib = tmp_path / "Calib.toml"
    calib.write_text(_toml(truth).replace("1088.0, 1920.0", "1096.0, 1920.0", 1))
    got = cameras_from_toml(calib, _videos(real_video, tmp_path))
    err = capsys.readouterr().err
    assert err.count("note:") == 1 and "cam0.mp4 is 272x480" in err and "1096x1920" in err
    assert got[0].K[0, 0] == pytest.approx(truth[0].K[0, 0] * 1088 / 1096, rel=1e-3)
    assert got[0].K[1, 1] == pytest.approx(truth[0].K[1, 1], rel=1e-3)


def test_a_lone_video_the_camera_file_does_not_name_is_said_to_be_the_first(tmp_path, capsys):
    """A user's ``--video myclip.mp4 --cameras cameras.json`` of four cameras was tracked
    through the first camera's calibration without a word (510 mm at confidence 0.95 for
    cam1's footage): now a note names the camera taken. A file that is no video at all (a
    README) is that one line, not the note and then the error."""
    from markovmotion.data.index import data_root
    from markovmotion.errors import MotionFormatError
    from markovmotion.video.cameras import camera_of_video, load_cameras

    real = data_root().parent / "video" / "pose2sim_balancing"
    cams, _ = load_cameras(real)
    assert camera_of_video(cams, "somewhere/cam2.mp4") == 2
    assert capsys.readouterr().err == ""
    (tmp_path / "myclip.mp4").symlink_to(real / "cam1.mp4")
    assert camera_of_video(cams, tmp_path / "myclip.mp4") == 0
    err = capsys.readouterr().err
    assert "myclip.mp4 is not a video the camera file names" in err and "cam0.mp4" in err
    with pytest.raises(MotionFormatError, match="cannot read this video"):
        camera_of_video(cams, real / "README.md")
    assert capsys.readouterr().err == ""


def test_a_video_at_another_rate_than_the_camera_file_is_said(tmp_path, capsys):
    """The camera file's fps is the one used; a video whose own header says another rate
    (re-encoded at 30 fps under a file saying 60) was tracked at the wrong speed, and paired
    with a reference frame by frame, without a word: now a note names both rates."""
    import json
    import shutil

    from markovmotion.data.index import data_root
    from markovmotion.video.cameras import load_cameras

    real = data_root().parent / "video" / "pose2sim_balancing"
    doc = json.loads((real / "cameras.json").read_text())
    doc["cameras"] = doc["cameras"][:1]
    shutil.copyfile(real / doc["cameras"][0]["video"], tmp_path / doc["cameras"][0]["video"])
    (tmp_path / "cameras.json").write_text(json.dumps(doc))
    load_cameras(tmp_path)
    assert capsys.readouterr().err == ""  # 60 and 60
    doc["fps"] = 30.0
    (tmp_path / "cameras.json").write_text(json.dumps(doc))
    load_cameras(tmp_path)
    assert "cam0.mp4 is 60 fps by its own header, the camera file says 30" in (
        capsys.readouterr().err
    )


def test_a_wrong_unit_or_up_axis_is_said(real_video, tmp_path, capsys):
    """A Pose2Sim file (metres, Z up) read with ``--units mm`` put the cameras 7 mm apart, and
    with ``--up y`` laid the person on their side; both tracked at confidence 0.93 without a
    word (a new user's trial). Now each gets a note; the right reading gets none."""
    from markovmotion.cli import main

    truth, _ = load_cameras(real_video)
    calib = tmp_path / "Calib.toml"
    calib.write_text(_toml(truth))
    videos = [str(v) for v in _videos(real_video, tmp_path)]
    for extra, says in (([], None), (["--units", "mm"], "at most 7 mm from one another"),
                        (["--up", "y"], "below the floor")):  # fmt: skip
        main(["video", "cameras", str(calib), *videos, "--out", str(tmp_path / "c.json"),
              "--force", *extra])  # fmt: skip
        err = capsys.readouterr().err
        assert ("note:" not in err) if says is None else (says in err), (extra, err)


def test_a_calibration_of_six_cameras_is_read(real_video, tmp_path):
    """A Pose2Sim file of six cameras had been refused ("1 to 4 are read"); a seventh is
    still refused (defaults.MAX_CAMERAS). The real four cameras, the first two again."""
    truth, _ = load_cameras(real_video)
    for n in (6, 7):
        calib = tmp_path / f"Calib{n}.toml"
        calib.write_text(_toml([truth[k % 4] for k in range(n)]))
        videos = []
        for k in range(n):
            video = tmp_path / f"v{n}" / f"cam{k}.mp4"
            video.parent.mkdir(exist_ok=True)
            video.symlink_to(real_video / f"cam{k % 4}.mp4")
            videos.append(video)
        if n == 6:
            main(["video", "cameras", str(calib), *map(str, videos)])
            assert len(load_cameras(videos[0].parent)[0]) == 6
        else:
            with pytest.raises(MotionFormatError, match="7 cameras .*: 1 to 6 are read"):
                cameras_from_toml(calib, videos)
