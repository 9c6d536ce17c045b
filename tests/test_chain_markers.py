"""The behaviour chain on marker takes (C3D, named points) and its cross-validation by people:
markers seen by name, placed back exactly, answered with markers; every pair of people left
out once, never trained on."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from markovmotion.cli import main
from markovmotion.core.markers import Markers
from markovmotion.data.splits import PAIR_TEST_EVERY
from markovmotion.errors import SkeletonMismatchError
from markovmotion.evaluate.chain import PARTNERS, cross_validate_people
from markovmotion.features.joint_shape import (
    JointShape,
    TwoPeople,
    marker_size,
    person_from_markers,
    rotate_yaw,
)
from markovmotion.models.chain.partner import VirtualPartner

SMALL = {"n_state_prototypes": 8, "n_behaviour_prototypes": 8, "n_epochs": 1}


@pytest.fixture(scope="module")
def handshakes(mocap) -> list[tuple]:
    """The collection's marker handshakes: (name, label, people, A, B), at least two pairs of
    people (the test says so)."""
    pairs = mocap.pairs(label="handshake", kind="markers")
    takes = [(a.file, a.label, a.subject, *mocap.load_pair(a, b)) for a, b in pairs]
    assert len({t[2] for t in takes}) >= 2, "the marker handshakes should hold two pairs of people"
    return takes


@pytest.fixture(scope="module")
def short(handshakes) -> list[tuple]:
    """The handshakes of two pairs of people, 5 s of each (a quick cross-validation)."""
    two = sorted({t[2] for t in handshakes})[:2]
    return [
        (n, lab, p, a.trim(0, 150), b.trim(0, 150)) for n, lab, p, a, b in handshakes if p in two
    ]


@pytest.fixture(scope="module")
def marker_partner(handshakes) -> VirtualPartner:
    """A small chain fitted on the marker handshakes of every pair of people but the last."""
    last = handshakes[-1][2]
    train = [(a, b) for _, _, people, a, b in handshakes if people != last]
    return VirtualPartner(**SMALL).fit(train)


def test_a_marker_take_never_seen_is_refused_by_name(short):
    """Markers holding no value at all: one line naming the model, the take and the role
    (it had been a note dropping every marker, NumPy's warnings and "sequence 0 holds NaN")."""
    (*_, a, b), (*_, a1, b1) = short[:2]
    blind = a.copy()
    blind.positions[:] = np.nan
    with pytest.raises(ValueError, match=r"VirtualPartner.fit: take 1 \(A\).*nothing of it"):
        VirtualPartner(n_state_prototypes=5, n_behaviour_prototypes=5).fit([(a1, b1), (blind, b)])


def test_marker_size_ignores_where_the_body_is_and_scales_with_it():
    rng = np.random.default_rng(0)
    pos = rng.normal(size=(20, 8, 3)) * 200
    moved = rotate_yaw(pos, 0.7) + np.array([1000.0, -300.0, 50.0])
    assert marker_size(moved) == pytest.approx(marker_size(pos))
    assert marker_size(2.5 * pos) == pytest.approx(2.5 * marker_size(pos))


def test_marker_people_are_placed_back_exactly_with_their_heights(handshakes):
    _, _, _, a, b = handshakes[0]
    take = TwoPeople.from_motions(a, b, fps=None)
    assert take.points.shape[1:] == (2, len(a.names), 3)
    # the reference is the markers' centroid, off the floor: d holds the vertical separation
    np.testing.assert_allclose(take.reference[:, 0], a.positions.mean(axis=1))
    js = JointShape().fit([take])
    assert js.vertical_
    c = js.transform([take])[0]
    assert c.shape[1] == 2 * js.shape_size + 5 + 1
    for person in (0, 1):
        partner = js.place(c, person, take.person(person))
        np.testing.assert_allclose(partner.points, take.points[:, 1 - person], atol=1e-6)


def test_marker_person_picks_markers_by_name_and_fills_gaps():
    rng = np.random.default_rng(1)
    names = ("HEAD", "L_SHOULDER", "R_SHOULDER", "TORSO")
    pos = rng.normal(size=(10, 4, 3)) * 100
    pos[3, 0] = np.nan  # an occluded sample
    m = Markers(names, pos, 30.0)
    p = person_from_markers(m, ["TORSO", "HEAD"])
    assert p.points.shape == (10, 2, 3) and np.isfinite(p.points).all()
    np.testing.assert_allclose(p.points[3, 1], (pos[2, 0] + pos[4, 0]) / 2)
    with pytest.raises(ValueError, match="NECK"):
        person_from_markers(m, ["TORSO", "NECK"])


def test_marker_chain_answers_with_markers_and_round_trips(marker_partner, handshakes, tmp_path):
    model = marker_partner
    assert model.uses_markers and model.source == "mocap" and model.skeletons_ is None
    _, _, _, a, b = handshakes[-1]  # a pair of people it has not seen
    assert model.markers_ == list(a.names)
    out = model.respond(a, n_hypotheses=10)
    assert isinstance(out, Markers) and out.names == a.names and out.fps == model.fps_
    truth = b.resample(model.fps_)
    assert out.n_frames == truth.n_frames and np.isfinite(out.positions).all()
    # the partner stands where B stands, not where A does
    to_b = np.linalg.norm(out.positions - truth.positions, axis=-1).mean()
    to_a = np.linalg.norm(out.positions - a.resample(model.fps_).positions, axis=-1).mean()
    assert to_b < 0.5 * to_a
    model.save(tmp_path / "m.npz")
    back = VirtualPartner.load(tmp_path / "m.npz")
    assert back.markers_ == model.markers_ and back.shape_step.vertical_
    np.testing.assert_allclose(back.respond(a, n_hypotheses=10).positions, out.positions)
    # markers in another order are picked by name
    order = list(reversed(range(len(a.names))))
    shuffled = Markers(tuple(a.names[i] for i in order), a.positions[:, order], a.fps, a.name)
    np.testing.assert_allclose(back.respond(shuffled, n_hypotheses=10).positions, out.positions)


def test_marker_chain_refuses_what_it_cannot_see(marker_partner, handshakes, salsa_pair):
    _, _, _, a, _ = handshakes[0]
    with pytest.raises(SkeletonMismatchError, match="R_HAND"):
        marker_partner.respond(a.select([n for n in a.names if n != "R_HAND"]))
    with pytest.raises(SkeletonMismatchError, match="trained on skeletons, not markers"):
        VirtualPartner(**SMALL).fit([salsa_pair]).respond(a)
    with pytest.raises(TypeError, match="all Motions or all Markers"):
        VirtualPartner(**SMALL).fit([(a, a), salsa_pair])


def test_marker_chain_answers_a_skeleton_by_its_body_points(marker_partner, salsa_pair, capsys):
    import dataclasses

    from markovmotion.core.motion import Motion
    from markovmotion.features.markers import named_body_points

    a = salsa_pair[0].trim(0, 120)
    points = named_body_points(a, marker_partner.markers_)
    out = marker_partner.respond(a, rng=0, n_hypotheses=10)
    same = marker_partner.respond(points, rng=0, n_hypotheses=10)
    assert out.names == tuple(marker_partner.markers_)
    np.testing.assert_allclose(out.positions, same.positions)
    # the partner stands at the skeleton's height (its centroid's, as the training pairs)
    gap = np.mean(out.positions[..., 1]) - np.mean(points.positions[..., 1])
    assert abs(gap) < 300.0, gap
    # online, frame by frame, the same frames
    a25 = a.resample(marker_partner.fps_)
    partner = marker_partner.partner(rng=0, n_hypotheses=10, size=None)
    frames = [f for t in range(a25.n_frames) if (f := partner.step(a25.trim(t, t + 1)))]
    assert len(frames) + len(partner.finish()) == a25.n_frames
    # a skeleton without a body point the markers name: one error naming it
    names = tuple("noggin" if n.lower() == "head" else n for n in a.skeleton.names)
    headless = Motion(
        dataclasses.replace(a.skeleton, names=names),
        a.rotations,
        a.translations,
        a.fps,
        name="headless",
    )
    with pytest.raises(SkeletonMismatchError, match="headless.*head"):
        marker_partner.respond(headless)
    capsys.readouterr()


@pytest.fixture(scope="module")
def salsa_pair(mocap):
    a, b = mocap.load_pair(*mocap.pairs(label="salsa")[0])
    return a.trim(0, 120), b.trim(0, 120)


# ---------------------------------------------------------------- cross-validation by people
def test_crossval_leaves_out_every_pair_of_people_once_and_never_trains_on_it(handshakes):
    report = cross_validate_people(handshakes, VirtualPartner(**SMALL), n_hypotheses=6)
    people = {t[2] for t in handshakes}
    files: dict[str, set[str]] = {p: set() for p in people}
    for _, _, p, a, b in handshakes:
        files[p] |= {Path(a.source).name, Path(b.source).name}
    held = [f["left_out"] for f in report["folds"]]
    assert sorted(held) == sorted(people) and report["left_out"] == "pairs of people"
    for fold in report["folds"]:
        trained = set(fold["trained_on"])
        others = set().union(*(files[p] for p in people if p != fold["left_out"]))
        assert trained == others  # every other take, by what the fitted copy recorded
        assert not trained & files[fold["left_out"]]
        assert fold["tested_on"] == [t[0] for t in handshakes if t[2] == fold["left_out"]]
    # every take answered once, each person masked in turn; pooled by pair, label, overall
    assert list(report["per_pair"]) == [t[0] for t in handshakes]
    frames = sum(r["frames"] for r in report["per_pair"].values())
    assert (
        report["overall"]["frames"]
        == frames
        == sum(r["frames"] for r in report["per_people"].values())
    )
    for part in ("world_mm", "body_centred_mm"):
        assert set(report["overall"][part]) == set(PARTNERS)
        weighted = sum(r[part]["mean_shape"] * r["frames"] for r in report["per_people"].values())
        assert report["overall"][part]["mean_shape"] == pytest.approx(weighted / frames, abs=0.1)
        assert all(0 < v < 2000 for v in report["overall"][part].values())
    # how much each partner jumps (the dual HMM's jump p90), the real partner's beside
    jumps = report["overall"]["jump_p90_mm"]
    assert set(jumps) == {*PARTNERS, "real"} and all(0 < v < 2000 for v in jumps.values())
    assert jumps["multiple_hypotheses"] == jumps["multiple_hypotheses_ml"]
    one = next(iter(report["per_pair"].values()))["jump_p90_mm"]
    assert set(one) == set(jumps)
    (label,) = report["per_label"]
    assert set(report["per_label"][label]["per_people"]) == people
    over = report["overall"]
    for key, single in (
        ("aim_met", "single_hypothesis"),
        ("aim_met_paper", "single_hypothesis_paper"),
    ):
        assert over[key]["world_mm"] == (
            over["world_mm"]["multiple_hypotheses"]
            < min(over["world_mm"][single], over["world_mm"]["mean_shape"])
        )


def test_crossval_with_both_roles_learns_each_take_twice(short):
    one = cross_validate_people(short, VirtualPartner(**SMALL), n_hypotheses=6)
    both = cross_validate_people(short, VirtualPartner(**SMALL), n_hypotheses=6, roles="both")
    assert both["roles"] == "both" and [f["trained_on"] for f in both["folds"]] == [
        f["trained_on"] for f in one["folds"]
    ]  # the same files, each also learnt with the people swapped
    assert both["overall"]["world_mm"] != one["overall"]["world_mm"]


def test_crossval_command_prints_json_and_refuses_unknown_labels(capsys):
    argv = ["chain", "crossval", "--labels", "handshake", "--kind", "markers", "--prototypes"]
    main([*argv, "4", "--behaviours", "4", "--epochs", "1", "--hypotheses", "4", "--json"])
    report = json.loads(capsys.readouterr().out)
    assert report["model"]["n_state_prototypes"] == 4 and report["model"]["hypotheses"] == 4
    assert report["overall"]["jump_p90_mm"]["real"] > 0
    assert set(report["per_label"]) == {"handshake"} and report["folds"]
    with pytest.raises(SystemExit) as info:
        main(["chain", "crossval", "--labels", "no_such_label", "--json"])
    err = capsys.readouterr().err
    assert info.value.code == 2 and "no_such_label" in err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1


@pytest.fixture
def chain_fits(monkeypatch) -> list[set[str]]:
    """The pairs of people of every fit a chain cross-validation or choice makes, in order."""
    import markovmotion.evaluate.chain as chain_eval

    seen: list[set[str]] = []
    fit = chain_eval._fit_on

    def spy(model, takes, roles):
        seen.append({t[2] for t in takes})
        return fit(model, takes, roles)

    monkeypatch.setattr(chain_eval, "_fit_on", spy)
    return seen


def test_nested_choice_never_sees_the_pair_of_people_it_is_reported_on(handshakes, chain_fits):
    """Each outer fold trains on the other pairs; each of its inner fits on fewer still (one
    per inner fold and setting), none on the held-out pair: settings are chosen on training
    pairs only, and the pick is the setting with the lowest inner error."""
    from markovmotion.evaluate import choose

    people = {t[2] for t in handshakes}
    assert len(people) >= 3  # the collection holds three pairs of handshakes
    short = [(n, lab, p, a.trim(0, 90), b.trim(0, 90)) for n, lab, p, a, b in handshakes]
    grid = [{"n_state_prototypes": 4}, {"n_state_prototypes": 6, "roles": "both"}]
    report = cross_validate_people(short, VirtualPartner(**SMALL), n_hypotheses=4, grid=grid)
    per_fold = len(grid) * (len(people) - 1) + 1  # inner fits, then the outer one
    assert len(chain_fits) == len(people) * per_fold
    for k, fold in enumerate(report["folds"]):
        fits = chain_fits[k * per_fold : (k + 1) * per_fold]
        held = fold["left_out"]
        assert all(held not in s for s in fits)
        assert all(len(s) == len(people) - 2 for s in fits[:-1])  # inner: one more pair out
        assert fits[-1] == people - {held}
        chosen = fold["chosen"]
        assert chosen["settings"] in grid and len(chosen["inner_mm"]) == len(grid)
        best = min(chosen["inner_mm"], key=chosen["inner_mm"].get)
        assert best == choose.setting_label(chosen["settings"])


def test_train_chooses_settings_by_leaving_people_out_and_records_the_pick(tmp_path):
    """``chain train --choose`` picks among settings by leaving one pair of people out on the
    training takes, trains with the pick and records it and every setting's error."""
    out = tmp_path / "chosen.npz"
    argv = ["chain", "train", "--label", "handshake", "--kind", "markers", "--epochs", "1"]
    argv += ["--prototypes", "4", "--behaviours", "4", "--hypotheses", "4", "--out", str(out)]
    main([*argv, "--choose", "n_state_prototypes+n_behaviour_prototypes=4,6;roles=one,both"])
    model = VirtualPartner.load(out)
    inner = model.chosen_["inner_mm"]
    assert len(inner) == 4
    pick = model.chosen_["settings"]
    assert min(inner, key=inner.get) == ",".join(f"{k}={v}" for k, v in pick.items())
    assert model.roles_ == pick["roles"]
    assert model.n_state_prototypes == model.n_behaviour_prototypes == pick["n_state_prototypes"]
    assert len(model.chain_.state_prototypes_) == pick["n_state_prototypes"]


def test_train_holds_out_the_test_trials_or_none(mocap, tmp_path, capsys):
    """``chain train --test-trials``: the collection's split by default (the last take of
    each label), the trials given, or with ``none`` every take; a trial no take has is
    refused in one line before anything is learnt."""
    pairs = mocap.pairs("handshake", kind="markers")
    argv = ["chain", "train", "--label", "handshake", "--kind", "markers", "--epochs", "1"]
    argv += ["--prototypes", "4", "--behaviours", "4", "--out", str(tmp_path / "m.npz")]

    def learnt(*extra: str) -> int:
        main([*argv, *extra])
        return int(capsys.readouterr().err.split("wrote ")[-1].split(": ")[1].split(" takes")[0])

    assert learnt("--test-trials", "none") == len(pairs)
    assert learnt() == len(pairs) - math.ceil(len(pairs) / PAIR_TEST_EVERY)
    first = pairs[0][0].trial
    assert learnt("--test-trials", first) == sum(a.trial != first for a, _ in pairs)
    with pytest.raises(SystemExit) as exc:
        main([*argv, "--test-trials", "no-such-trial"])
    assert exc.value.code == 2 and "no-such-trial" in capsys.readouterr().err
    # --test-people: a pair of people's takes are not learnt
    last = sorted({a.subject for a, _ in pairs})[-1]
    kept = sum(a.subject != last for a, _ in pairs)
    assert learnt("--test-trials", "none", "--test-people", last) == kept
    # alone, it replaces the collection's split: every other pair's take is learnt (the
    # split had held out other people's last takes too, and evaluate answered them as new)
    assert learnt("--test-people", last) == kept
    # the notes count the takes learnt, and the summary names the people held out
    main([*argv, "--test-people", last])
    said = " ".join(capsys.readouterr().err.split())
    assert f"using the {kept} two-person takes" in said and f"(held out: {last})" in said
    with pytest.raises(SystemExit) as exc:
        main([*argv, "--test-people", "nobody"])
    assert exc.value.code == 2 and "'nobody'" in capsys.readouterr().err


def test_the_old_choice_flags_are_the_grid_they_stand_for(monkeypatch, capsys):
    """``--choose-prototypes N,M --choose-roles`` (hidden) pass the same grid as --choose."""
    import markovmotion.evaluate.chain as chain_eval

    grids = []
    monkeypatch.setattr(
        chain_eval, "crossval_index", lambda *a, **k: grids.append(k["grid"]) or {"x": 1}
    )
    argv = ["chain", "crossval", "--json"]
    main([*argv, "--choose-prototypes", "20,40", "--choose-roles"])
    main([*argv, "--choose", "n_state_prototypes+n_behaviour_prototypes=20,40;roles=one,both"])
    assert grids[0] == grids[1] and len(grids[0]) == 4


def test_respond_command_reads_and_writes_c3d_for_a_marker_model(
    marker_partner, mocap, tmp_path, capsys
):
    from markovmotion.io import read_c3d

    model = tmp_path / "m.npz"
    marker_partner.save(model)
    a = mocap.pairs(label="handshake", kind="markers")[-1][0]
    argv = ["chain", "respond", "--model", str(model), "--input", str(a.path)]
    main([*argv, "--out", str(tmp_path / "b.c3d"), "--hypotheses", "10"])
    out = read_c3d(tmp_path / "b.c3d")
    expected = marker_partner.respond(mocap.load_take(a), n_hypotheses=10)
    assert out.names == expected.names and out.fps == marker_partner.fps_
    np.testing.assert_allclose(out.positions, expected.positions, atol=0.01)  # float32 file
    capsys.readouterr()
    with pytest.raises(SystemExit) as info:
        main([*argv, "--out", str(tmp_path / "b.bvh")])
    err = capsys.readouterr().err
    assert info.value.code == 2 and ".c3d" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "b.bvh").exists()


