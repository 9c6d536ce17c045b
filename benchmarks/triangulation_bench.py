"""``track --method triangulate`` against the textbook triangulation, on the same landmarks.

MediaPipe runs once per view (its time counts for neither); then, from the same 2-D landmarks:

* ``ours``: :mod:`markovmotion.video.triangulation` as ``track --method triangulate`` runs it
  (left and right agreed across the views, MSAC over the views per landmark, glitches out,
  every point filled, smoothed over time by the width the left-out cameras choose);
* ``dlt``: the textbook peer (as Pose2Sim triangulates, without its camera-excluding loop):
  per frame and landmark, the linear (DLT) triangulation over every view whose MediaPipe
  visibility is at least 0.5, each view's two equations weighted by its visibility, from
  MediaPipe's own landmarks as found (no left-right agreement, no smoothing).

Written here, not taken from a library: aniposelib's triangulation needs JAX and
opencv-contrib, Pose2Sim's a project folder; the DLT is a dozen lines of NumPy.

On the 11 rendered held-out kinds of ``held_out_kind.py`` (3 views, 320x240, the same renders,
cached) against the capture, and on the real 4-view video against its reference. Prints
MPJPE (mm, 19 body points) and each method's time per frame after MediaPipe, and the ratios.

    python3 benchmarks/triangulation_bench.py [--kinds salsa,bend] [--no-real] [--json]
        [--seconds 3] [--start 1] [--cache DIR] [--data DIR]
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
from held_out_kind import ELEVEN_KINDS, kind_arguments, rendered_kinds

from markovmotion.data.index import data_root
from markovmotion.video.cameras import camera_videos, load_cameras
from markovmotion.video.landmarks import MIN_VISIBILITY
from markovmotion.video.monocular import reference_report
from markovmotion.video.multiview import points_errors
from markovmotion.video.triangulation import (
    choose_smoothing,
    landmarks_to_body_points,
    person_views,
    triangulate_views,
)


def dlt(cameras, pixels: np.ndarray, visibility: np.ndarray) -> np.ndarray:
    """(F, 33, 3) world points by visibility-weighted DLT over the views seeing each landmark
    (``pixels`` (V, F, 33, 2), ``visibility`` (V, F, 33)); NaN where fewer than two do."""
    proj = np.stack([c.K @ np.c_[c.R, c.t] for c in cameras])  # (V, 3, 4)
    u, v = pixels[..., 0:1], pixels[..., 1:2]  # (V, F, L, 1)
    rows_u = u * proj[:, None, None, 2] - proj[:, None, None, 0]  # (V, F, L, 4)
    rows_v = v * proj[:, None, None, 2] - proj[:, None, None, 1]
    w = np.where(visibility >= MIN_VISIBILITY, visibility, 0.0)[..., None]
    w = np.where(np.isfinite(pixels).all(axis=-1, keepdims=True), w, 0.0)
    a = np.concatenate([np.nan_to_num(rows_u) * w, np.nan_to_num(rows_v) * w], axis=0)
    a = np.moveaxis(a, 0, -2)  # (F, L, 2V, 4)
    _, _, vh = np.linalg.svd(a)
    x = vh[..., -1, :]
    out = x[..., :3] / x[..., 3:]
    seen = (w[..., 0] > 0).sum(axis=0)
    return np.where((seen >= 2)[..., None], out, np.nan)


def ours(agreed, fps: float) -> np.ndarray:
    """``track --method triangulate``'s steps after MediaPipe (``track_triangulated_video``)."""
    tri, _ = triangulate_views(agreed).filled(agreed)
    tri, _ = tri.despiked(fps)
    return tri.smoothed(choose_smoothing(agreed, fps).seconds, fps).points


