"""Common body points found by joint names on every skeleton the data holds."""

from __future__ import annotations

import numpy as np
import pytest

from markovmotion.core.skeleton import Skeleton
from markovmotion.errors import SkeletonMismatchError
from markovmotion.features.body_points import (
    BODY_POINTS,
    MARKER_POINTS,
    body_point_index,
    body_points,
    normalise,
)
from markovmotion.io.asfamc import read_asf
from markovmotion.io.bvh import read_bvh

EXPECTED = {
    # file: joints for pelvis, left elbow, right wrist, left knee, right toe
    "cmu/bvh/cmu_18_01.bvh.gz": ("Hips", "LeftForeArm", "RightHand", "LeftLeg", "RightToeBase"),
    "cmu/bvh/salsa_01.bvh.gz": ("hip", "lForeArm", "rHand", "lShin", "rFoot_end"),
    "bandai/dataset-2/walk_active_001.bvh.gz": (
        "Hips",
        "LowerArm_L",
        "Hand_R",
        "LowerLeg_L",
        "Toes_R",
    ),
}
CHECKED = ("pelvis", "left_elbow", "right_wrist", "left_knee", "right_toe")


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_points_found_by_name_on_each_skeleton(mocap, name):
    motion = read_bvh(mocap.root / name)
    idx = body_point_index(motion.skeleton, CHECKED)
    assert tuple(motion.skeleton.names[i] for i in idx) == EXPECTED[name]
    assert len(set(body_point_index(motion.skeleton).tolist())) == len(BODY_POINTS)


def test_asf_skeleton_maps_shoulder_not_collar(mocap):
    asf = next((mocap.root / "cmu" / "asfamc").glob("*/*.asf"))
    sk = read_asf(asf)
    idx = body_point_index(sk, ("left_shoulder", "left_wrist", "chest", "spine"))
    assert [sk.names[i] for i in idx] == ["lhumerus", "lwrist", "thorax", "lowerback"]


def test_cgspeed_shoulder_is_the_arm_joint_not_the_collar(mocap):
    sk = read_bvh(mocap.root / "cmu/bvh/cmu_18_01.bvh.gz").skeleton
    assert sk.names[body_point_index(sk, ("left_shoulder",))[0]] == "LeftArm"


def test_namespaces_and_sides_written_either_way():
    assert normalise("mixamorig:LeftForeArm") == "leftforearm"
    names = ("mixamorig:Hips", "Elbow_L", "mixamorig:RightForeArm")
    sk = Skeleton(names, [-1, 0, 0], np.zeros((3, 3)), [("Xrotation",)] * 3)
    assert body_point_index(sk, ("pelvis", "left_elbow", "right_elbow")).tolist() == [0, 1, 2]


def test_3ds_max_biped_names_are_found_behind_their_bip01_prefix():
    """3ds Max Biped's ``Bip01 L Thigh`` (or ``Bip001_L_Thigh``): every body point is found
    (none was: 'bip01lthigh' matched no synonym, so the dual HMM, the chain and the VLMM's
    markers refused a Biped skeleton)."""
    parts = ["Pelvis", "Spine", "Spine1", "Neck", "Head"]
    for side in "LR":
        parts += [f"{side} {p}" for p in ("UpperArm", "Forearm", "Hand")]
        parts += [f"{side} {p}" for p in ("Thigh", "Calf", "Foot", "Toe0")]
    for prefix, sep in (("Bip01", " "), ("Bip001", "_")):
        names = (prefix, *(f"{prefix}{sep}{p.replace(' ', sep)}" for p in parts))
        sk = Skeleton(names, [-1] + [0] * len(parts), np.zeros((len(names), 3)),
                      [("Xrotation",)] * len(names))  # fmt: skip
        found = [names[i] for i in body_point_index(sk)]
        assert found[:5] == [
            f"{prefix}{sep}{p}" for p in ("Pelvis", "Spine", "Spine1", "Neck", "Head")
        ]
        assert f"{prefix}{sep}L{sep}Calf" in found and f"{prefix}{sep}R{sep}Toe0" in found
    assert normalise("Bip01 L Forearm") == "lforearm"
    assert normalise("Biped") == "biped"


