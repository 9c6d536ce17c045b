"""The observer study of the dual-HMM paper (§4.2, Tables 1-2), end to end.

A small dual HMM is trained on the real two-person takes of the collection (the
first take of every label of the subject pair with the most interaction
labels); ``markovmotion evaluation stimuli --study interaction`` builds the
point-light clips of the other takes (real, and B generated from A); an observer
answers in headless Chromium, one answer wrong, one with a comment; the results
page shows the rates computed from the answers stored, and the comment under its
video. Also: the analysis on hand-made answers, the command's option checks,
and bad requests (4xx, one line).
"""

from __future__ import annotations

import json
import shutil
from collections import defaultdict

import numpy as np
import pytest
from PIL import Image
from test_web import SHOTS, fetch, post_json

from markovmotion.cli import main
from markovmotion.errors import MarkovMotionError
from markovmotion.evaluate.interaction import (
    INTERACTION,
    INTERACTION_MANIFEST,
    OTHER,
    Clip,
    read_interaction_manifest,
    summarise_interaction,
)
from markovmotion.evaluate.stimuli import write_stimuli
from markovmotion.evaluate.store import Item, open_results
from markovmotion.features.body_points import MARKER_POINTS
from markovmotion.io import read_motion
from markovmotion.models.hmm.dual import DualHMM
from markovmotion.viz import render
from markovmotion.viz.point_light import point_lights
from markovmotion.web import create_app
from markovmotion.web.server import running

ADMIN = "admin-token-for-the-interaction-study"
COMMENT = "the second person's arm floats <b>oddly</b>"


def study_takes(mocap) -> tuple[list, list]:
    """Training and test takes: of the subject pair with the most interaction labels, the
    first take of every label trains, the others are shown (nothing named in the code)."""
    by_subject: dict[str, list] = defaultdict(list)
    for a, b in mocap.pairs():
        by_subject[a.subject].append((a, b))
    pairs = max(by_subject.values(), key=lambda ps: len({a.label for a, _ in ps}))
    train, test, seen = [], [], set()
    for a, b in pairs:
        (test if a.label in seen else train).append((a, b))
        seen.add(a.label)
    assert len({a.label for a, _ in pairs}) >= 2 and test, (
        "the study needs two labels and a test take"
    )
    return train, test


@pytest.fixture(scope="module")
def study(tmp_path_factory, mocap):
    """A dual HMM trained on real takes, and the stimuli built from it by the command line."""
    root = tmp_path_factory.mktemp("interaction")
    train, test = study_takes(mocap)
    model = DualHMM(n_states=8, n_iter=5).fit(
        [mocap.load_pair(a, b) for a, b in train], [a.label for a, _ in train]
    )
    model.save(root / "dual.npz")
    args = ["evaluation", "stimuli", "--study", "interaction", "--model", str(root / "dual.npz")]
    main(
        [*args, "--test", str(mocap.root / "INDEX.csv"), "--out", str(root / "stimuli"), "--videos"]
    )
    return root, model, train, test


def test_a_label_without_a_clip_is_said(study, mocap, tmp_path, capsys):
    """A label the model learnt every take of (the collection's one handshake) is offered
    but has no clip: said in a note, which names how to give it one."""
    from markovmotion.evaluate.interaction import write_interaction_stimuli

    root, model, train, test = study
    unshown = sorted({a.label for a, _ in train} - {a.label for a, _ in test})
    assert unshown  # the fixture's study has one
    capsys.readouterr()
    write_interaction_stimuli(tmp_path / "s", root / "dual.npz", mocap.root / "INDEX.csv")
    err = capsys.readouterr().err
    assert f"no clip is labelled {', '.join(unshown)}" in err and "--test-trials" in err


@pytest.fixture(scope="module")
def server(study):
    root, *_ = study
    app = create_app(root, root / "results.sqlite", stimuli=root / "stimuli", admin_token=ADMIN)
    with running(app) as url:
        yield url


# ---------------------------------------------------------------- stimuli


