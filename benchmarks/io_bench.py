"""BVH reading speed: markovmotion's reader against bvhio, and forward kinematics.

Reads every BVH file of the shared motion capture (``../shared/data/mocap``
beside the project root, or ``--data``). The files are gunzipped into a
temporary folder first, so decompression is in neither timing. Each file is
read by both readers one after the other (the machine may be shared; taking
turns spreads any load evenly).

- ours: ``markovmotion.io.read_bvh`` -> a Motion (local quaternions and
  translations for every joint and frame, in mm).
- bvhio: ``bvhio.readAsBvh(path)`` -> the parsed hierarchy with a ``Pose``
  (local position + quaternion) per joint and frame: the same information,
  its cheapest call producing per-frame joint transforms (``readAsHierarchy``
  adds rest-pose corrections on top and is slower still).

Also times forward kinematics (``Motion.positions()``) and checks on one file
that both readers give the same rotations.

    python3 benchmarks/io_bench.py [--data DIR] [--limit N]
"""

from __future__ import annotations

import argparse
import gzip
import tempfile
import time
from pathlib import Path

import bvhio
import numpy as np
from rich.console import Console
from rich.table import Table

from markovmotion.data import MocapIndex
from markovmotion.io.bvh import read_bvh
from markovmotion.io.files import base_suffix
from markovmotion.progress import track

PROJECT = Path(__file__).resolve().parents[1]


def bvhio_quaternions(path: Path) -> np.ndarray:
    """(F, J, 4) local rotations of a file read by bvhio, scalar last, joints in file order."""
    root = bvhio.readAsBvh(str(path)).Root
    joints = [j for j, _, _ in root.layout()]
    return np.array(
        [
            [[k.Rotation.x, k.Rotation.y, k.Rotation.z, k.Rotation.w] for k in j.Keyframes]
            for j in joints
        ]
    ).transpose(1, 0, 2)


def agreement(path: Path) -> float:
    """Largest angle (degrees) between the two readers' joint rotations in one file."""
    ours = read_bvh(path)
    theirs = bvhio_quaternions(path)
    rot = ours.rotations[:, ~ours.skeleton.end_site]
    sign = np.sign(np.sum(rot * theirs, axis=-1, keepdims=True))
    # 2 atan2(|q1 - q2|, |q1 + q2|) is the angle between the rotations, stable near zero
    angle = 2 * np.arctan2(
        np.linalg.norm(rot - sign * theirs, axis=-1), np.linalg.norm(rot + sign * theirs, axis=-1)
    )
    return float(np.degrees(angle).max())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=None, help="folder with INDEX.csv")
    parser.add_argument("--limit", type=int, default=None, help="read only the first N files")
    args = parser.parse_args()

    console = Console()
    index = MocapIndex.load(args.data)
    entries = [e for e in index if base_suffix(e.file) == ".bvh"][: args.limit]
    sources = sorted({e.source for e in entries})
    stats = {
        (s, what): {"files": 0, "frames": 0, "seconds": 0.0}
        for s in sources
        for what in ("ours", "bvhio", "fk")
    }
    with tempfile.TemporaryDirectory() as tmp:
        plain = []
        for e in track(entries, "gunzipping"):
            dst = Path(tmp) / f"{len(plain):03d}_{Path(e.file).name.removesuffix('.gz')}"
            dst.write_bytes(gzip.decompress(e.path.read_bytes()))
            plain.append((e, dst))
        if plain:  # the compiled kinematics loaded outside the clock (with --limit 20, inside
            # it gave 8,247 frames/s for 166,657)
            read_bvh(plain[0][1], fps=plain[0][0].fps).trim(0, 2).positions()
        for e, path in track(plain, "reading with both"):
            start = time.perf_counter()
            motion = read_bvh(path, fps=e.fps)
            ours = time.perf_counter() - start
            start = time.perf_counter()
            container = bvhio.readAsBvh(str(path))
            theirs = time.perf_counter() - start
            start = time.perf_counter()
            motion.positions()
            fk = time.perf_counter() - start
            assert container.FrameCount == motion.n_frames
            for what, seconds in (("ours", ours), ("bvhio", theirs), ("fk", fk)):
                row = stats[(e.source, what)]
                row["files"] += 1
                row["frames"] += motion.n_frames
                row["seconds"] += seconds
        worst = agreement(plain[0][1])

    label = {"ours": "read: markovmotion", "bvhio": "read: bvhio", "fk": "FK: markovmotion"}
    table = Table(title="BVH reading and forward kinematics (gunzipped files, one pass)")
    for col in ("source", "what", "files", "frames", "seconds", "frames/s"):
        table.add_column(col, justify="left" if col in ("source", "what") else "right")
    totals = {w: {"frames": 0, "seconds": 0.0} for w in label}
    for (source, what), row in stats.items():
        table.add_row(
            source,
            label[what],
            str(row["files"]),
            str(row["frames"]),
            f"{row['seconds']:.2f}",
            f"{row['frames'] / row['seconds']:,.0f}",
        )
        totals[what]["frames"] += row["frames"]
        totals[what]["seconds"] += row["seconds"]
    for what, t in totals.items():
        table.add_row(
            "all",
            label[what],
            str(len(entries)),
            str(t["frames"]),
            f"{t['seconds']:.2f}",
            f"{t['frames'] / t['seconds']:,.0f}",
            style="bold",
        )
    console.print(table)
    console.print(
        "read: markovmotion = io.read_bvh -> Motion; read: bvhio = bvhio.readAsBvh -> a Pose "
        "(local position + quaternion) per joint and frame; FK = Motion.positions()"
    )
    ratio = totals["bvhio"]["seconds"] / totals["ours"]["seconds"]
    console.print(
        f"ours is {ratio:.1f}x as fast as bvhio over {len(entries)} files; "
        f"largest rotation difference between the two on {plain[0][0].file}: {worst:.2g} degrees"
    )


if __name__ == "__main__":
    main()
