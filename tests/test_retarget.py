"""Retargeting takes of any skeleton onto the body model's template by their body points, and
the body model learnt from them (video/retarget.py, multiview.collection_body_model)."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from markovmotion.algorithms.kinematics import points_ik, rotvec_positions
from markovmotion.core.motion import Motion
from markovmotion.data import MocapIndex
from markovmotion.errors import SkeletonMismatchError
from markovmotion.features.body_points import BODY_POINTS, body_points
from markovmotion.video.body_model import local_rotvecs
from markovmotion.video.multiview import LIMIT_TAIL, collection_body_model, collection_takes
from markovmotion.video.retarget import Template, rebuild_points
from tests.conftest import make_motion


@pytest.fixture(scope="module")
def template(mocap):
    """The template from the first handshake take (both people), as the collection's is."""
    a, b = mocap.pairs(label="handshake", kind="skeleton")[0]
    return Template.fit([mocap.load_motion(e).resample(30.0) for e in (a, b)])


def _angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angles (rad) between rotations given as rotation vectors (..., 3)."""
    ra, rb = Rotation.from_rotvec(a.reshape(-1, 3)), Rotation.from_rotvec(b.reshape(-1, 3))
    return (ra.inv() * rb).magnitude().reshape(a.shape[:-1])


def test_ik_recovers_the_templates_rotations_from_its_body_points(template, take):
    """The held-out pull (the template's skeleton, never in its prior): its own body points
    give back its rotations where the points pin them down, and every joint's position."""
    motion = take[0]
    sk = template.skeleton
    rv, root = local_rotvecs(motion)[::3], motion.translations[::3, 0]
    targets = rotvec_positions(sk, rv, root, template.points)
    start_rv, start_root = template._initial(targets)
    got, got_root, err = points_ik(
        sk, targets, template.points, template.free, start_rv, start_root,
        template.mean, template.precision, upright=template.upright,
    )  # fmt: skip
    assert err.mean() < 6.0  # mm, the 19 points
    every = np.linalg.norm(
        rotvec_positions(sk, got, got_root) - rotvec_positions(sk, rv, root), axis=-1
    )
    assert every.mean() < 12.0  # every joint, end sites and fingers included

    def error_degrees(names):
        j = [sk.index(n) for n in names]
        return np.degrees(_angle(got[:, j], rv[:, j])).mean(axis=0)

    assert error_degrees(("LeftUpLeg", "LeftLeg", "RightUpLeg", "RightLeg")).max() < 8.0
    assert error_degrees(("LeftForeArm", "RightForeArm")).max() < 8.0
    # an upper arm's twist shows only through a bent elbow: pulls keep the arms straight
    assert error_degrees(("LeftArm", "RightArm")).max() < 30.0
    assert np.degrees(_angle(got[:, 0], rv[:, 0])).mean() < 8.0
    # from the mean pose alone the error is large: the fit is doing the work
    assert (
        np.linalg.norm(
            rotvec_positions(sk, start_rv, start_root, template.points) - targets, axis=-1
        ).mean()
        > 5 * err.mean()
    )


def _elbow_knee_angles(points: np.ndarray) -> np.ndarray:
    """(F, 4) bends (rad) at the elbows and knees of body points (F, 19, 3)."""
    at = {n: points[:, i] for i, n in enumerate(BODY_POINTS)}
    out = []
    for s in ("left", "right"):
        for a, b, c in (("shoulder", "elbow", "wrist"), ("hip", "knee", "ankle")):
            u, v = at[f"{s}_{b}"] - at[f"{s}_{a}"], at[f"{s}_{c}"] - at[f"{s}_{b}"]
            cos = np.sum(u * v, -1) / np.linalg.norm(u, axis=-1) / np.linalg.norm(v, axis=-1)
            out.append(np.arccos(np.clip(cos, -1, 1)))
    return np.stack(out, axis=1)


def test_a_take_of_another_skeleton_retargets_close_to_its_body_points(mocap, template):
    entry = mocap.query(label="salsa", kind="skeleton")[0]
    motion = entry.read()
    assert not motion.skeleton.same_topology(template.skeleton)
    rv, root, err = template.retarget(motion, stride=16)
    source = body_points(motion)[::16]
    scaled = rebuild_points(source, template.lengths, template.trunk)
    got = rotvec_positions(template.skeleton, rv, root, template.points)
    dist = np.linalg.norm(got - scaled, axis=-1)
    assert np.allclose(dist.mean(axis=1), err)
    limbs = [BODY_POINTS.index(f"{s}_{p}") for s in ("left", "right")
             for p in ("elbow", "wrist", "knee", "ankle")]  # fmt: skip
    assert dist[:, limbs].mean() < 25.0 and dist.mean() < 30.0
    # the limbs bend as the source's do (scaling keeps angles)
    bends = np.degrees(np.abs(_elbow_knee_angles(got) - _elbow_knee_angles(source)))
    assert np.median(bends) < 6.0
    # and they do move: a fit to the mean pose would not pass the checks above
    assert np.degrees(_elbow_knee_angles(source)).std(axis=0).min() > 5.0


def test_a_skeleton_without_body_points_is_one_clear_line(template):
    motion = make_motion()
    motion.name = "five_joints.bvh"
    with pytest.raises(SkeletonMismatchError) as info:
        template.retarget(motion)
    message = str(info.value)
    assert "\n" not in message and "five_joints.bvh" in message and "body points" in message


@pytest.fixture(scope="module")
def small_collection(mocap, tmp_path_factory):
    """An INDEX.csv of the handshake and pull takes, CMU's ASF/AMC bending take and one Bandai
    walk, beside links to the shared folders (so the retargeting stays quick)."""
    root = tmp_path_factory.mktemp("collection")
    for top in {e.file.split("/")[0] for e in mocap}:
        (root / top).symlink_to(mocap.root / top)
    with open(mocap.root / "INDEX.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    keep = [r for r in rows if r["label"] in ("handshake", "pull", "bend")]
    keep.append(next(r for r in rows if r["source"] == "bandai"))
    with open(root / "INDEX.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(keep)
    return root


def test_collection_limits_hold_the_retargeted_states(
    small_collection, body, tmp_path, monkeypatch
):
    monkeypatch.setenv("MARKOVMOTION_CACHE", str(tmp_path))
    new = collection_body_model(small_collection)
    template, takes = collection_takes(small_collection)
    assert list(tmp_path.glob("retarget/*.npz"))  # cached
    assert len(takes) >= 4

    def states(model, rv, root):
        quats = Rotation.from_rotvec(rv.reshape(-1, 3)).as_quat().reshape(*rv.shape[:2], 4)
        return model.states_of(Motion.from_rotations(template.skeleton, quats, root))

    x = np.concatenate([states(new, rv, root) for rv, root, _ in takes])
    inside = (x >= new.lower) & (x <= new.upper)
    assert inside[:, 4:].mean(axis=0).min() >= 1 - 2 * LIMIT_TAIL
    # a take of bending over: the interaction model's limits hold few frames, the new most
    entry = next(e for e in MocapIndex.load(small_collection) if e.label == "bend")
    rv, root, _ = template.retarget(entry.read(), stride=8)
    old_in = np.all(
        (states(body, rv, root) >= body.lower) & (states(body, rv, root) <= body.upper), axis=1
    )
    new_in = np.all(
        (states(new, rv, root) >= new.lower) & (states(new, rv, root) <= new.upper), axis=1
    )
    assert new_in.mean() > 0.9 and new_in.mean() > old_in.mean() + 0.2


def test_track_builds_the_collection_model_from_data_when_asked(
    small_collection, take, tmp_path, monkeypatch, capsys
):
    from markovmotion.cli import main

    _, path = take
    video = tmp_path / "video"
    main(["video", "render", str(path), "--out", str(video), "--views", "2", "--seconds", "0.1",
          "--fps", "30", "--width", "96", "--height", "72"])  # fmt: skip
    runs = {}
    for which in ("collection", "interaction"):
        cache = tmp_path / which
        monkeypatch.setenv("MARKOVMOTION_CACHE", str(cache))
        capsys.readouterr()
        extra = [] if which == "interaction" else ["--body-model", which]
        main(["track", "--video", str(video), "--data", str(small_collection), "--json",
              "--particles", "20", "--layers", "2", "--out", str(tmp_path / f"{which}.bvh"),
              *extra])  # fmt: skip
        runs[which] = (json.loads(capsys.readouterr().out), list(cache.glob("retarget/*.npz")))
    assert runs["collection"][0]["frames"] == runs["interaction"][0]["frames"] == 3
    assert runs["collection"][1] and not runs["interaction"][1]  # only `collection` retargets