def test_the_online_marker_partner_streams_what_respond_gives(marker_partner, handshakes):
    """Frame by frame on markers: with the person's size given, the frames respond gives;
    without, the size is the median of the frames so far (causal), which ends at respond's."""
    from markovmotion.web.live import ModelPartner

    _, _, _, a, _ = handshakes[-1]
    a = a.trim(0, 90).resample(marker_partner.fps_)
    whole = marker_partner.respond(a, n_hypotheses=10, rng=3)
    size = marker_size(a.select(marker_partner.markers_).positions)
    partner = marker_partner.partner(rng=3, size=size, n_hypotheses=10)
    assert partner.skeleton is None and partner.lag == 2
    out = [partner.step(a.trim(t, t + 1)) for t in range(a.n_frames)]
    assert out[:2] == [None, None]
    streamed = [f for f in out if f is not None] + partner.finish()
    assert all(isinstance(f, Markers) and f.names == whole.names for f in streamed)
    np.testing.assert_allclose(
        np.concatenate([f.positions for f in streamed]), whole.positions, atol=1e-6
    )
    # frames before A is first seen: the same stand-in frame each, nothing propagated, so
    # from A's first frame the stream is respond's (the stand-in had moved B 2 m when A came)
    late = marker_partner.partner(rng=3, size=size, n_hypotheses=10)
    out = [late.step(None) for _ in range(4)] + [late.step(a.trim(t, t + 1))
                                                 for t in range(a.n_frames)]  # fmt: skip
    shown = np.concatenate([f.positions for f in out if f is not None] +
                           [f.positions for f in late.finish()])  # fmt: skip
    assert len(shown) == 4 + a.n_frames and all(np.array_equal(shown[0], f) for f in shown[:4])
    np.testing.assert_array_equal(shown[4:], np.concatenate([f.positions for f in streamed]))
    # the size unknown: the running median of the frames' sizes, the take's once all are in
    causal = marker_partner.partner(rng=3, n_hypotheses=10)
    for t in range(a.n_frames):
        causal.step(a.trim(t, t + 1))
    assert np.median(causal._sizes) == pytest.approx(size)
    assert causal._people[-1].height[0] == pytest.approx(size)
    # a frame with a marker unseen is a missing frame: A's last frame again
    seen = a.trim(0, 1).positions.copy()
    seen[0, 0] = np.nan
    assert causal.step(Markers(a.names, seen, a.fps)) is not None
    # the live page draws the chain's markers as points
    live = ModelPartner(marker_partner, a)
    names = marker_partner.markers_
    assert live.parents[names.index("R_HAND")] == names.index("R_ELBOW")
    assert live.step(a.trim(0, 1)) is None
    with pytest.raises(ValueError, match="size"):
        marker_partner.partner(size=-1.0)