def test_stimuli_are_a_real_and_a_generated_clip_of_every_test_take(study, mocap):
    root, model, train, test = study
    s = read_interaction_manifest(root / "stimuli")
    assert s.labels == model.labels_ == sorted({a.label for a, _ in train})
    trained = {f"{a.name}+{b.name}" for a, b in train}
    takes = {f"{a.name}+{b.name}": a.label for a, b in test}
    assert {c.take for c in s.clips} == set(takes) and not trained & set(takes)
    assert s.left_out["left_out_training_files"] == [e.file for p in train for e in p]
    for take, label in takes.items():
        real, generated = (
            next(c for c in s.clips if c.take == take and c.kind == k)
            for k in ("real", "generated")
        )
        assert real.label == generated.label == label
        a_real, a_gen = (read_motion(root / "stimuli" / c.file_a) for c in (real, generated))
        b_real, b_gen = (read_motion(root / "stimuli" / c.file_b) for c in (real, generated))
        assert a_real.n_frames == a_gen.n_frames == b_real.n_frames == b_gen.n_frames > 30
        assert np.isclose(a_real.fps, model.fps) and np.isclose(b_gen.fps, model.fps)
        np.testing.assert_allclose(a_real.positions(), a_gen.positions(), atol=1e-3)
        assert not np.allclose(b_real.positions(), b_gen.positions(), atol=10.0)
    names = sorted(p.name for p in (root / "stimuli").iterdir())
    assert all(n.startswith("interaction_") or n == INTERACTION_MANIFEST for n in names)
    for c in s.clips:  # --videos: each clip also as a point-light MP4
        assert (root / "stimuli" / f"{c.id}.mp4").stat().st_size > 1000
    # the real and generated versions of a take share one view: a clip's frame size told
    # them apart (762 against 812 pixels)
    import imageio_ffmpeg

    for take in takes:
        sizes = {
            imageio_ffmpeg.read_frames(str(root / "stimuli" / f"{c.id}.mp4")).__next__()["size"]
            for c in s.clips
            if c.take == take
        }
        assert len(sizes) == 1, (take, sizes)


def test_point_light_strip_is_white_dots_on_black(study, tmp_path):
    root, *_ = study
    clip = read_interaction_manifest(root / "stimuli").clips[0]
    people = [read_motion(root / "stimuli" / f) for f in (clip.file_a, clip.file_b)]
    cloud = point_lights(people)
    assert cloud.positions.shape == (people[0].n_frames, 2 * len(MARKER_POINTS), 3)
    render(cloud, tmp_path / "strip.png", point_light=True, strip_frames=3)
    rgb = np.asarray(Image.open(tmp_path / "strip.png").convert("RGB")).astype(int)
    black, white = (rgb.max(-1) < 30), (rgb.min(-1) > 200)
    assert black.mean() > 0.9 and white.sum() > 100
    assert (black | white).mean() > 0.99  # nothing but the points (and their edges)


def test_summary_counts_the_answers():
    clips = [Clip("c1", "a", "b", "pull", "real"), Clip("c2", "a", "b", "pull", "generated")]

    def item(token, clip, answer, unusual=False, comment=""):
        return Item(
            token,
            INTERACTION,
            0,
            clip.id,
            clip.label,
            clip.kind,
            False,
            None,
            answer,
            unusual,
            comment,
        )

    items = [
        item("t1", clips[0], "pull"),
        item("t2", clips[0], "pull"),
        item("t1", clips[1], "pull", True, "floaty"),
        item("t2", clips[1], OTHER, True, ""),
        item("t3", clips[1], "handshake"),
        Item("t3", "naturalness", 0, "x.bvh", "active", "real", True, None, "real"),
    ]
    s = summarise_interaction(items, ["handshake", "pull"], clips)
    assert s["observers"] == 3 and s["answers"] == 5
    assert s["rates"]["pull"]["real"] == {"n": 2, "correct": 2, "rate": 100.0, "unusual": 0}
    gen = s["rates"]["pull"]["generated"]
    assert (gen["n"], gen["correct"], gen["unusual"]) == (3, 1, 2)
    assert gen["rate"] == pytest.approx(100 / 3)
    assert s["rates"]["handshake"]["real"]["rate"] is None
    assert [c["comments"] for c in s["clips"]] == [[], ["floaty"]]


# ---------------------------------------------------------------- command line


