"""The camera partner page (``/camera``) in headless Chromium with a fake camera playing camera 0
of the real video (``../shared/data/video/pose2sim_balancing``) at 30 fps: frames answered per
second and latency from grabbing a frame to drawing its answer, as the page reports them, and
the CPU time per frame answered of the server (this process: the server and Playwright's
client) and of the browser (every process under this one: Chromium and Playwright's driver),
so that a run on a loaded machine can be read. ``--client socket`` replaces the browser by a
WebSocket client in this process that sends the video's frames as JPEG (quality 80, as the
page) at 30 frames/s with the same rule (a frame is dropped while ``--inflight`` await an
answer): the server's own rate without the browser's share of the two cores.

    python3 benchmarks/camera_page.py [--seconds 20] [--inflight 2 3] [--graphs 1 2]
        [--client page|socket] [--load N]

Needs MediaPipe (``scripts/install-camera``) and Chromium (``scripts/install-test-browser``).
The partner is a dual HMM on two salsa takes (body points), trained here (about 20 s).
Run it on a quiet machine and give the load average (``uptime``) with the numbers.
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import multiprocessing
import os
import tempfile
import time
from pathlib import Path

from markovmotion.data.index import MocapIndex, data_root
from markovmotion.models.hmm.dual import DualHMM
from markovmotion.video.render import read_frames, write_y4m
from markovmotion.video.webcam import WebcamTracker
from markovmotion.web import create_app
from markovmotion.web.live import model_partner
from markovmotion.web.server import running

CHROMIUM = "/usr/bin/chromium"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=20.0, help="measured time per run")
    ap.add_argument("--inflight", type=int, nargs="+", default=[2, 3], help="frames in flight")
    ap.add_argument("--graphs", type=int, nargs="+", default=[1, 2], help="MediaPipe graphs")
    ap.add_argument("--client", choices=["page", "socket"], default="page")
    ap.add_argument(
        "--load", type=int, default=0, help="busy-loop processes run meanwhile (other jobs)"
    )
    args = ap.parse_args()
    from web_load import cpu_load  # this folder's: the same busy loops as the load test

    with cpu_load(args.load):
        _BUSY.update(p.pid for p in multiprocessing.active_children())
        run(args)


def run(args: argparse.Namespace) -> None:
    """Every setting of ``args``, one after another, each printed as it ends."""
    from playwright.sync_api import sync_playwright

    root = data_root().parent / "video" / "pose2sim_balancing"
    cam = json.loads((root / "cameras.json").read_text())["cameras"][0]
    fov = math.degrees(2 * math.atan(cam["width"] / 2 / cam["K"][0][0]))
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        mocap = MocapIndex.load()
        train = [mocap.load_pair(*p) for p in mocap.pairs(label="salsa")[:2]]
        DualHMM(n_states=8, n_iter=5).fit(
            [(a.trim(0, 600), b.trim(0, 600)) for a, b in train]
        ).save(tmp / "dual.npz")
        y4m = write_y4m(read_frames(root / cam["video"]), tmp / "cam0.y4m")
        (tmp / "lib").mkdir()
        flags = ["--headless", "--no-sandbox", "--disable-gpu", "--use-fake-ui-for-media-stream",
                 "--use-fake-device-for-media-stream", f"--use-file-for-fake-video-capture={y4m}"]  # fmt: skip
        partner = model_partner(tmp / "dual.npz")
        for graphs in args.graphs:
            camera = functools.partial(WebcamTracker, graphs=graphs)
            app = create_app(tmp / "lib", partner=partner, camera=camera)
            if args.client == "socket":
                frames = [jpeg(f) for f in read_frames(root / cam["video"])]
                with running(app) as url:
                    for inflight in args.inflight:
                        measure_socket(url, frames, fov, graphs, inflight, args.seconds)
                continue
            with running(app) as url, sync_playwright() as p:
                browser = p.chromium.launch(executable_path=CHROMIUM, args=flags)
                for inflight in args.inflight:
                    measure(browser, url, fov, graphs, inflight, args.seconds)
                browser.close()


def jpeg(rgb) -> bytes:
    import cv2

    bgr = cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)
    return cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, 80])[1].tobytes()


def measure_socket(
    url: str, frames: list[bytes], fov: float, graphs: int, inflight: int, seconds: float
) -> None:
    """The server alone: frames sent at 30 frames/s, at most ``inflight`` awaiting an answer
    (others dropped, as the page does); 10 answers of warm-up, then ``seconds`` measured."""
    import threading
    from collections import deque

    import numpy as np
    from websockets.sync.client import connect

    sent: deque[float] = deque()
    latency: list[float] = []
    work: list[tuple[float, float]] = []  # the server's track_ms, partner_ms
    answered = [0, 0]  # all, warm-up
    with connect(url.replace("http://", "ws://") + "/ws/camera") as ws:
        ws.send(json.dumps({"fov": fov}))
        assert json.loads(ws.recv(120))["type"] == "start"

        def read() -> None:
            for text in ws:
                msg = json.loads(text)
                if msg["type"] != "frame":
                    raise SystemExit(f"the server said {msg}")
                latency.append(1000 * (time.perf_counter() - sent.popleft()))
                work.append((msg["track_ms"], msg["partner_ms"]))
                answered[0] += 1

        reader = threading.Thread(target=read, daemon=True)
        reader.start()
        k, t0, cpu0, start = 0, time.perf_counter(), None, None
        while True:
            now = time.perf_counter()
            if start is None and answered[0] >= 10:
                start, cpu0, answered[1], warm = now, _cpu(), answered[0], len(latency)
            if start is not None and now - start >= seconds:
                break
            if len(sent) < inflight:
                sent.append(now)
                ws.send(frames[k % len(frames)])
            k += 1
            time.sleep(max(0.0, t0 + k / 30.0 - time.perf_counter()))
        cpu1, wall, n = _cpu(), time.perf_counter() - start, answered[0] - answered[1]
        ws.send(json.dumps({"type": "stop"}))
        reader.join(30)
    lat, ms = np.array(latency[warm:]), np.array(work[warm:]).mean(axis=0)
    print(
        f"graphs {graphs}, in flight {inflight}, no browser: {n / wall:.1f} frames/s answered "
        f"over {wall:.0f} s, latency mean {lat.mean():.0f} ms p99 "
        f"{np.percentile(lat, 99):.0f}; track {ms[0]:.1f} ms, partner {ms[1]:.1f} ms; server CPU {1000 * (cpu1[0] - cpu0[0]) / n:.0f} ms "
        f"per frame answered; load average {os.getloadavg()[0]:.1f}",
        flush=True,
    )


#: The ``--load`` busy loops: under this process, but not the browser's CPU.
_BUSY: set[int] = set()


def _cpu() -> tuple[float, float]:
    """CPU seconds (user + system) of this process and of all the processes under it but
    the ``--load`` busy loops (read from /proc: Linux)."""
    tick = os.sysconf("SC_CLK_TCK")
    parent, used = {}, {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            text = stat.read_text()
        except OSError:
            continue
        fields = text[text.rindex(")") + 2 :].split()  # after "pid (name) "
        pid = int(stat.parent.name)
        parent[pid] = int(fields[1])
        used[pid] = (int(fields[11]) + int(fields[12])) / tick
    me = os.getpid()
    below, todo = 0.0, [me]
    while todo:
        pid = todo.pop()
        kids = [c for c, pp in parent.items() if pp == pid and c not in _BUSY]
        below += sum(used[c] for c in kids)
        todo += kids
    return used.get(me, 0.0), below


def measure(browser, url: str, fov: float, graphs: int, inflight: int, seconds: float) -> None:
    """One run of the page: warm up to 10 answers, then measure for ``seconds``."""
    page = browser.new_page()
    page.goto(f"{url}/camera?inflight={inflight}")
    page.fill("#fov", f"{fov:.2f}")
    page.click("#start")
    page.wait_for_function("() => Number(document.body.dataset.frames || 0) > 10", timeout=120000)
    before = page.evaluate("() => ({...document.body.dataset})")
    cpu0, t0 = _cpu(), time.perf_counter()
    time.sleep(seconds)
    data = page.evaluate("() => ({...document.body.dataset})")
    cpu1, wall = _cpu(), time.perf_counter() - t0
    page.click("#stop")
    page.close()
    answered = int(data["frames"]) - int(before["frames"])
    seen = int(data["cameraFrames"]) - int(before["cameraFrames"])
    per = [1000 * (b - a) / max(answered, 1) for a, b in zip(cpu0, cpu1, strict=True)]
    print(
        f"graphs {graphs}, in flight {inflight}: {answered / wall:.1f} frames/s answered over "
        f"{wall:.0f} s (camera {seen / wall:.1f}; last 2 s: {data['fps']}), latency mean "
        f"{data['latency']} ms p99 {data['latencyP99']} (last 120 frames); track "
        f"{data['trackMs']} ms, page grab+JPEG {data['encodeMs']} ms a frame; CPU ms per "
        f"frame answered: server {per[0]:.0f}, browser {per[1]:.0f}; person found in "
        f"{data['framesA']} of {data['frames']}; load average {os.getloadavg()[0]:.1f}",
        flush=True,
    )


if __name__ == "__main__":
    main()
