"""Gait synthesis: steps on real walks, exponential maps, root travel, model files, commands."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from markovmotion import read_motion
from markovmotion.cli import main
from markovmotion.data.splits import held_out_every
from markovmotion.data.walks import gait_entries
from markovmotion.errors import ModelFormatError
from markovmotion.features import ExpMaps, FeaturePipeline
from markovmotion.features.gait import (
    align_walk,
    detect_steps,
    foot_slide,
    root_from_contact,
    step_positions,
    travel_yaw,
)
from markovmotion.features.reference_pose import ReferencePose
from markovmotion.models.gait.synthesizer import GaitSynthesizer


def angle_between(a: np.ndarray, b: np.ndarray) -> float:
    """Largest angle (rad) between quaternion arrays, sign-insensitive."""
    return float(np.max(2 * np.arccos(np.abs(np.sum(a * b, axis=-1)).clip(0, 1))))


@pytest.fixture(scope="session")
def normal_walks(mocap):
    """Four neutral Bandai walks (training split), read once."""
    train, _ = held_out_every(gait_entries(mocap, "normal"))
    return [mocap.load_motion(e) for e in train[:4]]


@pytest.fixture(scope="session")
def small_model(normal_walks):
    return GaitSynthesizer(n_iter=2).fit(normal_walks[:3])


def test_steps_on_a_real_walk(normal_walks):
    walk = align_walk(normal_walks[0])
    steps = detect_steps(walk)
    seconds = walk.n_frames / walk.fps
    # a ~9 s straight walk: a step every 0.45-0.7 s between the first and last heel strikes
    assert 10 <= steps.n_steps <= seconds / 0.45
    durations = np.diff(steps.boundaries) / walk.fps
    assert durations.min() > 0.4 and durations.max() < 0.75
    assert all(a != b for a, b in zip(steps.sides, steps.sides[1:], strict=False))
    assert steps.dropped == 0


def test_steps_on_a_cmu_walk(mocap):
    """Another skeleton, another frame rate: CMU subject 2's walk at 120 fps."""
    walk = align_walk(mocap.load_motion(mocap.find("cmu/asfamc/02/02_01.amc.gz")))
    steps = detect_steps(walk)
    assert 3 <= steps.n_steps <= 6
    assert 0.4 < np.diff(steps.boundaries).mean() / walk.fps < 0.75


def test_step_positions():
    assert step_positions(6) == ["first", "second", "inside", "inside", "last_but_one", "last"]
    assert step_positions(2) == ["first", "last"]
    assert step_positions(1) == ["first"]


def test_alignment_turns_the_walk_onto_z(normal_walks):
    walk = normal_walks[1]
    aligned = align_walk(walk)
    assert abs(travel_yaw(aligned)) < 1e-9
    # a rigid turn: distances between joints are kept
    p, q = walk.positions()[::40], aligned.positions()[::40]
    np.testing.assert_allclose(
        np.linalg.norm(p[:, 5] - p[:, 20], axis=1), np.linalg.norm(q[:, 5] - q[:, 20], axis=1)
    )


def test_expmap_rotation_expmap_round_trip(normal_walks):
    walks = [align_walk(m) for m in normal_walks[:2]]
    pipe = FeaturePipeline([ReferencePose(), ExpMaps(root_position="none")]).fit(walks)
    feats = pipe.transform(walks)
    back = pipe.inverse_transform(feats)
    rotating = pipe.steps[-1].joint_index_
    for m, b, f in zip(walks, back, feats, strict=True):
        assert angle_between(b.rotations[:, rotating], m.rotations[:, rotating]) < 1e-6
        np.testing.assert_allclose(pipe.transform([b])[0], f, atol=1e-9)
    # relative to the mean pose, no rotation vector comes near the singularity at pi
    assert max(np.abs(f).max() for f in feats) < 2.0


def test_root_travel_from_contact_keeps_the_foot_planted(normal_walks):
    real = align_walk(normal_walks[2])
    steps = detect_steps(real)
    still = real.copy()
    still.translations[:, 1] = real.skeleton.offsets[1]  # drop the pelvis travel
    rebuilt = root_from_contact(still, steps.boundaries, steps.sides)
    b = steps.boundaries
    slide = foot_slide(rebuilt, b, steps.sides)
    assert slide.max() < 1.0
    travel = lambda m: np.linalg.norm(np.diff(m.positions()[[b[0], b[-1]], 1, ::2], axis=0))  # noqa: E731
    assert travel(rebuilt) == pytest.approx(travel(real), rel=0.12)


