"""3-D tracking from multi-view video: annealed particle filter vs a plain particle filter.

Renders the held-out two-person takes (person A alone, 3 cameras at 320x240,
30 fps; ``markovmotion video render``), learns the body model on the
training takes, and tracks each video:

* ``apf``: Deutscher et al.'s annealed particle filter (200 particles, 10 layers);
* ``pf``: a plain particle filter (one layer, no annealing, no limb search)
  with as many particles as the APF evaluates in its layers per frame (2,000),
  so both spend about the same time (the APF's limb search adds 240);
* with ``--sweep`` instead: the APF with 1 and 2 views, 100 and 400
  particles, 5 and 15 layers.

Reports MPJPE (mm, over the 19 body points, against the capture), frames
tracked per second of wall time (video decoding and feature extraction
included) and per second of CPU time (the tracker is single-threaded, so this
is its rate on one unshared core). Videos are cached in ``--cache``.

    python3 benchmarks/tracker_bench.py [--data DIR] [--seconds 3] [--seeds 2] [--sweep] [--json]
        [--take cmu/bvh/FILE.bvh.gz ...] [--body-model interaction|collection] [--only apf]
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from markovmotion.data import MocapIndex
from markovmotion.data.index import read_listed_motion
from markovmotion.data.splits import held_out_pairs
from markovmotion.video.annealed_particle_filter import (
    AnnealedParticleFilter,
    open_video,
    track_features,
)
from markovmotion.video.multiview import (
    BODY_LABELS,
    BODY_MODELS,
    default_body_model,
    render_multiview,
    tracking_errors,
)

FPS = 30.0


def configs(sweep: bool) -> list[dict]:
    if sweep:
        return [
            *(
                {"name": f"apf {v} view(s)", "particles": 200, "layers": 10, "views": v}
                for v in (1, 2)
            ),
            *({"name": f"apf P={p}", "particles": p, "layers": 10, "views": 3} for p in (100, 400)),
            *({"name": f"apf L={m}", "particles": 200, "layers": m, "views": 3} for m in (5, 15)),
        ]
    return [
        {"name": "apf", "particles": 200, "layers": 10, "views": 3},
        {"name": "pf (no annealing)", "particles": 2000, "layers": 1, "views": 3, "refine": 0},
        {"name": "apf, no limb search", "particles": 200, "layers": 10, "views": 3, "refine": 0},
    ]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=None, help="folder with INDEX.csv")
    parser.add_argument("--seconds", type=float, default=3.0, help="seconds of each take")
    parser.add_argument("--seeds", type=int, default=2, help="runs per configuration")
    parser.add_argument("--sweep", action="store_true", help="views, particles, layers instead")
    parser.add_argument("--take", action="append", help="track these files of the index instead")
    parser.add_argument("--cache", type=Path, default=Path(tempfile.gettempdir()) / "mm-tracker")
    parser.add_argument("--json", action="store_true", help="print the results as JSON")
    parser.add_argument("--only", help="run only the configuration of this name (e.g. apf)")
    parser.add_argument("--body-model", choices=BODY_MODELS, default="interaction",
                        help="interaction: the model the tables in docs/video.md were made with")  # fmt: skip
    args = parser.parse_args()

    index = MocapIndex.load(args.data)
    _, test = held_out_pairs(index.pairs(label=list(BODY_LABELS), kind="skeleton"))
    chosen = [index.find(f) for f in args.take] if args.take else [a for a, _ in test]
    body = default_body_model(args.data, args.body_model)
    takes = []
    for a in chosen:
        folder = args.cache / f"{Path(a.file).name.split('.')[0]}-{args.seconds:g}s"
        if not (folder / "cameras.json").is_file():
            render_multiview(a.path, folder, views=3, seconds=args.seconds, fps=FPS)
        truth = read_listed_motion(a.path).resample(FPS)
        takes.append((a.file, folder, truth))

    rows = []
    for cfg in configs(args.sweep):
        if args.only and cfg["name"] != args.only:
            continue
        errs, fps, fps_cpu = [], [], []
        for _file, folder, truth in takes:
            for seed in range(args.seeds):
                mv = open_video(folder, views=cfg["views"])
                apf = AnnealedParticleFilter(
                    body,
                    mv.cameras,
                    cfg["particles"],
                    cfg["layers"],
                    fps=mv.fps,
                    seed=seed,
                    refine=cfg.get("refine", 30),
                )
                result = track_features(mv.features(seed), apf)
                motion = body.motion(result.states, result.fps)
                errs.append(tracking_errors(motion, truth)["mpjpe_mm"])
                fps.append(len(result.states) / result.seconds)
                fps_cpu.append(len(result.states) / result.cpu_seconds)
        rows.append(
            {
                **cfg,
                "takes": [t[0] for t in takes],
                "mpjpe_mm": round(float(np.mean(errs)), 1),
                "mpjpe_runs": errs,
                "fps": round(float(np.mean(fps)), 2),
                "fps_cpu": round(float(np.mean(fps_cpu)), 2),
                "evaluations_per_frame": cfg["particles"] * cfg["layers"],
            }
        )
    if args.json:
        print(json.dumps({"rows": rows, "cpus": os.cpu_count(), "load": os.getloadavg()}))
        return
    table = Table(title=f"Tracking {', '.join(t[0] for t in takes)} ({args.seconds:g} s, 320x240)")
    for col in (
        "tracker",
        "views",
        "particles",
        "layers",
        "MPJPE mm",
        "runs",
        "frames/s",
        "per CPU s",
    ):
        table.add_column(col, justify="left" if col == "tracker" else "right")
    for r in rows:
        table.add_row(
            r["name"],
            str(r["views"]),
            str(r["particles"]),
            str(r["layers"]),
            f"{r['mpjpe_mm']:.1f}",
            " ".join(f"{e:.0f}" for e in r["mpjpe_runs"]),
            f"{r['fps']:.2f}",
            f"{r['fps_cpu']:.2f}",
        )
    Console().print(table)
    named = {r["name"]: r for r in rows}
    apf, pf = named.get("apf"), next((r for n, r in named.items() if n.startswith("pf")), None)
    if apf and pf:  # the paper's peer: a plain particle filter of as many evaluations
        Console().print(
            f"APF against {pf['name']}: MPJPE {pf['mpjpe_mm'] / apf['mpjpe_mm']:.2f}x lower, "
            f"frames/s {apf['fps'] / pf['fps']:.2f}x"
        )
    Console().print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs")


if __name__ == "__main__":
    main()