@pytest.mark.parametrize(
    ("args", "problem"),
    [
        (["--study", "walks", "--out", "x"], "--study"),
        (["--study", "interaction", "--out", "x"], "--model"),
        (["--model", "m.npz", "--out", "x"], "--study interaction"),
        (["--videos", "--out", "x"], "--study interaction"),
        (["--study", "interaction", "--model", "m.npz", "--real", "a=b", "--out", "x"], "--real"),
        (["one", "--out", "two"], "--out"),
        (["--study", "interaction", "--model", "no-such-model.npz", "--out", "x"], "no-such-model"),
        (["--study", "interaction", "--model", "m.npz", "--out", "afile"], "not a folder"),
    ],
)
def test_bad_options_are_one_line_exit_2(args, problem, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "afile").write_text("")
    with pytest.raises(SystemExit) as exc:
        main(["evaluation", "stimuli", *args])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and problem in err and "Traceback" not in err
    assert not (tmp_path / "x").exists()


@pytest.mark.parametrize(
    "text",
    [
        "not json",
        "[1, 2]",
        '{"labels": "pull", "clips": []}',
        '{"labels": ["pull"], "clips": [{"id": "x", "file_a": "../../etc/passwd", '
        '"file_b": "x.bvh", "label": "pull", "kind": "real"}]}',
        '{"labels": ["pull"], "clips": [{"id": "x", "file_a": "a.bvh", "file_b": "a.bvh", '
        '"label": "pull", "kind": "fake"}]}',
    ],
)
def test_a_damaged_manifest_is_one_line(text, tmp_path):
    (tmp_path / "a.bvh").write_text("x")
    (tmp_path / INTERACTION_MANIFEST).write_text(text)
    with pytest.raises(MarkovMotionError) as exc:
        read_interaction_manifest(tmp_path)
    assert INTERACTION_MANIFEST in str(exc.value) and "\n" not in str(exc.value)


def test_gait_stimuli_as_before(mocap, tmp_path, capsys):
    walks = [e for e in mocap.query(category="style_walk") if "dataset-2" in e.file][:2]
    main(
        [
            "evaluation",
            "stimuli",
            str(tmp_path / "gait"),
            "--real",
            f"{walks[0].label}={walks[0].path}",
        ]
    )
    assert (tmp_path / "gait" / "manifest.csv").is_file()
    assert not (tmp_path / "gait" / INTERACTION_MANIFEST).exists()


# ---------------------------------------------------------------- API


def test_bad_requests_are_4xx_with_one_line(server):
    assert json.loads(fetch(server + "/api/studies")[1]) == {"studies": ["interaction"]}
    assert post_json(server + "/api/evaluation?study=gait")[0] == 404  # not on this server
    status, body = post_json(server + "/api/evaluation?study=<script>")
    assert status == 422 and "\n" not in body["detail"]
    token = post_json(server + "/api/evaluation?study=interaction")[1]["token"]
    state = json.loads(fetch(f"{server}/api/evaluation/{token}")[1])
    test = state["tests"][0]
    base = f"{server}/api/evaluation/{token}/{INTERACTION}"
    assert fetch(f"{base}/0/1")[0] == 404
    assert fetch(f"{base}/{len(test['items'])}/0")[0] == 404
    assert fetch(f"{server}/api/evaluation/{token}/naturalness/0/0")[0] == 404
    assert fetch(f"{base}/-1/0")[0] == 422
    for body, code in (
        ({"answer": "salsa-or-anything"}, 422),
        ({"answer": test["choices"][0][0], "comment": "x" * 2001}, 422),
        ({"answer": test["choices"][0][0], "unusual": [1, 2]}, 422),
        ({"unusual": True}, 422),
        ({"answer": test["choices"][0][0]}, 200),
    ):
        status, reply = post_json(f"{base}/0", body)
        assert status == code, reply
        assert code == 200 or ("detail" in reply and "\n" not in reply["detail"])
    status, reply = post_json(f"{base}/99", {"answer": test["choices"][0][0]})
    assert status == 422 and "no item" in reply["detail"]
    points = json.loads(fetch(f"{base}/0/0")[1])
    assert points["name"] == "" and set(points["parents"]) == {-1} and len(points["joints"]) == 26
    assert all(not j.startswith(("cmu", "interaction")) for j in points["joints"])


