"""Per-frame cost of the virtual partner (interaction paper, §5) and of the silhouette tracker.

1. Hypothesis propagation: a behaviour chain trained on the salsa training
   takes (or ``--model``) follows a held-out take frame by frame; the time of
   each ``step`` (propagation, likelihoods, resampling, response) with 200
   hypotheses (weighted-mean, ML and MAP responses) and with a single hypothesis;
   and the whole online partner (``model.partner().step``: A's frame in, shape
   vector, 200 hypotheses, B's frame out by inverse kinematics), beside the peer of every
   partner table, Gaussian mixture regression of B's shape on A's (the ``gmr`` package, 32
   components, one frame at a time), with the ratio.
2. Tracking one 640x480 frame: background subtraction, blobs, outlines and
   B-spline fits of two people, on frames rendered from a salsa take.

Everything runs on one core (BLAS and OpenCV threads set to 1). The target is
real time at 25 fps: under 40 ms per frame, median.

    python3 benchmarks/chain_bench.py [--data DIR] [--model M.npz] [--frames 500]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import cv2
import numpy as np
from rich.console import Console
from rich.table import Table
from threadpoolctl import threadpool_limits

from markovmotion.data import MocapIndex
from markovmotion.data.splits import held_out_pairs
from markovmotion.evaluate.chain import mocap_takes
from markovmotion.models.chain.partner import VirtualPartner
from markovmotion.video.render import render_frames, side_camera
from markovmotion.video.tracker import SilhouetteTracker

TARGET_MS = 40.0


def timed_steps(step, observations: np.ndarray) -> np.ndarray:
    """Milliseconds of each call of ``step`` on successive observations."""
    out = np.empty(len(observations))
    for t, obs in enumerate(observations):
        start = time.perf_counter()
        step(obs)
        out[t] = 1000 * (time.perf_counter() - start)
    return out


def gmr_steps(joint: np.ndarray, observations: np.ndarray, components: int = 32) -> np.ndarray:
    """Milliseconds per frame of Gaussian mixture regression (the ``gmr`` package) of B's
    features on A's, fitted on ``joint`` rows [A, B] by scikit-learn's EM, as the partner
    tables' GMR baseline (``evaluate.hmm.Baselines``)."""
    from gmr import GMM
    from sklearn.mixture import GaussianMixture

    fit = GaussianMixture(components, reg_covar=1e-3 * joint.var(0).mean(), random_state=0)
    fit.fit(joint)
    gmm = GMM(components, fit.weights_, fit.means_, fit.covariances_)
    given = np.arange(observations.shape[1])
    return timed_steps(lambda x: gmm.predict(given, x[None]), observations)


def row(table: Table, name: str, ms: np.ndarray) -> None:
    med = float(np.median(ms))
    table.add_row(
        name,
        str(len(ms)),
        f"{med:.2f}",
        f"{np.mean(ms):.2f}",
        f"{np.percentile(ms, 95):.2f}",
        f"{TARGET_MS / med:.0f}x" if med > 0 else "-",
        "yes" if med < TARGET_MS else "NO",
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=None, help="folder with INDEX.csv")
    parser.add_argument("--model", type=Path, default=None, help="mocap model from 'chain train'")
    parser.add_argument("--frames", type=int, default=500, help="frames of each measurement")
    args = parser.parse_args()
    cv2.setNumThreads(1)

    index = MocapIndex.load(args.data)
    train, test = held_out_pairs(index.pairs(label="salsa"))
    take = mocap_takes(index, test[:1])[0].trim(0, args.frames)
    if args.model:
        model = VirtualPartner.load(args.model)
    else:
        start = time.perf_counter()
        model = VirtualPartner().fit([index.load_pair(a, b) for a, b in train])
        print(f"trained the behaviour chain in {time.perf_counter() - start:.1f} s")
    observations = model.observe(take.person(0))

    table = Table(title="per-frame cost on one core (ms)")
    for col in ("what", "frames", "median", "mean", "p95", "headroom at 25 fps", "real time"):
        table.add_column(col, justify="left" if col == "what" else "right")
    for name, options in (
        ("200 hypotheses, weighted-mean response", {"n_hypotheses": 200, "response": "mean"}),
        ("200 hypotheses, ML response", {"n_hypotheses": 200, "response": "ml"}),
        ("200 hypotheses, MAP response (eq. 21)", {"n_hypotheses": 200, "response": "map"}),
        ("single hypothesis", {"n_hypotheses": 1}),
    ):
        prop = model.propagator(0, **options)
        row(table, name, timed_steps(prop.step, observations))
    a = index.load_pair(*test[0])[0].resample(model.fps_).trim(0, args.frames)
    partner = model.partner(n_hypotheses=200)
    frames_a = [a.trim(t, t + 1) for t in range(a.n_frames)]
    chain_ms = timed_steps(partner.step, frames_a)
    row(table, "online partner, 200 hypotheses (frame in, frame out)", chain_ms)
    # the peer: Gaussian mixture regression of B's shape on A's (the gmr package, the
    # baseline of every partner table), one frame at a time on the same take
    joint = np.vstack(
        [
            np.hstack([model.observe(t.person(0)), model.observe(t.person(1))])
            for t in mocap_takes(index, train)
        ]
    )
    gmr_ms = gmr_steps(joint, observations)
    row(table, "peer: GMR of B's shape on A's, 32 components (gmr)", gmr_ms)
    print(
        f"the online partner is {np.median(gmr_ms) / np.median(chain_ms):.1f}x as fast as GMR per "
        "frame (median; the partner also propagates 200 hypotheses and poses B by inverse "
        "kinematics)"
    )

    people = [take.person(0), take.person(1)]
    frames = list(render_frames(people, side_camera(people)))
    tracker = SilhouetteTracker(n_people=2).learn_background(frames[:: max(len(frames) // 60, 1)])
    merged = []

    def track(frame: np.ndarray) -> None:
        merged.append(tracker.track_frame(frame)[1])

    ms = timed_steps(track, frames)
    merged_arr = np.array(merged)
    row(table, "tracking a 640x480 frame, two people", ms)
    if merged_arr.any() and (~merged_arr).any():
        row(table, "  of which two people touching", ms[merged_arr])
        row(table, "  of which apart", ms[~merged_arr])
    Console().print(table)


if __name__ == "__main__":
    with threadpool_limits(1):
        main()