def test_the_live_page_streams_a_c3d_take_to_a_partner_of_markers(
    marker_partner, handshakes, tmp_path
):
    """``serve --partner`` with a model of markers takes a C3D file of the library as person A:
    A and B drawn as stick figures of their named points, B's frames the online partner's."""
    import json

    from websockets.sync.client import connect

    from markovmotion.io.c3d import write_c3d
    from markovmotion.web.app import create_app
    from markovmotion.web.server import running

    _, _, _, a, _ = handshakes[-1]
    a = a.trim(0, 60)
    lib = tmp_path / "lib"
    lib.mkdir()
    write_c3d(a, lib / "a.c3d")
    marker_partner.save(tmp_path / "chain.npz")
    from markovmotion.web.live import model_partner

    partner = model_partner(tmp_path / "chain.npz")
    app = create_app(lib, tmp_path / "r.sqlite", partner=partner, drop_late=float("inf"))
    with running(app) as url, connect("ws" + url.removeprefix("http") + "/ws/live") as ws:
        ws.send(json.dumps({"path": "a.c3d"}))
        start = json.loads(ws.recv(30))
        frames = []
        while (msg := json.loads(ws.recv(30)))["type"] == "frame":
            frames.append(msg)
    a25 = a.resample(marker_partner.fps_)
    assert start["frames"] == a25.n_frames == len(frames) and start["lag"] == 2
    # TORSO is the root; the shoulders and the head hang from it, each arm down its chain
    names = list(a.names)
    assert start["parents_a"] == start["parents_b"]
    assert start["parents_a"][names.index("R_HAND")] == names.index("R_ELBOW")
    assert start["parents_a"][names.index("TORSO")] == -1
    np.testing.assert_allclose(
        np.array([f["a"] for f in frames]).reshape(a25.n_frames, -1, 3), a25.positions, atol=0.051
    )
    online = marker_partner.partner()
    expected = [online.step(a25.trim(t, t + 1)) for t in range(a25.n_frames)]
    got = [f["b"] for f in frames]
    assert [g is None for g in got] == [e is None for e in expected]
    np.testing.assert_allclose(
        np.array([g for g in got if g is not None]).reshape(-1, len(names), 3),
        np.concatenate([e.positions for e in expected if e is not None]),
        atol=0.051,
    )