def test_missing_points_named_in_one_error():
    names = ("Hips", "LeftArm", "LeftForeArm")
    sk = Skeleton(names, [-1, 0, 1], np.zeros((3, 3)), [("Xrotation",)] * 3)
    with pytest.raises(SkeletonMismatchError, match=r"mine: .*left_wrist.*right_elbow") as err:
        body_point_index(sk, MARKER_POINTS, what="mine")
    assert "\n" not in str(err.value)
    assert err.value.reason.startswith("cannot find these body points")  # without "mine: "
    assert "left_wrist" in err.value.reason
    with pytest.raises(KeyError, match="nose"):
        body_point_index(sk, ("nose",))


def test_positions_are_the_joints_positions(mocap):
    motion = read_bvh(mocap.root / "cmu/bvh/cmu_18_01.bvh.gz")
    pts = body_points(motion, MARKER_POINTS)
    idx = body_point_index(motion.skeleton, MARKER_POINTS)
    np.testing.assert_allclose(pts, motion.positions()[:, idx])
    assert pts.shape == (motion.n_frames, 13, 3)


def test_marker_names_that_are_body_points_join_into_a_stick_figure():
    from markovmotion.features.body_points import point_bones

    names = ("TORSO", "HEAD", "R_SHOULDER", "L_SHOULDER", "R_ELBOW", "L_ELBOW", "R_HAND", "L_HAND")
    bones = {(names[c], names[p]) for c, p in point_bones(names)}
    assert bones == {
        ("HEAD", "TORSO"),  # no neck: the head hangs from the chest
        ("R_SHOULDER", "TORSO"),
        ("L_SHOULDER", "TORSO"),
        ("R_ELBOW", "R_SHOULDER"),
        ("L_ELBOW", "L_SHOULDER"),
        ("R_HAND", "R_ELBOW"),
        ("L_HAND", "L_ELBOW"),
    }
    assert point_bones(["m01", "m02", "m03"]).shape == (0, 2)  # nothing known: a point cloud
    assert point_bones(["Head"]).shape == (0, 2)


def test_the_right_hand_is_found_by_body_point_names():
    from markovmotion.models.hmm.contact import right_hand

    assert right_hand(("TORSO", "L_HAND", "R_HAND")) == 2
    assert right_hand(("LHand", "RHand")) == 1
    assert right_hand(("left_wrist", "right_wrist")) == 1
    assert right_hand(("HEAD", "L_HAND")) is None  # no right hand: no hand gap


def test_bone_lengths_are_restored_along_each_segments_direction():
    """Points whose segments were stretched frame by frame (as MediaPipe's are) come back to
    the true lengths, each segment keeping its direction; the median recovers the lengths."""
    from markovmotion.features.body_points import (
        POINT_PARENTS,
        bone_lengths,
        with_bone_lengths,
    )

    rng = np.random.default_rng(0)
    frames, n = 50, len(POINT_PARENTS)
    true_len = rng.uniform(80, 400, n)
    dirs = rng.normal(size=(frames, n, 3))
    dirs /= np.linalg.norm(dirs, axis=-1, keepdims=True)
    stretch = rng.uniform(0.8, 1.2, (frames, n))
    stretch[:, 0] = 1.0

    def build(lengths):
        pts = np.zeros((frames, n, 3))
        pts[:, 0] = rng.normal(0, 500, 3)
        for j, parent in enumerate(POINT_PARENTS):
            if parent >= 0:
                pts[:, j] = pts[:, parent] + dirs[:, j] * lengths[..., j, None]
        return pts

    state = rng.bit_generator.state
    truth = build(np.broadcast_to(true_len, (frames, n)))
    rng.bit_generator.state = state  # the same root
    noisy = build(true_len * stretch)
    np.testing.assert_allclose(with_bone_lengths(noisy, true_len), truth, atol=1e-9)
    got = bone_lengths(noisy)
    assert np.isnan(got[0])
    np.testing.assert_allclose(got[1:], true_len[1:], rtol=0.1)


