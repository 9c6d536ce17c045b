"""The held-out-kind tracking check: a take of a kind of motion the body model never saw.

For each kind (an INDEX.csv label of skeleton takes), the body model is learnt from every
skeleton take of the collection but that label's (``collection_body_model(leave_out=...)``,
the takes of other skeletons retargeted onto the template), and from the interaction
takes alone as before (``training_body_model``: it never saw any kind but handshakes and
pulls). The first take of the kind (INDEX.csv order) is rendered (``video render``: 3
cameras at 320x240, person A alone, ``--seconds`` from ``--start`` at 30 fps) and tracked
(annealed particle filter, 200 particles x 10 layers) with each body model; MPJPE (mm,
19 body points, and the 12 limb joints: shoulders ... ankles) against the capture, frames
tracked per second of wall time. ``floor``: the body model fitted to the true body points
of every 3rd frame (``triangulation.fit_state``, within its limits, no images); a take shorter than
``--start`` plus ``--seconds`` starts earlier: what the
model can reach at best. Takes of other skeletons place their trunk points (pelvis, spine,
chest, neck) elsewhere than the template does, which puts the 19-point floor far above the
limbs'.

Kinds: ``--kinds salsa,bend`` or, by default, chosen from INDEX.csv at run time: per
category of skeleton takes, the label with the most takes (ties: the first listed).

    python3 benchmarks/held_out_kind.py [--data DIR] [--kinds A,B] [--seconds 3] [--start 1]
        [--seeds 1] [--first-seed 0] [--models interaction,collection] [--guide none]
        [--body-size template] [--json]

``--models triangulate`` (alone or beside the body models; by default where MediaPipe is
installed) adds ``track --method triangulate``'s row: no body model, MediaPipe's landmarks triangulated (frames/s with
MediaPipe's time; no floor).

``--guide mediapipe``: MediaPipe's landmarks in every view guide the filter, as ``track
--guide mediapipe`` does (``track_video(..., guide=True)``); ``guide_seconds`` (MediaPipe's
time, not in frames/s) and ``seen`` (share of views and frames with landmarks) are reported.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from collections import Counter
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from markovmotion.data import MocapIndex
from markovmotion.data.index import read_listed_motion
from markovmotion.features.body_points import BODY_POINTS, body_points
from markovmotion.video.annealed_particle_filter import track_video
from markovmotion.video.monocular import mediapipe_installed
from markovmotion.video.multiview import (
    collection_body_model,
    points_errors,
    render_multiview,
    tracking_errors,
    training_body_model,
)
from markovmotion.video.triangulation import GUIDE_POINTS, fit_state, track_triangulated_video

FPS = 30.0


def default_kinds(index: MocapIndex) -> list[str]:
    """Per category of skeleton takes, its label with the most takes."""
    entries = index.query(kind="skeleton")
    counts = Counter(e.label for e in entries)
    best: dict[str, str] = {}
    for e in entries:
        if e.category not in best or counts[e.label] > counts[best[e.category]]:
            best[e.category] = e.label
    return list(best.values())


LIMBS = [BODY_POINTS.index(p) for p in GUIDE_POINTS]


def rendered(index: MocapIndex, kind: str, seconds: float, start: float, cache: Path):
    """``(take, folder, truth)``: the first skeleton take labelled ``kind``, rendered to 3
    cameras from ``start`` for ``seconds`` (into ``cache``, once; a take too short starts
    earlier) and its capture at the rendered rate from the same frame."""
    takes = index.query(label=kind, kind="skeleton")
    if not takes:
        raise SystemExit(f"no skeleton take labelled {kind!r} in {index.root}")
    take = takes[0]
    start = min(start, max(0.0, take.frames / take.fps - 0.1 - seconds))
    folder = cache / f"{take.name}-{start:g}-{seconds:g}s"
    if not (folder / "cameras.json").is_file():
        render_multiview(take.path, folder, views=3, seconds=seconds, fps=FPS, start=start)
    truth = read_listed_motion(take.path).resample(FPS).trim(int(round(start * FPS)))
    return take, folder, truth


def floor(body, truth: np.ndarray) -> np.ndarray:
    """(F, 19) distances (mm) of the body model fitted to true body points (F, 19, 3), each
    frame from the last one's state (the first: the best of 8 headings)."""
    x, out = body.standing(truth[0, 0]), []
    for t in truth:
        tries = []
        for yaw in np.linspace(-np.pi, np.pi, 8, endpoint=False) if not out else [x[3]]:
            x0 = x.copy()
            x0[:3], x0[3] = t[0], yaw
            f = fit_state(body, t, x0)
            tries.append((np.linalg.norm(body.joint_positions(f)[0] - t, axis=-1), f))
        err, x = min(tries, key=lambda e: e[0].mean())
        out.append(err)
    return np.array(out)


