"""The web application: motion JSON, safe paths, uploads, evaluation API, results, live WebSocket,
``serve``, a short load test, and end-to-end runs of every page in headless Chromium.

The server runs with uvicorn on 127.0.0.1 in a thread; the library is a temporary
folder with real Bandai walks, a CMU ASF/AMC take, a C3D file and evaluation
stimuli built from real walks ("synthetic" ones are other takes labelled so).
Screenshots of every page go to ``test-screenshots/``.
"""

from __future__ import annotations

import asyncio
import json
import math
import os
import shutil
import socket
import subprocess
import sys
import threading
import time
import urllib.error
import urllib.parse
import urllib.request
import uuid
import warnings
from pathlib import Path

import c3d
import numpy as np
import pytest
from conftest import make_motion
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect

from markovmotion.evaluate.perceptual import choices, summarise
from markovmotion.evaluate.stimuli import write_stimuli
from markovmotion.evaluate.store import open_results
from markovmotion.io import read_motion, write_motion
from markovmotion.io.bvh import bvh_text
from markovmotion.models.hmm.dual import DualHMM
from markovmotion.web import create_app, live
from markovmotion.web.library import (
    JSON_CHUNK,
    MotionLibrary,
    display_parents,
    motion_payload,
)
from markovmotion.web.library import motion_json as encoded_motion
from markovmotion.web.live import dual_hmm_partner
from markovmotion.web.loadtest import MirrorPartner, simulate_evaluators, simulate_live
from markovmotion.web.server import AppOptions, running, running_workers

ADMIN = "admin-token-for-tests"
SECRET = "TOP-SECRET-OUTSIDE-THE-LIBRARY"
SHOTS = Path(__file__).resolve().parent.parent / "test-screenshots"


BAD_BVH = "HIERARCHY\nROOT hips\n{\n  OFFSET 0 0 0\n  CHANNELS 3 Xposition Yposition\n}\nMOTION\n"


def write_c3d(path: Path) -> None:
    """Three markers over 20 frames at 60 fps; the second is unseen in frame 5."""
    writer = c3d.Writer(point_rate=60.0)
    frames = []
    for f in range(20):
        p = np.zeros((3, 5), np.float32)
        p[:, 0] = [0, 300, 600]
        p[:, 1] = 10 * f
        p[:, 2] = 1000
        p[1, 3] = -1 if f == 5 else 0
        frames.append((p, np.zeros((0, 0), np.float32)))
    writer.add_frames(frames)
    writer.set_point_labels(["LASI", "RASI", "HEAD"])
    with open(path, "wb") as fh, warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # "no analog data": none is wanted
        writer.write(fh)


@pytest.fixture(scope="session")
def site(tmp_path_factory, mocap):
    """The library folder: real walks, an ASF/AMC take, a C3D file, a short motion, stimuli."""
    root = tmp_path_factory.mktemp("web")
    lib = root / "lib"
    lib.mkdir()
    (root / "secret.bvh").write_text(SECRET)
    os.symlink(root / "secret.bvh", lib / "escape.bvh")
    walks = {}
    for style in ("active", "elderly", "exhausted", "normal"):
        entries = [e for e in mocap.query(label=style, source="bandai") if "dataset-2" in e.file]
        walks[style] = [entries[0].path, entries[1].path]
    shutil.copy(walks["active"][0], lib / "walk_active.bvh.gz")
    shutil.copy(walks["elderly"][0], lib / "walk_elderly.bvh.gz")
    asf = mocap.find("cmu/asfamc/02/02_03.amc.gz").path
    (lib / "cmu").mkdir()
    shutil.copy(asf, lib / "cmu" / "02_03.amc.gz")
    shutil.copy(asf.parent / "02.asf", lib / "cmu" / "02.asf")
    write_c3d(lib / "markers.c3d")
    write_motion(make_motion(24, fps=30), lib / "short.bvh")
    write_stimuli(
        lib / "stimuli",
        {s: w[0] for s, w in walks.items() if s != "normal"},
        {**{s: w[1] for s, w in walks.items() if s != "normal"}, "average": walks["normal"][0]},
    )
    SHOTS.mkdir(exist_ok=True)
    return root


@pytest.fixture(scope="session")
def dual(site, mocap):
    """A small dual HMM trained on two salsa takes; a third take's A (2 s) in the library."""
    pairs = mocap.pairs(label="salsa")
    train = [mocap.load_pair(*p) for p in pairs[:2]]
    model = DualHMM(n_states=8, n_iter=5)
    model.fit([(a.trim(0, 600), b.trim(0, 600)) for a, b in train])
    model.save(site / "dual.npz")
    a = mocap.load_motion(pairs[2][0])
    write_motion(a.trim(0, 120), site / "lib" / "salsa_a.bvh")
    return site / "dual.npz"


@pytest.fixture(scope="module")
def dual_server(site, dual):
    # every frame kept: these tests compare what is streamed with the offline answer, and
    # a busy machine must not turn that into a test of the clock
    app = create_app(
        site / "lib", site / "dual.sqlite", partner=dual_hmm_partner(dual), drop_late=math.inf
    )
    with running(app) as url:
        yield url


@pytest.fixture(scope="module")
def server(site):
    app = create_app(
        site / "lib",
        site / "results.sqlite",
        admin_token=ADMIN,
        partner=MirrorPartner,
        drop_late=math.inf,
    )
    with running(app) as url:
        yield url


