"""Walks cut into steps: heel strikes, step contexts, root travel from foot contact (gait paper §4, §5.1.4).

The Bandai Namco and CMU walks are not segmented. A heel strike is found where
an ankle, after a swing (fast horizontal motion), comes down near the floor and
almost stops; a step runs from one heel strike to the next (of the other foot)
and is named by the foot that lands at its end (``"L"`` or ``"R"``, the foot that
swings). Each step gets a position context as in §5.2.1: first, second,
inside, last-but-one or last step of the walk.

Synthesized walks carry no root translation: :func:`root_from_contact` puts the
body back on the ground, keeping the stance foot's lowest point (ankle or toe)
still, so the planted foot does not slide (§5.1.4).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from markovmotion.core.motion import GROUND, UP, Motion
from markovmotion.errors import MotionFormatError

SIDES = ("L", "R")
POSITIONS = ("first", "second", "inside", "last_but_one", "last")
#: Every (side, position) context; a context id is its index here.
CONTEXTS = tuple((s, p) for s in SIDES for p in POSITIONS)

#: Thresholds of the heel-strike detector, as fractions of each foot's own
#: ranges (95th percentiles of ankle speed, height above the floor).
SWING_SPEED = 0.3
CONTACT_SPEED = 0.15
CONTACT_HEIGHT = 0.3
MIN_SWING_FRAMES = 3


def context_id(side: str, position: str) -> int:
    return CONTEXTS.index((side, position))


def context_questions() -> list[np.ndarray]:
    """Yes/no questions on the step contexts for clustering (§5.1.1), as masks over :data:`CONTEXTS`."""
    side = np.array([s for s, _ in CONTEXTS])
    pos = np.array([p for _, p in CONTEXTS])
    sets = [{p} for p in POSITIONS] + [
        {"first", "second"},
        {"last_but_one", "last"},
        {"first", "last"},
        {"first", "second", "last_but_one", "last"},
    ]
    return [side == "L"] + [np.isin(pos, list(s)) for s in sets]


def step_positions(n_steps: int) -> list[str]:
    """Position context of each of ``n_steps`` steps (first, second, ..., last; §5.2.1).

    In walks of fewer than five steps the ends win: first, then last, second,
    last-but-one.
    """
    out = ["inside"] * n_steps
    for k, name in (
        (n_steps - 2, "last_but_one"),
        (1, "second"),
        (n_steps - 1, "last"),
        (0, "first"),
    ):
        if 0 <= k < n_steps:
            out[k] = name
    return out


def foot_joints(motion: Motion) -> dict[str, tuple[int, int]]:
    """``{"L": (ankle, toe), "R": (ankle, toe)}`` joint indices of the two legs.

    Each leg is followed from its hip (:meth:`Motion.hip_joints`) through first
    children to its tip; the tip is the toe, and the ankle is two joints above
    an end site (one above a tip that is a real joint).
    """
    hips = motion.hip_joints()
    if hips is None:
        sk = motion.skeleton
        kids = ", ".join(sk.names[k] for k in sk.children(sk.body_root)) or "none"
        raise MotionFormatError(
            motion.name or "motion",
            f"cannot tell the left leg from the right (the joints under the pelvis "
            f"{sk.names[sk.body_root]}: {kids}; the two lowest must be named apart by L / R)",
        )
    sk = motion.skeleton
    out = {}
    for side, hip in zip(SIDES, hips, strict=True):
        chain = [hip]
        while kids := sk.children(chain[-1]):
            chain.append(kids[0])
        tip = chain[-1]
        back = 3 if sk.end_site[tip] else 2
        if len(chain) < back:
            raise MotionFormatError(motion.name or "motion", f"leg {sk.names[hip]} has no foot")
        out[side] = (chain[-back], tip)
    return out


def heel_strikes(motion: Motion, positions: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Frames at which each foot lands: ``{"L": frames, "R": frames}``.

    A strike is the first frame, after at least ``MIN_SWING_FRAMES`` of swing
    (ankle ground speed above ``SWING_SPEED`` of its 95th percentile), at which
    the ankle is slow (below ``CONTACT_SPEED``) and low (within
    ``CONTACT_HEIGHT`` of its height range above its 5th-percentile floor).
    """
    pos = motion.positions() if positions is None else positions
    out = {}
    for side, (ankle, _) in foot_joints(motion).items():
        if len(pos) < 2:  # a single frame (a pose): no speed, no strike
            out[side] = np.zeros(0, dtype=int)
            continue
        h = pos[:, ankle, 1]
        speed = np.linalg.norm(np.gradient(pos[:, ankle, GROUND], axis=0), axis=1) * motion.fps
        floor, top = np.percentile(h, [5, 95])
        fast = np.percentile(speed, 95)
        swing = speed > SWING_SPEED * fast
        contact = (speed < CONTACT_SPEED * fast) & (h < floor + CONTACT_HEIGHT * (top - floor))
        strikes, run, armed = [], 0, False
        for t in range(len(h)):
            run = run + 1 if swing[t] else 0
            armed = armed or run >= MIN_SWING_FRAMES
            if armed and contact[t] and not swing[t]:
                strikes.append(t)
                armed = False
        out[side] = np.array(strikes, dtype=int)
    return out