def _flat(names: tuple[str, ...]) -> Skeleton:
    """A skeleton of ``names`` (a ``*_end`` name an end site), every joint under the first:
    body points are found by name alone."""
    n = len(names)
    return Skeleton(names, [-1] + [0] * (n - 1), np.zeros((n, 3)),
                    [() if x.endswith("_end") else ("Xrotation",) for x in names],
                    np.array([x.endswith("_end") for x in names]))  # fmt: skip


#: Rigs of outside files, each with its body points (pelvis, spine, chest, neck, head, left
#: shoulder, elbow, wrist, hip, knee, ankle, toe): none had all of them found.
OUTSIDE_RIGS = {
    # the Biovision specification's example, as many tools still write it
    "biovision": (
        "Hips Chest Neck Head LeftCollar LeftUpArm LeftLowArm LeftHand RightCollar RightUpArm "
        "RightLowArm RightHand LeftUpLeg LeftLowLeg LeftFoot LeftFoot_end RightUpLeg "
        "RightLowLeg RightFoot RightFoot_end",
        "Hips Chest Chest Neck Head LeftUpArm LeftLowArm LeftHand LeftUpLeg LeftLowLeg "
        "LeftFoot LeftFoot_end",
    ),
    # a mocap-bank BVH (19 joints): the legs end at the ankle, two chest joints
    "mocapbank": (
        "Hips Chest Chest2 LeftCollar LeftShoulder LeftElbow LeftWrist RightCollar "
        "RightShoulder RightElbow RightWrist Neck Head LeftHip LeftKnee LeftAnkle "
        "LeftAnkle_end RightHip RightKnee RightAnkle RightAnkle_end",
        "Hips Chest Chest2 Neck Head LeftShoulder LeftElbow LeftWrist LeftHip LeftKnee "
        "LeftAnkle LeftAnkle_end",
    ),
    # video2bvh's CMU-like skeleton from 3-D keypoints: the neck ends at Neck1, the nose
    "video2bvh": (
        "Hips LeftHipJoint LeftUpLeg LeftLeg LeftFoot LeftFoot_end LowerBack Spine Spine1 "
        "LeftShoulder LeftArm LeftForeArm LeftHand Neck Neck1 Neck1_end RightShoulder "
        "RightArm RightForeArm RightHand RightHipJoint RightUpLeg RightLeg RightFoot "
        "RightFoot_end",
        "Hips Spine Spine1 Neck Neck1 LeftArm LeftForeArm LeftHand LeftUpLeg LeftLeg "
        "LeftFoot LeftFoot_end",
    ),
    # PyMO's demo walker: one spine joint under the head
    "pymo": (
        "Hips Spine Head LeftShoulder LeftArm LeftForeArm LeftHand RightShoulder RightArm "
        "RightForeArm RightHand LeftUpLeg LeftLeg LeftFoot LeftToeBase RightUpLeg RightLeg "
        "RightFoot RightToeBase",
        "Hips Spine Spine Head Head LeftArm LeftForeArm LeftHand LeftUpLeg LeftLeg LeftFoot "
        "LeftToeBase",
    ),
}


@pytest.mark.parametrize("rig", sorted(OUTSIDE_RIGS))
def test_every_body_point_is_found_on_the_rigs_of_outside_files(rig):
    """The classic Biovision names (``LeftUpArm``, ``LeftLowArm``, ``LeftLowLeg``), a leg
    ending at the ankle (its end site is the toe), a trunk without a spine joint below the
    chest or without chest and neck (the nearest trunk joint stands for them), video2bvh's
    head at ``Neck1``: every body point is found, so the dual HMM, the chain's markers and
    the VLMM's take these skeletons (they had been left out, naming the points missing)."""
    names, wanted = OUTSIDE_RIGS[rig]
    sk = _flat(tuple(names.split()))
    left = [p for p in BODY_POINTS if not p.startswith("right")]
    assert [sk.names[i] for i in body_point_index(sk, left)] == wanted.split()
    right = body_point_index(sk, ("right_shoulder", "right_elbow", "right_knee", "right_toe"))
    assert all(sk.names[i].startswith("Right") for i in right)
    assert len(body_point_index(sk)) == len(BODY_POINTS)
