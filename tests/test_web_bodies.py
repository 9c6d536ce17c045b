"""JSON bodies of the web API: every bad one a 422 whose detail is one line naming the field
(or the body) and the problem, never FastAPI's generic text.

The endpoints that take a JSON body are ``POST /api/evaluation`` (an optional ``{"study"}``)
and ``POST /api/evaluation/{token}/{test}/{position}`` (an answer). Requests go through a
real uvicorn server with raw ``http.client`` requests, so bodies and headers are exactly
those sent. The interaction study's manifest is written by hand (no model is trained).
"""

from __future__ import annotations

import http.client
import json
import urllib.parse

import pytest
from conftest import make_motion

from markovmotion.evaluate.interaction import INTERACTION, INTERACTION_MANIFEST
from markovmotion.evaluate.stimuli import write_stimuli
from markovmotion.evaluate.store import open_results
from markovmotion.io import write_motion
from markovmotion.web import create_app
from markovmotion.web.app import MAX_DIGITS, json_body
from markovmotion.web.security import MAX_BODY
from markovmotion.web.server import running

JSON = {"Content-Type": "application/json"}


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """A library whose stimuli folder holds both studies: four walks, two clips."""
    root = tmp_path_factory.mktemp("bodies")
    stimuli = root / "stimuli"
    walks = {}
    for i, style in enumerate(("happy", "sad")):
        walks[style] = root / f"{style}.bvh"
        write_motion(make_motion(12, seed=i), walks[style])
    write_stimuli(stimuli, walks, walks)
    for side in ("a", "b"):
        write_motion(make_motion(12), stimuli / f"clip_{side}.bvh")
    clips = [
        {"id": f"interaction_00{n}", "file_a": "clip_a.bvh", "file_b": "clip_b.bvh"}
        | {"label": "pull", "kind": kind}
        for n, kind in enumerate(("real", "generated"))
    ]
    manifest = {"labels": ["pull", "handshake"], "clips": clips}
    (stimuli / INTERACTION_MANIFEST).write_text(json.dumps(manifest))
    return root


@pytest.fixture(scope="module")
def server(site):
    app = create_app(site, site / "results.sqlite", stimuli=site / "stimuli", admin_token="x")
    with running(app) as url:
        yield url


def send(url: str, target: str, body: bytes | None, headers: dict | None = None):
    """``(status, reply)`` of one POST sent as given (bounded: the connection's 30 s
    timeout); the reply's detail checked to be one line."""
    parts = urllib.parse.urlsplit(url)
    con = http.client.HTTPConnection(parts.hostname, parts.port, timeout=30)
    try:
        con.request("POST", target, body=body, headers=headers or {})
        r = con.getresponse()
        status, reply = r.status, json.loads(r.read())
    finally:
        con.close()
    if status != 200:
        detail = reply["detail"]
        assert isinstance(detail, str) and "\n" not in detail and len(detail) <= 200, detail
    return status, reply


def send_get(url: str, target: str) -> dict:
    parts = urllib.parse.urlsplit(url)
    con = http.client.HTTPConnection(parts.hostname, parts.port, timeout=30)
    try:
        con.request("GET", target)
        return json.loads(con.getresponse().read())
    finally:
        con.close()


def token(url: str, study: str) -> str:
    return send(url, f"/api/evaluation?study={study}", None)[1]["token"]


DEEP = b"[" * 50_000  # within the body limit
BAD_BODIES = [
    # (body, headers, the detail's start)
    (b"hello", JSON, "body: not JSON ("),
    (b'{"answer": "real"', JSON, "body: not JSON ("),
    (b"\xff\xfe{}", JSON, "body: not UTF-8 text"),
    (b"null", JSON, "body: expected a JSON object, found null"),
    (b"[]", JSON, "body: expected a JSON object, found an array"),
    (b'"real"', JSON, "body: expected a JSON object, found a string"),
    (b"3", JSON, "body: expected a JSON object, found a number"),
    (b'{"answer": "real"}', {"Content-Type": "text/plain"}, "body: not sent as JSON"),
    (b'{"answer": "real"}', {}, "body: not sent as JSON"),
    (b'{"answer": 1' + b"0" * 5000 + b"}", JSON, "answer: a number of 5001 digits"),
    (b'{"answer": NaN}', JSON, "answer: NaN is not JSON"),
    (b'{"answer": -Infinity}', JSON, "answer: -Infinity is not JSON"),
    (b'{"answer": 1e400}', JSON, "answer: 1e400 is too large a number"),
    (b'{"answer": [1, [2, {"x": NaN}]]}', JSON, "answer.1.1.x: NaN is not JSON"),
    (DEEP, JSON, "body: JSON nested too deeply"),
    (b'{"answer": ' + DEEP[:5000] + b"]" * 5000 + b"}", JSON, "body: JSON nested too deeply"),
    (b'{"answer": "real", "answer": "synthetic"}', JSON, "answer: given twice"),
]


