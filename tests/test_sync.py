"""Cameras started at different times: ``markovmotion video sync`` and ``skip_frames``."""

from __future__ import annotations

import dataclasses
import json

import cv2
import numpy as np
import pytest

from markovmotion.cli import main
from markovmotion.video.cameras import load_cameras, ring_of_cameras
from markovmotion.video.sync import (
    MIN_GAIN_ANGLE,
    epipolar_distances,
    estimate_offsets,
    fundamental,
)
from markovmotion.video.triangulation import ViewLandmarks


def _cameras(views: int = 3):
    return ring_of_cameras(np.array([0.0, 900.0, 0.0]), 3500.0, views, (272, 480))


def test_epipolar_distance_is_zero_on_true_pairs_and_agrees_with_brute_force():
    """A point seen by two cameras lies on its epipolar line; a pixel moved off it is as far
    from the line as brute force says: the other camera's ray through the pixel, two of its
    points projected, the distance from the line through them (both ways, averaged)."""
    rng = np.random.default_rng(0)
    cams = _cameras(2)
    pts = rng.uniform([-600, 0, -600], [600, 1800, 600], (30, 3))
    x0, x1 = (c.project(pts)[0] for c in cams)
    f = fundamental(*cams)
    assert epipolar_distances(f, x0, x1).max() < 1e-6
    moved = x1 + rng.normal(0, 5, x1.shape)
    got = epipolar_distances(f, x0, moved)

    def line_distance(src, dst, pixel, point):
        """Distance of ``point`` from the line that ``src``'s ray through ``pixel`` makes in
        ``dst``'s image: the ray's points at two depths, projected."""
        ray = np.linalg.inv(src.K) @ np.r_[pixel, 1.0]
        a, b = (dst.project((src.R.T @ (ray * z - src.t))[None])[0][0] for z in (1e3, 6e3))
        u, w = b - a, point - a
        return abs(u[0] * w[1] - u[1] * w[0]) / np.linalg.norm(u)

    brute = [
        0.5 * (line_distance(cams[0], cams[1], p0, p1) + line_distance(cams[1], cams[0], p1, p0))
        for p0, p1 in zip(x0, moved, strict=True)
    ]
    np.testing.assert_allclose(got, brute, rtol=1e-6, atol=1e-6)


def _moving_landmarks(frames: int, fps: float) -> np.ndarray:
    """(F, 33, 3) mm: 33 points on a body swaying and reaching, each its own way."""
    rng = np.random.default_rng(4)
    base = rng.uniform([-250, 100, -150], [250, 1750, 150], (33, 3))
    t = np.arange(frames)[:, None] / fps
    freq, phase = rng.uniform(0.4, 1.6, (2, 33))
    pts = np.repeat(base[None], frames, axis=0)
    pts[..., 0] += 200 * np.sin(2 * np.pi * freq * t + 6 * phase)
    pts[..., 1] += 120 * np.sin(2 * np.pi * 0.7 * freq * t + phase)
    return pts


@pytest.mark.parametrize("late", [0, 6, -4])
def test_offsets_of_cameras_started_late_are_found(late):
    """Camera 2's video starts ``late`` frames after the others' (its frame f shows their
    frame f + late): the offset is found, the others stay in step; a person standing still
    gives no offset."""
    fps, frames = 30.0, 120
    cams = _cameras(3)
    pts = _moving_landmarks(frames + 20, fps)
    pix = np.stack([c.project(pts.reshape(-1, 3))[0].reshape(frames + 20, 33, 2) for c in cams])
    pix = pix + np.random.default_rng(1).normal(0.0, 1.0, pix.shape)
    shown = pix[:, 10 : 10 + frames].copy()
    shown[2] = pix[2, 10 + late : 10 + late + frames]
    views = ViewLandmarks(cams, shown, np.ones(shown.shape[:3]))
    result = estimate_offsets(views, fps)
    assert result.offsets.tolist() == [0, 0, -late]
    if late:
        assert result.score_px[2] < 0.5 * result.score_none_px[2]
        skips = result.skips()
        assert skips.min() == 0 and skips[0] - skips[2] == late  # the others wait for it
    still = np.repeat(pix[:, :1], frames, axis=1)
    still = still + np.random.default_rng(2).normal(0.0, 1.0, still.shape)
    assert not estimate_offsets(
        ViewLandmarks(cams, still, np.ones(still.shape[:3])), fps
    ).offsets.any()