def test_both_studies_from_one_folder(study, mocap, tmp_path):
    """Gait stimuli and interaction clips side by side: each evaluator gets one study, and
    the gait figures count only gait answers."""
    root, *_ = study
    folder = tmp_path / "both"
    shutil.copytree(root / "stimuli", folder)
    walks = [e for e in mocap.query(category="style_walk") if "dataset-2" in e.file][:2]
    write_stimuli(folder, {w.label: w.path for w in walks}, {})
    app = create_app(tmp_path, tmp_path / "both.sqlite", stimuli=folder, admin_token=ADMIN)
    with running(app) as url:
        assert json.loads(fetch(url + "/api/studies")[1]) == {"studies": ["gait", "interaction"]}
        gait = post_json(url + "/api/evaluation")[1]["token"]  # the default, as before
        inter = post_json(url + "/api/evaluation?study=interaction")[1]["token"]
        by_body = post_json(url + "/api/evaluation", {"study": "interaction"})[1]["token"]
        assert json.loads(fetch(f"{url}/api/evaluation/{by_body}")[1])["tests"][0]["name"] == (
            INTERACTION
        )  # a JSON body is read, not ignored
        assert post_json(url + "/api/evaluation?study=gait", {"study": "interaction"})[0] == 422
        assert post_json(url + "/api/evaluation", {"study": "gait", "x": 1})[0] == 422
        g = json.loads(fetch(f"{url}/api/evaluation/{gait}")[1])
        i = json.loads(fetch(f"{url}/api/evaluation/{inter}")[1])
        assert [t["name"] for t in g["tests"]] == ["naturalness", "recognition", "resemblance"]
        assert [t["name"] for t in i["tests"]] == [INTERACTION]
        assert "interaction.js" in fetch(f"{url}/evaluation/{inter}")[1].decode()
        assert "evaluation.js" in fetch(f"{url}/evaluation/{gait}")[1].decode()
        label = i["tests"][0]["choices"][0][0]
        assert (
            post_json(f"{url}/api/evaluation/{inter}/{INTERACTION}/0", {"answer": label})[0] == 200
        )
        assert post_json(f"{url}/api/evaluation/{gait}/naturalness/0", {"answer": "real"})[0] == 200
        # an answer of one study is not one of the other
        assert (
            post_json(f"{url}/api/evaluation/{gait}/{INTERACTION}/0", {"answer": label})[0] == 422
        )
        r = json.loads(fetch(f"{url}/api/results?token={ADMIN}")[1])
    assert r["studies"] == ["gait", "interaction"] and r["registered"] == 3  # one by body
    assert r["evaluators"] == 1 and r["answers"]["naturalness"] == 1
    assert r["interaction"]["observers"] == 1 and r["interaction"]["answers"] == 1


# ---------------------------------------------------------------- browser


def light_pixels(page) -> tuple[int, int]:
    """(white, other non-black) pixels of the point-light canvas."""
    return tuple(
        page.evaluate(
            """() => {
            const c = document.querySelector('canvas.stage');
            const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
            let white = 0, other = 0;
            for (let i = 0; i < d.length; i += 4) {
              const [r, g, b] = [d[i], d[i + 1], d[i + 2]];
              if (r > 200 && g > 200 && b > 200) white++;
              else if (r > 40 || g > 40 || b > 40) other++;
            }
            return [white, other];
        }"""
        )
    )


