"""The dual HMM on the paper's kind of interactions: both trellises of §3.2 against brute
force, the smoothing that keeps the partner from jumping, body points across skeletons, and
error bounds on the real CMU 18/19 handshakes and pulls held out."""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import pytest
from conftest import make_motion
from scipy.spatial.transform import Rotation

from markovmotion.core.motion import Motion
from markovmotion.errors import SkeletonMismatchError
from markovmotion.evaluate.hmm import evaluate_pair, summarise
from markovmotion.evaluate.takes import jump_sizes
from markovmotion.models.hmm.dual import DualHMM
from markovmotion.models.hmm.trellis import Trellis, smooth_place, successors

K, T, D = 3, 4, 2


def toy_trellis(kind: str, seed: int = 0) -> tuple[Trellis, list[tuple], list[int]]:
    """A trellis over 12 random training frames, one state, identity precisions."""
    rng = np.random.default_rng(seed)
    n = 12
    motion = make_motion(n)
    trellis = Trellis(
        members=[np.arange(n)],
        white_a=[rng.normal(size=(n, D))],
        prec_a=np.eye(D)[None],
        prec_b=np.eye(D)[None],
        train_b=rng.normal(size=(n, D)),
        size=K,
        motion_b=motion,
        successor=successors([5, 7]),
        kind=kind,
    )
    states = [0] * T
    cols = [(rng.choice(n, K, replace=False), rng.uniform(0.5, 2.0, K)) for _ in range(T)]
    return trellis, cols, states


@pytest.mark.parametrize("seed", range(5))
def test_path_trellis_is_the_lowest_error_path_by_brute_force(seed):
    trellis, cols, states = toy_trellis("path", seed)
    got = trellis.best_path(states, cols)
    best, best_cost = None, np.inf
    for pick in itertools.product(range(K), repeat=T):
        cost = cols[0][1][pick[0]]
        for t in range(1, T):
            i, j = cols[t][0][pick[t]], cols[t - 1][0][pick[t - 1]]
            d = np.linalg.norm(trellis.train_b[i] - trellis.train_b[trellis.successor[j]])
            cost += d * cols[t][1][pick[t]]
        if cost < best_cost - 1e-12:
            best, best_cost = pick, cost
    assert got.tolist() == [cols[t][0][best[t]] for t in range(T)]


@pytest.mark.parametrize("seed", range(5))
def test_paper_trellis_picks_per_column_the_lowest_sum_of_distances_times_d4(seed):
    trellis, cols, states = toy_trellis("paper", seed)
    got = trellis.best_path(states, cols)
    want = [cols[0][0][np.argmin(cols[0][1])]]
    for t in range(1, T):
        e = [
            sum(np.linalg.norm(trellis.train_b[i] - trellis.train_b[j]) for j in cols[t - 1][0])
            * d4
            for i, d4 in zip(*cols[t], strict=True)
        ]
        want.append(cols[t][0][int(np.argmin(e))])
    assert got.tolist() == want


def test_successor_is_the_next_frame_of_the_same_recording():
    assert successors([3, 2]).tolist() == [1, 2, 2, 4, 4]


def test_blend_spreads_a_cut_and_keeps_a_recording():
    trellis, _, _ = toy_trellis("path")
    q = trellis.motion_b.rotations
    path = np.arange(12)
    np.testing.assert_array_equal(trellis.blend(path, 0), q[path])
    # q and -q are one rotation: the blend does not care which it gets
    flipped = trellis.motion_b.copy()
    flipped.rotations = -q
    other = dataclasses.replace(trellis, motion_b=flipped)  # caches (init=False) start empty
    np.testing.assert_allclose(np.abs(other.blend(path, 2)), np.abs(trellis.blend(path, 2)))
    # a cut between two poses held still becomes a ramp of 2 half + 1 frames
    still = trellis.motion_b.copy()
    turn = Rotation.from_euler("x", [[0], [60]], degrees=True).as_quat()
    still.rotations = np.repeat(turn[:, None], still.skeleton.n_joints, axis=1)[[0] * 6 + [1] * 6]
    cut = dataclasses.replace(trellis, motion_b=still)
    angle = Rotation.from_quat(cut.blend(path, 2)[:, 1]).magnitude()
    steps = np.diff(np.degrees(angle))
    assert np.isclose(steps.max(), 12.0, atol=1.0) and (steps > 1).sum() == 5
    assert np.allclose(cut.blend(path, 2, count=3), cut.blend(path, 2)[:3])


def test_smooth_place_averages_headings_across_the_wrap():
    origin = np.zeros((3, 3))
    yaw = np.array([np.pi - 0.1, -np.pi + 0.1, np.pi - 0.1])
    _, smooth = smooth_place(origin, yaw, 1)
    # the direction of the mean unit vector: the ends' two average to pi exactly, the middle
    # three to about pi - 0.1 / 3 (not 0.1 / 3 from -pi + 0.1: no jump across the wrap)
    assert np.allclose(np.abs(smooth), [np.pi, np.pi - 0.1 / 3, np.pi], atol=1e-3)
    same, unchanged = smooth_place(origin, yaw, 0)
    assert unchanged is yaw and same is origin


def test_jump_sizes_are_the_median_point_step():
    pts = np.zeros((3, 3, 3))
    pts[1] += [10.0, 0, 0]
    pts[2, :2] += [10.0, 0, 300]  # two of three points move 300 mm: the median does
    assert jump_sizes(pts).tolist() == [10.0, 300.0]


