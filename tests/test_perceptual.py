"""Perceptual evaluation of the gait paper (§6): stimuli, answer store, analysis, report."""

from __future__ import annotations

import csv
import io
import json
import sqlite3
import threading

import numpy as np
import pytest
from conftest import make_motion
from scipy.stats import pearsonr

from markovmotion.cli import main
from markovmotion.errors import MotionFormatError
from markovmotion.evaluate.perceptual import (
    CSV_COLUMNS,
    NATURALNESS,
    answers_csv,
    choices,
    confusion,
    efficiency,
    naturalness,
    per_style_recognition,
    recognition_rates,
    resemblance,
    style_correlation,
    summarise,
)
from markovmotion.evaluate.stimuli import (
    MANIFEST,
    read_manifest,
    without_displacement,
    write_stimuli,
)
from markovmotion.evaluate.store import EvaluationError, EvaluationStore, Item, open_results
from markovmotion.io import write_motion

STYLES = ["cool", "proud", "sad"]


def random_items(rng: np.random.Generator, n: int = 600) -> list[Item]:
    """Answered items of every test with random labels and answers."""
    items = []
    for k in range(n):
        test = ("naturalness", "recognition", "resemblance")[k % 3]
        style = rng.choice([*STYLES, "average"]) if test != "resemblance" else rng.choice(STYLES)
        kind = "synthetic" if style == "average" else rng.choice(["real", "synthetic"])
        offered = choices(test, STYLES)
        answer = style if test == "recognition" and rng.random() < 0.4 else rng.choice(offered)
        items.append(
            Item(
                f"t{k % 17}",
                test,
                k,
                f"f{k}.bvh",
                str(style),
                str(kind),
                bool(rng.random() < 0.5),
                "g.bvh" if test == "resemblance" else None,
                str(answer),
            )
        )
    return items


def test_choices_follow_the_paper():
    assert choices("naturalness", STYLES) == ("real", "synthetic", "dont_know")
    # 11 styles + "average walk" + "I don't know" = 13 choices in §6.3
    assert len(choices("recognition", [f"s{i}" for i in range(11)])) == 13
    assert choices("resemblance", STYLES) == ("4", "3", "2", "1", "0")
    with pytest.raises(ValueError):
        choices("other", STYLES)


def test_efficiency_reproduces_the_papers_values():
    # eq. 16 with 13 choices (chance 7.69 %): eta = 6.19 and 4.83 in §6.3
    assert efficiency(47.6, 13) == pytest.approx(6.19, abs=0.005)
    assert efficiency(37.15, 13) == pytest.approx(4.83, abs=0.005)


def test_naturalness_on_counted_answers():
    answers = ["real"] * 5 + ["synthetic"] * 3 + ["dont_know"] * 2
    items = [
        Item("t", "naturalness", i, "f", "sad", "real", True, None, a)
        for i, a in enumerate(answers)
    ]
    items += [Item("t", "naturalness", 10, "f", "sad", "synthetic", True, None, "real")]
    items += [Item("t", "naturalness", 11, "f", "sad", "synthetic", True, None, None)]  # unanswered
    out = naturalness(items)
    assert out["real"] == {"n": 10, "real": 50.0, "synthetic": 30.0, "dont_know": 20.0}
    assert out["synthetic"] == {"n": 1, "real": 100.0, "synthetic": 0.0, "dont_know": 0.0}