def test_chain_train_takes_several_labels_as_dualhmm_does(tmp_path):
    """``chain train --labels handshake,wave``: one model of both actions' takes, both
    labels recorded (``--label`` is the same option)."""
    out = tmp_path / "both.npz"
    argv = ["chain", "train", "--labels", "handshake,wave", "--kind", "markers", "--epochs", "1"]
    main([*argv, "--prototypes", "4", "--behaviours", "4", "--out", str(out)])
    model = VirtualPartner.load(out)
    assert model.labels_ == ["handshake", "wave"]
    from markovmotion.data import MocapIndex
    from markovmotion.data.splits import held_out_pairs
    from markovmotion.models.base import file_sha256

    index = MocapIndex.load()
    wanted = {
        sha
        for lab in ("handshake", "wave")
        for a, b in held_out_pairs(index.pairs(label=lab, kind="markers"))[0]
        for sha in (file_sha256(a.path), file_sha256(b.path))
    }
    assert {f["sha256"] for f in model.train_files_} == wanted


def test_shape_centre_takes_out_a_persons_own_offset_and_runs_online():
    from markovmotion.features.person import ShapeCentre

    rng = np.random.default_rng(4)
    k = 6  # one person's shape size
    takes = [rng.normal(size=(40, 2 * k + 3)) for _ in range(3)]
    step = ShapeCentre(k, prior=10.0).fit(takes)
    out = step.transform(takes)[0]
    # brute force: each half minus its running mean (started from the training mean with
    # the weight of 10 frames) plus the training mean; separation and scale pass through
    for sl in (slice(0, k), slice(k, 2 * k)):
        x, mean = takes[0][:, sl], step.mean_[sl]
        for t in (0, 7, 39):
            running = (10.0 * mean + x[: t + 1].sum(axis=0)) / (10.0 + t + 1)
            np.testing.assert_allclose(out[t, sl], x[t] - running + mean)
    np.testing.assert_allclose(out[:, 2 * k :], takes[0][:, 2 * k :])
    # a person whose shape is off by a constant is seen off by a share that decays with time
    s = takes[1][:, :k]
    offset = rng.normal(size=k)
    gap = step.person(s + offset, 0) - step.person(s, 0)
    t = np.arange(1, len(s) + 1)[:, None]
    np.testing.assert_allclose(gap, offset * 10.0 / (10.0 + t))
    # online, row by row, as a whole take; either half: the halves' average
    online = step.online(1)
    np.testing.assert_allclose([online(row) for row in s], step.person(s, 1))
    np.testing.assert_allclose(step.target(None), (step.mean_[:k] + step.mean_[k:]) / 2)