def fetch(url: str, data: bytes | None = None, headers: dict | None = None) -> tuple[int, bytes]:
    request = urllib.request.Request(url, data=data, headers=headers or {})
    try:
        with urllib.request.urlopen(request, timeout=30) as r:
            return r.status, r.read()
    except urllib.error.HTTPError as exc:
        return exc.code, exc.read()


def post_json(url: str, body: dict | None = None) -> tuple[int, dict]:
    status, data = fetch(url, json.dumps(body or {}).encode(), {"Content-Type": "application/json"})
    return status, json.loads(data)


def upload(url: str, name: str, content: bytes) -> tuple[int, dict]:
    boundary = uuid.uuid4().hex
    body = (
        (
            f'--{boundary}\r\nContent-Disposition: form-data; name="file"; filename="{name}"\r\n'
            "Content-Type: application/octet-stream\r\n\r\n"
        ).encode()
        + content
        + f"\r\n--{boundary}--\r\n".encode()
    )
    status, data = fetch(
        url + "/api/upload", body, {"Content-Type": f"multipart/form-data; boundary={boundary}"}
    )
    return status, json.loads(data)


def motion_json(server: str, path: str) -> dict:
    status, data = fetch(f"{server}/api/motion?path={urllib.parse.quote(path)}")
    assert status == 200, data
    return json.loads(data)


# ---------------------------------------------------------------- motions


def test_library_lists_every_readable_file(server):
    files = json.loads(fetch(server + "/api/motions")[1])["files"]
    for f in (
        "walk_active.bvh.gz",
        "cmu/02_03.amc.gz",
        "markers.c3d",
        "short.bvh",
        "stimuli/stimulus_001.bvh",
    ):
        assert f in files
    assert not any(f.endswith((".asf", ".csv")) for f in files)
    assert "escape.bvh" not in files  # a link out of the folder


def test_motion_json_is_the_forward_kinematics(server, site):
    d = motion_json(server, "walk_active.bvh.gz")
    motion = read_motion(site / "lib" / "walk_active.bvh.gz")
    pos = np.array(d["positions"]).reshape(d["frames"], -1, 3)
    np.testing.assert_allclose(pos, motion.positions(), atol=0.051)
    assert d["fps"] == pytest.approx(motion.fps) and d["joints"] == list(motion.skeleton.names)
    assert d["parents"] == display_parents(motion.skeleton)
    assert d["parents"][motion.skeleton.body_root] == -1  # no bone from Bandai's ground root


def test_every_file_type_is_served(server):
    amc = motion_json(server, "cmu/02_03.amc.gz")
    assert amc["frames"] == 173 and amc["fps"] == 120
    markers = motion_json(server, "markers.c3d")
    assert markers["joints"] == ["LASI", "RASI", "HEAD"] and markers["parents"] == [-1, -1, -1]
    pos = markers["positions"]
    assert len(pos) == 20 * 3 * 3 and pos[(5 * 3 + 1) * 3] is None and pos[0] == 0


@pytest.mark.parametrize(
    "path",
    [
        "../secret.bvh",
        "stimuli/../../secret.bvh",
        "escape.bvh",  # a symbolic link out of the folder
        "/etc/passwd",
        "%2e%2e/secret.bvh",
        "..\\secret.bvh",
        "",
        "short.bvh\x00.bvh",
        "cmu/02.asf",
        "nothing.bvh",
    ],
)
def test_paths_cannot_escape_the_library(server, site, path):
    if path.startswith("%"):
        url = f"{server}/api/motion?path={path}"
    else:
        url = f"{server}/api/motion?path={urllib.parse.quote(path)}"
    status, body = fetch(url)
    assert status == 404
    assert SECRET.encode() not in body and b"root:" not in body


def test_static_files_cannot_escape(server):
    for url in (
        "/static/../../secret.bvh",
        "/static/%2e%2e/%2e%2e/secret.bvh",
        "/static/..%2f..%2fsecret.bvh",
    ):
        status, body = fetch(server + url)
        assert status == 404 and SECRET.encode() not in body


def test_invalid_upload_gets_a_clear_message(server):
    status, body = upload(server, "broken.bvh", BAD_BVH.encode())
    assert status == 422
    assert body["detail"].startswith("broken.bvh:") and "/tmp" not in body["detail"]
    status, body = upload(server, "notes.txt", b"hello")
    assert status == 422 and "only BVH" in body["detail"]
    status, body = upload(server, "mine.bvh", bvh_text(make_motion(12)).encode())
    assert status == 200 and body["frames"] == 12 and body["name"] == "mine.bvh"
    # sent as JSON: 415, saying how to send a file (it had been a 422 naming upload.bvh)
    status, data = fetch(
        server + "/api/upload", b'{"file": "x"}', {"Content-Type": "application/json"}
    )
    assert status == 415 and "multipart/form-data" in json.loads(data)["detail"]