def test_analysis_agrees_with_brute_force_counting():
    items = random_items(np.random.default_rng(3))
    for kind in ("real", "synthetic"):
        c = confusion(items, STYLES, kind)
        rows = [i for i in items if i.test == "recognition" and i.kind == kind]
        assert c.counts.sum() == len(rows)
        for r, style in enumerate(c.rows):
            for k, answer in enumerate(c.columns):
                assert c.counts[r, k] == sum(i.style == style and i.answer == answer for i in rows)
        np.testing.assert_allclose(c.percent.sum(axis=1), 100.0)
        # the recognition rate is the diagonal of the confusion matrix
        diagonal = sum(c.counts[r, c.columns.index(s)] for r, s in enumerate(c.rows))
        rates = recognition_rates(items)[kind]
        assert rates["all"] == pytest.approx(100.0 * diagonal / len(rows))
        static = [i for i in rows if not i.displacement]
        assert rates["static"] == pytest.approx(
            100.0 * sum(i.answer == i.style for i in static) / len(static)
        )
    real = per_style_recognition(items, STYLES, "real")
    synth = per_style_recognition(items, STYLES, "synthetic")
    assert style_correlation(items, STYLES) == pytest.approx(pearsonr(real, synth)[0])
    score, hist = resemblance(items)
    scores = [int(i.answer) for i in items if i.test == "resemblance"]
    assert score == pytest.approx(np.mean(scores))
    assert hist.tolist() == [scores.count(level) for level in range(5)]


def test_correlation_is_undefined_without_two_styles():
    items = [
        Item("t", "recognition", 0, "f", "sad", "real", True, None, "sad"),
        Item("t", "recognition", 1, "f", "sad", "synthetic", True, None, "cool"),
    ]
    assert np.isnan(style_correlation(items, STYLES))


def test_report_is_json_and_csv_round_trips():
    items = random_items(np.random.default_rng(4), n=90)
    report = summarise(items, STYLES)
    d = json.loads(json.dumps(report.to_dict(), allow_nan=False))
    assert d["answers"] == {"naturalness": 30, "recognition": 30, "resemblance": 30}
    assert d["chance"] == pytest.approx(100 / 5)
    assert d["evaluators"] == len({i.token for i in items})
    rows = list(csv.DictReader(io.StringIO(answers_csv(items))))
    assert len(rows) == len(items) and tuple(rows[0]) == CSV_COLUMNS
    assert [r["answer"] for r in rows] == [i.answer for i in items]


# ---------------------------------------------------------------- stimuli


def write_walks(folder, styles=("cool", "sad")) -> tuple[dict, dict]:
    real, synth = {}, {}
    for k, style in enumerate(styles):
        for kind, out, seed in (("real", real, 2 * k), ("synthetic", synth, 2 * k + 1)):
            path = folder / f"{kind}_{style}.bvh"
            write_motion(make_motion(30, seed=seed), path)
            out[style] = path
    path = folder / "average.bvh"
    write_motion(make_motion(30, seed=99), path)
    synth["average"] = path
    return real, synth


@pytest.fixture()
def stimuli_dir(tmp_path):
    real, synth = write_walks(tmp_path)
    write_stimuli(tmp_path / "stimuli", real, synth)
    return tmp_path / "stimuli"


def test_write_stimuli_and_read_the_manifest(stimuli_dir):
    stimuli = read_manifest(stimuli_dir)
    assert len(stimuli) == 10  # (2 real + 3 synthetic) x (with, without displacement)
    assert {(s.style, s.kind) for s in stimuli} == {
        ("cool", "real"),
        ("sad", "real"),
        ("cool", "synthetic"),
        ("sad", "synthetic"),
        ("average", "synthetic"),
    }
    assert sum(s.displacement for s in stimuli) == 5
    # names tell nothing about the stimulus
    assert all(s.file.startswith("stimulus_") for s in stimuli)


@pytest.mark.parametrize(
    ("row", "problem"),
    [
        ("x.bvh,sad,fake,yes", "kind"),
        ("x.bvh,sad,real,maybe", "displacement"),
        ("missing.bvh,sad,real,yes", "not a file"),
        ("../outside.bvh,sad,real,yes", "not a file"),
        ("x.bvh,,real,yes", "empty style"),
    ],
)
def test_bad_manifest_rows_name_the_line(tmp_path, row, problem):
    folder = tmp_path / "stim"
    folder.mkdir()
    write_motion(make_motion(5), folder / "x.bvh")
    write_motion(make_motion(5), tmp_path / "outside.bvh")
    (folder / MANIFEST).write_text(f"file,style,kind,displacement\nx.bvh,sad,real,no\n{row}\n")
    with pytest.raises(MotionFormatError, match=problem) as exc:
        read_manifest(folder)
    assert exc.value.line == 3 and exc.value.path.endswith(MANIFEST)