def test_a_person_normalised_marker_chain_streams_what_respond_gives(handshakes, tmp_path):
    last = handshakes[-1][2]
    train = [(a, b) for _, _, people, a, b in handshakes if people != last]
    model = VirtualPartner(**SMALL, normalise="person").fit(train)
    assert model.shape_centre is not None
    _, _, _, a, _ = handshakes[-1]
    a = a.trim(0, 90).resample(model.fps_)
    whole = model.respond(a, n_hypotheses=10, rng=3)
    size = marker_size(a.select(model.markers_).positions)
    partner = model.partner(rng=3, size=size, n_hypotheses=10)
    out = [f for t in range(a.n_frames) if (f := partner.step(a.trim(t, t + 1)))]
    out += partner.finish()
    np.testing.assert_allclose(
        np.concatenate([f.positions for f in out]), whole.positions, atol=1e-6
    )
    # the option and the centre's mean go through the model file
    path = tmp_path / "person.npz"
    model.save(path)
    back = VirtualPartner.load(path)
    assert back.normalise == "person"
    np.testing.assert_allclose(back.shape_centre.mean_, model.shape_centre.mean_)
    np.testing.assert_allclose(back.respond(a, n_hypotheses=10, rng=3).positions, whole.positions)
    with pytest.raises(ValueError, match="normalise"):
        VirtualPartner(**SMALL, normalise="everyone").fit(train)