def test_observer_answers_and_the_results_page_shows_rates_and_comments(study, server, page):
    root, *_ = study
    clips = {c.id: c for c in read_interaction_manifest(root / "stimuli").clips}
    page.goto(f"{server}/evaluation")
    page.wait_for_function("() => document.body.dataset.studies === 'interaction'")
    assert not page.is_visible("#begin") and page.is_visible("#begin-interaction")
    page.screenshot(path=SHOTS / "interaction-start.png")
    page.click("#begin-interaction")
    page.wait_for_url("**/evaluation/*")
    token = page.url.rsplit("/", 1)[1]
    store = open_results(root / "results.sqlite")
    drawn = {i.position: clips[i.file] for i in store.items(token)}
    assert sorted(c.id for c in drawn.values()) == sorted(clips)  # every clip once

    given: dict[str, tuple[str, bool, str]] = {}
    for n in range(len(clips)):
        page.wait_for_function(f"() => document.body.dataset.position === '{n}'")
        clip = drawn[n]
        if n == 0:
            page.click(".play")
            page.wait_for_function("() => Number(document.body.dataset.frame) > 5")
            white, other = light_pixels(page)
            assert white > 20 and other < white * 3  # white dots on black, nothing else
            page.screenshot(path=SHOTS / "interaction-clip.png")
        wrong = n == 1
        answer = next(
            c
            for c in (*read_interaction_manifest(root / "stimuli").labels, OTHER)
            if (c != clip.label) == wrong
        )
        assert page.is_disabled("#submit")
        page.click(f"#choices button[data-value='{answer}']")
        unusual, comment = False, ""
        if n == 0:
            page.fill("#comment", COMMENT)  # writing ticks "noticed something unusual"
            unusual, comment = True, COMMENT
        elif n == 2:
            page.check("#unusual")
            unusual = True
        page.click("#submit")
        given[clip.id] = (answer, unusual, comment)
    page.wait_for_selector("#done", state="visible")
    page.screenshot(path=SHOTS / "interaction-done.png")

    stored = {i.file: (i.answer, i.unusual, i.comment) for i in store.items(token)}
    assert stored == given  # every answer committed as given

    page.goto(f"{server}/results?token={ADMIN}")
    page.wait_for_function("() => document.body.dataset.loaded === 'yes'")
    assert page.is_visible("#interaction") and not page.is_visible("#naturalness")
    assert page.text_content("#n-interaction .big") == str(
        sum(i.test == INTERACTION for i in store.answered())
    )
    labels = read_interaction_manifest(root / "stimuli").labels
    answers = [i for i in store.answered() if i.test == INTERACTION]  # every observer's
    assert {i.token for i in answers} >= {token}
    for label in labels:
        for kind in ("real", "generated"):
            mine = [i for i in answers if (i.style, i.kind) == (label, kind)]
            correct = sum(i.answer == label for i in mine)
            row = f"#interaction-rates tr[data-label='{label}']"
            cell = page.text_content(f"{row} td[data-kind='{kind}'][data-what='rate']")
            rate = "–" if not mine else f"{100 * correct / len(mine):.1f} %"
            assert cell == f"{rate} ({correct}/{len(mine)})"
            noticed = page.text_content(f"{row} td[data-kind='{kind}'][data-what='unusual']")
            assert noticed == f"{sum(bool(i.unusual) for i in mine)}/{len(mine)}"
    wrong_clip = drawn[1]
    cell = page.text_content(
        f"#interaction-rates tr[data-label='{wrong_clip.label}'] td[data-kind='{wrong_clip.kind}'][data-what='rate']"
    )
    assert not cell.startswith("100.0")  # the wrong answer lowered it
    assert page.locator(f"#clip-{drawn[0].id} .comment").all_text_contents() == [COMMENT]
    assert page.locator(".comment").count() == 1
    page.screenshot(path=SHOTS / "interaction-results.png", full_page=True)


def test_a_partner_of_markers_is_refused_in_one_line(capsys, tmp_path, mocap):
    """The observer study's clips are skeletons as point lights: a marker partner (the
    README's handshake model) is one line, exit 2, nothing written (it was a traceback)."""
    from markovmotion.models.hmm import DualHMM

    takes = [mocap.load_pair(a, b) for a, b in mocap.pairs("handshake", kind="markers")[:2]]
    model = tmp_path / "shake.npz"
    DualHMM(n_states=3, n_iter=1).fit([(a.trim(0, 60), b.trim(0, 60)) for a, b in takes]).save(
        model
    )
    with pytest.raises(SystemExit) as exc:
        main(["evaluation", "stimuli", "--study", "interaction", "--model", str(model),
              "--out", str(tmp_path / "clips")])  # fmt: skip
    err = capsys.readouterr().err.strip()
    assert exc.value.code == 2 and "\n" not in err and "a partner of markers" in err
    assert not (tmp_path / "clips").exists()