def test_a_long_upload_is_encoded_a_few_frames_at_a_time(site, monkeypatch):
    """An upload's JSON had been encoded by a JSONResponse in the event loop in one
    json.dumps (3 s for a 60 MB BVH, which holds the interpreter lock throughout), every
    other request and live session of the server stopped meanwhile. Now in the upload's
    worker thread, JSON_CHUNK frames per json.dumps (motion_json), the lock let go between."""
    motion = make_motion(20_000)
    floats = motion.n_frames * motion.skeleton.n_joints * 3
    longest = [0]
    dumps = json.dumps

    def spy(*args, **kwargs):
        text = dumps(*args, **kwargs)
        longest[0] = max(longest[0], len(text))
        return text

    with running(create_app(site / "lib", admin_token=ADMIN)) as url:
        monkeypatch.setattr(json, "dumps", spy)
        status, payload = upload(url, "long.bvh", bvh_text(motion).encode())
    assert status == 200 and len(payload["positions"]) == floats
    # a chunk's floats (about 7 characters each), not the take's
    assert longest[0] < 10 * JSON_CHUNK * motion.skeleton.n_joints * 3, longest[0]


def test_uploads_beyond_those_being_read_are_a_429(site, monkeypatch):
    """Each upload had been read at once, whatever the number (a 60 MB BVH takes about
    300 MB while read: four at once took 1.6-1.9 GB, the server's 40 threads would take
    12 GB); now MAX_READING at a time, another refused with a 429 saying to send it again."""
    from markovmotion.web import library

    release = threading.Event()
    reading = threading.Semaphore(0)
    read_bvh = library.read_bvh

    def slow_read(path):
        reading.release()
        release.wait(30)
        return read_bvh(path)

    monkeypatch.setattr(library, "read_bvh", slow_read)
    text = bvh_text(make_motion(12)).encode()
    with running(create_app(site / "lib", admin_token=ADMIN)) as url:
        done: list[int] = []
        first = [
            threading.Thread(target=lambda: done.append(upload(url, "mine.bvh", text)[0]))
            for _ in range(library.MAX_READING)
        ]
        for t in first:
            t.start()
        for _ in first:
            assert reading.acquire(timeout=30)
        try:
            status, body = upload(url, "third.bvh", text)
        finally:
            release.set()
            for t in first:
                t.join(30)
        assert status == 429 and "third.bvh again" in body["detail"], body
        assert done == [200] * library.MAX_READING
        assert upload(url, "mine.bvh", text)[0] == 200  # once they are read


def test_motion_json_is_the_payload_s_json():
    """The chunked encoding gives the bytes json.dumps gives of the whole payload."""
    for n in (0, 1, JSON_CHUNK, JSON_CHUNK + 1, 3 * JSON_CHUNK - 5):
        motion = make_motion(n) if n else make_motion(5).trim(0, 0)
        whole = json.dumps(motion_payload(motion), separators=(",", ":")).encode()
        assert encoded_motion(motion) == whole
        named = json.dumps({**motion_payload(motion), "name": "x"}, separators=(",", ":"))
        assert encoded_motion(motion, "x") == named.encode()


# ---------------------------------------------------------------- evaluation API


def test_evaluation_api(server, site):
    status, body = post_json(server + "/api/evaluation")
    assert status == 200
    token = body["token"]
    state = json.loads(fetch(f"{server}/api/evaluation/{token}")[1])
    assert [t["name"] for t in state["tests"]] == ["naturalness", "recognition", "resemblance"]
    assert all(len(t["items"]) == 10 for t in state["tests"])
    rec = state["tests"][1]["choices"]
    assert [c[0] for c in rec] == ["active", "elderly", "exhausted", "average", "dont_know"]
    assert all(i["pair"] for i in state["tests"][2]["items"])
    stim = json.loads(fetch(f"{server}/api/evaluation/{token}/resemblance/0/1")[1])
    assert stim["name"] == "" and stim["frames"] > 100  # anonymous
    assert fetch(f"{server}/api/evaluation/{token}/naturalness/0/1")[0] == 404
    assert fetch(f"{server}/api/evaluation/{token}/naturalness/10/0")[0] == 404
    assert post_json(f"{server}/api/evaluation/{token}/naturalness/0", {"answer": "real"})[0] == 200
    status, body = post_json(
        f"{server}/api/evaluation/{token}/naturalness/1", {"answer": "natural"}
    )
    assert status == 422 and "not a choice" in body["detail"]
    items = open_results(site / "results.sqlite").items(token)
    assert [i.answer for i in items if i.answer] == ["real"]


def test_unknown_evaluator_token_is_404(server):
    assert fetch(server + "/evaluation/no-such-token")[0] == 404
    assert fetch(server + "/api/evaluation/no-such-token")[0] == 404
    assert fetch(server + "/api/evaluation/no-such-token/naturalness/0/0")[0] == 404
    assert (
        post_json(server + "/api/evaluation/no-such-token/naturalness/0", {"answer": "real"})[0]
        == 404
    )


def test_results_need_the_admin_token(server):
    for path in ("/results", "/api/results", "/api/results.csv"):
        assert fetch(server + path)[0] == 403
        assert fetch(server + path + "?token=wrong")[0] == 403
        assert fetch(f"{server}{path}?token={ADMIN}")[0] == 200
    csv_text = fetch(f"{server}/api/results.csv?token={ADMIN}")[1].decode()
    assert csv_text.startswith("token,test,position,file,style,kind,displacement,file_b,answer")


