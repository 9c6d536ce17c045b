"""The body model's size: scaled bones, and the size measured back from body points."""

from __future__ import annotations

import numpy as np
import pytest

from markovmotion.features.body_points import BODY_POINTS
from markovmotion.video.body_size import body_size_from_points, scaled_body


def _bone(points: np.ndarray, a: str, b: str) -> np.ndarray:
    return np.linalg.norm(
        points[..., BODY_POINTS.index(a), :] - points[..., BODY_POINTS.index(b), :], axis=-1
    )


def test_scaled_bones_and_size_measured_back(body):
    """Poses of the body scaled by (0.9, 0.95, 1.1): shins, forearms and shoulders' width
    scale by their factors; measured from those poses, the leg and arm ratios are
    0.9 * 0.95 and 0.9 * 1.1, so the size is (sqrt of their product, and each over it)."""
    rng = np.random.default_rng(0)
    states = np.tile(body.standing(np.array([100.0, body.height, -50.0])), (20, 1))
    span = np.where(np.isfinite(body.upper), body.upper - body.lower, 0.0)
    states[:, 4:] += rng.uniform(-0.3, 0.3, (20, body.n_dof - 4)) * span[4:]
    body.clip(states)
    size = (0.9, 0.95, 1.1)
    small = scaled_body(body, *size)
    a, b = body.joint_positions(states), small.joint_positions(states)
    assert np.allclose(
        _bone(b, "left_knee", "left_ankle"), 0.9 * 0.95 * _bone(a, "left_knee", "left_ankle")
    )
    assert np.allclose(
        _bone(b, "right_elbow", "right_wrist"), 0.9 * 1.1 * _bone(a, "right_elbow", "right_wrist")
    )
    assert np.allclose(
        _bone(b, "left_shoulder", "right_shoulder"),
        0.9 * _bone(a, "left_shoulder", "right_shoulder"),
    )
    assert small.height == pytest.approx(body.height * 0.9 * 0.95)
    leg, arm = 0.9 * 0.95, 0.9 * 1.1
    scale = np.sqrt(leg * arm)
    assert body_size_from_points(body, b) == pytest.approx((scale, leg / scale, arm / scale))
    assert body_size_from_points(body, a) == pytest.approx((1.0, 1.0, 1.0), rel=1e-6)


def test_implausible_size_is_refused(body):
    pts = body.joint_positions(body.standing(np.array([0.0, body.height, 0.0])))
    pts[..., 1] *= 3.0  # a giant's legs and arms
    with pytest.raises(ValueError, match="not a measurement to trust"):
        body_size_from_points(body, pts)


def test_segments_scaled_and_measured_back_in_any_pose(body):
    """Each segment (upper arm, forearm, thigh, shin, the shoulders' width) scaled by its own
    factor keeps its length in every pose (the others unchanged), and is measured back from
    poses of the scaled body, frames with a point unseen left out; implausible sizes refused."""
    from markovmotion.video.body_size import segment_body, segment_sizes_from_points

    rng = np.random.default_rng(1)
    states = np.tile(body.standing(np.array([0.0, body.height, 0.0])), (15, 1))
    span = np.where(np.isfinite(body.upper), body.upper - body.lower, 0.0)
    states[:, 4:] += rng.uniform(-0.3, 0.3, (15, body.n_dof - 4)) * span[4:]
    body.clip(states)
    want = {"shoulder-elbow": 0.9, "elbow-wrist": 1.3, "hip-knee": 0.92, "knee-ankle": 0.88,
            "shoulders-width": 0.95}  # fmt: skip
    sized = segment_body(body, want)
    a, b = body.joint_positions(states), sized.joint_positions(states)
    for (p, q), f in (
        (("left_elbow", "left_wrist"), 1.3),
        (("right_knee", "right_ankle"), 0.88),
        (("left_shoulder", "right_shoulder"), 0.95),
        (("left_ankle", "left_toe"), 1.0),
        (("neck", "head"), 1.0),
        (("left_hip", "right_hip"), 1.0),
    ):
        assert np.allclose(_bone(b, p, q), f * _bone(a, p, q)), (p, q)
    assert sized.height < body.height  # shorter legs stand lower
    b[3, BODY_POINTS.index("left_elbow")] = np.nan
    assert segment_sizes_from_points(body, b) == pytest.approx(want)
    assert segment_sizes_from_points(body, a) == pytest.approx(dict.fromkeys(want, 1.0))
    notes: list[str] = []
    wide = b.copy()  # one implausible segment: the template's kept for it alone, and said
    wide[:, BODY_POINTS.index("left_ankle"), 1] -= 2000.0
    wide[:, BODY_POINTS.index("right_ankle"), 1] -= 2000.0
    got = segment_sizes_from_points(body, wide, notes)
    assert got == pytest.approx({k: v for k, v in want.items() if k != "knee-ankle"})
    assert len(notes) == 1 and "knee-ankle" in notes[0] and "template" in notes[0]
    b *= 3.0  # every segment three times the template's: nothing to trust
    with pytest.raises(ValueError, match="not a measurement to trust"):
        segment_sizes_from_points(body, b)


def test_body_size_from_every_camera_on_the_real_video(capsys):
    """``track --body-size views`` on the real 4-view video: the man's segments measured from
    MediaPipe triangulated, within the plausible range, in the summary; one camera's video is
    one line."""
    import json

    from markovmotion.cli import main
    from markovmotion.data.index import data_root

    video = data_root().parent / "video" / "pose2sim_balancing"
    main(["track", "--video", str(video), "--body-size", "views", "--max-frames", "20",
          "--particles", "10", "--layers", "2", "--json"])  # fmt: skip
    size = json.loads(capsys.readouterr().out)["body_size"]
    assert set(size) == {"shoulder-elbow", "elbow-wrist", "hip-knee", "knee-ankle",
                         "shoulders-width"}  # fmt: skip
    assert 0.8 < size["knee-ankle"] < 1.0 and 1.1 < size["elbow-wrist"] < 1.6  # his forearms
    with pytest.raises(SystemExit) as exc:
        main(["track", "--video", str(video / "cam0.mp4"), "--body-size", "views"])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip()
    assert "every camera" in err and len(err.splitlines()) == 1
