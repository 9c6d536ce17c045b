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