def test_synthesized_walk(small_model, tmp_path):
    walk = small_model.generate(8)
    assert walk.skeleton.names == small_model.pipeline_.steps[-1].skeleton_.names
    assert 8 * 12 < walk.n_frames < 8 * 22
    steps = detect_steps(walk)
    assert 5 <= steps.n_steps <= 8  # the synthesized walk has steps the detector finds again
    pelvis = walk.positions()[:, walk.skeleton.body_root]
    assert np.ptp(pelvis[:, 2]) > 3000  # it travels forwards (mm)
    assert np.abs(pelvis[:, 0]).max() < 0.2 * np.ptp(pelvis[:, 2])
    assert 800 < pelvis[:, 1].mean() < 1000  # standing on the floor
    faster = small_model.generate(8, speed=1.5)
    assert faster.n_frames < walk.n_frames
    static, _, _ = small_model.generate_features(8, gv=False)
    with_gv, _, _ = small_model.generate_features(8)
    assert np.var(with_gv, axis=0).sum() > np.var(static, axis=0).sum()


def test_model_file_round_trip(small_model, normal_walks, tmp_path):
    path = tmp_path / "avg.npz"
    small_model.save(path)
    back = GaitSynthesizer.load(path)
    a, _, _ = small_model.generate_features(6)
    b, _, _ = back.generate_features(6)
    np.testing.assert_array_equal(a, b)
    assert back.train_files_ == small_model.train_files_ and back.role_ == "average"
    assert back.own_files == [Path(m.source).name for m in normal_walks[:3]]
    assert back.n_inherited_files_ == 0
    from markovmotion.persist import save_npz

    save_npz(tmp_path / "other.npz", "not-a-kind", {}, {})
    with pytest.raises(ModelFormatError, match="unknown model kind .not-a-kind."):
        GaitSynthesizer.load(tmp_path / "other.npz")


def test_adapt_and_synthesize_commands(small_model, mocap, tmp_path, capsys):
    model = tmp_path / "avg.npz"
    small_model.save(model)
    style = mocap.find("bandai/dataset-2/walk_elderly_001.bvh.gz").path
    adapted = tmp_path / "elderly.npz"
    main(
        ["gait", "adapt", "--model", str(model), "--style-data", str(style)]
        + ["--label", "elderly", "--steps", "6", "--out", str(adapted)]
    )
    assert GaitSynthesizer.load(adapted).role_ == "adapted"
    assert "of 1 walk: walk_elderly_001.bvh.gz" in capsys.readouterr().err  # names what it used
    main(
        ["gait", "adapt", "--model", str(model), "--style-data", str(style)]
        + ["--label", "elderly", "--steps", "1", "--out", str(tmp_path / "one.npz")]
    )
    assert "model from 1 step of 1 walk: " in capsys.readouterr().err  # it said "1 steps"
    out = tmp_path / "walk.bvh"
    main(
        ["gait", "synthesize", "--model", str(adapted), "--steps", "6", "--no-gv"]
        + ["--seed", "1", "--out", str(out)]
    )
    walk = read_motion(out)
    assert walk.n_frames > 60 and walk.fps == pytest.approx(30)
    with pytest.raises(SystemExit) as exc:
        main(["gait", "synthesize", "--model", str(tmp_path / "none.npz"), "--out", str(out)])
    assert exc.value.code == 2


def test_adaptation_and_objective_evaluation(mocap, normal_walks, small_model):
    """Adapted to 'elderly' from 12 training steps: its steps recognised as elderly, closer to held-out ones."""
    from markovmotion.evaluate.gait import Evaluation, StyleClassifier

    train, test = held_out_every(gait_entries(mocap, "elderly"))
    elderly = [mocap.load_motion(e) for e in (*train[:2], test[0])]
    ev = Evaluation.prepare(
        {"normal": normal_walks[:2], "elderly": elderly[:2]},
        {"normal": normal_walks[3:4], "elderly": elderly[2:]},
        StyleClassifier(n_components=None),
        n_walks=2,
        walk_steps=8,
    )
    real = ev.real()
    assert real["rate"] == 1.0 and real["chance"] == 0.5 and real["eta"] == 2.0
    assert real["confusion"]["elderly"] == {"elderly": 100.0, "normal": 0.0}
    adapted = small_model.adapt(elderly[:1], "elderly", 12)
    assert adapted.role_ == "adapted" and adapted.n_steps_ == 12
    scratch = small_model.scratch(elderly[:1], "elderly", 12)
    assert scratch.n_steps_ == 12 and scratch.train_files_ == adapted.train_files_
    # an adapted model depends on the average model's walks and its own
    assert adapted.train_files_[:3] == small_model.train_files_
    assert adapted.own_files == [Path(elderly[0].source).name]
    results = {
        role: ev.models({"elderly": [model]})[0]
        for role, model in (("adapted", adapted), ("average", small_model), ("scratch", scratch))
    }
    for metrics in results.values():
        for key in ("real_rate", "synthesized_rate", "chance", "eta_real", "eta_synthesized"):
            assert 0.0 <= metrics[key] <= 2.0
        lo, hi = metrics["synthesized_rate_ci"]
        assert lo <= metrics["synthesized_rate"] <= hi
        assert metrics["synthesized_steps"] >= 2 * 5  # two walks of 8 steps, ends cut
        assert metrics["foot_slide_mm"] < 5.0  # the synthesized stance foot barely moves
        # drawn durations vary step to step about as much as the real walk's (0.035 s here;
        # 0.066-0.084 s at the old floor of 1 frame squared per state)
        assert metrics["step_duration_sd"] < 1.5 * metrics["real_step_duration_sd"]
    for role in ("adapted", "scratch"):  # the neutral walk swings more than an elderly one
        assert 0.7 < results[role]["gv_ratio"] < 1.4
    assert results["adapted"]["synthesized_rate"] == 1.0
    assert results["average"]["synthesized_rate"] == 0.0  # the neutral walk is not elderly
    assert results["adapted"]["dtw_joint_mm"] < results["average"]["dtw_joint_mm"]
    # the adapted model generalises to the held-out walk better than the average model
    assert results["adapted"]["test_log_likelihood"] > results["average"]["test_log_likelihood"]
    # the sweep adapts on exactly K steps of the first training takes, scratch on the same
    sweep = ev.sweep(small_model, ["elderly"], [3])["3"]
    assert sweep["adapted"]["adaptation_steps"] == {"elderly": [3]}
    assert sweep["scratch"]["adaptation_steps"] == {"elderly": [3]}
    assert sweep["adapted"]["adaptation_files"] == {"elderly": [[Path(elderly[0].source).name]]}
    diff = sweep["adapted_minus_scratch"]
    lo, hi = diff["synthesized_rate_ci"]
    assert lo <= diff["synthesized_rate"] <= hi
    assert 0.0 <= diff["told_apart"] <= 1.0  # adapted walks against from-scratch ones