def test_serve_command_prints_the_admin_token(site, dual, tmp_path):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    cmd = [sys.executable, "-c", "from markovmotion.cli import main; main()"]
    cmd += [
        "serve",
        "--library",
        str(site / "lib"),
        "--port",
        str(port),
        "--db",
        str(tmp_path / "r.sqlite"),
        "--partner",
        str(dual),
    ]
    env = {k: v for k, v in os.environ.items() if k != "MARKOVMOTION_ADMIN_TOKEN"}
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True, env=env)
    try:
        token = None
        for line in proc.stdout:
            if line.startswith("admin token:"):
                token = line.split(":", 1)[1].strip()
                break
        assert token
        url = f"http://127.0.0.1:{port}"
        for _ in range(200):
            try:
                status = fetch(f"{url}/api/results?token={token}")[0]
                break
            except urllib.error.URLError:
                time.sleep(0.05)
        assert status == 200
        assert fetch(f"{url}/api/results")[0] == 403
        assert json.loads(fetch(f"{url}/api/motions")[1])["partner"] is True
    finally:
        proc.terminate()
        proc.wait(10)
        proc.stdout.close()


# ---------------------------------------------------------------- live partner


def ws_url(server: str) -> str:
    return "ws" + server.removeprefix("http") + "/ws/live"


def test_live_session_streams_a_and_the_partner(server):
    with connect(ws_url(server)) as ws:
        ws.send(json.dumps({"path": "short.bvh"}))
        start = json.loads(ws.recv(10))
        assert start["type"] == "start" and start["frames"] == 24 and start["lag"] == 3
        frames = [json.loads(ws.recv(10)) for _ in range(24)]
        assert json.loads(ws.recv(10)) == {"type": "end", "frames": 24, "skipped": 0}
    assert [f["i"] for f in frames] == list(range(24))
    assert all(f["b"] is None for f in frames[:3]) and all(f["b"] is not None for f in frames[3:])
    a = np.array([f["a"] for f in frames]).reshape(24, -1, 3)
    b = np.array([f["b"] for f in frames[3:]]).reshape(21, -1, 3)
    np.testing.assert_allclose(b[:, :, 2], 2000 - a[:-3, :, 2], atol=0.11)
    np.testing.assert_allclose(a, make_motion(24, fps=30).positions(), atol=0.051)
    assert all(f["latency_ms"] >= 0 for f in frames)


@pytest.mark.parametrize(
    ("request_", "field"),
    [
        ({"path": "short.bvh", "loop": "no"}, "loop"),
        ({"path": "short.bvh", "loop": 0}, "loop"),
        ({"bvh": "HIERARCHY", "name": {"a": 1}}, "name"),
        ({"bvh": "HIERARCHY", "name": 5}, "name"),
        ({"path": 3}, "path"),
        ({"bvh": ["HIERARCHY"]}, "bvh"),
    ],
)
def test_a_live_request_field_of_the_wrong_type_is_named(server, request_, field):
    """``"loop": "no"`` had looped A (truthy), and a ``"name"`` object had been shown as
    Python in the error; each field of the wrong type is now an error naming it."""
    with connect(ws_url(server)) as ws:
        ws.send(json.dumps(request_))
        msg = json.loads(ws.recv(10))
        assert msg["type"] == "error" and msg["message"].startswith(f"{field}: "), msg
        with pytest.raises(ConnectionClosed) as closed:
            ws.recv(10)
    assert closed.value.rcvd.code == 1008 and closed.value.rcvd.reason.startswith(f"{field}: ")


def test_live_session_with_the_dual_hmm(dual_server, dual, site):
    model = DualHMM.load(dual)
    a = read_motion(site / "lib" / "salsa_a.bvh").resample(model.fps)
    expected = model.respond(a, method="windowed").positions()
    with connect(ws_url(dual_server)) as ws:
        ws.send(json.dumps({"path": "salsa_a.bvh"}))
        start = json.loads(ws.recv(10))
        assert start["fps"] == model.fps and start["frames"] == a.n_frames == 60
        assert start["lag"] == model.window - 1
        assert start["parents_b"] == display_parents(model.skeleton_b_)
        frames = [json.loads(ws.recv(10)) for _ in range(60)]
        assert json.loads(ws.recv(10))["type"] == "end"
    lag = start["lag"]
    assert all(f["b"] is None for f in frames[:lag])
    b = np.array([f["b"] for f in frames[lag:]]).reshape(60 - lag, -1, 3)
    # what the page is streamed is what the model generates with windowed Viterbi
    np.testing.assert_allclose(b, expected[: 60 - lag], atol=0.051)
    with connect(ws_url(dual_server)) as ws:  # another skeleton: matched by body points
        ws.send(json.dumps({"path": "walk_active.bvh.gz"}))
        assert json.loads(ws.recv(10))["type"] == "start"
    with connect(ws_url(dual_server)) as ws:  # a skeleton without the body points
        ws.send(json.dumps({"path": "short.bvh"}))
        msg = json.loads(ws.recv(10))
        assert msg["type"] == "error" and "body points" in msg["message"]


class SlowPartner(MirrorPartner):
    """A stand-in that falls behind: each step takes 4.5 frames' time at 30 fps. It notes
    what it was asked, frame by frame: "step" or "drop"."""

    made: list[SlowPartner] = []

    def __init__(self, motion):
        super().__init__(motion)
        self.calls: list[str] = []
        SlowPartner.made.append(self)

    def step(self, frame_a):
        self.calls.append("step")
        time.sleep(0.15)
        return super().step(frame_a)

    def drop(self) -> None:
        self.calls.append("drop")
        super().drop()


