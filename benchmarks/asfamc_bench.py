"""ASF/AMC reading speed, and how exactly the motion survives conversion to BVH.

For every AMC file of the shared motion capture (``../shared/data/mocap``, or
``--data``): the time to read it (ASF + gzipped AMC -> Motion), the largest
joint-position difference after writing it as BVH and reading that back, and
the pelvis height and lowest point of the figure (the floor) as a sanity check.

    python3 benchmarks/asfamc_bench.py [--data DIR]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from markovmotion.data import MocapIndex
from markovmotion.io import read_motion, write_motion
from markovmotion.io.files import base_suffix


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=None, help="folder with INDEX.csv")
    args = parser.parse_args()
    entries = [e for e in MocapIndex.load(args.data) if base_suffix(e.file) == ".amc"]
    table = Table(title="ASF/AMC -> Motion -> BVH -> Motion")
    for col in ("file", "frames", "read s", "frames/s", "BVH max err mm", "pelvis mm", "floor mm"):
        table.add_column(col, justify="left" if col == "file" else "right")
    total_frames, total_seconds = 0, 0.0
    with tempfile.TemporaryDirectory() as tmp:
        for e in entries:
            start = time.perf_counter()
            motion = read_motion(e.path)
            seconds = time.perf_counter() - start
            total_frames += motion.n_frames
            total_seconds += seconds
            bvh = Path(tmp) / "x.bvh"
            write_motion(motion, bvh)
            pos = motion.positions()
            err = np.abs(read_motion(bvh).positions() - pos).max()
            floor = pos[..., 1].min()
            table.add_row(
                Path(e.file).name.split(".")[0],
                str(motion.n_frames),
                f"{seconds:.3f}",
                f"{motion.n_frames / seconds:,.0f}",
                f"{err:.1e}",
                f"{np.median(pos[:, 0, 1]) - floor:.0f}",
                f"{floor:.0f}",
            )
    table.add_row(
        "all", str(total_frames), f"{total_seconds:.2f}", f"{total_frames / total_seconds:,.0f}"
    )
    Console().print(table)


if __name__ == "__main__":
    main()