def test_synthesized_walks_vary_with_the_seed(small_model):
    """Durations drawn from the densities: walks differ from one another, a seed repeats them."""
    rng = np.random.default_rng(1)
    walks = [small_model.generate_features(8, rng=rng, stochastic=True) for _ in range(3)]
    lengths = {len(f) for f, _, _ in walks}
    assert len(lengths) > 1
    repeat = small_model.generate_features(8, rng=np.random.default_rng(1), stochastic=True)
    np.testing.assert_array_equal(repeat[0], walks[0][0])
    np.testing.assert_array_equal(repeat[1], walks[0][1])
    # not stochastic: the most likely durations, whatever the generator
    likely = small_model.generate_features(8)[1]
    np.testing.assert_array_equal(small_model.generate_features(8, rng=rng)[1], likely)


def test_adaptation_steps_come_from_the_first_takes(normal_walks, small_model):
    from markovmotion.errors import DataNotFoundError
    from markovmotion.evaluate.gait import adaptation_takes

    takes = adaptation_takes(normal_walks, [11, 12, 13, 14], 12)
    assert takes == normal_walks[:2]
    assert adaptation_takes(normal_walks, [11, 12, 13, 14], 11) == normal_walks[:1]
    # replicates take the next takes, never sharing one
    assert adaptation_takes(normal_walks, [11, 12, 13, 14], 11, replicate=1) == normal_walks[1:2]
    assert adaptation_takes(normal_walks, [11, 12, 13, 14], 12, replicate=1) == normal_walks[2:3]
    with pytest.raises(DataNotFoundError, match="24 adaptation steps asked for replicate 1"):
        adaptation_takes(normal_walks, [11, 12, 13, 10], 24, replicate=1)
    with pytest.raises(DataNotFoundError, match="only 35 in the 3 takes left"):
        adaptation_takes(normal_walks[:3], [11, 12, 12], 36)
    data = small_model.walk_set(normal_walks[:1])
    assert data.first_steps(5).n_steps == 5
    with pytest.raises(DataNotFoundError, match=r"50 steps asked, only \d+ found in 1 walk$"):
        data.first_steps(50)


def fake_walks(rng: np.random.Generator, centre: np.ndarray, n_walks: int, n_steps: int = 12):
    """Walks whose per-step statistics are ``centre`` + a walk offset + step noise."""
    from markovmotion.evaluate.gait import WalkSteps

    out = []
    for _ in range(n_walks):
        stats = centre + rng.normal(scale=0.3, size=len(centre)) + rng.normal(size=(n_steps, 9))
        sides = tuple("LR"[k % 2] for k in range(n_steps))
        empty = np.zeros((n_steps + 1, 1))
        out.append(
            WalkSteps("fake", empty, empty, np.arange(n_steps + 1), sides, stats, empty, empty)
        )
    return out