def test_a_session_behind_its_clock_drops_frames_instead_of_sending_a_backlog(site):
    """The server gives the frames it is late with to the partner as dropped, sends only the
    present frame, and counts what it dropped; it never queues the backlog."""
    app = create_app(site / "lib", admin_token=ADMIN, partner=SlowPartner)
    with running(app) as url, connect(ws_url(url)) as ws:
        ws.send(json.dumps({"path": "short.bvh"}))
        assert json.loads(ws.recv(10))["frames"] == 24
        frames = []
        while (msg := json.loads(ws.recv(10)))["type"] == "frame":
            frames.append(msg)
    sent = [f["i"] for f in frames]
    calls = SlowPartner.made[-1].calls
    # every frame of A reached the partner once, in order: stepped and sent, or dropped
    assert len(calls) == 24 and [i for i, c in enumerate(calls) if c == "step"] == sent
    # 4.5 frames' time per step: most frames dropped, the last one still shown
    assert len(sent) <= 12 and sent[-1] == 23
    # the clock starts when the first frame is out (a first step may load or compile)
    assert sent[:2] == [0, 1]
    assert msg == {"type": "end", "frames": len(sent), "skipped": 24 - len(sent)}
    # each frame says how many were dropped before it; each jump is to the present frame
    assert [f["skipped"] for f in frames] == [i - k for k, i in enumerate(sent)]
    assert all(b - a >= 4 for a, b in zip(sent[1:-2], sent[2:-1], strict=True))


def test_a_partner_model_is_compiled_before_its_first_session(dual):
    """``serve --partner`` (each worker) steps a partner once at start-up, so the kernels a
    live step calls are compiled before a session needs them: compiled in a first session,
    they held every session of the worker (the event loop and numba's compile lock)."""
    check = (
        "import sys, numba\n"
        "from markovmotion.web.live import model_partner\n"
        "model_partner(sys.argv[1])\n"
        "from markovmotion.models.hmm import dual, trellis\n"
        "from markovmotion.algorithms import windowed_viterbi\n"
        "kernels = [trellis.lowest_error_path, trellis.blend_quaternions,\n"
        "           trellis.pair_distances, trellis.whitened_distances, dual._turn_root,\n"
        "           windowed_viterbi.viterbi_kernel]\n"
        "print([k.__name__ for k in kernels if not k.signatures])\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", check, str(dual)], capture_output=True, text=True, check=True
    )
    assert out.stdout.strip() == "[]"
    assert "warning" not in out.stderr


class PageSocket:
    """A WebSocket's sending side, as a live session sees it: frames kept; with ``slow``, a
    send waits until the page reads (``read`` set)."""

    def __init__(self, slow: bool = False):
        self.frames: list[dict] = []
        self.read = asyncio.Event()
        self.slow = slow

    async def send_text(self, text: str) -> None:
        if self.slow:
            await self.read.wait()
        self.frames.append(json.loads(text))


def _in_thread(function, *args, **kwargs):
    """``function`` (one that calls ``asyncio.run``) in a thread of its own: the browser
    tests' Playwright (a session fixture) keeps an event loop running in the main thread
    once any of them has run, whatever the order the tests run in."""
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(1) as pool:
        return pool.submit(function, *args, **kwargs).result()


def _run(coroutine):
    return _in_thread(asyncio.run, coroutine)


def test_a_stream_served_late_starts_its_clock_with_its_first_frame():
    """A session's first frame served a second after the session began (a busy worker) is
    frame 0, nothing dropped, and frame 1 is due a frame after it, not at once and not
    after a second's shift."""

    async def run() -> tuple[PageSocket, live._Stream, float]:
        ws, motion = PageSocket(), make_motion(24, fps=30)
        partner = MirrorPartner(motion)
        step = live.stepper(partner, motion)
        poses = [live.positions_json(p) for p in motion.positions()]
        stream = live._Stream(ws, motion, poses, partner, step, False, 0.07, asyncio.Event())
        stream.start -= 1.0
        stream.serve()
        await asyncio.sleep(0)
        return ws, stream, time.perf_counter()

    ws, stream, now = _run(run())
    assert [(f["i"], f["skipped"]) for f in ws.frames] == [(0, 0)]
    assert stream.frame == 1 and 0 < stream.due - now <= 1 / 30


def test_a_slow_page_holds_up_only_its_own_send():
    """A frame's send finishes at once when the transport takes it; for a page that reads
    slowly it goes on in a task of its own while the worker's other sessions are served."""

    async def run() -> None:
        quick, slow = PageSocket(), PageSocket(slow=True)
        assert live._send_soon(quick, '{"i":0}') is None and quick.frames == [{"i": 0}]
        waiting = live._send_soon(slow, '{"i":1}')
        await asyncio.sleep(0.01)
        assert not waiting.done() and slow.frames == []
        slow.read.set()
        await asyncio.wait_for(waiting, 1)
        assert slow.frames == [{"i": 1}]

    _run(run())


def test_live_session_from_an_uploaded_bvh(server):
    with connect(ws_url(server)) as ws:
        ws.send(json.dumps({"bvh": bvh_text(make_motion(6)), "name": "mine.bvh"}))
        assert json.loads(ws.recv(10))["frames"] == 6
    with connect(ws_url(server)) as ws:
        ws.send(json.dumps({"bvh": BAD_BVH, "name": "broken.bvh"}))
        msg = json.loads(ws.recv(10))
        assert msg["type"] == "error" and msg["message"].startswith("broken.bvh:")


