"""How far real people's joints lie from their path's median: the threshold of
``features.smoothing.despike`` (``SPIKE_MM``), chosen on the collection's motion capture.

    python3 benchmarks/spike_threshold.py [--data DIR] [--window 0.05]

For every skeleton take of INDEX.csv, at its own frame rate, the 12 limb joints' distance
from the per-axis median of their ±window path; prints the pooled percentiles, the takes
with the largest, and the share a threshold would replace. A threshold above nearly all of
real motion replaces glitches (a landmark that leaves its path for a frame or two), not
motion. Not a timing: a measurement behind a default, kept here with the other scripts.
"""

from __future__ import annotations

import argparse

import numpy as np

from markovmotion.data.index import MocapIndex
from markovmotion.features.body_points import body_points
from markovmotion.features.smoothing import SPIKE_MM, SPIKE_WINDOW_S, despike
from markovmotion.video.monocular import REFERENCE_JOINTS


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=None, help="Collection (default: README's).")
    ap.add_argument("--window", type=float, default=SPIKE_WINDOW_S, help="Half window (s).")
    args = ap.parse_args()
    distances, largest, replaced, total = [], [], 0, 0
    for entry in MocapIndex.load(args.data):
        if entry.kind != "skeleton":
            continue
        motion = entry.read()
        points = body_points(motion, REFERENCE_JOINTS)
        k = max(1, round(args.window * motion.fps))
        windows = np.lib.stride_tricks.sliding_window_view(
            np.pad(points, ((k, k), (0, 0), (0, 0)), mode="edge"), 2 * k + 1, axis=0
        )
        d = np.linalg.norm(points - np.median(windows, axis=-1), axis=-1)
        distances.append(d.ravel())
        largest.append((float(d.max()), entry.file, entry.fps))
        _, spiked = despike(points, motion.fps, args.window)
        replaced, total = replaced + int(spiked.sum()), total + spiked.size
    pooled = np.concatenate(distances)
    pct = np.percentile(pooled, [99, 99.9, 99.99])
    print(f"{len(distances)} takes, {pooled.size:,} joint-frames, half window {args.window} s")
    print("distance from the median, mm: " + ", ".join(
        f"{q}% {v:.1f}" for q, v in zip(("99", "99.9", "99.99"), pct, strict=True)
    ) + f", max {pooled.max():.1f}")  # fmt: skip
    print("largest:", ", ".join(f"{f} ({fps:g} fps) {d:.0f}" for d, f, fps in sorted(largest)[-5:]))
    print(f"SPIKE_MM {SPIKE_MM:g}: {replaced:,} of {total:,} replaced ({replaced / total:.4%})")


if __name__ == "__main__":
    main()