def test_shrink_blends_the_partner_with_the_mean_shape_whole_and_online(marker_partner, handshakes):
    """``shrink``: 0 the paper's partner, 1 the mean shape's (the baseline partner), between a
    convex blend of the two in shape space; the online partner streams respond's frames; a
    value outside 0-1 is one ValueError."""
    import copy

    from markovmotion.features.joint_shape import person_from_take

    _, _, _, a, _ = handshakes[-1]
    a = a.trim(0, 60).resample(marker_partner.fps_)
    real = person_from_take(a.select(marker_partner.markers_), marker_partner.markers_)
    options = dict(n_hypotheses=10, rng=3)
    paper = marker_partner.respond_shapes(real, 0, **options)
    mean = marker_partner.mean_partner(real, np.zeros(real.n_frames, dtype=int))
    full, half = copy.deepcopy(marker_partner), copy.deepcopy(marker_partner)
    full.set_params(shrink=1.0)
    half.set_params(shrink=0.5)
    mean = full.place_average()(mean)  # placed as every partner is (place_window)
    np.testing.assert_allclose(full.respond_shapes(real, 0, **options).partner.points,
                               mean.points, atol=1e-9)  # fmt: skip
    blended = half.respond_shapes(real, 0, **options)
    np.testing.assert_allclose(blended.shapes, 0.5 * paper.shapes + 0.5 * half.mean_shape_)
    whole = half.respond(a, **options)
    size = marker_size(a.select(half.markers_).positions)
    online = half.partner(size=size, **options)
    out = [f for t in range(a.n_frames) if (f := online.step(a.trim(t, t + 1)))] + online.finish()
    np.testing.assert_allclose(np.concatenate([f.positions for f in out]), whole.positions,
                               atol=1e-6)  # fmt: skip
    with pytest.raises(ValueError, match="shrink must be from 0 to 1"):
        VirtualPartner(shrink=1.5).check_params()