@pytest.mark.parametrize("scale", [1.0, 0.5])
def test_an_offset_is_judged_alike_at_half_the_image_size(scale):
    """The same cameras and person at half the image size (K halved, MediaPipe's jitter
    halved): every score halves, and the offset found at full size (2 frames, 16 % and 0.63
    px better than none) is still found; the gain asked for is in focal lengths, not pixels
    (0.5 px asked at any size would have turned down the 0.32 px of the half)."""
    fps, frames, late = 30.0, 120, 2
    cams = [
        dataclasses.replace(
            c,
            K=np.diag([scale, scale, 1.0]) @ c.K,
            width=int(c.width * scale),
            height=int(c.height * scale),
        )  # fmt: skip
        for c in _cameras(3)
    ]
    pts = _moving_landmarks(frames + 20, fps)
    pts = pts.mean(axis=0) + 1.1 * (pts - pts.mean(axis=0))
    pix = np.stack([c.project(pts.reshape(-1, 3))[0].reshape(frames + 20, 33, 2) for c in cams])
    pix = pix + np.random.default_rng(1).normal(0.0, 3.0 * scale, pix.shape)
    shown = pix[:, 10 : 10 + frames].copy()
    shown[2] = pix[2, 10 + late : 10 + late + frames]
    result = estimate_offsets(ViewLandmarks(cams, shown, np.ones(shown.shape[:3])), fps)
    assert result.offsets.tolist() == [0, 0, -late]
    gain = result.score_none_px[2] - result.score_px[2]
    assert 0.6 * scale < gain < 0.7 * scale
    assert gain >= MIN_GAIN_ANGLE * cams[2].focal  # asked in focal lengths: 0.35 px, 0.17 px
    if scale < 1:
        assert gain < 0.5  # 0.5 px, asked at any size, would have turned it down


def test_video_sync_measures_and_records_the_offsets_of_the_real_video(real_copy, capsys):
    """The real video with camera 1 made to start 10 frames late (``skip_frames``): ``video
    sync`` finds it (-10), and camera 2's own 3 frames (its landmarks 4.4 px from their
    epipolar lines so shifted, 5.6 as given; the reference's README measured the same);
    ``--write`` records skips that align all four, after which they are in step."""
    doc = json.loads((real_copy / "cameras.json").read_text())
    doc["cameras"][1]["skip_frames"] = 10
    (real_copy / "cameras.json").write_text(json.dumps(doc))
    main(["video", "sync", str(real_copy), "--json", "--write"])
    s = json.loads(capsys.readouterr().out)
    offsets = [c["offset_frames"] for c in s["cameras"].values()]
    # camera 2 within a frame of its own 3 (60 fps: with MediaPipe shown the frames enlarged,
    # 3 as the video is and 4 with camera 1's first 10 frames cut, 4.75 against 4.77 px)
    assert offsets[0] == 0 and abs(offsets[1] + 10) <= 1 and abs(offsets[2] - 3) <= 1
    assert offsets[3] == 0
    cams, _ = load_cameras(real_copy)
    assert [c.skip for c in cams] == [0, 10 + offsets[1], offsets[2], 0]
    main(["video", "sync", str(real_copy), "--json"])
    again = json.loads(capsys.readouterr().out)
    assert again["in_step"] or all(abs(c["offset_frames"]) <= 1 for c in again["cameras"].values())


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        ({"skip_frames": -1}, "skip_frames must be a whole number"),
        ({"skip_frames": 2.5}, "skip_frames must be a whole number"),
        ({"skip_frames": True}, "skip_frames must be a whole number"),
    ],
)
def test_a_bad_skip_is_one_line(real_copy, capsys, edit, message):
    doc = json.loads((real_copy / "cameras.json").read_text())
    doc["cameras"][0].update(edit)
    (real_copy / "cameras.json").write_text(json.dumps(doc))
    with pytest.raises(SystemExit) as exc:
        main(["video", "sync", str(real_copy)])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1