@pytest.mark.parametrize(
    ("first", "problem"),
    [
        ("not json", "not JSON"),
        ("[1, 2]", "not a JSON object"),
        ('{"x": 1}', '"path" or "bvh"'),
        ('{"path": "../secret.bvh"}', "outside the library"),
    ],
)
def test_garbage_ends_only_its_own_session(server, first, problem):
    with connect(ws_url(server)) as good:
        good.send(json.dumps({"path": "walk_active.bvh.gz", "loop": True}))
        assert json.loads(good.recv(10))["type"] == "start"
        with connect(ws_url(server)) as bad:
            bad.send(first)
            msg = json.loads(bad.recv(10))
            assert msg["type"] == "error" and problem in msg["message"]
        with connect(ws_url(server)) as rude:  # garbage in the middle of streaming
            rude.send(json.dumps({"path": "short.bvh", "loop": True}))
            assert json.loads(rude.recv(10))["type"] == "start"
            rude.send("garbage")
            with pytest.raises(ConnectionClosed):  # the server ends that session
                while True:
                    rude.recv(10)
        with connect(ws_url(server)) as leaver:  # closes its tab in the middle of streaming
            leaver.send(json.dumps({"path": "short.bvh", "loop": True}))
            assert json.loads(leaver.recv(10))["type"] == "start"
            leaver.recv(10)
        # the good session goes on streaming, in order
        seen = [json.loads(good.recv(10)) for _ in range(5)]
        assert all(m["type"] == "frame" for m in seen)
        assert [m["i"] for m in seen] == list(range(seen[0]["i"], seen[0]["i"] + 5))
        good.send(json.dumps({"type": "stop"}))


def test_short_load_every_answer_is_stored(site, tmp_path):
    db = tmp_path / "load.sqlite"
    app = create_app(site / "lib", db, admin_token=ADMIN, partner=MirrorPartner)
    with running(app) as url:
        evaluators = simulate_evaluators(url, n=50, seconds=4.0)
        live = simulate_live(url, "short.bvh", n=20, seconds=2.0)  # a loop may run here
    assert not evaluators.errors and evaluators.answers > 50
    assert open_results(db).count_answers() == evaluators.answers
    assert not live.errors and live.sessions == 20 and min(live.frames) > 0


def test_two_server_processes_share_the_sessions_and_store_every_answer(site, dual, tmp_path):
    db = tmp_path / "workers.sqlite"
    options = AppOptions(site / "lib", db, admin_token=ADMIN, partner=dual)
    with running_workers(options, workers=2) as url:
        evaluators = simulate_evaluators(url, n=10, seconds=3.0)
        live = simulate_live(url, "salsa_a.bvh", n=6, seconds=1.5)
        assert fetch(f"{url}/api/motions")[0] == 200
    # two writers on one SQLite file: every accepted answer is there once
    assert not evaluators.errors and evaluators.answers > 10
    assert open_results(db).count_answers() == evaluators.answers
    assert not live.errors and live.sessions == 6 and min(live.frames) > 0


def test_library_streams_a_file_read_once_until_it_changes(site):
    lib = MotionLibrary(site / "lib")
    motion, frames = lib.stream("short.bvh", 15.0)
    again = lib.stream("short.bvh", 15.0)
    assert again[0] is motion and again[1] is frames  # one read for every session
    assert motion.fps == 15.0 and len(frames) == motion.n_frames == 12
    np.testing.assert_allclose(
        np.array(json.loads(frames[3])).reshape(-1, 3), motion.positions()[3], atol=0.051
    )
    assert lib.stream("short.bvh")[0].n_frames == 24  # another rate, another entry
    path = site / "lib" / "short.bvh"
    stat = path.stat()
    os.utime(path, ns=(stat.st_atime_ns, stat.st_mtime_ns + 1_000_000))
    assert lib.stream("short.bvh", 15.0)[0] is not motion  # the file changed: read again


# ---------------------------------------------------------------- browser


def frame_of(page) -> int:
    return int(page.evaluate("document.body.dataset.frame || '-1'"))


def colours_drawn(page, selector: str) -> dict[str, int]:
    """Pixels of the first two figure colours (blue A, orange B) on a canvas."""
    return page.evaluate(
        """(sel) => {
        const c = document.querySelector(sel);
        const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
        let blue = 0, orange = 0;
        for (let i = 0; i < d.length; i += 4) {
          const [r, g, b] = [d[i], d[i + 1], d[i + 2]];
          if (Math.abs(r - 47) < 30 && Math.abs(g - 111) < 30 && Math.abs(b - 214) < 30) blue++;
          if (Math.abs(r - 224) < 30 && Math.abs(g - 123) < 30 && Math.abs(b - 34) < 30) orange++;
        }
        return {blue, orange};
    }""",
        selector,
    )


def test_viewer_plays_motions(server, page):
    page.goto(f"{server}/viewer?files=walk_active.bvh.gz")
    page.wait_for_function("() => Number(document.body.dataset.frame) > 5")
    first = frame_of(page)
    page.wait_for_function(f"() => Number(document.body.dataset.frame) > {first}")  # frames advance
    page.click("#play")  # pause
    paused = frame_of(page)
    page.wait_for_timeout(300)
    assert frame_of(page) == paused
    page.click("li[data-path='walk_elderly.bvh.gz']")  # a second person in the same scene
    page.wait_for_selector("#legend span:nth-child(2)")
    page.click("#play")
    page.wait_for_timeout(500)
    assert colours_drawn(page, "canvas.stage")["orange"] > 50
    page.screenshot(path=SHOTS / "viewer-one-scene.png")
    page.uncheck("#together")
    assert page.locator("canvas.stage").count() == 2
    page.wait_for_timeout(300)
    page.screenshot(path=SHOTS / "viewer-side-by-side.png")
    page.click("#clear")
    page.click("li[data-path='markers.c3d']")
    page.click("li[data-path='cmu/02_03.amc.gz']")
    page.wait_for_selector("#legend span:nth-child(2)")
    page.wait_for_timeout(300)
    assert page.text_content("#error") == ""
    page.screenshot(path=SHOTS / "viewer-c3d-and-amc.png")