# ------------------------------------------------------------------ the real interactions
@pytest.fixture(scope="module")
def interactions(mocap):
    """The index's interaction takes of the people of its handshakes (any labels they do)."""
    shakes = mocap.pairs(label=["handshake"], kind="skeleton")
    if not shakes:
        pytest.fail("the shared index has no handshake take")
    pairs = [p for p in mocap.pairs(kind="skeleton") if p[0].subject == shakes[0][0].subject]
    return [(a.label, a.name, *mocap.load_pair(a, b)) for a, b in pairs]


def test_held_out_pull_beats_the_mean_pose_and_moves_like_a_person(interactions):
    """Leave one pull out (the index's first), train on the rest: the generated partner is
    nearer the real one than the mean pose, windowed within 10 % of standard, and its frame
    steps no larger than twice the real B's (90th percentile)."""
    i = next(k for k, t in enumerate(interactions) if t[0] == "pull")
    label, name, a, b = interactions[i]
    rest = [t for k, t in enumerate(interactions) if k != i]
    model = DualHMM().fit([(x, y) for _, _, x, y in rest], [lab for lab, *_ in rest])
    res = evaluate_pair(model, a, b, name, label)
    err = {k: v.mean() for k, v in res.errors.items()}
    assert err["standard"] < 0.85 * err["mean_pose"] and err["windowed"] < 0.85 * err["mean_pose"]
    assert abs(err["windowed"] - err["standard"]) < 0.1 * err["standard"]
    report = summarise([res], model)["overall"]
    assert report["windowed_jump_p90_mm"] <= 2 * report["real_jump_p90_mm"]
    assert set(report["trellis"]) == {"paper", "path"}
    assert report["trellis"]["path"]["windowed_mm"] == report["windowed_mm"]


def test_a_on_another_skeleton_goes_through_body_points(interactions, mocap):
    """A model of the CMU 18/19 people answers a salsa dancer (another skeleton, other joint
    names); a skeleton without the body points is one error naming the missing ones."""
    model = DualHMM(n_states=8, n_iter=5).fit([(a, b) for _, _, a, b in interactions])
    salsa = mocap.load_pair(*mocap.pairs(label=["salsa"])[0])[0].trim(0, 120)
    out = model.respond(salsa, "windowed")
    assert out.skeleton is model.skeleton_b_ and out.n_frames == 60
    assert np.isfinite(out.positions()).all()
    with pytest.raises(SkeletonMismatchError, match=r"mine: .*body points.*left_elbow"):
        model.check_input(make_motion(10), "mine")


def test_b_on_two_skeletons_is_one_clear_error(interactions, mocap):
    salsa = mocap.load_pair(*mocap.pairs(label=["salsa"])[0])
    pairs = [interactions[0][2:], salsa]
    with pytest.raises(SkeletonMismatchError, match="person B comes on 2 skeletons.*--labels"):
        DualHMM(n_states=4, n_iter=2).fit(pairs, [interactions[0][0], "salsa"])


def test_the_online_partner_is_smooth_and_identical_to_respond(interactions):
    _, _, a, b = interactions[0]
    model = DualHMM(n_states=8, n_iter=5).fit([(x, y) for _, _, x, y in interactions[1:]])
    a = a.resample(model.fps)
    partner = model.partner()
    frames = [partner.step(a.trim(t, t + 1)) for t in range(a.n_frames)]
    frames = [f for f in frames if f is not None] + partner.finish()
    online = np.concatenate([f.positions() for f in frames])
    np.testing.assert_allclose(online, model.respond(a, "windowed").positions(), atol=1e-6)
    assert isinstance(frames[0], Motion)


def test_heading_of_a_skeleton_whose_hip_joints_sit_at_the_pelvis(interactions):
    """cgspeed's CMU skeleton hangs the legs from LHipJoint / RHipJoint at the pelvis itself:
    the hips are their children, and the heading follows the shoulders' facing."""
    a = interactions[0][2]
    left, right = a.hip_joints()
    assert np.any(a.skeleton.offsets[left]) and np.any(a.skeleton.offsets[right])
    pos = a.positions()
    sk = a.skeleton
    across = pos[:, sk.index("LeftArm")] - pos[:, sk.index("RightArm")]
    shoulders = np.arctan2(-across[:, 2], across[:, 0])
    gap = np.angle(np.exp(1j * (a.heading(pos) - shoulders)))
    assert np.median(np.abs(gap)) < np.radians(30) and np.ptp(a.heading(pos)) > np.radians(20)


def test_b_place_frame_is_chosen_on_the_training_takes(interactions, mocap):
    """CMU's pulls: B stays in front while A turns side-on, so the other takes tell B's place
    better along the world's axes; salsa partners turn together, so in A's facing."""
    pairs = [(a, b) for _, _, a, b in interactions]
    model = DualHMM(n_states=4, n_iter=2).fit(pairs)
    assert model.frame_ == "world"
    # (leaving one take out at a time: two 10 s takes nearly tie, four settle it)
    salsa = [mocap.load_pair(*p) for p in mocap.pairs(label=["salsa"])[:4]]
    salsa = [(a.trim(0, 600), b.trim(0, 600)) for a, b in salsa]
    assert DualHMM(n_states=4, n_iter=2).fit(salsa).frame_ == "heading"
    fixed = DualHMM(n_states=4, n_iter=2, frame="heading").fit(pairs)
    a = pairs[0][0].resample(30)
    assert fixed.frame_ == "heading" and np.ptp(fixed.ground(a)[1]) > 0
    assert np.all(model.ground(a)[1] == 0) and np.allclose(model.ground(a)[0], fixed.ground(a)[0])