def test_manifest_without_columns(tmp_path):
    (tmp_path / MANIFEST).write_text("file,style\n")
    with pytest.raises(MotionFormatError, match="missing column"):
        read_manifest(tmp_path)


def test_without_displacement_walks_on_the_spot(mocap):
    walk = mocap.load_motion(mocap.query(category="walk")[0])
    static = without_displacement(walk)
    pelvis = static.positions()[:, walk.skeleton.body_root]
    travel = walk.positions()[:, walk.skeleton.body_root]
    assert np.ptp(travel[:, [0, 2]], axis=0).max() > 1000  # a real walk travels metres
    np.testing.assert_allclose(
        pelvis[:, [0, 2]], np.broadcast_to(travel[0, [0, 2]], (len(pelvis), 2)), atol=1e-6
    )
    np.testing.assert_allclose(pelvis[:, 1], travel[:, 1], atol=1e-6)
    np.testing.assert_allclose(
        static.body_centred_positions(), walk.body_centred_positions(), atol=1e-6
    )


# ---------------------------------------------------------------- store


def test_store_draws_ten_items_per_test_and_pairs_alike(stimuli_dir, tmp_path):
    store = EvaluationStore(tmp_path / "r.sqlite", read_manifest(stimuli_dir))
    token = store.create_evaluator(np.random.default_rng(0))
    items = store.items(token)
    by = {s.file: s for s in store.stimuli}
    for test in ("naturalness", "recognition", "resemblance"):
        assert [i.position for i in items if i.test == test] == list(range(10))
    singles = [i.file for i in items if i.test == "naturalness"]
    assert len(set(singles)) == 10  # no repeat while unseen stimuli are left
    for i in items:
        if i.test == "resemblance":
            a, b = by[i.file], by[i.file_b]
            assert {a.kind, b.kind} == {"real", "synthetic"}
            assert a.style == b.style != "average" and a.displacement == b.displacement
    mode = sqlite3.connect(tmp_path / "r.sqlite").execute("PRAGMA journal_mode").fetchone()[0]
    assert mode == "wal"


def test_answers_are_committed_at_once_and_survive(stimuli_dir, tmp_path):
    db = tmp_path / "r.sqlite"
    store = EvaluationStore(db, read_manifest(stimuli_dir))
    token = store.create_evaluator()
    store.answer(token, "naturalness", 0, "real")
    store.answer(token, "recognition", 3, "average")
    store.answer(token, "resemblance", 9, "4")
    store.answer(token, "naturalness", 0, "synthetic")  # changed mind: replaced
    # another process (a plain connection) sees the answers without any close
    rows = (
        sqlite3.connect(db)
        .execute("SELECT test, position, answer FROM answers ORDER BY test")
        .fetchall()
    )
    assert rows == [
        ("naturalness", 0, "synthetic"),
        ("recognition", 3, "average"),
        ("resemblance", 9, "4"),
    ]
    again = open_results(db)  # the evaluator comes back later
    assert again.exists(token) and not again.exists("nope")
    answered = {(i.test, i.position): i.answer for i in again.items(token) if i.answer}
    assert answered == {
        ("naturalness", 0): "synthetic",
        ("recognition", 3): "average",
        ("resemblance", 9): "4",
    }
    assert again.styles == ["cool", "sad"]


@pytest.mark.parametrize(
    ("test", "position", "answer", "problem"),
    [
        ("naturalness", 0, "natural", "not a choice"),
        ("recognition", 0, "happy", "not a choice"),
        ("resemblance", 0, "5", "not a choice"),
        ("naturalness", 10, "real", "no item"),
        ("dancing", 0, "real", "unknown test"),
    ],
)
def test_bad_answers_are_refused(stimuli_dir, tmp_path, test, position, answer, problem):
    store = EvaluationStore(tmp_path / "r.sqlite", read_manifest(stimuli_dir))
    token = store.create_evaluator()
    with pytest.raises(EvaluationError, match=problem):
        store.answer(token, test, position, answer)
    with pytest.raises(EvaluationError, match="no item"):
        store.answer("unknown-token", "naturalness", 0, "real")
    assert store.count_answers() == 0