def test_viewer_invalid_upload_shows_the_error(server, page):
    page.goto(f"{server}/viewer")
    page.set_input_files(
        "#upload",
        files=[{"name": "broken.bvh", "mimeType": "text/plain", "buffer": BAD_BVH.encode()}],
    )
    page.wait_for_function("() => document.getElementById('error').textContent.length > 0")
    message = page.text_content("#error")
    assert message.startswith("broken.bvh:") and "channel" in message.lower()
    page.screenshot(path=SHOTS / "viewer-invalid-upload.png")
    page.set_input_files(
        "#upload",
        files=[
            {
                "name": "mine.bvh",
                "mimeType": "text/plain",
                "buffer": bvh_text(make_motion(40)).encode(),
            }
        ],
    )
    page.wait_for_selector("#legend span")
    assert "mine.bvh" in page.text_content("#legend")


def answer_current(page, pick: int = 0) -> None:
    """Answer the item on screen with its ``pick``-th choice and wait for the next one."""
    before = (
        page.evaluate("document.body.dataset.test"),
        page.evaluate("document.body.dataset.position"),
    )
    buttons = page.locator("#choices button")
    buttons.nth(pick % buttons.count()).click()
    page.wait_for_function(
        "([t, p]) => document.body.dataset.test !== t || document.body.dataset.position !== p",
        arg=list(before),
    )
    if page.evaluate("document.body.dataset.test") != "done":
        page.wait_for_selector("#choices button")


def test_evaluator_completes_all_tests_leaving_and_resuming(server, site, browser, page):
    page.goto(f"{server}/evaluation")
    page.screenshot(path=SHOTS / "evaluation-start.png")
    page.click("#begin")
    page.wait_for_url("**/evaluation/*")
    token = page.url.rsplit("/", 1)[1]
    page.wait_for_selector("#choices button")
    page.click(".play")
    page.wait_for_function("() => Number(document.body.dataset.frame) > 3")
    page.screenshot(path=SHOTS / "evaluation-naturalness.png")
    for k in range(4):
        answer_current(page, k)
    page.close()  # the evaluator leaves ...

    again = browser.new_context(viewport={"width": 1280, "height": 800}).new_page()
    again.goto(f"{server}/evaluation/{token}")  # ... and comes back with the link
    again.wait_for_selector("#choices button")
    assert "(4/10)" in again.text_content("#tabs button[data-test='naturalness']")
    assert again.evaluate("document.body.dataset.position") == "4"
    rng = np.random.default_rng(0)
    shots = {"recognition": False, "resemblance": False}
    while again.evaluate("document.body.dataset.test") != "done":
        test = again.evaluate("document.body.dataset.test")
        if test in shots and not shots[test]:
            again.click(".play >> nth=0")
            again.wait_for_timeout(400)
            again.screenshot(path=SHOTS / f"evaluation-{test}.png")
            shots[test] = True
        answer_current(again, int(rng.integers(13)))
    assert again.is_visible("#done")
    again.screenshot(path=SHOTS / "evaluation-done.png")
    again.context.close()
    items = open_results(site / "results.sqlite").items(token)
    assert len(items) == 30 and all(i.answer is not None for i in items)
    store = open_results(site / "results.sqlite")
    for i in items:
        assert i.answer in choices(i.test, store.styles)


def test_results_page_shows_the_recomputed_figures(server, site, page):
    assert page.goto(f"{server}/results").status == 403
    page.screenshot(path=SHOTS / "results-forbidden.png")
    assert page.goto(f"{server}/evaluation/not-a-token").status == 404
    assert "does not exist" in page.text_content("main")
    # an evaluator of its own who answers every item, so the test does not rely on others
    token = post_json(server + "/api/evaluation")[1]["token"]
    for test in json.loads(fetch(f"{server}/api/evaluation/{token}")[1])["tests"]:
        for k in range(len(test["items"])):
            url = f"{server}/api/evaluation/{token}/{test['name']}/{k}"
            assert post_json(url, {"answer": test["choices"][0][0]})[0] == 200
    page.goto(f"{server}/results?token={ADMIN}")
    page.wait_for_function("() => document.body.dataset.loaded === 'yes'")
    store = open_results(site / "results.sqlite")
    report = summarise(store.answered(), store.styles)
    assert page.text_content("#n-registered .big") == str(store.count_evaluators())
    assert page.text_content("#n-naturalness .big") == str(report.answers["naturalness"])
    assert page.text_content("#n-resemblance .big") == str(report.answers["resemblance"])
    assert page.text_content("#resemblance-score") == f"{report.resemblance_score:.2f}"
    real_as_real = report.naturalness["real"]["real"]  # "–" if no real walk was shown
    shown = "–" if np.isnan(real_as_real) else f"{real_as_real:.1f} %"
    assert shown in page.text_content("#nat-real")
    assert page.locator("#confusion-real tr").count() == len(report.confusion["real"].rows) + 1
    page.screenshot(path=SHOTS / "results.png", full_page=True)


