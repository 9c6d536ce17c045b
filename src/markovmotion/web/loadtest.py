"""Load tests of a running server on loopback: simulated evaluators and live-partner sessions,
and a stand-in partner that costs nothing.

Both simulations are bounded in time and in count, and stop by themselves; the numbers go
to ``benchmarks/web_load.py``, a shortened run to the tests.
"""

from __future__ import annotations

import asyncio
import collections
import http.client
import json
import threading
import time
from dataclasses import dataclass, field
from urllib.parse import urlsplit

import numpy as np
from websockets.asyncio.client import connect

from markovmotion.core.motion import Motion
from markovmotion.web.library import display_parents


class MirrorPartner:
    """A stand-in live partner with no model cost, to measure the streaming alone:
    A's pose mirrored across the plane z = 1 m, ``lag`` frames late."""

    lag = 3
    fps = None

    def __init__(self, motion: Motion):
        self.parents = display_parents(motion.skeleton)
        self.poses: collections.deque[np.ndarray] = collections.deque(maxlen=self.lag + 1)

    def step(self, frame_a: Motion) -> np.ndarray | None:
        self.poses.append(frame_a.positions()[0])
        if len(self.poses) <= self.lag:
            return None
        b = self.poses[0].copy()
        b[:, 2] = 2000.0 - b[:, 2]
        return b

    def drop(self) -> None:
        """A dropped frame of A: B holds A's last pose seen for it."""
        if self.poses:
            self.poses.append(self.poses[-1])


STALL_SECONDS = 0.25
"""A live session stalls when no frame arrives for this long (7.5 frames at 30 fps)."""


@dataclass
class EvaluatorLoad:
    """What simulated evaluators did: answers accepted, their latencies, failures."""

    evaluators: int = 0
    answers: int = 0
    errors: list[str] = field(default_factory=list)
    latency_ms: list[float] = field(default_factory=list)
    seconds: float = 0.0


def _request(con: http.client.HTTPConnection, method: str, path: str, body: dict | None = None):
    data = None if body is None else json.dumps(body).encode()
    headers = {} if body is None else {"Content-Type": "application/json"}
    con.request(method, path, body=data, headers=headers)
    response = con.getresponse()
    return response.status, response.read()


def _evaluator(
    url: str, deadline: float, rng: np.random.Generator, out: EvaluatorLoad, lock
) -> None:
    """One simulated person: registers, answers every item, registers again, until the deadline."""
    parts = urlsplit(url)
    con = http.client.HTTPConnection(parts.hostname, parts.port, timeout=30)
    try:
        while time.monotonic() < deadline:
            status, body = _request(con, "POST", "/api/evaluation")
            if status != 200:
                with lock:
                    out.errors.append(f"register: {status}")
                return
            token = json.loads(body)["token"]
            _, body = _request(con, "GET", f"/api/evaluation/{token}")
            with lock:
                out.evaluators += 1
            for test in json.loads(body)["tests"]:
                values = [c[0] for c in test["choices"]]
                for item in test["items"]:
                    if time.monotonic() >= deadline:
                        return
                    answer = values[rng.integers(len(values))]
                    t0 = time.perf_counter()
                    status, _ = _request(
                        con,
                        "POST",
                        f"/api/evaluation/{token}/{test['name']}/{item['position']}",
                        {"answer": answer},
                    )
                    ms = 1000.0 * (time.perf_counter() - t0)
                    with lock:
                        if status == 200:
                            out.answers += 1
                            out.latency_ms.append(ms)
                        else:
                            out.errors.append(f"answer: {status}")
    except OSError as exc:
        with lock:
            out.errors.append(f"connection: {exc}")
    finally:
        con.close()


def simulate_evaluators(
    url: str, n: int = 50, seconds: float = 30.0, seed: int = 0
) -> EvaluatorLoad:
    """``n`` evaluators answering at random, concurrently, for ``seconds``."""
    out = EvaluatorLoad()
    lock = threading.Lock()
    deadline = time.monotonic() + seconds
    rngs = np.random.default_rng(seed).spawn(n)
    threads = [
        threading.Thread(target=_evaluator, args=(url, deadline, rng, out, lock)) for rng in rngs
    ]
    start = time.monotonic()
    for t in threads:
        t.start()
    for t in threads:
        t.join(seconds + 60)
    out.seconds = time.monotonic() - start
    return out


