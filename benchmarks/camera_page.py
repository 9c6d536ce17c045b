"""The camera partner page (``/camera``) in headless Chromium with a fake camera playing camera 0
of the real video (``../shared/data/video/pose2sim_balancing``) at 30 fps: frames answered per
second and latency from grabbing a frame to drawing its answer, as the page reports them.

    python3 benchmarks/camera_page.py [--seconds 20] [--inflight 1 2]

Needs MediaPipe (``scripts/install-camera``) and Chromium (``scripts/install-test-browser``).
The partner is a dual HMM on two salsa takes (body points), trained here (about 20 s).
Run it on a quiet machine and give the load average (``uptime``) with the numbers.
"""

from __future__ import annotations

import argparse
import json
import math
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
    ap.add_argument("--inflight", type=int, nargs="+", default=[1, 2], help="frames in flight")
    args = ap.parse_args()
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
        app = create_app(tmp / "lib", partner=model_partner(tmp / "dual.npz"), camera=WebcamTracker)
        flags = ["--headless", "--no-sandbox", "--disable-gpu", "--use-fake-ui-for-media-stream",
                 "--use-fake-device-for-media-stream", f"--use-file-for-fake-video-capture={y4m}"]  # fmt: skip
        with running(app) as url, sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, args=flags)
            for inflight in args.inflight:
                page = browser.new_page()
                page.goto(f"{url}/camera?inflight={inflight}")
                page.fill("#fov", f"{fov:.2f}")
                page.click("#start")
                page.wait_for_function(
                    "() => Number(document.body.dataset.frames || 0) > 10", timeout=120000
                )
                time.sleep(args.seconds)
                data = page.evaluate("() => ({...document.body.dataset})")
                page.click("#stop")
                page.close()
                print(
                    f"in flight {inflight}: {data['fps']} frames/s answered (last 2 s), latency "
                    f"mean {data['latency']} ms p99 {data['latencyP99']} (last 120 frames); "
                    f"camera frames {data['cameraFrames']}, sent {data['sent']}, answered "
                    f"{data['frames']}, person found in {data['framesA']}; load average "
                    f"{os.getloadavg()[0]:.1f}"
                )
            browser.close()


if __name__ == "__main__":
    main()
