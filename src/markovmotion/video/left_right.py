"""Left and right made consistent over one camera's video of MediaPipe Pose landmarks.

MediaPipe Pose sometimes swaps a person's left and right landmarks for tens of frames, the
whole body or only some limbs: in camera 1 of the real video (issue 24) a second person
stands behind the man. Each swap is a jump of the landmarks from one frame to the next (in
the image and in MediaPipe's world points), which a relabelling undoes. :func:`consistent_sides`
chooses, over the whole video (offline), a kept / swapped label per frame, first for the whole
body and then for each group of :data:`SIDE_GROUPS`, as the Viterbi path (Rabiner eqs. 32-35,
over triples of consecutive labels) whose cost adds the landmarks' motion under the labelling
from the previous frame and from the one before it (a swap spread over frames, as a partial
swap is), a fixed cost per change of labelling and a small cost per swapped frame. Continuity
alone cannot tell a video from the same one with every frame's sides swapped (the person
turned round): the labelling before the video counts as kept (MediaPipe's own), and
``faces_camera`` adds the webcam's prior that the person faces the camera.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence

import numpy as np

from markovmotion.video.landmarks import LANDMARKS

#: Left-right landmark groups relabelled together (MediaPipe's partial swaps: one limb
#: segment at a time), each decoded on its own.
SIDE_GROUPS: tuple[tuple[str, ...], ...] = (
    ("eye_inner", "eye", "eye_outer", "ear", "mouth", "shoulder"),
    ("elbow",),
    ("wrist", "pinky", "index", "thumb"),
    ("hip",),
    ("knee",),
    ("ankle", "heel", "foot_index"),
)
#: Cost of a change of labelling between two frames, in torso lengths of 2-D motion: a pair
#: of landmarks must jump across at least a quarter torso (each of the two moving it) before
#: relabelling it is worth a switch; closer pairs hardly matter to the body's placement.
SWITCH_COST = 0.5
#: Cost per frame of the swapped labelling (torso lengths): the tie-break that keeps
#: MediaPipe's own labels wherever continuity does not decide, and, of the two labellings
#: that continuity cannot tell apart (all flipped), the one that swaps fewer frames.
SWAPPED_COST = 0.01
#: Each group's parent (an index into :data:`SIDE_GROUPS`, decoded first), whose same side
#: a group's landmarks should lie nearer to in MediaPipe's 3-D world points.
PARENTS: tuple[int | None, ...] = (None, 0, 1, 0, 3, 4)
#: Cost per frame (torso lengths) of a labelling whose landmarks lie nearer the parent's
#: other side, at full evidence (the distances' difference at least the parent's width).
ATTACH_COST = 0.1
#: Cost per frame (torso lengths) of a whole-body labelling whose torso faces away from the
#: camera, at full evidence (:func:`facing_costs`).
FACING_COST = 0.1


def landmark_pair(stem: str) -> tuple[int, int]:
    """The indices of MediaPipe's left and right landmark of ``stem`` ("wrist", "mouth" ...)."""
    names = ("mouth_left", "mouth_right") if stem == "mouth" else (f"left_{stem}", f"right_{stem}")
    return LANDMARKS.index(names[0]), LANDMARKS.index(names[1])


def torso_lengths(points: np.ndarray) -> np.ndarray:
    """(F,) shoulder-middle to hip-middle distance of landmarks (F, 33, D)."""
    sh = [LANDMARKS.index(f"{s}_shoulder") for s in ("left", "right")]
    hp = [LANDMARKS.index(f"{s}_hip") for s in ("left", "right")]
    return np.linalg.norm(points[:, sh].mean(1) - points[:, hp].mean(1), axis=1)


def continuity_costs(
    pixels: np.ndarray,
    visibility: np.ndarray,
    pairs: list[tuple[int, int]],
    lag: int = 1,
    scale: float | None = None,
) -> np.ndarray:
    """(F, 2) cost of frame t's labelling relative to frame t-``lag``'s: column 0 the same
    labelling, column 1 the other one; the landmarks' motion (``pixels`` (F, 33, D): the
    2-D landmarks, or the world points, weighted by both frames' visibility) in torso
    lengths (``scale``; default the median shoulder-to-hip distance). Rows before ``lag``
    and rows next to a frame without a person are 0 (no continuity across a gap)."""
    li, ri = (np.array(x) for x in zip(*pairs, strict=True))
    if scale is None:
        torso = torso_lengths(pixels)
        scale = float(np.nanmedian(torso)) if np.isfinite(torso).any() else 1.0
    out = np.zeros((len(pixels), 2))
    for t in range(lag, len(pixels)):
        a, b = pixels[t - lag], pixels[t]
        w = np.minimum(visibility[t - lag], visibility[t])
        same = w[li] * np.linalg.norm(b[li] - a[li], axis=1) + w[ri] * np.linalg.norm(
            b[ri] - a[ri], axis=1
        )
        swap = w[li] * np.linalg.norm(b[li] - a[ri], axis=1) + w[ri] * np.linalg.norm(
            b[ri] - a[li], axis=1
        )
        if np.isfinite(same).all() and np.isfinite(swap).all():
            out[t] = same.sum() / max(scale, 1e-9), swap.sum() / max(scale, 1e-9)
    return out


