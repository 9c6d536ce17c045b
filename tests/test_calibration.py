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