@pytest.mark.parametrize(("body", "headers", "start"), BAD_BODIES)
def test_a_bad_answer_body_is_a_422_naming_the_field(server, body, headers, start):
    """Each had been FastAPI's text: "There was an error parsing the body" (400: the number,
    the nesting), "0: JSON decode error", "request: Input should be a valid dictionary or
    object to extract fields from" (null, an array, not sent as JSON), or a 200 (NaN)."""
    target = f"/api/evaluation/{token(server, 'gait')}/naturalness/0"
    status, reply = send(server, target, body, headers)
    assert status == 422 and reply["detail"].startswith(start), reply


@pytest.mark.parametrize(("body", "headers", "start"), BAD_BODIES)
def test_a_bad_study_choice_body_is_a_422_naming_the_field(server, body, headers, start):
    status, reply = send(server, "/api/evaluation", body, headers)
    assert status == 422 and reply["detail"].startswith(start), reply


@pytest.mark.parametrize(
    ("body", "start"),
    [
        (b"", "body: missing (send a JSON object"),
        (b"{}", "answer: Field required"),
        (b'{"answer": 3}', "answer: Input should be a valid string, found a number"),
        (b'{"answer": null}', "answer: Input should be a valid string, found null"),
        (b'{"answer": ["real"]}', "answer: Input should be a valid string, found an array"),
        (b'{"answer": "real", "comment": 5}', "comment: Input should be a valid string"),
        (b'{"answer": "real", "comment": "\\ud800"}', "comment: not Unicode text"),
    ],
)
def test_an_answer_field_of_the_wrong_type_is_named(server, body, start):
    target = f"/api/evaluation/{token(server, 'gait')}/naturalness/0"
    status, reply = send(server, target, body, JSON)
    assert status == 422 and reply["detail"].startswith(start), reply


@pytest.mark.parametrize(
    ("body", "start"),
    [
        ({"study": 1}, "study: Input should be 'gait' or 'interaction'"),
        ({"study": "walks"}, "study: Input should be 'gait' or 'interaction'"),
        ({"study": "gait", "x": 1}, "x: not a field of this request"),
        ({"k" * 60_000: 1}, "k" * 57 + "...: not a field of this request"),
    ],
)
def test_a_study_choice_field_is_named(server, body, start):
    status, reply = send(server, "/api/evaluation", json.dumps(body).encode(), JSON)
    assert status == 422 and reply["detail"].startswith(start), reply


def test_a_study_choice_body_may_be_left_out_or_empty(server):
    """What the start page sends (no body), an empty object, and the study given."""
    for body, headers in ((None, {}), (b"{}", JSON), (b'{"study": "interaction"}', JSON)):
        status, reply = send(server, "/api/evaluation", body, headers)
        assert status == 200 and reply["token"], reply


def test_json_body_names_the_path_of_a_refused_value():
    def problem(text: bytes) -> str:
        with pytest.raises(json.JSONDecodeError) as refused:
            json_body(text)
        return refused.value.msg

    assert problem(b'{"a": {"b": [1, 2, {"c": Infinity}]}}') == (
        "a.b.2.c: Infinity is not JSON (JSON numbers are finite)"
    )
    assert problem(b'{"a": 1, "b": {"x": 1, "x": 2}}') == "b.x: given twice"
    digits = MAX_DIGITS + 1
    assert problem(b'{"n": -' + b"9" * digits + b"}") == (
        f"n: a number of {digits} digits (at most {MAX_DIGITS})"
    )
    assert json_body(b'{"n": -' + b"9" * MAX_DIGITS + b', "x": [1.5, true, null]}') == {
        "n": -int("9" * MAX_DIGITS),
        "x": [1.5, True, None],
    }


def test_a_body_of_many_refused_values_names_the_first():
    """200,000 NaNs: the hooks keep the first refusal, and the path found is its own (the
    containers are walked, not copied: 0.6 s before; timings are for benchmarks/)."""
    body = b'{"answer": [' + b"NaN," * 200_000 + b"1]}"
    with pytest.raises(json.JSONDecodeError, match=r"answer\.0: NaN"):
        json_body(body)


# ---------------------------------------------------------------- strict answers