def labelling_cost(
    labels: np.ndarray,
    continuity: np.ndarray,
    unary: np.ndarray | None = None,
    skip: np.ndarray | None = None,
) -> float:
    """Total cost of a labelling (F,) (0 kept, 1 swapped) given :func:`continuity_costs`
    from the previous frame and ``skip`` from the one before it, and per-frame costs
    ``unary`` (F, 2): the labelling before the video counts as kept, so a swapped first
    frame costs a switch."""
    labels = np.asarray(labels, dtype=int)
    f = np.arange(len(labels))
    change = np.diff(labels, prepend=0) != 0
    total = (
        continuity[f[1:], change[1:].astype(int)].sum()
        + SWITCH_COST * change.sum()
        + SWAPPED_COST * labels.sum()
    )
    if skip is not None and len(labels) > 2:
        total += skip[f[2:], (labels[2:] != labels[:-2]).astype(int)].sum()
    if unary is not None:
        total += unary[f, labels].sum()
    return float(total)


def attachment_costs(
    world: np.ndarray, pairs: Sequence[tuple[int, int]], parent: Sequence[tuple[int, int]]
) -> np.ndarray:
    """(F, 2) cost of keeping or swapping a group's pairs (3-D world points (F, 33, 3))
    given its parent's pairs as labelled: :data:`ATTACH_COST` times how much nearer each
    landmark lies to the parent's other side than to its own, over the parent's width,
    clipped to [0, 1]."""
    (li, ri), (pl, pr) = pairs[0], parent[0]
    own = np.linalg.norm(world[:, li] - world[:, pl], axis=1) + np.linalg.norm(
        world[:, ri] - world[:, pr], axis=1
    )
    other = np.linalg.norm(world[:, li] - world[:, pr], axis=1) + np.linalg.norm(
        world[:, ri] - world[:, pl], axis=1
    )
    width = np.linalg.norm(world[:, pl] - world[:, pr], axis=1)
    e = np.nan_to_num(np.clip((other - own) / np.maximum(width, 1e-9), -1.0, 1.0))
    return ATTACH_COST * np.c_[np.maximum(-e, 0.0), np.maximum(e, 0.0)]


def facing_costs(pixels: np.ndarray) -> np.ndarray:
    """(F, 2) cost of keeping or swapping the whole body's labels (2-D landmarks (F, 33, 2))
    for the prior that the person faces the camera (the webcam's user):
    :data:`FACING_COST` times how far the shoulders' and hips' left-right order in the image
    says the torso is turned away (their signed separation across the torso's up direction,
    over the torso's length, clipped to [0, 1]); continuity alone cannot tell a sequence from
    the same one with every frame's sides swapped (turned round)."""
    ls, rs, lh, rh = (
        LANDMARKS.index(f"{s}_{p}") for p in ("shoulder", "hip") for s in ("left", "right")
    )
    up = (pixels[:, ls] + pixels[:, rs] - pixels[:, lh] - pixels[:, rh]) / 2
    torso = np.maximum(np.linalg.norm(up, axis=1), 1e-9)
    across = pixels[:, ls] - pixels[:, rs] + pixels[:, lh] - pixels[:, rh]
    # facing the camera, upright: left at image right, up at image -y: cross(across, up) < 0
    away = (across[:, 0] * up[:, 1] - across[:, 1] * up[:, 0]) / torso**2
    e = np.nan_to_num(np.clip(away, -1.0, 1.0))
    return FACING_COST * np.c_[np.maximum(e, 0.0), np.maximum(-e, 0.0)]


