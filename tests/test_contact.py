"""B's place from the hands' contact (``contact_weight``, models.hmm.contact): the causal
running mean against brute force, the online partner against windowed respond, model files,
and the held-out pair of people of the collection's real handshakes."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import streamed as stream

from markovmotion import persist
from markovmotion.errors import ModelFormatError
from markovmotion.evaluate import choose
from markovmotion.models.base import Model
from markovmotion.models.hmm.contact import CONTACT_MM, OnlineContact, contact_shifts
from markovmotion.models.hmm.dual import DualHMM
from tests.conftest import assert_seen_streams_as_stepped

NEW_PEOPLE = dict(frame="heading", place_memory=300, normalise="person", output="regression")


def test_contact_shifts_are_the_mean_over_the_contact_frames_in_memory():
    rng = np.random.default_rng(0)
    shifts = rng.normal(0, 50, (60, 3))
    shifts[rng.random(60) < 0.5] = np.nan
    shifts[:5] = np.nan  # nothing moves before the first contact
    for memory in (None, 7, 100):
        got = contact_shifts(shifts, 0.5, memory)
        online = OnlineContact(0.5, memory)
        np.testing.assert_allclose([online.step(s) for s in shifts], got, atol=1e-9)
        for t in range(60):
            window = shifts[max(0, t + 1 - (memory or 10**9)) : t + 1]
            seen = window[np.isfinite(window).all(axis=1)]
            want = 0.5 * seen.mean(axis=0) if len(seen) else np.zeros(3)
            np.testing.assert_allclose(got[t], want, atol=1e-9)
    assert not got[:5].any()


@pytest.fixture(scope="module")
def handshakes(mocap):
    """(subject, A, B) of the real markers handshakes; at least two pairs of people."""
    pairs = mocap.pairs("handshake", kind="markers")
    takes = [(a.subject, *mocap.load_pair(a, b)) for a, b in pairs]
    assert len({s for s, _, _ in takes}) >= 2
    return takes


@pytest.fixture(scope="module")
def held_out(handshakes):
    """Models learnt on every pair of people but the last (both roles), contact weight 0 and
    1, and the last pair's takes."""
    last = sorted({s for s, _, _ in handshakes})[-1]
    train = [(s, a, b) for s, a, b in handshakes if s != last]
    pairs, people = choose.learnt(
        [(str(i), "handshake", a, b) for i, (_, a, b) in enumerate(train)],
        [s for s, _, _ in train],
        "both",
    )
    models = {
        w: DualHMM(**NEW_PEOPLE, contact_weight=w).fit(
            [(a, b) for _, _, a, b in pairs], groups=people
        )
        for w in (0.0, 1.0)
    }
    return models, [(a, b) for s, a, b in handshakes if s == last]


def test_new_people_are_placed_better(held_out):
    """On a pair of people the model never saw (who stand further apart than the training
    pairs), with the contact B stands nearer the real B's distance from A where the real
    hands touch, and nearer the real B in the world."""
    models, test = held_out
    assert models[0.0].contact is None and models[1.0].contact is not None
    hand = models[1.0].contact_hand_
    apart, errors = {0.0: [], 1.0: []}, {0.0: [], 1.0: []}
    for a, b in test:
        for w, model in models.items():
            real, gen = model.body_positions(b), model.body_positions(model.respond(a, "windowed"))
            a_pts = model.body_positions(a)
            n = min(len(real), len(gen))
            touch = np.linalg.norm(real[:n, hand] - a_pts[:n, hand], axis=-1) < CONTACT_MM

            apart[w].append(np.abs(_apart(gen, a_pts, n) - _apart(real, a_pts, n))[touch])
            errors[w].append(np.linalg.norm(gen[:n] - real[:n], axis=-1).mean())
    assert np.concatenate(apart[1.0]).mean() < 0.8 * np.concatenate(apart[0.0]).mean()
    assert np.mean(errors[1.0]) < np.mean(errors[0.0])