@pytest.mark.parametrize(
    ("fields", "start"),
    [
        ({"unusual": "1"}, "unusual: Input should be a valid boolean, found a string"),
        ({"unusual": "true"}, "unusual: Input should be a valid boolean, found a string"),
        ({"unusual": 1}, "unusual: Input should be a valid boolean, found a number"),
        ({"unusual": 0.0}, "unusual: Input should be a valid boolean, found a number"),
        ({"unusual": None}, "unusual: Input should be a valid boolean, found null"),
        ({"comment": 5}, "comment: Input should be a valid string, found a number"),
        ({"comment": ["x"]}, "comment: Input should be a valid string, found an array"),
        ({"answer": 1}, "answer: Input should be a valid string, found a number"),
        ({"answer": "salsa"}, "answer: 'salsa' is not a choice of the interaction test"),
        ({"zzz": 1}, "zzz: not a field of this request"),
        ({"position": 0}, "position: not a field of this request"),
    ],
)
def test_an_interaction_answer_is_taken_only_of_the_exact_types(server, site, fields, start):
    """Each of these had been stored (``"1"``, ``"true"``, ``1`` and ``0.0`` converted to a
    boolean, the unknown fields ignored), or refused without the field's name."""
    who = token(server, "interaction")
    body = {"answer": "pull", "unusual": True, "comment": "odd"} | fields
    status, reply = send(
        server, f"/api/evaluation/{who}/{INTERACTION}/0", json.dumps(body).encode(), JSON
    )
    assert status == 422 and reply["detail"].startswith(start), reply
    assert [i.answer for i in open_results(site / "results.sqlite").items(who)] == [None, None]


def test_an_interaction_answer_as_the_page_sends_it_is_stored(server, site):
    """The body ``static/interaction.js`` posts: the choice's value as given by the state, the
    box's ``checked`` (a boolean) and the comment box's value (a string)."""
    who = token(server, "interaction")
    state = send_get(server, f"/api/evaluation/{who}")
    choice = state["tests"][0]["choices"][-1][0]
    for position, (unusual, comment) in enumerate(((True, "wobbly"), (False, ""))):
        body = {"answer": choice, "unusual": unusual, "comment": comment}
        target = f"/api/evaluation/{who}/{INTERACTION}/{position}"
        assert send(server, target, json.dumps(body).encode(), JSON) == (200, {"ok": True})
    items = open_results(site / "results.sqlite").items(who)
    assert [(i.answer, i.unusual, i.comment) for i in items] == [
        (choice, True, "wobbly"),
        (choice, False, ""),
    ]


@pytest.mark.parametrize(
    ("fields", "start"),
    [
        ({"unusual": False}, "unusual: only the interaction study takes it"),
        ({"comment": ""}, "comment: only the interaction study takes it"),
        ({"answer": "natural"}, "answer: 'natural' is not a choice of the naturalness test"),
        ({"answer": True}, "answer: Input should be a valid string, found true or false"),
    ],
)
def test_a_walk_answer_is_its_choice_alone(server, site, fields, start):
    """A walk's answer had taken (and dropped) the interaction study's fields."""
    who = token(server, "gait")
    body = json.dumps({"answer": "real"} | fields).encode()
    status, reply = send(server, f"/api/evaluation/{who}/naturalness/0", body, JSON)
    assert status == 422 and reply["detail"].startswith(start), reply
    assert all(i.answer is None for i in open_results(site / "results.sqlite").items(who))


def test_a_walk_answer_as_the_page_sends_it_is_stored(server, site):
    """``static/evaluation.js`` posts ``{"answer": value}``, value a choice of the state."""
    who = token(server, "gait")
    for test in send_get(server, f"/api/evaluation/{who}")["tests"]:
        body = json.dumps({"answer": test["choices"][0][0]}).encode()
        target = f"/api/evaluation/{who}/{test['name']}/0"
        assert send(server, target, body, JSON) == (200, {"ok": True}), test["name"]
    answered = [i for i in open_results(site / "results.sqlite").items(who) if i.answer]
    assert len(answered) == 3


# ---------------------------------------------------------------- size


def test_a_json_body_is_at_most_64_kib_and_the_worst_is_answered_at_once(server):
    """A JSON body is parsed and checked on the event loop: 1 MiB of unknown fields had held
    it 0.75 s (every live session with it); the limit is 64 KiB, whose worst takes ms (a
    timing for benchmarks/: here, a body over it is refused and the worst under it read)."""
    target = f"/api/evaluation/{token(server, 'gait')}/naturalness/0"
    too_big = json.dumps({"answer": "real", "comment": "x" * MAX_BODY}).encode()
    status, reply = send(server, target, too_big, JSON)
    assert status == 413 and reply["detail"] == f"request body larger than {MAX_BODY} bytes"
    fields = ",".join(f'"k{k}":1' for k in range(MAX_BODY // 10))
    worst = {
        "unknown fields": ("{" + fields + "}").encode(),
        "empty arrays": b'{"answer": [' + b"[]," * (MAX_BODY // 3 - 10) + b"1]}",
    }
    for name, body in worst.items():  # within the limit: read, and refused in one line
        assert len(body) <= MAX_BODY, name
        status, reply = send(server, target, body, JSON)
        assert status == 422 and "\n" not in reply["detail"], (name, reply)