def decode_labels(
    continuity: np.ndarray, unary: np.ndarray | None = None, skip: np.ndarray | None = None
) -> np.ndarray:
    """The labelling (F,) of least :func:`labelling_cost`, by Viterbi over the triples of
    consecutive labels: the state at t is (label t-2, label t-1, label t), so the costs that
    depend on two labels (``continuity`` from t-1, ``skip`` from t-2, (F, 2) each) are
    per-state costs and the transitions ((a, b, c) to (b, c, d)) are fixed (Rabiner
    eqs. 32-35 in log space, :func:`~markovmotion.algorithms.hmm_recursions.viterbi`)."""
    from markovmotion.algorithms.hmm_recursions import viterbi

    n = len(continuity)
    states = np.arange(8)
    s2, s1, s0 = states >> 2 & 1, states >> 1 & 1, states & 1
    change = (s1 != s0).astype(int)
    cost = continuity[:, change] + SWITCH_COST * change + SWAPPED_COST * s0
    if skip is not None:
        cost += skip[:, (s2 != s0).astype(int)]
    cost[0] = (SWAPPED_COST + SWITCH_COST) * s0  # the labelling before the video: kept
    if unary is not None:
        cost += unary[:, s0]
    start = np.where((s2 == s1) & (s1 == s0), 0.0, -np.inf)
    trans = np.where((states[:, None] & 3) == (states[None, :] >> 1), 0.0, -np.inf)
    path, _ = viterbi(start, trans, -cost)
    return s0[path][:n]