def run(folder: Path, score) -> dict:
    """Both methods on one multi-view video; ``score(points (F, 19, 3), fps)`` gives a dict of
    errors (mm); each method's ``placed``: its share of body-point frames placed (the DLT
    leaves a point no two views see with visibility 0.5 unplaced, and is scored without it)."""
    cams, doc = load_cameras(folder)
    fps = float(doc["fps"])
    views = person_views(camera_videos(folder, cams), cams, fps)
    t0 = time.perf_counter()
    mine = ours(views.agreed, fps)
    t1 = time.perf_counter()
    found = views.found
    peer = landmarks_to_body_points(dlt(found.cameras, found.pixels, found.visibility))
    t2 = time.perf_counter()
    frames = len(mine)
    out: dict = {"frames": frames}
    for name, points, seconds in (("ours", mine, t1 - t0), ("dlt", peer, t2 - t1)):
        for key, value in score(points, fps).items():
            out[f"{name}_{key}"] = round(value, 1)
        out[f"{name}_placed"] = round(float(np.isfinite(points).all(axis=-1).mean()), 3)
        out[f"{name}_ms_per_frame"] = round(1000 * seconds / frames, 3)
    return out


#: Frames of the real video where its reference is itself wrong (docs/video.md: its left
#: side 10-60 cm off the man in every view): a tracker that follows him is far from it there.
REFERENCE_WRONG = slice(41, 75)


def main() -> None:
    parser = kind_arguments(__doc__.splitlines()[0], ELEVEN_KINDS)
    parser.add_argument("--no-real", action="store_true", help="leave out the real video")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    rows = []
    for kind, folder, truth in rendered_kinds(args):  # the renders of held_out_kind.py

        def score(points, fps, truth=truth):
            return {"mm": points_errors(points, fps, truth)["mpjpe_mm"]}

        rows.append({"video": kind, **run(folder, score)})
        if not args.json:
            print(json.dumps(rows[-1]), flush=True)
    if not args.no_real:
        real = data_root().parent / "video" / "pose2sim_balancing"
        ref = real / "reference_mediapipe_triangulated_mm.csv"

        def against_reference(points, fps):
            outside = points.copy()
            outside[REFERENCE_WRONG] = np.nan
            return {
                "mm": reference_report(points, ref, fps)[0]["mean_mm"],
                "mm_outside_41_74": reference_report(outside, ref, fps)[0]["mean_mm"],
            }

        rows.append({"video": "real 4-view (reference)", **run(real, against_reference)})
        if not args.json:
            print(json.dumps(rows[-1]), flush=True)
    rendered_rows = [r for r in rows if r["video"] != "real 4-view (reference)"]
    summary = {
        "rows": rows,
        "rendered_ours_mm": round(float(np.mean([r["ours_mm"] for r in rendered_rows])), 1)
        if rendered_rows
        else None,
        "rendered_dlt_mm": round(float(np.mean([r["dlt_mm"] for r in rendered_rows])), 1)
        if rendered_rows
        else None,
    }
    if args.json:
        print(json.dumps(summary))
        return
    for r in rows:
        outside = (
            f"; outside frames 41-74 ours {r['ours_mm_outside_41_74']}, DLT "
            f"{r['dlt_mm_outside_41_74']}"
            if "ours_mm_outside_41_74" in r
            else ""
        )
        print(
            f"{r['video']:>26}: ours {r['ours_mm']:6.1f} mm ({r['ours_placed']:.0%} placed), "
            f"DLT {r['dlt_mm']:6.1f} mm ({r['dlt_placed']:.0%} placed){outside}; after "
            f"MediaPipe ours {r['ours_ms_per_frame']:.2f} ms a frame, DLT "
            f"{r['dlt_ms_per_frame']:.3f} (ours {r['ours_ms_per_frame'] / max(r['dlt_ms_per_frame'], 1e-6):.0f}x "
            "the time)"
        )
    if rendered_rows:
        print(
            f"held-out kinds: ours {summary['rendered_ours_mm']} mm, DLT "
            f"{summary['rendered_dlt_mm']} mm over the points it placed"
        )


if __name__ == "__main__":
    main()
