"""Start-up of the command line: ``markovmotion --help`` and ``markovmotion info FILE``.

Each is run as a fresh process, in turns with a bare ``python3 -c pass`` (the reference:
what the machine's load costs any process) and ``python3 -c "import numpy"``; medians of
wall-clock seconds, with the load average before and after. The compiled kernels are
loaded from numba's cache (one ``info`` run first fills it).

    python3 benchmarks/startup_bench.py [FILE] [--runs 5]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_FILE = ROOT.parent / "shared/data/mocap/bandai/dataset-1/walk_active_001.bvh.gz"
CLI = "import markovmotion.cli as c; c.main()"


def wall(args: list[str]) -> float:
    t0 = time.perf_counter()
    subprocess.run(args, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - t0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("file", nargs="?", type=Path, default=DEFAULT_FILE)
    parser.add_argument("--runs", type=int, default=5)
    args = parser.parse_args()
    py = sys.executable
    commands = {
        "python3 -c pass": [py, "-c", "pass"],
        "python3 -c 'import numpy'": [py, "-c", "import numpy"],
        "markovmotion --help": [py, "-c", CLI, "--help"],
        "markovmotion info FILE": [py, "-c", CLI, "info", str(args.file)],
    }
    wall(commands["markovmotion info FILE"])  # numba's cache filled, files in the page cache
    load = os.getloadavg()[0]
    times: dict[str, list[float]] = {name: [] for name in commands}
    for _ in range(args.runs):
        for name, command in commands.items():
            times[name].append(wall(command))
    bare = float(np.median(times["python3 -c pass"]))
    print(f"load average {load:.2f} -> {os.getloadavg()[0]:.2f}; {args.runs} runs in turns")
    for name, t in times.items():
        m = float(np.median(t))
        print(f"{name:28s} median {m:.2f} s (min {min(t):.2f}), {m / bare:.1f}x bare python")


if __name__ == "__main__":
    main()