def consistent_sides(
    pixels: np.ndarray, world: np.ndarray, visibility: np.ndarray, faces_camera: bool = False
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One camera's MediaPipe landmarks (F, 33, 2) pixels, (F, 33, 3) world points and
    (F, 33) visibility with left and right made consistent over the whole video, each of
    :data:`SIDE_GROUPS` relabelled by :func:`decode_labels` (offline: it needs every frame),
    and (F, len(SIDE_GROUPS)) which groups were swapped back. A second person behind the
    one tracked makes MediaPipe swap his sides for tens of frames, sometimes only some limbs
    (issue 24, camera 1 of the real video): each swap is a jump in 2-D that continuity sees."""
    pixels, world, visibility = pixels.copy(), world.copy(), visibility.copy()
    swapped = np.zeros((len(pixels), len(SIDE_GROUPS)), dtype=bool)
    # the whole body first (MediaPipe's swaps are mostly whole-body mirrorings, which a
    # group seen edge on, such as the shoulders, may hardly jump at), then each group
    everything = [landmark_pair(s) for stems in SIDE_GROUPS for s in stems]
    body = decode_labels(
        _continuity(pixels, world, visibility, everything),
        facing_costs(pixels) if faces_camera else None,
        _continuity(pixels, world, visibility, everything, 2),
    ).astype(bool)
    relabel((pixels, world, visibility), body, everything)
    swapped[body] = True
    for g, stems in enumerate(SIDE_GROUPS):
        pairs = [landmark_pair(s) for s in stems]
        up = PARENTS[g]
        unary = (
            None
            if up is None
            else attachment_costs(world, pairs, [landmark_pair(x) for x in SIDE_GROUPS[up]])
        )
        labels = decode_labels(
            _continuity(pixels, world, visibility, pairs),
            unary,
            _continuity(pixels, world, visibility, pairs, 2),
        ).astype(bool)
        swapped[:, g] ^= labels
        relabel((pixels, world, visibility), labels, pairs)
    return pixels, world, visibility, swapped


def _continuity(pixels, world, visibility, pairs, lag: int = 1, scales=(None, None)):
    """Continuity in the image and in MediaPipe's world points (which also see a swap of a
    body seen edge on, whose left and right landmarks lie close in the image)."""
    return continuity_costs(pixels, visibility, pairs, lag, scales[0]) + continuity_costs(
        world, visibility, pairs, lag, scales[1]
    )


class OnlineSides:
    """:func:`consistent_sides` frame by frame, for a live camera (the camera page): each
    frame's labels are decided when it arrives, from the frames before it alone.

    Each stage (the whole body, then each of :data:`SIDE_GROUPS`, as offline) keeps the
    labels it gave the two frames before and gives the new frame the label of least cost in
    :func:`decode_labels`'s triple state (continuity from the frame before and the one
    before that, :data:`SWITCH_COST`, :data:`SWAPPED_COST`, the parent's attachment and, with
    ``faces_camera``, the facing prior): the Viterbi's forward step with every decision
    final (greedy), since a live partner cannot wait for later frames to revise one. A jump
    is seen, and a swap undone, on the frame it happens; what is lost against the offline
    decoder is a later frame showing that an earlier decision was wrong. Torso lengths (the
    costs' unit) are the median over the last ``memory`` frames. :meth:`gap` marks a frame
    without a person (no continuity across it; the labels carry on)."""

    def __init__(self, faces_camera: bool = False, memory: int = 900):
        self.faces_camera = faces_camera
        self._stages = [[landmark_pair(s) for stems in SIDE_GROUPS for s in stems]] + [
            [landmark_pair(s) for s in stems] for stems in SIDE_GROUPS
        ]
        n = len(LANDMARKS)
        # each stage's left and right rows in the stacked [pixels (x, y, 0); world] (66, 3)
        self._rows = [
            tuple(np.r_[idx, np.array(idx) + n] for idx in zip(*pairs, strict=True))
            for pairs in self._stages
        ]
        self._swaps = [(np.r_[left, right], np.r_[right, left]) for left, right in self._rows]
        self._parents = [None] + [
            None if up is None else [landmark_pair(x) for x in SIDE_GROUPS[up]] for up in PARENTS
        ]
        self._labels = np.zeros((len(self._stages), 2), dtype=int)  # at t-1, t-2
        self._before: list[list[tuple[np.ndarray, np.ndarray]]] = [[] for _ in self._stages]
        self._torso = (deque(maxlen=memory), deque(maxlen=memory))

    def gap(self) -> None:
        """The frame before the next had no person: no continuity across it."""
        self._before = [[] for _ in self._stages]

    def step(
        self, pixels: np.ndarray, world: np.ndarray, visibility: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """One frame's landmarks (33, 2) pixels, (33, 3) world points and (33,) visibility,
        relabelled, and which of :data:`SIDE_GROUPS` (len(SIDE_GROUPS),) were swapped."""
        n = len(LANDMARKS)
        points = np.zeros((2 * n, 3))
        points[:n, :2], points[n:] = pixels, world
        vis = np.r_[visibility, visibility]
        inverse = np.empty(2 * n)  # 1 / torso length, per row (pixels, then world)
        for k, (hist, pts) in enumerate(zip(self._torso, (pixels, world), strict=True)):
            hist.append(float(torso_lengths(pts[None])[0]))
            torso = np.array(hist)
            scale = float(np.nanmedian(torso)) if np.isfinite(torso).any() else 1.0
            inverse[k * n : (k + 1) * n] = 1.0 / max(scale, 1e-9)
        swapped = np.zeros(len(SIDE_GROUPS), dtype=bool)
        for k, (left, right) in enumerate(self._rows):
            cost = self._cost(k, left, right, points, vis, inverse)
            label = int(np.argmin(cost))
            self._before[k] = [(points.copy(), vis.copy())] + self._before[k][:1]
            self._labels[k] = label, self._labels[k, 0]
            if label:
                both, other = self._swaps[k]
                points[both], vis[both] = points[other], vis[other]
                if k == 0:
                    swapped[:] = True
                else:
                    swapped[k - 1] ^= True
        return points[:n, :2], points[n:], vis[:n], swapped

    def _cost(self, k: int, left, right, points, vis, inverse) -> np.ndarray:
        """(2,) cost of keeping or swapping stage ``k``'s pairs in the new frame: the terms
        of :func:`labelling_cost`, continuity as :func:`continuity_costs` has it."""
        label = np.array([0, 1])
        l1, l2 = self._labels[k]
        change = (label != l1).astype(int)
        cost = SWITCH_COST * change + SWAPPED_COST * label
        both, other = self._swaps[k]  # rows left + right, and right + left
        for lag, (before, seen) in enumerate(self._before[k], start=1):  # from t-1, t-2
            w = (np.minimum(seen, vis) * inverse)[both]
            now = points[both]
            same, swap = w @ _dist(now, before[both]), w @ _dist(now, before[other])
            if np.isfinite(same) and np.isfinite(swap):
                moved = change if lag == 1 else (label != l2).astype(int)
                cost += np.array([same, swap])[moved]
        n = len(LANDMARKS)
        if k == 0 and self.faces_camera:
            cost += facing_costs(points[None, :n, :2])[0]
        elif self._parents[k] is not None:
            cost += attachment_costs(points[None, n:], self._stages[k], self._parents[k])[0]
        return cost


def _dist(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.sqrt(((a - b) ** 2).sum(axis=1))


def relabel(
    arrays: tuple[np.ndarray, ...], rows: np.ndarray, pairs: Sequence[tuple[int, int]]
) -> None:
    """Swap the left and right ``pairs`` of ``arrays`` (F, 33, ...) in place in ``rows``."""
    li, ri = (list(x) for x in zip(*pairs, strict=True))
    at = np.nonzero(rows)[0]
    for arr in arrays:
        arr[np.ix_(at, li + ri)] = arr[np.ix_(at, ri + li)]