def test_live_partner_page_draws_both_figures(dual_server, page):
    page.goto(f"{dual_server}/live")
    page.wait_for_function("() => document.querySelectorAll('#motion option').length > 1")
    offered = page.eval_on_selector_all("#motion option", "os => os.map((o) => o.value)")
    # a partner of skeletons is not offered the library's C3D (it would refuse it)
    assert "salsa_a.bvh" in offered and "markers.c3d" not in offered
    assert json.loads(fetch(dual_server + "/api/motions")[1])["partner_reads"] == "skeleton"
    page.select_option("#motion", "salsa_a.bvh")
    page.check("#loop")
    page.click("#start")
    page.wait_for_function("() => Number(document.body.dataset.framesB || 0) > 20", timeout=20000)
    drawn = colours_drawn(page, "#stage")
    assert drawn["blue"] > 50 and drawn["orange"] > 50
    assert float(page.text_content("#latency")) >= 0
    page.screenshot(path=SHOTS / "live-partner.png")
    page.click("#stop")
    page.wait_for_function("() => document.getElementById('start').disabled === false")
    page.set_input_files(
        "#upload",
        files=[{"name": "broken.bvh", "mimeType": "text/plain", "buffer": BAD_BVH.encode()}],
    )
    page.click("#start")
    page.wait_for_function(
        "() => document.getElementById('error').textContent.startsWith('broken.bvh:')"
    )
    page.screenshot(path=SHOTS / "live-invalid-upload.png")


def test_results_without_stimuli_explain_how_to_start_an_evaluation(tmp_path):
    write_motion(make_motion(n_frames=5), tmp_path / "walk.bvh")
    with running(create_app(tmp_path, admin_token=ADMIN)) as url:
        status, body = fetch(f"{url}/results?token={ADMIN}")
    assert status == 503
    assert b"No evaluation on this server" in body and b"--stimuli" in body


def test_evaluation_without_stimuli_says_so_on_the_first_page(tmp_path):
    """/evaluation on a server without stimuli: no Begin that then fails, but the page saying
    there is no evaluation and how to start one (issue 22)."""
    write_motion(make_motion(n_frames=5), tmp_path / "walk.bvh")
    with running(create_app(tmp_path, tmp_path / "r.sqlite")) as url:
        status, body = fetch(f"{url}/evaluation")
    assert status == 503
    assert b"No evaluation on this server" in body and b"--stimuli" in body
    assert b"Begin" not in body and b"evaluation-start.js" not in body


def test_live_partner_page_with_a_behaviour_chain(tmp_path, mocap, page):
    """``serve --partner`` takes a behaviour chain: the /live page streams its B frames."""
    from markovmotion.models.chain.partner import VirtualPartner
    from markovmotion.web.live import model_partner

    a, b = mocap.load_pair(*mocap.pairs(label="salsa")[0])
    chain = VirtualPartner(n_state_prototypes=8, n_behaviour_prototypes=6, n_epochs=1)
    chain.fit([(a.trim(0, 300), b.trim(0, 300))]).save(tmp_path / "chain.npz")
    (tmp_path / "lib").mkdir()
    write_motion(a.trim(300, 420), tmp_path / "lib" / "salsa_a.bvh")
    app = create_app(
        tmp_path / "lib",
        tmp_path / "r.sqlite",
        partner=model_partner(tmp_path / "chain.npz"),
        drop_late=math.inf,
    )
    with running(app) as url:
        with connect(ws_url(url)) as ws:
            ws.send(json.dumps({"path": "salsa_a.bvh"}))
            start = json.loads(ws.recv(10))
            assert start["fps"] == 25.0 and start["lag"] == 2 and start["frames"] == 50
            assert start["parents_b"] == display_parents(chain.skeletons_[1])
            frames = [json.loads(ws.recv(10)) for _ in range(50)]
        assert [f["b"] is None for f in frames] == [True] * 2 + [False] * 48
        page.goto(f"{url}/live")
        page.select_option("#motion", "salsa_a.bvh")
        page.check("#loop")
        page.click("#start")
        page.wait_for_function(
            "() => Number(document.body.dataset.framesB || 0) > 20", timeout=20000
        )
        drawn = colours_drawn(page, "#stage")
        assert drawn["blue"] > 50 and drawn["orange"] > 50
        page.screenshot(path=SHOTS / "live-partner-chain.png")
        page.click("#stop")


def test_load_table_of_sessions_that_all_failed_reports_without_dividing_by_zero():
    """A run where no live session started (fps unknown, no frames) still prints its table
    (the causes are printed beneath it), instead of a ZeroDivisionError."""
    import importlib.util

    from markovmotion.web.loadtest import LiveLoad

    root = Path(__file__).resolve().parents[1]
    spec = importlib.util.spec_from_file_location("web_load", root / "benchmarks/web_load.py")
    web_load = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(web_load)
    failed = LiveLoad(sessions=3, frames=[0, 0, 0], errors=["ConnectionClosedError: 1011"] * 3)
    table = web_load.live_table(failed, 3, 30.0, "dual HMM partner")
    values = dict(zip(table.columns[0]._cells, table.columns[1]._cells, strict=True))
    assert values["sessions ended cleanly"] == "0 / 3"
    assert values["real-time factor (received / expected)"] == "-"
    assert "no session started" in table.title