def test_step_classifier_separates_two_styles():
    """Two styles 2.5 standard deviations apart, shared by four of nine statistics: ~89 % of steps."""
    from markovmotion.evaluate.gait import Recognition, StyleClassifier, interval

    rng = np.random.default_rng(0)
    centres = {"a": np.zeros(9), "b": np.r_[np.full(4, 1.25), np.zeros(5)]}
    train = {s: fake_walks(rng, c, 10) for s, c in centres.items()}
    test = {s: fake_walks(rng, c, 30) for s, c in centres.items()}
    walks = [w for ws in train.values() for w in ws]
    labels = [s for s, ws in train.items() for _ in ws]
    clf = StyleClassifier(target=0.8).fit(walks, labels)
    # the statistics that move together with the style make the first principal component
    assert clf.n_components_ == 1 and clf.cv_rates_[1] >= 0.8
    rec = Recognition.of(clf, {s: [ws] for s, ws in test.items()})
    assert 0.83 < rec.rate() < 0.95  # the Bayes rate is Phi(1.25) = 0.89
    assert rec.walk_rate() > 0.95  # twelve steps of a walk together leave little doubt
    lo, hi = interval(rec.replicates(n_boot=500))
    assert lo < rec.rate() < hi and hi - lo < 0.1
    table = rec.table()
    assert sum(table["a"].values()) == pytest.approx(100.0)
    share = 100 * rec.correct["a"].sum() / rec.steps["a"].sum()
    assert table["a"]["a"] == pytest.approx(share, abs=0.05)  # percent, one decimal
    # walks of a style the classifier never saw as such are not recognised
    swapped = Recognition.of(clf, {"a": [test["b"]], "b": [test["a"]]})
    assert swapped.rate() < 0.2
    # far apart, every statistic kept: every step recognised
    far = {"a": np.zeros(9), "b": np.full(9, 4.0)}
    train = {s: fake_walks(rng, c, 4) for s, c in far.items()}
    walks = [w for ws in train.values() for w in ws]
    full = StyleClassifier(n_components=None).fit(walks, ["a"] * 4 + ["b"] * 4)
    assert full.n_components_ is None
    test = {s: [fake_walks(rng, c, 5)] for s, c in far.items()}
    assert Recognition.of(full, test).rate() == 1.0


def test_a_style_of_one_walk_among_two_keeps_every_component_and_is_still_recognised():
    """Of two styles, one with a single walk: no fold by walk trains on both, so the
    components cannot be chosen by cross-validation (scikit-learn had stopped ``gait
    evaluate`` with "needs samples of at least 2 classes"); every component is kept and
    the classifier still tells the styles apart."""
    from markovmotion.evaluate.gait import Recognition, StyleClassifier

    rng = np.random.default_rng(1)
    far = {"a": np.zeros(9), "b": np.full(9, 4.0)}
    walks = fake_walks(rng, far["a"], 4) + fake_walks(rng, far["b"], 1)
    clf = StyleClassifier().fit(walks, ["a"] * 4 + ["b"])
    assert clf.n_components_ is None and clf.cv_rates_ == {}
    test = {s: [fake_walks(rng, c, 3)] for s, c in far.items()}
    assert Recognition.of(clf, test).rate() == 1.0


def test_real_and_synthesized_steps_told_apart_only_when_they_differ():
    from markovmotion.evaluate.gait import real_vs_synthesized

    rng = np.random.default_rng(1)
    real = fake_walks(rng, np.zeros(9), 10)
    same = fake_walks(rng, np.zeros(9), 10)
    shifted = fake_walks(rng, np.r_[np.full(3, 1.5), np.zeros(6)], 10)
    assert real_vs_synthesized(same, real) < 0.65
    assert real_vs_synthesized(shifted, real) > 0.9
    assert np.isnan(real_vs_synthesized(shifted, real[:1]))  # one walk: no fold holds both
    # two short synthesized walks and three long real ones: grouped folds by size alone
    # would train one fold on real walks only; folds then keep both kinds
    long_real = fake_walks(rng, np.zeros(9), 3, n_steps=20)
    assert 0.0 <= real_vs_synthesized(shifted[:2], long_real) <= 1.0


def test_bootstrap_of_a_rate_over_styles():
    from markovmotion.evaluate.gait import bootstrap_means, interval

    perfect = (np.array([[10, 12]]), np.array([[10, 12]]))
    half = (np.array([[5, 0, 10]]), np.array([[10, 10, 10]]))
    reps = bootstrap_means([perfect, half], n_boot=4000, seed=1)
    assert reps.max() <= 1.0 and reps.min() >= 0.5
    assert reps.mean() == pytest.approx((1.0 + 0.5) / 2, abs=0.02)
    lo, hi = interval(reps)
    assert lo < 0.75 < hi
    assert interval(bootstrap_means([perfect], 100)) == [1.0, 1.0]
    # two models of a style, each walk fully right or wrong: models are resampled first
    models = (np.array([[10, 10], [0, 0]]), np.full((2, 2), 10))
    reps = bootstrap_means([models], n_boot=4000, seed=2)
    assert set(np.round(reps, 6)) <= {0.0, 0.25, 0.5, 0.75, 1.0}
    assert np.mean(reps == 1.0) == pytest.approx(0.25, abs=0.03)  # both draws the good model


