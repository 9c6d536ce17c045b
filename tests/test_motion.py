"""Motion edits: resampling, trimming, heading, body-centred positions, real-data sanity."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import make_motion
from scipy.spatial.transform import Rotation

from markovmotion import Motion


def test_resample_keeps_the_motion():
    m = make_motion(n_frames=61, fps=60)
    half = m.resample(30)
    assert half.fps == 30 and half.n_frames == 31
    np.testing.assert_allclose(half.positions(), m.positions()[::2], atol=1e-9)
    up = half.resample(60)
    assert up.n_frames == 61
    # slerp between frames stays close to the original smooth motion
    assert np.abs(up.positions() - m.positions()).max() < 5.0


def test_resample_slerp_is_halfway():
    m = make_motion(n_frames=2, fps=1)
    m.rotations[:, 1] = Rotation.from_rotvec([[0, 0, 0], [0, 0, 1.0]]).as_quat()
    mid = m.resample(2).rotations[1, 1]
    np.testing.assert_allclose(Rotation.from_quat(mid).as_rotvec(), [0, 0, 0.5], atol=1e-12)


def test_trim():
    m = make_motion(n_frames=20)
    t = m.trim(5, 15)
    assert t.n_frames == 10
    np.testing.assert_array_equal(t.rotations, m.rotations[5:15])


def turned(m: Motion, yaw: float) -> Motion:
    out = m.copy()
    turn = Rotation.from_rotvec([0, yaw, 0])
    out.rotations[:, 0] = (turn * Rotation.from_quat(m.rotations[:, 0])).as_quat()
    out.translations[:, 0] = turn.apply(m.translations[:, 0])
    return out


def test_heading_follows_a_turn_and_body_centred_ignores_it():
    m = make_motion()
    assert m.hip_joints() == (1, 2)  # lleg / rleg told apart by their names
    for yaw in (0.3, -2.0, 3.0):
        t = turned(m, yaw)
        diff = np.angle(np.exp(1j * (t.heading() - m.heading())))
        np.testing.assert_allclose(diff, yaw, atol=1e-9)
        np.testing.assert_allclose(
            t.body_centred_positions(), m.body_centred_positions(), atol=1e-6
        )


def test_align_heading_sets_yaw_and_origin():
    m = turned(make_motion(), 1.2)
    a = m.align_heading(0.5)
    assert a.heading()[0] == pytest.approx(0.5)
    pelvis = a.positions()[0, a.skeleton.body_root]
    np.testing.assert_allclose(pelvis[[0, 2]], 0, atol=1e-9)
    assert pelvis[1] == pytest.approx(m.positions()[0, 0, 1])


def test_real_walk_is_upright_and_moves_forward(mocap):
    entry = mocap.query(source="bandai", label="normal")[0]
    m = mocap.load_motion(entry)
    pos = m.positions()
    sk = m.skeleton
    head = pos[:, sk.index("Head"), 1]
    feet = pos[:, [sk.index("Foot_L"), sk.index("Foot_R")], 1]
    assert np.all(head > feet.max(axis=1) + 1000)  # Y up, a standing adult (mm)
    pelvis = pos[:, sk.body_root]
    travelled = pelvis[-1] - pelvis[0]
    yaw = m.heading(pos)
    forward = np.array([np.sin(yaw[0]), 0, np.cos(yaw[0])])
    assert travelled @ forward > 0.8 * np.linalg.norm(travelled[[0, 2]])  # walks where it faces