def test_sync_needs_every_camera_and_a_writable_file(real_copy, capsys, monkeypatch):
    with pytest.raises(SystemExit) as exc:
        main(["video", "sync", str(real_copy / "cam0.mp4")])
    assert exc.value.code == 2
    assert "needs the folder of every camera" in capsys.readouterr().err
    before = (real_copy / "cameras.json").read_bytes()

    def refused(*args, **kwargs):  # a read-only folder (chmod does not stop root)
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr("markovmotion.io.files.atomic_write", refused)
    with pytest.raises(SystemExit) as exc:
        main(["video", "sync", str(real_copy), "--write", "--max-frames", "30"])
    assert exc.value.code == 2
    assert (real_copy / "cameras.json").read_bytes() == before
    err = capsys.readouterr().err.strip()
    assert "cannot write the offsets here" in err and len(err.splitlines()) == 1


def test_a_camera_that_cannot_be_measured_is_said_and_not_written(real_copy, capsys):
    """On 8 frames too few landmarks are seen in camera 1 and the first camera together: it is
    'not measured' (JSON None), the cameras are not called in step, and --write refuses."""
    from markovmotion.video.sync import MIN_PAIRS

    cams, _ = load_cameras(real_copy)
    fps, frames = 30.0, 8
    pts = _moving_landmarks(frames, fps)
    pix = np.stack([c.project(pts.reshape(-1, 3))[0].reshape(frames, 33, 2) for c in cams])
    vis = np.ones(pix.shape[:3])
    vis[1, :, : 33 - MIN_PAIRS // frames + 2] = 0.0  # camera 1 sees too little
    result = estimate_offsets(ViewLandmarks(cams, pix, vis), fps)
    assert not result.measured[1] and result.measured[[0, 2, 3]].all()
    assert not result.in_step and result.summary(fps)["cam1"]["offset_frames"] is None
    from markovmotion.errors import MotionFormatError
    from markovmotion.video.sync import write_skips

    with pytest.raises(MotionFormatError, match="cam1 could not be measured"):
        write_skips(real_copy, result)


def test_skipped_frames_are_counted_everywhere_and_a_skip_past_the_end_is_one_line(
    real_copy, capsys
):
    """A camera skipping 60 of its 100 frames: its reader gives 40, the progress bar expects
    40, the background is spread over those 40; skipping 150 is one line naming the camera."""
    from markovmotion.video.render import expected_frames, read_frames, spread_frames

    cams, _ = load_cameras(real_copy)
    cam = dataclasses.replace(cams[0], skip=60)
    video = real_copy / cam.video
    skipped = list(read_frames(video, cam))
    whole = list(read_frames(video, dataclasses.replace(cam, skip=0)))
    assert len(skipped) == 40 and all(
        np.array_equal(a, b) for a, b in zip(skipped, whole[60:], strict=True)
    )
    folder = real_copy / "frames"  # a folder of images skips its first files
    folder.mkdir()
    for i, frame in enumerate(whole[58:63]):
        cv2.imwrite(str(folder / f"{i:03d}.png"), cv2.cvtColor(frame, cv2.COLOR_RGB2BGR))
    got = list(read_frames(folder, dataclasses.replace(cam, skip=2, distortion=())))
    assert len(got) == 3 and np.array_equal(got[0], whole[60])
    assert expected_frames([video], None, [cam]) == 40
    assert len(spread_frames(video, 31, cam)) == 31
    doc = json.loads((real_copy / "cameras.json").read_text())
    doc["cameras"][0]["skip_frames"] = 150
    (real_copy / "cameras.json").write_text(json.dumps(doc))
    for method in ("monocular", "triangulate"):
        with pytest.raises(SystemExit) as exc:
            main(["track", "--video", str(real_copy), "--method", method])
        assert exc.value.code == 2
        err = capsys.readouterr().err.strip()
        assert "camera cam0 skips 150 frames (skip_frames) but its video has 100" in err, err
        assert len(err.splitlines()) == 1