@dataclass(frozen=True)
class Steps:
    """A walk cut at heel strikes.

    Attributes:
        boundaries: (n + 1,) frames of the heel strikes; step k is frames
            ``boundaries[k]:boundaries[k + 1]``.
        sides: (n,) the foot that lands at the end of each step.
        dropped: strikes left out because the feet did not alternate there.
    """

    boundaries: np.ndarray
    sides: tuple[str, ...]
    dropped: int = 0

    @property
    def n_steps(self) -> int:
        return len(self.sides)

    def contexts(self) -> np.ndarray:
        """Context id (side and position, :data:`CONTEXTS`) of each step."""
        pos = step_positions(self.n_steps)
        return np.array([context_id(s, p) for s, p in zip(self.sides, pos, strict=True)], int)


def detect_steps(motion: Motion, positions: np.ndarray | None = None) -> Steps:
    """Heel strikes of both feet merged into steps: the longest run in which the feet alternate."""
    strikes = heel_strikes(motion, positions)
    events = sorted((int(t), s) for s, ts in strikes.items() for t in ts)
    best: list[tuple[int, str]] = []
    run: list[tuple[int, str]] = []
    for ev in events:
        if run and (ev[1] == run[-1][1] or ev[0] == run[-1][0]):
            run = []
        run.append(ev)
        if len(run) > len(best):
            best = list(run)
    frames = np.array([t for t, _ in best], dtype=int)
    sides = tuple(s for _, s in best[1:])
    return Steps(frames, sides, dropped=len(events) - len(best))


def travel_yaw(motion: Motion, positions: np.ndarray | None = None) -> float:
    """Yaw (about +Y, 0 = +Z) of the pelvis's ground-plane travel from first to last frame."""
    pos = motion.positions() if positions is None else positions
    d = pos[-1, motion.skeleton.body_root] - pos[0, motion.skeleton.body_root]
    return float(np.arctan2(d[0], d[2]))


def turn_body(motion: Motion, yaw: float) -> Motion:
    """The motion turned by ``yaw`` about the vertical through the world origin.

    The turn goes into the pelvis (:attr:`Skeleton.body_root`) rotation and
    translation, expressed in its parent's frame, so static joints above the
    pelvis (Bandai's ``joint_Root``) are untouched and the pelvis exponential
    map carries the new heading.
    """
    sk = motion.skeleton
    br = sk.body_root
    turn = Rotation.from_rotvec(yaw * UP)
    out = motion.copy()
    if br == 0:
        out.rotations[:, 0] = (turn * Rotation.from_quat(motion.rotations[:, 0])).as_quat()
        out.translations[:, 0] = turn.apply(motion.translations[:, 0])
        return out
    rot, pos = motion.global_transforms()
    parent = sk.parents[br]
    p_rot = Rotation.from_matrix(rot[:, parent])
    local = p_rot.inv() * turn * p_rot * Rotation.from_quat(motion.rotations[:, br])
    out.rotations[:, br] = local.as_quat()
    out.translations[:, br] = p_rot.inv().apply(turn.apply(pos[:, br]) - pos[:, parent])
    return out