def triangulated_row(kind: str, take, folder: Path, truth) -> dict:
    """The row of ``--method triangulate`` (no body model: MediaPipe in the 3 views,
    triangulated, glitches out, smoothed by the width the left-out cameras choose)."""
    t0 = time.perf_counter()
    tr, s = track_triangulated_video(folder)
    seconds = time.perf_counter() - t0
    err = points_errors(tr.points, tr.fps, truth)
    mpjpe = err["mpjpe_mm"]
    return {
        "kind": kind,
        "take": take.file,
        "body_model": "none (triangulate)",
        "guide": "-",
        "left_right": "views",
        "body_size": "-",
        "mpjpe_mm": mpjpe,
        "mpjpe_runs": [mpjpe],
        "limbs_mm": round(float(np.mean([err["per_joint_mm"][p] for p in GUIDE_POINTS])), 1),
        "floor_mm": None,
        "floor_limbs_mm": None,
        "fps": round(len(tr.points) / seconds, 2),  # with MediaPipe's time
        "smoothing_s": s["smoothing_s"],
        "guide_seconds": 0.0,
        "guide_seen": None,
        "build_seconds": None,
        "load": round(os.getloadavg()[0], 1),
    }


#: The 11 kinds the docs' tables are measured on (one per category of the collection's
#: skeleton takes when they were made).
ELEVEN_KINDS = "indian_dance,salsa,martial_arts,run,punch,normal,active,swordplay,bend,jump,wash"


def rendered_kinds(args: argparse.Namespace):
    """``(kind, folder, truth)`` of each of ``args.kinds`` from the index at ``args.data``
    (:func:`kind_arguments`), rendered once into ``args.cache`` (:func:`rendered`)."""
    index = MocapIndex.load(args.data)
    for kind in args.kinds.split(","):
        _, folder, truth = rendered(index, kind, args.seconds, args.start, args.cache)
        yield kind, folder, truth