def test_the_chains_new_people_preset_sets_its_options_unless_given(tmp_path, capsys):
    """``chain --preset new-people`` is docs/chain.md's partner for new people (both roles,
    the person normalisation, the shape pulled half way to the mean shape); an option given
    beside it wins; crossval reports the paper's single hypothesis beside ours."""
    from markovmotion.defaults import CHAIN_NEW_PEOPLE

    small = ["--labels", "handshake", "--kind", "markers", "--prototypes", "4", "--behaviours",
             "4", "--epochs", "1"]  # fmt: skip
    out = tmp_path / "p.npz"
    main(["chain", "train", *small, "--test-people", "pair3", "--preset", "new-people",
          "--shrink", "0.25", "--out", str(out)])  # fmt: skip
    err = capsys.readouterr().err
    assert "--preset new-people: --roles both --normalise person" in err and "in both roles" in err
    assert "--shrink given" in err
    model = VirtualPartner.load(out)
    assert model.normalise == CHAIN_NEW_PEOPLE["normalise"] and model.shrink == 0.25
    main(["chain", "crossval", *small, "--hypotheses", "4", "--preset", "new-people", "--json"])
    report = json.loads(capsys.readouterr().out)
    assert report["roles"] == "both" and report["model"]["shrink"] == CHAIN_NEW_PEOPLE["shrink"]
    over = report["overall"]
    assert over["world_mm"]["single_hypothesis_paper"] > 0 and set(over["aim_met_paper"]) == {
        "world_mm",
        "body_centred_mm",
    }


