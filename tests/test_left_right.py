"""The per-group left/right Viterbi of video.sides on synthetic MediaPipe landmarks."""

import itertools

import numpy as np
import pytest

from markovmotion.video import left_right
from markovmotion.video.left_right import (
    SIDE_GROUPS,
    OnlineSides,
    consistent_sides,
    continuity_costs,
    decode_labels,
    labelling_cost,
)
from markovmotion.video.monocular import LANDMARKS


def _walk(n=60, seed=0):
    """A body whose left landmarks sit 60 px right of its right ones, drifting slowly."""
    rng = np.random.default_rng(seed)
    base = np.zeros((len(LANDMARKS), 2))
    for i, name in enumerate(LANDMARKS):
        x = 60.0 if "left" in name else 0.0
        base[i] = (100 + x + rng.normal(0, 3), 50 + 10 * i)
    drift = np.cumsum(rng.normal(0, 0.5, (n, 1, 2)), axis=0)
    pixels = base[None] + drift
    world = np.concatenate([pixels, np.zeros((n, len(LANDMARKS), 1))], axis=2)
    return pixels, world, np.ones((n, len(LANDMARKS)))


def _swap(pixels, world, frames, stems):
    pixels, world = pixels.copy(), world.copy()
    for stem in stems:
        a = LANDMARKS.index("mouth_left" if stem == "mouth" else f"left_{stem}")
        b = LANDMARKS.index("mouth_right" if stem == "mouth" else f"right_{stem}")
        for arr in (pixels, world):
            arr[np.ix_(frames, [a, b])] = arr[np.ix_(frames, [b, a])]
    return pixels, world


def _online(p, w, v):
    """:class:`OnlineSides` frame by frame, stacked as :func:`consistent_sides` returns."""
    sides = OnlineSides()
    out = [sides.step(p[t], w[t], v[t]) for t in range(len(p))]
    return tuple(np.stack(x) for x in zip(*out, strict=True))


@pytest.mark.parametrize("decoder", [consistent_sides, _online], ids=["offline", "online"])
def test_unswapped_sequence_is_unchanged(decoder):
    p, w, v = _walk()
    q, x, _, swapped = decoder(p, w, v)
    assert not swapped.any()
    np.testing.assert_array_equal(q, p)
    np.testing.assert_array_equal(x, w)


@pytest.mark.parametrize("decoder", [consistent_sides, _online], ids=["offline", "online"])
def test_full_and_partial_swaps_are_restored_exactly(decoder):
    """The online decoder too: each swap is undone on the frame its jump appears."""
    p, w, v = _walk()
    every = [s for g in SIDE_GROUPS for s in g]
    bad_p, bad_w = _swap(p, w, np.arange(20, 35), every)  # the whole body
    bad_p, bad_w = _swap(bad_p, bad_w, np.arange(40, 50), ["wrist", "pinky", "index", "thumb"])
    q, x, _, swapped = decoder(bad_p, bad_w, v)
    np.testing.assert_array_equal(q, p)
    np.testing.assert_array_equal(x, w)
    assert swapped[20:35].all() and swapped[40:50, 2].all() and not swapped[40:50, 0].any()


def test_viterbi_equals_brute_force():
    rng = np.random.default_rng(3)
    for _ in range(5):
        cont, skip, unary = (rng.uniform(0, 1.5, (9, 2)) for _ in range(3))
        cont[0] = skip[:2] = 0
        best = min(
            labelling_cost(np.array(lab), cont, unary, skip)
            for lab in itertools.product((0, 1), repeat=len(cont))
        )
        got = decode_labels(cont, unary, skip)
        assert np.isclose(labelling_cost(got, cont, unary, skip), best)


def test_continuity_cost_sees_a_jump():
    p, w, v = _walk(10)
    bad, _ = _swap(p, w, np.arange(5, 10), ["shoulder"])
    pair = [(LANDMARKS.index("left_shoulder"), LANDMARKS.index("right_shoulder"))]
    c = continuity_costs(bad, v, pair)
    assert c[5, 1] < c[5, 0] and (c[6:, 0] < c[6:, 1]).all()


def test_online_decision_is_the_least_cost_next_label():
    """Each whole-body label is the one that adds least to :func:`labelling_cost` given the
    labels already given (the torso is the same in every frame, so the running scale is the
    offline one)."""
    p, w, v = _walk(40, seed=5)
    rng = np.random.default_rng(1)
    every = [s for g in SIDE_GROUPS for s in g]
    for _ in range(6):  # swaps at random frames, some only half way (a jump of half a swap)
        at = rng.choice(40, size=rng.integers(1, 8), replace=False)
        p, w = _swap(p, w, at, every[: rng.integers(1, len(every) + 1)])
    pairs = [left_right.landmark_pair(s) for s in every]
    cont = left_right._continuity(p, w, v, pairs)
    skip = left_right._continuity(p, w, v, pairs, 2)
    sides = OnlineSides()
    labels: list[int] = []
    for t in range(len(p)):
        best = min(
            (0, 1), key=lambda c: labelling_cost(labels + [c], cont[: t + 1], None, skip[: t + 1])
        )
        sides.step(p[t], w[t], v[t])
        labels.append(int(sides._labels[0, 0]))
        assert labels[-1] == best