def kind_arguments(description: str, kinds: str | None = None) -> argparse.ArgumentParser:
    """A parser with the options of the rendered kinds (:func:`rendered`): --data, --kinds
    (default ``kinds``, else :func:`default_kinds`), --seconds, --start, --cache."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--data", type=Path, default=None, help="folder with INDEX.csv")
    parser.add_argument("--kinds", default=kinds,
                        help="labels, comma-separated (default: " + (kinds or "per category") + ")")  # fmt: skip
    parser.add_argument("--seconds", type=float, default=3.0, help="seconds of each take (default 3)")  # fmt: skip
    parser.add_argument("--start", type=float, default=1.0, help="seconds into the take (default 1)")  # fmt: skip
    parser.add_argument("--cache", type=Path, default=Path(tempfile.gettempdir()) / "mm-kinds",
                        help="folder the rendered kinds are kept in (default: TMP/mm-kinds)")  # fmt: skip
    return parser


def main() -> None:
    parser = kind_arguments(__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=1, help="runs per body model")
    parser.add_argument("--models", default=None,
                        help="body models to run, comma-separated (interaction, collection; triangulate: no body model; "
                        "default: all three, triangulate only where MediaPipe is installed)")  # fmt: skip
    parser.add_argument("--first-seed", type=int, default=0, help="seeds from this one")
    parser.add_argument("--guide", choices=("none", "mediapipe"), default="none",
                        help="what guides the particle filter besides the images")  # fmt: skip
    parser.add_argument("--left-right", choices=("views", "continuity", "both", "mediapipe"),
                        default="views", help="with the guide: MediaPipe's left and right made "
                        "consistent (triangulation.LEFT_RIGHT)")  # fmt: skip
    parser.add_argument("--body-size", choices=("template", "views"), default="template",
                        help="views: the segments scaled to the person's, measured from the "
                        "guide's triangulated landmarks (track --body-size views)")  # fmt: skip
    parser.add_argument("--json", action="store_true", help="print the results as JSON")
    args = parser.parse_args()
    if args.models is None:
        args.models = ("triangulate," if mediapipe_installed() else "") + "interaction,collection"

    index = MocapIndex.load(args.data)
    kinds = args.kinds.split(",") if args.kinds else default_kinds(index)
    old = training_body_model(args.data)
    rows = []
    for kind in kinds:
        t0 = time.perf_counter()
        new = (
            collection_body_model(args.data, leave_out=(kind,))
            if "collection" in args.models.split(",")
            else None
        )
        build = time.perf_counter() - t0
        take, folder, truth = rendered(index, kind, args.seconds, args.start, args.cache)
        for name, body in (("interaction (old)", old), ("collection without it", new)):
            if name.split()[0] not in args.models.split(","):
                continue
            errs, limbs, fps, guide_s, seen = [], [], [], [], []
            low = floor(body, body_points(truth)[: int(round(args.seconds * FPS)) : 3])
            for seed in range(args.first_seed, args.first_seed + args.seeds):
                result = track_video(
                    folder, body, seed=seed, guide=args.guide == "mediapipe",
                    left_right=args.left_right, size_from_views=args.body_size == "views",
                )  # fmt: skip
                motion = (result.body or body).motion(result.states, result.fps)
                e = tracking_errors(motion, truth)
                errs.append(e["mpjpe_mm"])
                limbs.append(np.mean([e["per_joint_mm"][p] for p in GUIDE_POINTS]))
                fps.append(len(result.states) / result.seconds)
                guide_s.append(result.guide_seconds)
                seen.append(result.guide_seen if result.guide_seen is not None else np.nan)
            rows.append(
                {
                    "kind": kind,
                    "take": take.file,
                    "body_model": name,
                    "guide": args.guide,
                    "left_right": args.left_right,
                    "body_size": args.body_size,
                    "mpjpe_mm": round(float(np.mean(errs)), 1),
                    "mpjpe_runs": errs,
                    "limbs_mm": round(float(np.mean(limbs)), 1),
                    "floor_mm": round(float(low.mean()), 1),
                    "floor_limbs_mm": round(float(low[:, LIMBS].mean()), 1),
                    "fps": round(float(np.mean(fps)), 2),
                    "guide_seconds": round(float(np.mean(guide_s)), 1),
                    "guide_seen": round(float(np.mean(seen)), 3) if args.guide != "none" else None,
                    "build_seconds": round(build, 1) if name != "interaction (old)" else None,
                    "load": round(os.getloadavg()[0], 1),
                }
            )
            if not args.json:  # as each run ends (the table comes at the end)
                print(json.dumps(rows[-1]), flush=True)
        if "triangulate" in args.models.split(","):
            rows.append(triangulated_row(kind, take, folder, truth))
            if not args.json:  # as each run ends (the table comes at the end)
                print(json.dumps(rows[-1]), flush=True)
    if args.json:
        print(json.dumps({"rows": rows, "cpus": os.cpu_count(), "seconds": args.seconds}))
        return
    table = Table(
        title=f"Held-out kinds ({args.seconds:g} s from {args.start:g} s, 3 views, "
        f"guide {args.guide})"
    )
    cols = ("kind", "take", "body model", "MPJPE mm", "runs", "limbs mm", "floor", "floor limbs",
            "frames/s", "guide s", "seen", "smoothing", "load")  # fmt: skip
    for col in cols:
        table.add_column(col)
    for r in rows:
        table.add_row(
            r["kind"], Path(r["take"]).name, r["body_model"], f"{r['mpjpe_mm']:.1f}",
            " ".join(f"{e:.0f}" for e in r["mpjpe_runs"]), f"{r['limbs_mm']:.1f}",
            _mm(r["floor_mm"]), _mm(r["floor_limbs_mm"]), f"{r['fps']:.2f}",
            f"{r['guide_seconds']:.1f}", "-" if r["guide_seen"] is None else f"{r['guide_seen']:.2f}",
            f"{1000 * r['smoothing_s']:.0f} ms" if "smoothing_s" in r else "-", str(r["load"]),
        )  # fmt: skip
    Console(width=max(160, Console().width)).print(table)


def _mm(value: float | None) -> str:
    return "-" if value is None else f"{value:.1f}"


if __name__ == "__main__":
    main()