def test_evaluate_reports_each_pair_of_people(mocap, tmp_path, capsys):
    """``chain evaluate`` on takes of several pairs of people reports each pair as well
    (``per_people``, as dualhmm evaluate does), the pairs' frame-weighted means being the
    whole's (the same seed answers a take alike alone or among others)."""
    pairs = mocap.pairs("handshake", kind="markers")
    last = sorted({a.trial for a, _ in pairs})[-1]
    out = tmp_path / "m.npz"
    main(["chain", "train", "--labels", "handshake", "--kind", "markers", "--prototypes", "4",
          "--behaviours", "4", "--epochs", "1", "--test-trials", last, "--out", str(out)])  # fmt: skip
    main(["chain", "evaluate", "--model", str(out), "--hypotheses", "4", "--json"])
    report = json.loads(capsys.readouterr().out)
    people = {a.subject for a, _ in pairs if a.trial == last}
    assert set(report["per_people"]) == people and len(people) > 1
    for key in ("multiple_hypotheses", "mean_shape", "single_hypothesis_paper"):
        pooled = sum(r[key] * r["frames"] for r in report["per_people"].values())
        assert pooled / report["frames"] == pytest.approx(report[key], rel=1e-9)


def test_a_take_of_nothing_recorded_is_one_line_on_the_command_line(
    marker_partner, mocap, tmp_path, capsys
):
    """A C3D file whose every sample is unseen (a tracker that never found the person) is
    refused in one line, exit 2, by every family's respond: it had been a ValueError's
    traceback (NothingRecordedError is still a ValueError for library callers)."""
    from markovmotion.errors import NothingRecordedError
    from markovmotion.io import read_c3d, write_c3d

    a = read_c3d(mocap.pairs(label="handshake", kind="markers")[-1][0].path)
    a.positions[:] = np.nan
    blind = tmp_path / "blind.c3d"
    write_c3d(a, blind)
    model = tmp_path / "m.npz"
    marker_partner.save(model)
    capsys.readouterr()
    with pytest.raises(SystemExit) as info:
        main(["chain", "respond", "--model", str(model), "--input", str(blind),
              "--out", str(tmp_path / "b.c3d")])  # fmt: skip
    err = capsys.readouterr().err
    assert info.value.code == 2 and "Traceback" not in err
    assert err.strip().splitlines() == [
        f"error: VirtualPartner.respond: blind.c3d holds NaN or infinite values in every one "
        f"of its {a.n_frames} frames: nothing of it was recorded"
    ]
    assert not (tmp_path / "b.c3d").exists()
    with pytest.raises(NothingRecordedError) as whole:
        marker_partner.respond(read_c3d(blind))
    assert isinstance(whole.value, ValueError)


def test_evaluate_skips_a_take_with_a_marker_never_seen_and_answers_the_others(
    marker_partner, mocap, tmp_path, capsys
):
    """One take of a user's capture whose tracker never saw a marker the model needs is
    skipped with one line naming it, as a take that does not fit is: it had stopped the
    whole evaluation ("marker R_HAND never seen") after the other takes were read."""
    import csv

    from markovmotion.data.index import COLUMNS
    from markovmotion.evaluate.chain import evaluate_model
    from markovmotion.io import read_c3d, write_c3d

    a, b = mocap.pairs(label="handshake", kind="markers")[-1]
    rows = []
    for take in ("clean", "blind"):
        for me, other, entry in (("a", "b", a), ("b", "a", b)):
            markers = read_c3d(entry.path)
            if take == "blind" and me == "a":
                markers.positions[:, markers.names.index("R_HAND")] = np.nan
            write_c3d(markers, tmp_path / f"{take}_{me}.c3d")
            row = {c: getattr(entry, c) for c in COLUMNS}
            rows.append({**row, "file": f"{take}_{me}.c3d", "trial": take,
                         "partner_file": f"{take}_{other}.c3d"})  # fmt: skip
    with open(tmp_path / "INDEX.csv", "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    report = evaluate_model(marker_partner, tmp_path / "INDEX.csv", n_hypotheses=4)
    assert report["test_files"] == ["clean_a.c3d", "clean_b.c3d"]
    err = capsys.readouterr().err
    assert "skipped blind_a.c3d + blind_b.c3d: blind_a.c3d: marker R_HAND never seen" in err
    assert np.isfinite(report["multiple_hypotheses"])