def align_walk(motion: Motion) -> Motion:
    """The walk turned so that it travels along +Z (the paper aligns all walk directions, §4)."""
    return turn_body(motion, -travel_yaw(motion))


def root_from_contact(
    motion: Motion, boundaries: np.ndarray, sides: tuple[str, ...], floor: float = 0.0
) -> Motion:
    """Root travel computed so that the stance foot does not slide (§5.1.4).

    During step k (frames ``boundaries[k]:boundaries[k+1]``), the foot that
    landed at its start stands; its lowest point, ankle or toe, is kept still
    on the ground plane from frame to frame, and the body is lifted so that its
    lowest foot point touches ``floor`` (mm). Frames outside the boundaries
    take the nearest step's stance foot. The travel goes into the pelvis
    (:attr:`Skeleton.body_root`) translation, as in the captured files.
    """
    feet = foot_joints(motion)
    sk = motion.skeleton
    br = sk.body_root
    base = motion.copy()
    base.translations[:, [0, br]] = sk.offsets[[0, br]]
    rot, pos = base.global_transforms()
    frames = np.arange(motion.n_frames)
    left = _stance_is_left(motion.n_frames, boundaries, sides)
    pair = np.where(left[:, None], feet["L"], feet["R"])  # (F, 2): ankle, toe
    lowest = np.argmin(pos[frames[:, None], pair, 1], axis=1)
    point = pair[frames, lowest]
    prev = pos[np.maximum(frames - 1, 0), point]
    travel = np.cumsum((prev - pos[frames, point]) * [1.0, 0.0, 1.0], axis=0)
    foot_points = np.concatenate([feet["L"], feet["R"]])
    travel[:, 1] = floor - pos[:, foot_points, 1].min(axis=1)
    out = base.copy()
    if br == 0:
        out.translations[:, 0] += travel
    else:
        parent = sk.parents[br]
        world = pos[:, br] + travel
        out.translations[:, br] = np.einsum("fba,fb->fa", rot[:, parent], world - pos[:, parent])
    return out


def _stance_is_left(n_frames: int, boundaries: np.ndarray, sides: tuple[str, ...]) -> np.ndarray:
    """(F,) True where the left foot stands: the foot that landed at the latest boundary."""
    landed_left = np.array([sides[0] == "R", *(s == "L" for s in sides)])
    k = np.searchsorted(np.asarray(boundaries), np.arange(n_frames), side="right") - 1
    return landed_left[np.clip(k, 0, len(sides))]


def foot_slide(motion: Motion, boundaries: np.ndarray, sides: tuple[str, ...]) -> np.ndarray:
    """Ground-plane travel in mm of the stance foot's lowest point during each step.

    A foot that stays planted scores 0. Between successive frames the lower of
    ankle and toe is followed, while it is within ``CONTACT_HEIGHT`` of the
    feet's height range above their floor.
    """
    pos = motion.positions()
    feet = foot_joints(motion)
    left = _stance_is_left(motion.n_frames, boundaries, sides)
    both = pos[:, [*feet["L"], *feet["R"]], 1]
    floor, top = np.percentile(both.min(axis=1), [5, 95])
    out = []
    for k in range(len(sides)):
        t = np.arange(boundaries[k], boundaries[k + 1] + 1)
        pair = np.array(feet["L"] if left[boundaries[k]] else feet["R"])
        seg = pos[t][:, pair]
        which = np.argmin(seg[..., 1], axis=1)[1:]
        now = seg[np.arange(1, len(t)), which]
        before = seg[np.arange(len(t) - 1), which]
        low = np.maximum(now[:, 1], before[:, 1]) < floor + CONTACT_HEIGHT * (top - floor)
        moves = np.linalg.norm((now - before)[:, GROUND], axis=1)
        out.append(float(moves[low].sum()))
    return np.array(out)
