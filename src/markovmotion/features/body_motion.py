"""A person's pose and how it moves: body-centred joint positions with their causal changes."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from markovmotion.core.motion import Motion
from markovmotion.features.base import FeatureStep
from markovmotion.features.body_points import body_point_index
from markovmotion.state import register


def ground_frame(
    motion: Motion, positions: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Where a person stands and faces, per frame: pelvis on the floor (F, 3) and heading (F,).

    ``positions``: the motion's :meth:`~Motion.positions`, if already computed.
    """
    pos = motion.positions() if positions is None else positions
    origin = pos[:, motion.skeleton.body_root].copy()
    origin[:, 1] = 0.0
    return origin, motion.heading(pos)


def pelvis_centred(
    motion: Motion, positions: np.ndarray | None = None, turn: bool = True
) -> np.ndarray:
    """(F, J, 3) joint positions about the pelvis: turned to face +Z
    (:meth:`Motion.body_centred_positions`) or, with ``turn=False``, in the world's axes."""
    if turn:
        return motion.body_centred_positions(positions)
    pos = motion.positions() if positions is None else positions
    root = motion.skeleton.body_root
    return pos - pos[:, root : root + 1]


def place_rows(origin: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """(F, D + 2) places as rows a mean can average: the origin (F, D), then the heading's
    cosine and sine. :func:`mean_place` reads an average of them back; every averaged place
    (the dual HMM's A, whole and online, the chain's partner) goes through the two."""
    yaw = np.asarray(yaw, dtype=float)
    return np.column_stack([origin, np.cos(yaw), np.sin(yaw)])


def mean_place(mean: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The place of averaged :func:`place_rows` (..., D + 2): the origins' mean and the
    heading as the direction of the mean unit vector (an angle's mean would jump at +-pi)."""
    return mean[..., :-2], np.arctan2(mean[..., -1], mean[..., -2])


def ground_travel(origin: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """(F, 3) per-frame travel in the body's own frame: sideways and forward step (mm), turn (rad).

    Backward differences: row t is the move from frame t - 1 to t, seen from
    the heading at t - 1; row 0 is zero.
    """
    step = origin[1:] - origin[:-1]
    c, s = np.cos(yaw[:-1]), np.sin(yaw[:-1])
    out = np.zeros((len(yaw), 3))
    out[1:, 0] = c * step[:, 0] - s * step[:, 2]
    out[1:, 1] = s * step[:, 0] + c * step[:, 2]
    turn = yaw[1:] - yaw[:-1]
    out[1:, 2] = np.arctan2(np.sin(turn), np.cos(turn))  # wrapped to [-pi, pi]
    return out


_ARC = np.array([1.0, 1.0, 1000.0])
"""The travel's units to mm: the turn (rad) as arc length at 1 m."""


@register
class BodyMotion(FeatureStep):
    """Motion -> (F, 6J + 3): pose, its change and the body's travel, all in mm.

    Row t holds the body-centred joint positions p_t
    (:meth:`Motion.body_centred_positions`), their change p_t - p_{t-1}
    scaled to ``horizon`` seconds, and the pelvis's ground travel and turn
    (:func:`ground_travel`; the turn as arc length at 1 m) scaled to
    ``travel_horizon`` seconds. A change scaled to h seconds is how far the
    point would move in h s at its present speed, so the weights do not
    depend on the frame rate. Only frames up to t are used, so an online
    partner computes row t as soon as frame t arrives; the first row's
    changes are zero.

    The dual-HMM paper describes A by its pose alone; on CMU's salsa the
    partner's response depends on where A is going as much as on A's pose, so
    the model sees both (README, "Virtual partner").

    ``points``: body point names (:mod:`~markovmotion.features.body_points`):
    the joints kept, found by name on each motion's skeleton, so motions of
    any skeleton that has them go through; default: every joint of the
    training skeleton (and only that skeleton). ``turn``: with False, the pose
    keeps the person's facing (positions about the pelvis in the world's
    axes) and the travel is in the world's axes: for data whose world axes
    mean something (one capture room), see :class:`DualHMM`'s ``frame``.
    """

    def __init__(
        self,
        horizon: float = 1 / 6,
        travel_horizon: float = 2 / 3,
        points: Sequence[str] | None = None,
        turn: bool = True,
    ):
        self.horizon = horizon
        self.travel_horizon = travel_horizon
        self.points = points
        self.turn = turn

    def fit(self, sequences: Sequence[Motion]) -> BodyMotion:
        self.skeleton_ = sequences[0].skeleton
        for m in sequences:
            self._index(m)
        return self

    def _index(self, motion: Motion) -> np.ndarray | slice:
        """The joints of ``motion`` the features hold."""
        if self.points is None:
            self.skeleton_.check_compatible(motion.skeleton)
            return slice(None)
        return body_point_index(motion.skeleton, self.points, motion.name or "motion")

    def pose(self, motion: Motion, positions: np.ndarray | None = None) -> np.ndarray:
        """(F, J, 3) body-centred positions of the joints (or body points) the features
        hold, from the motion's world ``positions`` if already computed."""
        return pelvis_centred(motion, positions, self.turn)[:, self._index(motion)]

    def transform(self, sequences: Sequence[Motion]) -> list[np.ndarray]:
        out = []
        for m in sequences:
            pos = m.positions()
            origin, yaw = ground_frame(m, pos)
            if not self.turn:
                yaw = np.zeros_like(yaw)
            out.append(self.rows(self.pose(m, pos), origin, yaw, m.fps))
        return out

    def rows(self, pose: np.ndarray, origin: np.ndarray, yaw: np.ndarray, fps: float) -> np.ndarray:
        """(F, 6J + 3) features of consecutive frames from their body-centred positions
        (F, J, 3) and ground frame (:func:`ground_frame`), forward kinematics done by the
        caller: an online partner gets row t from frames t - 1 and t alone."""
        pose = pose.reshape(len(pose), -1)
        d = pose.shape[1]
        out = np.zeros((len(pose), 2 * d + 3))
        out[:, :d] = pose
        out[1:, d : 2 * d] = (pose[1:] - pose[:-1]) * (self.horizon * fps)
        out[:, 2 * d :] = ground_travel(origin, yaw) * (_ARC * (self.travel_horizon * fps))
        return out

    def inverse_transform(self, sequences: Sequence[np.ndarray]) -> list[np.ndarray]:
        """(F, J, 3) body-centred positions (the changes are dropped)."""
        n = self.skeleton_.n_joints if self.points is None else len(self.points)
        return [np.asarray(x)[:, : n * 3].reshape(len(x), -1, 3) for x in sequences]
