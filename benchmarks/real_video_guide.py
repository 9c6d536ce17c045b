"""The real 4-view video (issue 24): the annealed particle filter with and without MediaPipe's
guide, with the plates and with the learnt background, two seeds; and MediaPipe triangulated
(with and without the smoothing the left-out cameras choose).

    python3 benchmarks/real_video_guide.py [--video DIR] [--seeds 0 1 (none: no filter)] [--json]
        [--body-model collection|interaction] [--backgrounds plates learnt] [--no-triangulate]

Prints one JSON line per run (``--json``) or a Markdown table: mean error over the 12 joints
against the triangulated reference, the same outside the frames its README calls wrong (45-70),
per joint, frames/s of the tracking (wall) and with MediaPipe's time. State the load average
(``uptime``) beside the speeds: the machine is shared.
"""

from __future__ import annotations

import argparse
import json
import shutil
import tempfile
from pathlib import Path

import numpy as np

from markovmotion.data.index import data_root
from markovmotion.features.body_points import BODY_POINTS, body_points
from markovmotion.video.monocular import REFERENCE_JOINTS, read_reference, reference_errors
from markovmotion.video.multiview import BODY_MODELS, default_body_model, track_take
from markovmotion.video.triangulation import track_triangulated_video

#: Frames the reference's README says are wrong for one leg.
WRONG = (45, 70)


def outside_wrong(points: np.ndarray, reference: Path) -> float:
    """Mean error (mm) over the 12 joints in the frames outside :data:`WRONG`."""
    frames, ref = read_reference(reference)
    keep = (frames < len(points)) & ((frames < WRONG[0]) | (frames > WRONG[1]))
    idx = [BODY_POINTS.index(j) for j in REFERENCE_JOINTS]
    return round(
        float(np.nanmean(np.linalg.norm(points[frames[keep]][:, idx] - ref[keep], axis=-1))), 1
    )


def without_plates(video: Path, into: Path) -> Path:
    """A copy of ``cameras.json`` without the ``background`` keys, beside links to the videos."""
    doc = json.loads((video / "cameras.json").read_text(encoding="utf-8"))
    for cam in doc["cameras"]:
        cam.pop("background", None)
        (into / cam["video"]).symlink_to((video / cam["video"]).resolve())
    (into / "cameras.json").write_text(json.dumps(doc), encoding="utf-8")
    return into / "cameras.json"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--video", type=Path, default=data_root().parent / "video" / "pose2sim_balancing"
    )
    ap.add_argument("--seeds", type=int, nargs="*", default=[0, 1], help="none: no particle filter")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--body-model", choices=BODY_MODELS, default="interaction")
    ap.add_argument("--backgrounds", nargs="+", choices=("plates", "learnt"),
                    default=["plates", "learnt"])  # fmt: skip
    ap.add_argument("--no-triangulate", action="store_true", help="skip MediaPipe triangulated")
    args = ap.parse_args()
    reference = args.video / "reference_mediapipe_triangulated_mm.csv"
    rows = []
    if not args.no_triangulate:
        for smooth, name in ((0.0, "triangulate, not smoothed"), (None, "triangulate")):
            tr, s = track_triangulated_video(args.video, reference=reference, smooth=smooth)
            rows.append({"method": name, "background": "-", "seed": "-",
                         "mean_mm": s["mean_mm"], "outside_45_70_mm": outside_wrong(tr.points, reference),
                         "aligned_mean_mm": s["aligned_mean_mm"], "smoothing_s": s["smoothing_s"],
                         "smoothing_left_out_px": s["smoothing_left_out_px"],
                         "per_joint_mm": s["per_joint_mm"], "fps": s["fps"], "fps_with_guide": s["fps"]})  # fmt: skip
            if args.json:
                print(json.dumps(rows[-1]), flush=True)
    body = default_body_model(None, args.body_model)
    tmp = Path(tempfile.mkdtemp(prefix="nobg"))
    try:
        plain = without_plates(args.video, tmp)
        for background, cams in (("plates", None), ("learnt", plain)):
            if background not in args.backgrounds:
                continue
            for seed in args.seeds:
                for guide in (False, True):
                    motion, _, s = track_take(
                        args.video, body, cams, seed=seed, learn_background=cams is not None,
                        guide=guide,
                    )  # fmt: skip
                    pts = body_points(motion)
                    err = reference_errors(pts, reference)
                    rows.append({
                        "method": "apf + guide" if guide else "apf", "background": background,
                        "seed": seed, "mean_mm": err["mean_mm"],
                        "outside_45_70_mm": outside_wrong(pts, reference),
                        "per_joint_mm": err["per_joint_mm"], "fps": s["fps"],
                        "fps_with_guide": s.get("fps_with_guide", s["fps"]),
                        "recoveries": s["recoveries"], "body_model": args.body_model,
                    })  # fmt: skip
                    if args.json:
                        print(json.dumps(rows[-1]), flush=True)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    if not args.json:
        print(
            "| method | background | seed | mean mm | outside 45-70 | frames/s | with MediaPipe |"
        )
        print("|---|---|---|---|---|---|---|")
        for r in rows:
            print(f"| {r['method']} | {r['background']} | {r['seed']} | {r['mean_mm']} | "
                  f"{r['outside_45_70_mm']} | {r['fps']} | {r['fps_with_guide']} |")  # fmt: skip
        print("\nper joint (mm), left / right")
        print(
            "| method | background | seed | shoulders | elbows | wrists | hips | knees | ankles |"
        )
        print("|---|---|---|---|---|---|---|---|---|")
        for r in rows:
            pj = r["per_joint_mm"]
            parts = [f"{pj['left_' + p]:.0f} / {pj['right_' + p]:.0f}"
                     for p in ("shoulder", "elbow", "wrist", "hip", "knee", "ankle")]  # fmt: skip
            print(
                f"| {r['method']} | {r['background']} | {r['seed']} | " + " | ".join(parts) + " |"
            )

        for r in rows:
            if r.get("smoothing_left_out_px"):
                print(f"\n{r['method']}: the left-out cameras' error (px) by the smoothing's sigma")
                print(", ".join(f"{k} {v}" for k, v in r["smoothing_left_out_px"].items()))


if __name__ == "__main__":
    main()