def test_evaluate_command_errors(tmp_path, small_model):
    (tmp_path / "empty").mkdir()
    for args in (
        ["--models", str(tmp_path / "empty")],  # no gait models
        ["--models", str(tmp_path / "none")],  # no such folder
        ["--models", str(tmp_path), "--components", "some"],
    ):
        with pytest.raises(SystemExit) as exc:
            main(["gait", "evaluate", *args])
        assert exc.value.code == 2
    small_model.save(tmp_path / "scratch-only.npz")
    scratch = GaitSynthesizer.load(tmp_path / "scratch-only.npz")
    scratch.role_ = "scratch"
    scratch.save(tmp_path / "scratch-only.npz")
    with pytest.raises(SystemExit) as exc:  # the sweep needs the average model
        main(["gait", "evaluate", "--models", str(tmp_path), "--sweep", "3"])
    assert exc.value.code == 2


def _write_index(root: Path, rows: list[tuple[str, object]]) -> Path:
    """An INDEX.csv in ``root`` listing COPIES of shared walks as ``(new name, entry)``."""
    import csv
    import shutil

    root.mkdir(parents=True, exist_ok=True)
    with open(root / "INDEX.csv", "w", newline="") as fh:
        out = csv.writer(fh)
        out.writerow(
            ["file", "source", "subject", "trial", "category", "label"]
            + ["partner_file", "fps", "frames", "description"]
        )
        for name, e in rows:
            (root / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(e.path, root / name)
            out.writerow([name, "mine", "", "", e.category, e.label, "", e.fps, e.frames, ""])
    return root / "INDEX.csv"


def test_evaluate_on_another_index_leaves_training_walks_out(mocap, small_model, tmp_path, capsys):
    """--test: walks found by content under other names; the model's own are left out and listed."""
    import json

    model = tmp_path / "avg.npz"
    small_model.save(model)
    normal_train, normal_test = held_out_every(gait_entries(mocap, "normal"))
    elderly = gait_entries(mocap, "elderly")
    test = _write_index(
        tmp_path / "mine",
        [
            ("walks/seen.bvh.gz", normal_train[0]),  # trained on: left out
            ("walks/new.bvh.gz", normal_test[0]),  # evaluated
            ("walks/old.bvh.gz", elderly[0]),  # another style: does not fit the model
            ("walks/taught.bvh.gz", normal_train[3]),  # the classifier learns from it
        ],
    )
    # the style classifier learns from a small reference index (copies too)
    ref = [
        (f"bandai/dataset-2/{e.file.split('/')[-1]}", e) for e in normal_train[3:7] + elderly[:4]
    ]
    data = _write_index(tmp_path / "ref", ref)
    args = ["gait", "evaluate", "--model", str(model), "--test", str(test), "--data", str(data)]
    main(
        [*args, "--json", "--walks", "2", "--walk-steps", "6", "--components", "0"]
        + ["--bootstrap", "100"]
    )
    result = json.loads(capsys.readouterr().out)
    assert result["test_files"] == ["walks/new.bvh.gz"]
    assert result["left_out_training_files"] == ["walks/seen.bvh.gz"]
    assert result["left_out_classifier_files"] == ["walks/taught.bvh.gz"]
    assert result["targets"] == ["normal"] and result["real"]["walks"] == 1
    assert result["average"]["synthesized_steps"] > 0
    assert np.isfinite(result["average"]["test_log_likelihood"])
    # an index of training walks only: one line, exit 2
    only = _write_index(tmp_path / "seen", [("a.bvh.gz", normal_train[1])])
    with pytest.raises(SystemExit) as exc:
        main(["gait", "evaluate", "--model", str(model), "--test", str(only)])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "trained on" in err and "a.bvh.gz" in err


def test_a_walk_without_steps_is_left_out_in_a_note(mocap, small_model, tmp_path, capsys):
    """A take with fewer than two heel strikes (10 frames) had stopped ``gait adapt`` and
    ``gait evaluate`` ("error: short.bvh: no steps found") though the other walks have
    dozens of steps: it is left out in a note naming it, as a walk of another skeleton is,
    and only walks with no step at all are one line, exit 2."""
    import json

    from markovmotion.io import write_motion

    model = tmp_path / "avg.npz"
    small_model.save(model)
    elderly = mocap.find("bandai/dataset-2/walk_elderly_001.bvh.gz")
    short = tmp_path / "short.bvh"
    write_motion(mocap.load_motion(elderly).trim(0, 10), short)
    adapted = tmp_path / "elderly.npz"
    main(
        ["gait", "adapt", "--model", str(model), "--style-data", elderly.path]
        + ["--style-data", str(short), "--label", "elderly", "--steps", "6", "--out", str(adapted)]
    )
    err = capsys.readouterr().err
    assert "note: walks without steps (fewer than two heel strikes) left out: short.bvh (10 " in err
    assert "of 1 walk: walk_elderly_001.bvh.gz" in err and adapted.is_file()
    with pytest.raises(SystemExit) as exc:
        main(
            ["gait", "adapt", "--model", str(model), "--style-data", str(short)]
            + ["--label", "elderly", "--out", str(tmp_path / "none.npz")]
        )
    err = capsys.readouterr().err.strip()
    assert exc.value.code == 2 and len(err.splitlines()) == 1
    assert err.startswith("error: short.bvh (10 frames): no steps found")
    # gait evaluate --test: the short walk among the test walks is left out, named
    normal_train, normal_test = held_out_every(gait_entries(mocap, "normal"))
    test = _write_index(tmp_path / "mine", [("new.bvh.gz", normal_test[0])])
    write_motion(mocap.load_motion(normal_test[1]).trim(0, 10), tmp_path / "mine" / "short.bvh")
    with open(test, "a") as fh:
        fh.write("short.bvh,mine,,,walk,normal,,30,10,\n")
    ref = [(f"bandai/dataset-2/{e.file.split('/')[-1]}", e) for e in normal_train[3:6]]
    data = _write_index(tmp_path / "ref", ref + [(f"bandai/dataset-2/e{k}.bvh.gz", e)
                        for k, e in enumerate(gait_entries(mocap, "elderly")[:3])])  # fmt: skip
    main(
        ["gait", "evaluate", "--model", str(model), "--test", str(test), "--data", str(data)]
        + ["--json", "--walks", "2", "--walk-steps", "6", "--components", "0"]
        + ["--bootstrap", "100"]
    )
    out = capsys.readouterr()
    assert json.loads(out.out)["test_files"] == ["new.bvh.gz"]
    assert "note: test walks without steps (fewer than two heel strikes) left out: short.bvh" in (
        out.err
    )


def test_a_model_of_a_style_without_test_walks_is_named_not_dropped(
    mocap, small_model, tmp_path, capsys
):
    """``gait evaluate --models DIR`` had silently ignored an adapted model whose style has
    no held-out walk (a style of one take, used to adapt): a note names its file and why;
    no model left to evaluate is one line, exit 2."""
    elderly = gait_entries(mocap, "elderly")[0]
    models = tmp_path / "models"
    models.mkdir()
    small_model.save(models / "average.npz")
    small_model.adapt([mocap.load_motion(elderly)], "elderly", 6).save(
        models / "adapted-elderly.npz"
    )
    normal_train, _ = held_out_every(gait_entries(mocap, "normal"))
    data = _write_index(
        tmp_path / "ref",
        [(f"bandai/dataset-2/{e.file.split('/')[-1]}", e) for e in normal_train[3:7]]
        + [(f"bandai/dataset-2/{elderly.file.split('/')[-1]}", elderly)],
    )
    args = ["--data", str(data), "--walks", "2", "--walk-steps", "6", "--bootstrap", "100"]
    args += ["--components", "0"]  # auto: cross-validation by take, and elderly has one
    main(["gait", "evaluate", "--models", str(models), *args, "--json"])
    err = capsys.readouterr().err
    assert (
        "note: adapted-elderly.npz: no held-out walk of style elderly (1 take, used to adapt; "
        "every 4th take of a style is held out): not evaluated"
    ) in err
    (models / "average.npz").unlink()
    with pytest.raises(SystemExit) as exc:
        main(["gait", "evaluate", "--models", str(models), *args])
    err = capsys.readouterr().err.strip().splitlines()
    assert exc.value.code == 2 and err[-1] == (
        "error: no model left to evaluate: the held-out walks are of normal only"
    )
    assert [line for line in err[:-1] if not line.startswith("note: ")] == []


def test_evaluate_on_walks_of_another_skeleton_says_what_differs(
    mocap, small_model, tmp_path, capsys
):
    """Normal walks on another skeleton only (CMU's, written as BVH): one line naming the
    joint counts and joints that differ, exit 2."""
    from markovmotion.io import write_motion

    model = tmp_path / "avg.npz"
    small_model.save(model)
    (tmp_path / "other").mkdir()
    walk = mocap.load_motion(mocap.find("cmu/asfamc/02/02_01.amc.gz"))
    write_motion(walk, tmp_path / "other" / "cmu_walk.bvh")
    (tmp_path / "other" / "INDEX.csv").write_text(
        "file,source,subject,trial,category,label,partner_file,fps,frames,description\n"
        f"cmu_walk.bvh,mine,,,walk,normal,,{walk.fps:g},{walk.n_frames},a CMU walk\n"
    )
    with pytest.raises(SystemExit) as exc:
        main(["gait", "evaluate", "--model", str(model), "--test", str(tmp_path / "other")])
    err = capsys.readouterr().err.strip()
    assert exc.value.code == 2 and len(err.splitlines()) == 1
    assert "cmu_walk.bvh: (" in err and "the models' joints" in err
    assert "are not in cmu_walk.bvh, which has" in err


def test_gait_steps_lists_the_steps_of_each_walk(capsys):
    """``gait steps`` (README's command table): a row per walk with its steps, and the total."""
    from markovmotion.cli import main

    main(["gait", "steps", "--label", "normal"])
    out = capsys.readouterr().out
    rows = [line for line in out.splitlines() if line.startswith("walk_normal_")]
    assert rows and all(int(r.split(",")[2]) > 0 for r in rows)
    assert f"steps in {len(rows)} walks" in out


def test_a_long_walk_is_scored_in_runs_of_steps_in_linear_memory(
    small_model, normal_walks, monkeypatch
):
    """A walk's chain grows with its steps, so scoring it whole costs frames x steps: a
    100,000-frame walk asked for 22 GB (a traceback). Past ``MARKOVMOTION_MAX_VALUES`` cells
    it is scored in runs of steps cut at its heel strikes: a walk of ordinary length is one
    run (the score unchanged), a cut one scores within a few per cent of the whole, and
    every run is within the limit."""
    from markovmotion.algorithms.hsmm_recursions import check_chain
    from markovmotion.errors import LimitError
    from markovmotion.models.gait.synthesizer import step_chunks

    walk = normal_walks[3]
    bounds = small_model.walk_set([walk]).boundaries[0]
    n_states = small_model.hsmm_.n_states
    assert step_chunks(bounds, n_states) == [(0, len(bounds) - 1)]
    whole = small_model.score([walk])
    cells = 60 * 30 * n_states  # about 6 steps a run
    monkeypatch.setenv("MARKOVMOTION_MAX_VALUES", str(cells))
    runs = step_chunks(bounds, n_states)
    assert len(runs) > 1 and runs[0][0] == 0 and runs[-1][1] == len(bounds) - 1
    assert all(a[1] == b[0] for a, b in zip(runs, runs[1:], strict=False))
    for start, stop in runs:
        check_chain(int(bounds[stop] - bounds[start]), (stop - start) * n_states)
    cut = small_model.score([walk])
    assert np.isfinite(cut) and abs(cut - whole) < 0.05 * abs(whole)
    with pytest.raises(LimitError, match="chain states"):
        small_model.hsmm_.score(small_model.walk_set([walk]).obs, [np.zeros(40, int)])


def test_gait_reads_every_walk_of_a_users_own_index_of_one_skeleton(mocap, tmp_path, capsys):
    """A user's index has no ``bandai/dataset-2/`` folder: its walks are every walk (the
    default subset is the shared collection's only where the index has it); a walk on
    another skeleton is left out in a note naming it, not a traceless error; a label no
    walk has is one line that does not say "None"."""
    from markovmotion.data.walks import load_walks

    normal = gait_entries(mocap, "normal")[:3]
    cmu = next(e for e in mocap.query(category="walk") if e.source == "cmu")
    mine = _write_index(
        tmp_path / "mine",
        [(f"my_walks/w{k}.bvh.gz", e) for k, e in enumerate(normal)] + [("other/c.amc.gz", cmu)],
    )
    if cmu.file.endswith(".amc.gz"):  # an AMC reads its ASF beside it
        asf = Path(cmu.path).parent / f"{Path(cmu.file).name.split('_')[0]}.asf"
        shutil.copyfile(asf, tmp_path / "mine" / "other" / "c.asf")
    capsys.readouterr()
    walks = load_walks([mine], None, "all")
    assert len(walks) == 3
    assert "left out" in capsys.readouterr().err
    main(["gait", "steps", "--data", str(mine), "--label", "normal"])
    assert "steps in 3 walks" in capsys.readouterr().out
    with pytest.raises(SystemExit) as exc:
        main(["gait", "steps", "--data", str(mine), "--label", "nope"])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and "no walks labelled nope in" in err and "None" not in err


def test_a_walk_of_too_many_or_no_steps_is_one_line(small_model):
    """``generate(n_steps)`` from Python: past the steps limit (a million steps had asked
    for 24.5 GiB), not whole, or under 1: one LimitError."""
    from markovmotion.errors import LimitError

    for n in (10**6, 0, 2.5, "4", None):
        with pytest.raises(LimitError):
            small_model.generate(n_steps=n)


def test_walks_of_two_skeletons_are_one_line_naming_the_joints_that_differ(mocap, normal_walks):
    """fit on a Bandai walk and a CMU walk (other joints) was NumPy's "all the input array
    dimensions except for the concatenation axis must match"; score and adapt said it already
    (against the model's skeleton), now fit does too, against its first walk."""
    from markovmotion.errors import SkeletonMismatchError

    cmu = mocap.load_motion(mocap.find("cmu/asfamc/02/02_01.amc.gz"))
    with pytest.raises(SkeletonMismatchError) as err:
        GaitSynthesizer(n_iter=1).fit([normal_walks[0], cmu])
    message = str(err.value)
    assert message.startswith("GaitSynthesizer.fit: walk 1 (02_01.amc.gz) is not on the skeleton")
    assert "(36 joints, expected 27; expected joints" in message and "\n" not in message
    assert "are not in it, which has" in message
    assert err.value.reason.startswith("(36 joints, expected 27")


def test_a_walk_of_one_frame_has_no_steps_not_a_traceback(mocap, tmp_path, capsys):
    """A capture of one frame (a pose) listed among walks: ``gait steps`` lists it with no
    step (np.gradient had raised on it, a traceback), and training leaves it out in its note."""
    from markovmotion import write_motion
    from markovmotion.features.gait import heel_strikes

    walk = mocap.load_motion(mocap.query(label="normal", source="bandai")[0])
    pose = walk.trim(0, 1)
    assert {s: len(f) for s, f in heel_strikes(pose).items()} == {"L": 0, "R": 0}
    write_motion(pose, tmp_path / "pose.bvh")
    write_motion(walk, tmp_path / "walk.bvh")
    main(
        [
            "gait",
            "steps",
            "--data",
            str(tmp_path / "pose.bvh"),
            "--data",
            str(tmp_path / "walk.bvh"),
        ]
    )
    out = capsys.readouterr().out
    assert "pose.bvh" in out and "walk.bvh" in out
    main(["gait", "train", "--data", str(tmp_path / "pose.bvh"), "--data", str(tmp_path / "walk.bvh"),
          "--n-iter", "1", "--out", str(tmp_path / "m.npz")])  # fmt: skip
    assert "left out: pose.bvh" in capsys.readouterr().err


def test_components_chosen_for_few_steps_stay_within_each_folds_steps():
    """``n_components="auto"`` on 12 steps of 9 statistics: a fold trains on fewer steps than
    ``min(steps, statistics)``; the components tried stop at the smallest fold's (an outside
    collection of nine walks had asked a fold of 14 steps for 15 components: a traceback)."""
    from markovmotion.evaluate.gait import StyleClassifier

    rng = np.random.default_rng(2)
    walks = [w for c in (np.zeros(9), np.full(9, 0.3)) for w in fake_walks(rng, c, 3, n_steps=2)]
    clf = StyleClassifier(target=1.01).fit(walks, ["a"] * 3 + ["b"] * 3)  # never reached
    assert max(clf.cv_rates_) <= 9 and clf.n_components_ is None


def test_evaluate_takes_the_walks_of_the_index_the_models_learnt(mocap, tmp_path, capsys):
    """Models trained on a user's index record it (``data_index``): ``gait evaluate`` without
    ``--data`` evaluates them on its held-out walks (it had taken the shared collection's, on
    another skeleton, into the style classifier: a NumPy traceback); ``--data`` naming an
    index of another skeleton is one line."""
    import json
    from dataclasses import replace

    from markovmotion.io import write_motion

    mine = tmp_path / "mine"
    rows = ["file,source,subject,trial,category,label,partner_file,fps,frames,description"]
    for style, category in (("normal", "walk"), ("elderly", "style_walk")):
        for k, e in enumerate(gait_entries(mocap, style)[:4]):
            walk = mocap.load_motion(e)  # the rig as another lab names it
            sk = replace(walk.skeleton, names=tuple(f"lab_{n}" for n in walk.skeleton.names))
            write_motion(replace(walk, skeleton=sk), mine / f"{style}_{k}.bvh")
            rows.append(f"{style}_{k}.bvh,lab,,{k},{category},{style},,{e.fps},,")
    (mine / "INDEX.csv").write_text("\n".join(rows) + "\n")
    models = tmp_path / "models"
    main(["gait", "train", "--data", str(mine), "--n-iter", "2",
          "--out", str(models / "average.npz")])  # fmt: skip
    main(["gait", "adapt", "--data", str(mine), "--model", str(models / "average.npz"),
          "--label", "elderly", "--steps", "6", "--out", str(models / "adapted-elderly.npz")])  # fmt: skip
    capsys.readouterr()
    main(["gait", "evaluate", "--models", str(models), "--walks", "2", "--bootstrap", "100",
          "--json"])  # fmt: skip
    out = capsys.readouterr()
    assert "Traceback" not in out.err
    assert json.loads(out.out)["test_files"] == ["elderly_3.bvh", "normal_3.bvh"]
    with pytest.raises(SystemExit) as exc:
        main(["gait", "evaluate", "--models", str(models), "--data", str(mocap.root)])
    err = capsys.readouterr().err.strip()
    assert exc.value.code == 2 and len(err.splitlines()) == 1
    assert "held-out walks of" in err and "is on the models' skeleton (" in err