@dataclass
class LiveLoad:
    """What live sessions received: frames, frames the server dropped (per session), partner
    latency, gaps between frames, how late frames came against the stream's clock, stalls."""

    sessions: int = 0
    fps: float = 0.0
    frames: list[int] = field(default_factory=list)
    skipped: list[int] = field(default_factory=list)
    latency_ms: list[float] = field(default_factory=list)
    gap_ms: list[float] = field(default_factory=list)
    late_ms: list[float] = field(default_factory=list)
    stalls: int = 0
    errors: list[str] = field(default_factory=list)
    seconds: float = 0.0


async def _live(url: str, path: str, seconds: float, out: LiveLoad) -> None:
    """One simulated page: streams ``path`` in a loop for ``seconds``, noting every frame."""
    ws_url = "ws" + url.removeprefix("http") + "/ws/live"
    frames, skipped, latency, gaps, late, stalls = 0, 0, [], [], [], 0
    try:
        async with connect(ws_url, open_timeout=30, max_size=None, compression=None) as ws:
            await ws.send(json.dumps({"path": path, "loop": True}))
            start = json.loads(await asyncio.wait_for(ws.recv(), 30))
            if start.get("type") != "start":
                raise RuntimeError(start.get("message", "no start message"))
            deadline = time.monotonic() + seconds
            last = first = None
            while time.monotonic() < deadline:
                msg = json.loads(await asyncio.wait_for(ws.recv(), 5))
                now = time.monotonic()
                if msg["type"] != "frame":  # the server ended the session: say why
                    raise RuntimeError(f"{msg['type']}: {msg.get('message', msg)}")
                frames += 1
                skipped = msg["skipped"]
                latency.append(msg["latency_ms"])
                # how late frame i came against the stream's clock (the first frame's arrival
                # plus i / fps; frames the server dropped still take their time on it): the
                # end-to-end frame latency beyond the schedule
                first = (now, msg["i"]) if first is None else first
                late.append(1000.0 * (now - first[0] - (msg["i"] - first[1]) / start["fps"]))
                if last is not None:
                    gaps.append(1000.0 * (now - last))
                    stalls += now - last > STALL_SECONDS
                last = now
            await ws.send(json.dumps({"type": "stop"}))
        out.fps = start["fps"]
    except Exception as exc:  # noqa: BLE001 - a load test reports every failure's cause
        out.errors.append(f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__)
    out.sessions += 1
    out.frames.append(frames)
    out.skipped.append(skipped)
    out.latency_ms += latency
    out.gap_ms += gaps
    out.late_ms += late
    out.stalls += stalls


def simulate_live(url: str, path: str, n: int = 20, seconds: float = 30.0) -> LiveLoad:
    """``n`` concurrent live-partner WebSocket sessions streaming library file ``path`` for
    ``seconds``. The simulated pages share one event loop in the calling thread (pages in
    browsers elsewhere cost the server's machine nothing; here every page's CPU is taken
    from the server under test, 0.12-0.14 ms a frame, a tenth less than with a thread per
    page)."""
    out = LiveLoad()

    async def run() -> None:
        await asyncio.wait_for(
            asyncio.gather(*(_live(url, path, seconds, out) for _ in range(n))), seconds + 60
        )

    start = time.monotonic()
    _run_async(run())
    out.seconds = time.monotonic() - start
    return out


def _run_async(coroutine) -> None:
    """``asyncio.run``, in a thread of its own when this thread already runs an event loop (a
    notebook, or Playwright's sync API), where ``asyncio.run`` refuses to start."""
    try:
        asyncio.get_running_loop()
    except RuntimeError:  # no loop running here: the usual case
        asyncio.run(coroutine)
        return
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(1) as pool:
        pool.submit(asyncio.run, coroutine).result()
