"""B's place scaled by A's size (``DualHMM(place_scale="size")``): the running size against
brute force and online, what a bigger A does to B's distance, the online partner against
windowed respond, model files, and the options' errors."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import streamed as stream

from markovmotion import persist
from markovmotion.core.markers import Markers
from markovmotion.errors import ModelFormatError, SkeletonMismatchError
from markovmotion.features.person import OnlineSizeScale, body_radius, size_scale
from markovmotion.models.base import Model
from markovmotion.models.hmm.dual import DualHMM
from tests.conftest import make_motion

NAMES = ["HEAD", "TORSO", "R_SHOULDER", "L_SHOULDER", "R_HAND", "L_HAND"]
BODY = np.array(
    [[0, 1600, 0], [0, 1200, 0], [-200, 1450, 0], [200, 1450, 0], [-250, 900, 60], [250, 900, 0]],
    dtype=float,
)


def test_body_radius_is_the_rms_distance_from_the_centroid():
    rng = np.random.default_rng(0)
    p = rng.normal(0, 100, (5, 7, 3))
    want = [np.sqrt(np.mean([np.sum((q - q.mean(0)) ** 2) for q in [f]]) / 7) for f in p]
    np.testing.assert_allclose(body_radius(p), want)
    np.testing.assert_allclose(body_radius(2 * p + 30), 2 * body_radius(p))


def test_size_scale_is_the_causal_running_mean_and_runs_online():
    rng = np.random.default_rng(1)
    radius = rng.uniform(250, 350, 80)
    seen = rng.random(80) > 0.2
    radius[~seen] = np.nan  # an unseen frame has no size and keeps the mean before it
    got = size_scale(radius, seen, 300.0, prior=30)
    online = OnlineSizeScale(300.0, prior=30)
    for t in range(80):
        r = radius[: t + 1][seen[: t + 1]]
        mean = (30 * 300.0 + r.sum()) / (30 + len(r))
        assert got[t] == pytest.approx((mean + 300.0) / 600.0)
        if seen[t]:
            online(radius[t])
        assert online.scale == pytest.approx(got[t])
    # the training people's size gives the training pairs' place
    np.testing.assert_allclose(size_scale(np.full(9, 300.0), np.ones(9, bool), 300.0), 1.0)


def _pair(size: float, frames: int = 120, seed: int = 0) -> tuple[Markers, Markers]:
    """A and B of one size (scaled bodies) shaking hands: B stands 2.6 radii from A, A's
    hand moves; the farther apart the bigger the pair, as the Bütepage pairs."""
    rng = np.random.default_rng(seed)
    t = np.arange(frames) / 30.0
    a = np.repeat(BODY[None] * size, frames, axis=0)
    a[:, 4, 2] += 150 * (1 + np.sin(2 * np.pi * t))  # A's hand out and back
    a += rng.normal(0, 3, a.shape)
    apart = 2.6 * float(np.mean(body_radius(BODY[None] * size)))
    turn = np.array([[-1, 0, 0], [0, 1, 0], [0, 0, -1]], dtype=float)  # B faces A
    b = (BODY[None] * size) @ turn.T + np.array([0, 0, apart])
    b = np.repeat(b, frames, axis=0) + rng.normal(0, 3, a.shape)
    b[:, 4, 2] -= 150 * (1 + np.sin(2 * np.pi * t))
    return Markers(NAMES, a, 30.0, "A"), Markers(NAMES, b, 30.0, "B")


def _apart(b: Markers, a: Markers, start: int = 150) -> float:
    """Median horizontal distance between the two people's centroids from frame ``start``
    (once A's running size has settled)."""
    d = (b.positions[start:] - a.positions[start : b.n_frames]).mean(axis=1)[:, [0, 2]]
    return float(np.median(np.linalg.norm(d, axis=-1)))


def _training_pairs() -> list[tuple[Markers, Markers]]:
    return [_pair(s, seed=i) for i, s in enumerate((0.9, 0.95, 1.0, 1.05, 1.1))]


@pytest.fixture(scope="module")
def models():
    pairs = _training_pairs()
    common = dict(n_states=3, n_iter=5, frame="heading", window=5, normalise="person")
    return {
        scale: DualHMM(**common, place_scale=scale).fit(pairs, groups=list("abcde"))
        for scale in ("none", "size")
    }


def test_a_bigger_or_smaller_person_is_answered_from_their_distance(models):
    """Pairs 25 % bigger and 10 % smaller than the training pairs' average stand 25 % further
    apart and 10 % nearer: with ``place_scale="size"`` B is placed nearer their distance than
    without (B is of the average size, so half of the difference is the most it can take)."""
    fitted = models["size"]
    people = [x for pair in _training_pairs() for x in pair]  # each person's mean size
    assert fitted.place_size_ == pytest.approx(
        np.mean([body_radius(x.positions).mean() for x in people])
    )
    for size in (1.25, 0.9):
        a, b = _pair(size, frames=400, seed=9)
        real = _apart(b, a)
        off = {k: abs(_apart(m.respond(a, "windowed"), a) - real) for k, m in models.items()}
        assert off["size"] < 0.85 * off["none"], (size, off)
    # a pair of the training people's size is placed as without the scale
    a, b = _pair(1.0, frames=400, seed=10)
    gap = abs(_apart(fitted.respond(a, "windowed"), a) - _apart(models["none"].respond(a), a))
    assert gap < 0.02 * _apart(b, a)


def test_a_size_scaled_partner_streams_what_windowed_respond_gives(models, capsys):
    model = models["size"]
    a, _ = _pair(1.2, seed=11)
    a.positions[40:43, 2] = np.nan  # a marker unseen for three frames: held
    partner = model.partner()
    assert partner.see(a) is None  # the running size is kept across loops: step it
    shown = stream(partner, a)
    whole = model.respond(a, "windowed")
    np.testing.assert_allclose(shown, whole.positions, atol=1e-6)
    capsys.readouterr()


def test_size_scaled_model_files_round_trip_and_are_checked(models, tmp_path):
    model = models["size"]
    a, _ = _pair(1.2, seed=12)
    path = tmp_path / "sized.npz"
    model.save(path)
    loaded = Model.load(path)
    assert loaded.place_size_ == model.place_size_
    np.testing.assert_array_equal(loaded.respond(a).positions, model.respond(a).positions)
    header, arrays = persist.load_npz(path)
    text = str(header)
    assert "place_size_" in text
    _set(header, "place_size_", -3.0)
    persist.save_npz(path, "dual_hmm", header, arrays)
    with pytest.raises(ModelFormatError, match="place_size_"):
        Model.load(path)


def _set(tree, key: str, value) -> bool:
    """Set ``key`` wherever it is in a nested JSON header."""
    if isinstance(tree, dict):
        for k, v in tree.items():
            if k.endswith(key) and not isinstance(v, dict | list):
                tree[k] = value
                return True
            if _set(v, key, value):
                return True
    elif isinstance(tree, list):
        return any(_set(v, key, value) for v in tree)
    return False


def test_place_scale_is_checked():
    with pytest.raises(ValueError, match="place_scale must be one of"):
        DualHMM(place_scale="height").check_params()
    pair = (make_motion(40, seed=0), make_motion(40, seed=1))
    with pytest.raises(SkeletonMismatchError, match="place_scale 'size'"):
        DualHMM(place_scale="size", n_states=2, n_iter=1).fit([pair])


def test_train_with_place_scale_on_skeletons_is_one_line(tmp_path, capsys):
    from markovmotion.cli import main

    with pytest.raises(SystemExit) as exc:
        main(["dualhmm", "train", "--labels", "handshake", "--kind", "skeleton", "--states", "2",
              "--n-iter", "1", "--place-scale", "size", "--out", str(tmp_path / "m.npz")])  # fmt: skip
    assert exc.value.code == 2
    err = [ln for ln in capsys.readouterr().err.splitlines() if not ln.startswith("note:")]
    assert len(err) == 1 and "place_scale 'size' measures people by their markers" in err[0]
    assert not (tmp_path / "m.npz").exists()
