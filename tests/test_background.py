"""The background behind a person: the check of a median background, and learning it where
the person is not (synthetic scenes; the real 4-view video when MediaPipe is installed)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from markovmotion.data.index import data_root
from markovmotion.video.background import (
    HELD_LIMIT,
    BackgroundCheck,
    background_note,
    check_background,
    learn_background,
    person_background,
    person_masks,
)
from markovmotion.video.monocular import LANDMARKS


def _scene(moves: float, frames: int = 21, seed: int = 0):
    """A textured scene with a grey block (the person) sliding ``moves`` px over the frames."""
    rng = np.random.default_rng(seed)
    scene = rng.integers(0, 255, (60, 80, 3), dtype=np.uint8)
    out, masks = [], np.zeros((frames, 60, 80), dtype=bool)
    for f in range(frames):
        x = int(round(10 + moves * f / (frames - 1)))
        img = scene.copy()
        img[15:50, x : x + 12] = 128
        masks[f, 15:50, x : x + 12] = True
        out.append(img)
    return scene, out, masks


def test_a_still_person_is_held_by_the_median_and_learnt_away():
    scene, frames, masks = _scene(moves=6)  # barely moves: half its width
    check = check_background(masks)
    assert check.holds_person and check.held > HELD_LIMIT and 0 < check.unseen < check.held
    assert "still holds the person" in check.message("cam0")
    plain = np.median(np.stack(frames), axis=0).astype(np.uint8)
    learnt = person_background(frames, masks)
    seen = ~masks.all(axis=0)  # pixels uncovered in some frame: the scene itself
    assert (plain[seen] != scene[seen]).any()
    assert np.array_equal(learnt[seen], scene[seen])


def test_a_moving_person_leaves_the_median_empty():
    _, frames, masks = _scene(moves=60)
    check = check_background(masks)
    assert not check.holds_person and check.unseen == 0.0
    assert "empty scene" in check.message("cam1")


def test_the_backgrounds_of_every_camera_are_one_note_naming_them():
    """The cameras without an empty-scene image are said in one line naming them (it had been
    a line per camera); none without such cameras."""
    held, empty = BackgroundCheck(0.81, 0.01, 100.0), BackgroundCheck(0.05, 0.0, 100.0)
    lines = background_note([("cam0", held), ("cam2", empty), ("cam3", held)])
    assert len(lines) == 1 and lines[0].startswith("note: cam0, cam2, cam3: no empty-scene image")
    assert "still holds the person in cam0 (81% of their mean silhouette; 1% never " \
        "uncovered), cam3 (81%; 1%): give an empty-scene image" in lines[0]  # fmt: skip
    assert lines[0].endswith("the plain median is the empty scene in cam2 (holds 5%)")
    plain = background_note([("cam0", None), ("cam1", None)], "MediaPipe not installed")
    assert plain == [
        "note: cam0, cam1: median background (no empty-scene image), not checked for the "
        "person (MediaPipe not installed)"
    ]
    assert background_note([]) == []


def test_person_mask_covers_the_landmarks_and_little_else():
    pixels = np.zeros((1, len(LANDMARKS), 2))
    at = {n: i for i, n in enumerate(LANDMARKS)}
    pose = {
        "left_shoulder": (60, 40),
        "right_shoulder": (40, 40),
        "left_hip": (57, 90),
        "right_hip": (43, 90),
        "left_elbow": (65, 65),
        "right_elbow": (35, 65),
        "left_wrist": (66, 88),
        "right_wrist": (34, 88),
        "left_knee": (56, 125),
        "right_knee": (44, 125),
        "left_ankle": (56, 160),
        "right_ankle": (44, 160),
        "left_heel": (56, 165),
        "right_heel": (44, 165),
        "left_foot_index": (60, 168),
        "right_foot_index": (40, 168),
    }
    for n in LANDMARKS:
        pixels[0, at[n]] = pose.get(n, (50 + (at[n] % 3) - 1, 25))
    mask = person_masks(pixels, np.ones((1, len(LANDMARKS))), (200, 100))[0]
    p = np.round(pixels[0]).astype(int)
    assert mask[p[:, 1], p[:, 0]].all()
    assert mask.mean() < 0.3 and not mask[:, :15].any() and not mask[:, 85:].any()


def test_real_video_median_holds_the_balancing_man():
    """cam2 of the real 4-view video: the man barely leaves his spot on the treadmill, so the
    plain median holds him; the learnt background is much nearer the hand-made plate."""
    try:
        import mediapipe  # noqa: F401
    except ImportError:
        pytest.fail("these tests need MediaPipe: run scripts/install-camera", pytrace=False)
    folder = data_root().parent / "video" / "pose2sim_balancing"
    plain, learnt, check = learn_background(folder / "cam2.mp4", frames=15)
    assert check.holds_person
    plate = cv2.cvtColor(cv2.imread(str(folder / "cam2_background.png")), cv2.COLOR_BGR2RGB)

    def off(img: np.ndarray) -> int:
        return int((np.abs(img.astype(int) - plate.astype(int)).max(axis=2) > 30).sum())

    assert off(learnt) < off(plain) / 3


def test_track_bad_background_or_reference_is_one_line(tmp_path, capsys):
    from markovmotion.cli import main

    folder = data_root().parent / "video" / "pose2sim_balancing"
    for extra, message in (
        (["--reference", str(tmp_path / "none.csv")], "no such reference file"),
        (["--background", "plate"], "--background"),
    ):
        with pytest.raises(SystemExit) as exc:
            main(["track", "--video", str(folder), *extra])
        assert exc.value.code == 2
        err = capsys.readouterr().err.strip()
        assert message in err and len(err.splitlines()) == 1


def test_the_learnt_background_is_the_median_of_the_frames_without_the_person():
    """Band by band, the median of each pixel's uncovered frames (the plain median where the
    person always covers it) agrees with NumPy's nanmedian over the whole stack (brute force),
    bands of rows cut anywhere."""
    import warnings

    from markovmotion.video import background

    rng = np.random.default_rng(0)
    for n, h, w in ((1, 5, 4), (4, 70, 9), (11, 130, 7)):
        frames = [rng.integers(0, 256, (h, w, 3), dtype=np.uint8) for _ in range(n)]
        masks = rng.random((n, h, w)) < 0.6
        masks[:, 0, 0] = True  # always covered
        stack = np.stack(frames).astype(np.float32)
        hidden = stack.copy()
        hidden[masks] = np.nan
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            clean = np.nanmedian(hidden, axis=0)
        expected = np.where(np.isfinite(clean), clean, np.median(stack, axis=0))
        got = background.person_background(frames, masks)
        assert np.array_equal(got, np.round(expected).astype(np.uint8))