def test_a_hand_raised_or_out_to_the_side_is_not_a_handshake(held_out):
    """The regression is linear in A's hand: a hand held high or far to the side reads as
    "out" to it. Only where the hand lies as the training handshakes' did (and the pair would
    stand as they did) is it contact: A's real handshake hand is taken in its contact frames,
    the same hand moved 600 mm up or 500 mm sideways (in A's ground frame) in none of them."""
    from markovmotion.features.markers import turn_about_up

    model = held_out[0][1.0]
    contact = model.contact
    assert contact.bounds.shape == (4, 2)
    a, b = held_out[1][0]
    a_pts, real = model.body_positions(model._rate(a)), model.body_positions(model._rate(b))
    n = min(len(a_pts), len(real))
    a_pts, real = a_pts[:n], real[:n]
    yaw = model.placing(model._rate(a))[1][:n]
    gen = model.body_positions(model.respond(a, "windowed"))[:n]
    touch = np.linalg.norm(real[:, contact.hand] - a_pts[:, contact.hand], axis=-1) < CONTACT_MM
    taken = np.isfinite(contact.shifts(a_pts, yaw, gen)).all(axis=1)
    assert taken[touch].mean() > 0.5
    for move in ([0.0, 600.0, 0.0], [-500.0, 0.0, 0.0], [500.0, 0.0, 0.0]):
        moved = a_pts.copy()
        moved[:, contact.hand] += turn_about_up(np.broadcast_to(move, (n, 1, 3)), yaw)[:, 0]
        assert not np.isfinite(contact.shifts(moved, yaw, gen)).all(axis=1)[touch].any()


def _apart(b: np.ndarray, a: np.ndarray, n: int) -> np.ndarray:
    """(n,) horizontal distance between the two people's centroids."""
    return np.linalg.norm((b[:n] - a[:n]).mean(axis=1)[:, [0, 2]], axis=-1)


def test_a_contact_model_streams_what_windowed_respond_gives(held_out, capsys):
    model = held_out[0][1.0]
    a = model._rate(held_out[1][0][0]).copy()  # the fixture's take stays whole
    a.positions[40:43, 2] = np.nan  # a marker unseen for three frames: held
    partner = model.partner()
    shown = stream(partner, a)
    whole = model.respond(a, "windowed")
    np.testing.assert_allclose(shown, whole.positions, atol=1e-6)
    assert not np.allclose(whole.positions, held_out[0][0.0].respond(a, "windowed").positions)
    capsys.readouterr()


def test_a_contact_model_seen_at_once_streams_what_stepping_gives(handshakes, capsys):
    """The live page's path (:meth:`Partner.see`, for a model without a running centre)."""
    pairs = [(a, b) for _, a, b in handshakes]
    model = DualHMM(frame="heading", place_memory=60, contact_weight=0.5).fit(pairs)
    assert model.contact is not None
    a = model._rate(handshakes[-1][1]).copy()  # the fixture's take stays whole
    a.positions[40:43, 2] = np.nan
    assert model.partner().see(a).points is not None
    assert_seen_streams_as_stepped(model, a)
    capsys.readouterr()


def test_contact_model_files_round_trip_and_are_checked(held_out, tmp_path):
    model, a = held_out[0][1.0], held_out[1][0][0]
    path = tmp_path / "contact.npz"
    model.save(path)
    loaded = Model.load(path)
    assert loaded.contact is not None
    np.testing.assert_array_equal(loaded.respond(a).positions, model.respond(a).positions)
    header, arrays = persist.load_npz(path)
    key = next(k for k in arrays if k.endswith("contact_coef_"))
    arrays[key] = arrays[key][:2]
    persist.save_npz(path, "dual_hmm", header, arrays)
    with pytest.raises(ModelFormatError, match="contact_coef_"):
        Model.load(path)


def test_contact_weight_is_checked():
    for bad in (-0.1, 1.5, "half", float("nan")):
        with pytest.raises(ValueError, match="contact_weight must be 0 to 1"):
            DualHMM(contact_weight=bad).check_params()


def test_train_says_when_there_is_no_contact_to_learn(tmp_path, capsys):
    """Waves: nobody's hands touch, so --contact-weight learns nothing, and says so."""
    from markovmotion.cli import main

    out = tmp_path / "wave.npz"
    main(["dualhmm", "train", "--labels", "wave", "--kind", "markers", "--states", "4",
          "--n-iter", "3", "--contact-weight", "1", "--out", str(out)])  # fmt: skip
    assert "no frames whose right hands touch" in capsys.readouterr().err
    assert Model.load(out).contact is None