def test_concurrent_answers_are_all_kept(stimuli_dir, tmp_path):
    store = EvaluationStore(tmp_path / "r.sqlite", read_manifest(stimuli_dir))
    tokens = [store.create_evaluator() for _ in range(8)]

    def answer_all(token):
        for item in store.items(token):
            store.answer(token, item.test, item.position, choices(item.test, store.styles)[0])

    threads = [threading.Thread(target=answer_all, args=(t,)) for t in tokens]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert store.count_answers() == 8 * 30


def test_open_results_refuses_other_files(tmp_path):
    with pytest.raises(EvaluationError, match="no such"):
        open_results(tmp_path / "none.sqlite")
    (tmp_path / "junk.sqlite").write_bytes(b"not a database at all" * 100)
    with pytest.raises(EvaluationError, match="not an evaluation database"):
        open_results(tmp_path / "junk.sqlite")
    (tmp_path / "empty.sqlite").write_bytes(b"")
    with pytest.raises(EvaluationError, match="empty.sqlite: .*the file is empty"):
        open_results(tmp_path / "empty.sqlite")
    assert (tmp_path / "empty.sqlite").stat().st_size == 0  # left as it was


def test_report_command(stimuli_dir, tmp_path, capsys):
    db = tmp_path / "r.sqlite"
    store = EvaluationStore(db, read_manifest(stimuli_dir))
    rng = np.random.default_rng(1)
    for _ in range(3):
        token = store.create_evaluator(rng)
        for item in store.items(token):
            offered = choices(item.test, store.styles)
            store.answer(token, item.test, item.position, offered[rng.integers(len(offered))])
    main(
        [
            "evaluation",
            "report",
            str(db),
            "--csv",
            str(tmp_path / "a.csv"),
            "--json",
            str(tmp_path / "r.json"),
        ]
    )
    out = capsys.readouterr().out
    assert (
        "3 evaluators registered, 3 answered" in out
        and "efficiency" in out
        and "Resemblance" in out
    )
    expected = summarise(store.answered(), store.styles).to_dict()
    assert json.loads((tmp_path / "r.json").read_text()) == json.loads(json.dumps(expected))
    assert len(list(csv.DictReader((tmp_path / "a.csv").open()))) == 90
    assert set(NATURALNESS) >= {
        r["answer"]
        for r in csv.DictReader((tmp_path / "a.csv").open())
        if r["test"] == "naturalness"
    }


def test_report_command_on_a_missing_database(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["evaluation", "report", str(tmp_path / "nothing.sqlite")])
    assert exc.value.code == 2
    assert "no such evaluation database" in capsys.readouterr().err


def test_wal_mode_is_retried_while_the_database_is_locked():
    """Two server workers opening a new database together: the change of journal mode can
    fail at once with "database is locked" (SQLite's busy handler is not asked), which
    stopped a worker once in CI; it is tried again, and another error is not."""
    import sqlite3

    from markovmotion.evaluate.store import write_ahead

    class Locked:
        def __init__(self, fails: int, message: str = "database is locked"):
            self.fails, self.message, self.calls = fails, message, 0

        def execute(self, sql: str):
            self.calls += 1
            if self.calls <= self.fails:
                raise sqlite3.OperationalError(self.message)

    con = Locked(3)
    write_ahead(con)  # type: ignore[arg-type]
    assert con.calls == 4
    with pytest.raises(sqlite3.OperationalError, match="disk I/O"):
        write_ahead(Locked(1, "disk I/O error"))  # type: ignore[arg-type]
    with pytest.raises(sqlite3.OperationalError, match="locked"):
        write_ahead(Locked(10**6), seconds=0.2)  # type: ignore[arg-type]
