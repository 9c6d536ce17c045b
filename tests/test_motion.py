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


def test_core_exports_the_motion_types():
    """``from markovmotion.core import Motion`` (it was an ImportError: the package was empty),
    in a fresh interpreter so that no import cycle hides behind modules already loaded."""
    import subprocess
    import sys

    import markovmotion.core
    from markovmotion.core.markers import Markers
    from markovmotion.core.skeleton import Skeleton

    assert markovmotion.core.Motion is Motion
    assert markovmotion.core.Markers is Markers and markovmotion.core.Skeleton is Skeleton
    code = "from markovmotion.core import Markers, Motion, Skeleton; print(Motion.__name__)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "Motion"


def test_repr_is_one_short_line_not_the_arrays():
    """repr(Motion) printed every frame's rotations (29,000 characters for 40 frames)."""
    from markovmotion.core import Markers

    m = make_motion(n_frames=40, fps=30.0)
    assert repr(m) == "Motion(40 frames, 5 joints, 30 fps, 'synthetic')"
    m.name = ""
    assert repr(m) == "Motion(40 frames, 5 joints, 30 fps)"
    assert repr(make_motion(n_frames=5000, fps=120.0)).startswith("Motion(5000 frames, 5 joints")
    markers = Markers(("A", "B"), np.zeros((7, 2, 3)), 100.0, name="take.c3d")
    assert repr(markers) == "Markers(7 frames, 2 markers, 100 fps, 'take.c3d')"


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


def test_slerp_of_every_joint_at_once_gives_scipys_rotations():
    from scipy.spatial.transform import Slerp

    from markovmotion.core.motion import slerp_frames

    q = Rotation.random(40 * 5, random_state=2).as_quat().reshape(40, 5, 4) * 3.0  # not unit
    q[6] = -q[5]  # the same rotation, the other sign: no turn between them
    at = np.concatenate([np.linspace(0, 39, 517), np.arange(40.0)])
    ours = slerp_frames(q, at)
    ref = np.stack(
        [Slerp(np.arange(40), Rotation.from_quat(q[:, j]))(at).as_quat() for j in range(5)], 1
    )
    np.testing.assert_allclose(np.linalg.norm(ours, axis=-1), 1.0, atol=1e-12)
    # the same rotations (a quaternion and its negative are one rotation)
    np.testing.assert_allclose(np.abs(np.sum(ours * ref, axis=-1)), 1.0, atol=1e-9)
    # and at a captured frame, that frame's own quaternion (its sign kept)
    np.testing.assert_allclose(
        ours[517:], q / np.linalg.norm(q, axis=-1, keepdims=True), atol=1e-12
    )


def test_forward_kinematics_matches_scipys_rotations_and_refuses_a_zero_quaternion():
    from markovmotion.core.motion import _quat_matrices

    q = np.random.default_rng(0).normal(size=(6, 7, 4)) * 3
    ref = Rotation.from_quat(q.reshape(-1, 4)).as_matrix().reshape(6, 7, 3, 3)
    np.testing.assert_allclose(_quat_matrices(q), ref, atol=1e-12)
    m = make_motion(5)
    m.rotations[2, 1] = 0.0
    with pytest.raises(ValueError, match="zero norm"):
        m.positions()


def test_numpy_forward_kinematics_equals_the_compiled_loop(mocap):
    """``compiled=False`` (NumPy, level by level, for ``info``) gives the compiled loop's
    rotations and positions on a real take and on random rotations, and refuses a zero
    quaternion the same way."""
    from markovmotion.io import read_motion

    walk = read_motion(mocap.root / "bandai/dataset-1/walk_active_001.bvh.gz")
    m = make_motion(40)
    m.rotations = np.random.default_rng(1).normal(size=m.rotations.shape)
    for motion in (walk, m):
        rot, pos = motion.global_transforms()
        rot_np, pos_np = motion.global_transforms(compiled=False)
        np.testing.assert_allclose(rot_np, rot, atol=1e-12)
        np.testing.assert_allclose(pos_np, pos, atol=1e-9)
    m.rotations[3, 2] = 0.0
    with pytest.raises(ValueError, match="zero norm"):
        m.positions(compiled=False)


def test_the_legs_are_found_whatever_motion_of_the_skeleton_comes_first(mocap):
    """A motion whose first frame has a leg at hip height (a generated walk did) does not
    leave its skeleton remembered as legless: the legs are looked for in later frames too,
    and a failure is not remembered."""
    from markovmotion.core import motion as motion_module

    walk = mocap.load_motion(mocap.query(label="normal")[0]).trim(0, 60)
    legs = walk.hip_joints()
    assert legs is not None
    motion_module._HIPS.clear()
    from scipy.spatial.transform import Rotation

    odd = walk.copy()  # the first frame's right leg turned half a turn, up beside the trunk
    turned = Rotation.from_euler("z", 180, degrees=True) * Rotation.from_quat(
        odd.rotations[0, legs[1]]
    )
    odd.rotations[0, legs[1]] = turned.as_quat()
    assert odd._find_hip_joints(0) is None  # the first frame cannot tell the legs
    assert odd.hip_joints() == legs  # the middle frame can
    motion_module._HIPS.clear()
    assert walk.hip_joints() == legs
