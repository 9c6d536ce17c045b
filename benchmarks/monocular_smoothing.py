"""``MONOCULAR_SMOOTHING_S`` of ``track --method monocular``, chosen by leaving one kind of
motion out.

For each kind (as ``held_out_kind.py``: the first take of the label rendered to 3 cameras at
320x240, 30 fps, cached), MediaPipe tracks each camera alone (``track_monocular``, not
smoothed), the track is finished with each smoothing sigma (``finished_points``: smoothed,
then constant bones) and compared with the capture over the 12 limb joints after a rigid
alignment per frame (mm; the aim's measure). Per kind, the sigma best on the *other* kinds
is taken and its error on the kind left out reported: the cross-validated error beside
each fixed sigma's. One camera has no view to leave out, so the width cannot be chosen on
the video itself, as ``--method triangulate`` does.

    python3 benchmarks/monocular_smoothing.py [--data DIR] [--kinds A,B] [--json]
"""

from __future__ import annotations

import json

import numpy as np
from held_out_kind import ELEVEN_KINDS, kind_arguments, rendered_kinds
from rich.console import Console
from rich.table import Table

from markovmotion.features.body_points import BODY_POINTS, body_points
from markovmotion.video.cameras import camera_videos, load_cameras
from markovmotion.video.monocular import (
    MONOCULAR_SMOOTHING_S,
    REFERENCE_JOINTS,
    finished_points,
    kabsch_align,
    track_monocular,
)
from markovmotion.video.triangulation import SMOOTHING_S


def aligned_error(points: np.ndarray, truth: np.ndarray) -> float:
    """Mean distance (mm) of the 12 limb joints after each frame's rigid alignment."""
    idx = [BODY_POINTS.index(j) for j in REFERENCE_JOINTS]
    n = min(len(points), len(truth))
    p, t = points[:n, idx], truth[:n, idx]
    ok = np.isfinite(p).all(axis=(1, 2))
    return float(np.linalg.norm(kabsch_align(p[ok], t[ok]) - t[ok], axis=-1).mean())


def main() -> None:
    parser = kind_arguments(
        "Choose MONOCULAR_SMOOTHING_S by leaving one kind of motion out: the rigidly aligned "
        "limb error (mm) of each camera's monocular track per smoothing sigma, and the "
        "cross-validated choice. About 2 min; renders are cached in --cache.",
        ELEVEN_KINDS,
    )
    parser.add_argument("--json", action="store_true", help="print the results as JSON")
    args = parser.parse_args()

    kinds = args.kinds.split(",")
    rows, names = [], []  # one per kind and camera: the error per sigma
    for kind, folder, truth in rendered_kinds(args):
        cams, doc = load_cameras(folder)
        fps, true = float(doc["fps"]), body_points(truth)
        for cam, video in zip(cams, camera_videos(folder, cams), strict=True):
            tr = track_monocular(video, cam, fps, constant_bones=False)
            raw = tr.points
            rows.append([aligned_error(finished_points(raw, fps, w), true) for w in SMOOTHING_S])
            names.append((kind, cam.name))
    errors = np.array(rows)
    kind_of = np.array([k for k, _ in names])
    folds = {}
    for kind in kinds:
        best = int(np.argmin(errors[kind_of != kind].mean(axis=0)))
        folds[kind] = {"chosen_s": SMOOTHING_S[best], "mm": errors[kind_of == kind, best].mean(),
                       "unsmoothed_mm": errors[kind_of == kind, 0].mean()}  # fmt: skip
    summary = {
        "sigmas_s": list(SMOOTHING_S),
        "mean_mm": errors.mean(axis=0).round(2).tolist(),
        "folds": folds,
        "cross_validated_mm": float(np.mean([f["mm"] for f in folds.values()])),
        "unsmoothed_mm": float(errors[:, 0].mean()),
        "now_s": MONOCULAR_SMOOTHING_S,
    }
    if args.json:
        print(json.dumps(summary))
        return
    table = Table(title="Monocular, limb joints rigidly aligned (mm) by smoothing sigma")
    for col in ("kind", *(f"{1000 * w:.0f} ms" for w in SMOOTHING_S), "chosen on the others"):
        table.add_column(col)
    for kind in kinds:
        mine = errors[kind_of == kind].mean(axis=0)
        f = folds[kind]
        table.add_row(kind, *(f"{e:.1f}" for e in mine),
                      f"{f['mm']:.1f} ({1000 * f['chosen_s']:.0f} ms)")  # fmt: skip
    table.add_row("mean", *(f"{e:.1f}" for e in errors.mean(axis=0)),
                  f"{summary['cross_validated_mm']:.1f}")  # fmt: skip
    Console(width=160).print(table)
    print(f"now MONOCULAR_SMOOTHING_S = {1000 * MONOCULAR_SMOOTHING_S:.1f} ms")


if __name__ == "__main__":
    main()
