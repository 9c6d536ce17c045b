"""Is the real video's reference right? It and MediaPipe triangulated here, drawn over every view.

    python3 benchmarks/reference_overlay.py [--video DIR] [--frames 50 58 81] [--out FILE]

The reference of ``pose2sim_balancing`` (``reference_mediapipe_triangulated_mm.csv``) is
MediaPipe triangulated from the full-resolution views; ``track --method triangulate`` does the
same from the 272x480 videos. Prints, per frame, the mean distance between the two over the 12
joints (after no alignment), and draws both (reference red, ours green; left limbs thick) over
the four views at ``--frames`` (one row each) into ``--out`` (default ``reference_check.jpg``
here; docs/video.md's figure is ``--out docs/img/reference_check.jpg`` with the default
frames): where they disagree, the picture says which follows the man.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import cv2
import numpy as np

from markovmotion.data.index import data_root
from markovmotion.features.body_points import BODY_POINTS
from markovmotion.io.files import atomic_write
from markovmotion.video.cameras import camera_videos, load_cameras
from markovmotion.video.monocular import REFERENCE_JOINTS, read_reference
from markovmotion.video.render import read_frames
from markovmotion.video.triangulation import track_triangulated_video

#: Lines between the 12 joints (indices into REFERENCE_JOINTS, looked up by name).
BONES = [
    (f"{s}_{a}", f"{s}_{b}")
    for s in ("left", "right")
    for a, b in (("shoulder", "elbow"), ("elbow", "wrist"), ("hip", "knee"), ("knee", "ankle"))
] + [
    ("left_shoulder", "right_shoulder"),
    ("left_hip", "right_hip"),
    ("left_shoulder", "left_hip"),
    ("right_shoulder", "right_hip"),
]


def draw(img: np.ndarray, xy: np.ndarray, colour: tuple[int, int, int]) -> None:
    """The 12 joints' lines (left limbs thicker) at pixels ``xy`` (12, 2) on ``img`` (RGB)."""
    at = {j: tuple(int(v) for v in xy[i]) for i, j in enumerate(REFERENCE_JOINTS)}
    for a, b in BONES:
        if a in at and b in at and np.isfinite(xy).all():
            cv2.line(img, at[a], at[b], colour, 3 if a.startswith("left") else 1, cv2.LINE_AA)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--video", type=Path, default=data_root().parent / "video" / "pose2sim_balancing"
    )
    ap.add_argument("--frames", type=int, nargs="+", default=[50, 58, 81])
    ap.add_argument("--out", type=Path, default=Path("reference_check.jpg"))
    args = ap.parse_args()
    frames, ref = read_reference(args.video / "reference_mediapipe_triangulated_mm.csv")
    track, _ = track_triangulated_video(args.video)
    ours = track.points[:, [BODY_POINTS.index(j) for j in REFERENCE_JOINTS]]
    keep = frames < len(ours)
    gap = np.linalg.norm(ours[frames[keep]] - ref[keep], axis=-1).mean(axis=1)
    print("frame  mean distance reference - ours (mm)")
    for f, g in zip(frames[keep], gap, strict=True):
        print(f"{f:5d}  {g:7.1f}{'  <- over 100 mm' if g > 100 else ''}")
    cams, _ = load_cameras(args.video / "cameras.json")
    videos = camera_videos(args.video / "cameras.json", cams)
    wanted = sorted(set(args.frames))
    rows = {f: [] for f in wanted}
    for cam, video in zip(cams, videos, strict=True):
        for i, rgb in enumerate(read_frames(video)):
            if i in rows:
                img = np.array(rgb)
                row = np.flatnonzero(frames == i)
                if len(row):
                    draw(img, cam.project(ref[row[0]])[0], (230, 30, 30))
                draw(img, cam.project(ours[i])[0], (40, 220, 40))
                cv2.putText(img, f"frame {i}", (6, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.5,
                            (255, 255, 255), 1, cv2.LINE_AA)  # fmt: skip
                rows[i].append(img)
            if i >= wanted[-1]:
                break
    picture = np.vstack([np.hstack(rows[f]) for f in wanted])
    args.out.parent.mkdir(parents=True, exist_ok=True)
    _, data = cv2.imencode(".jpg", cv2.cvtColor(picture, cv2.COLOR_RGB2BGR),
                           [cv2.IMWRITE_JPEG_QUALITY, 80])  # fmt: skip
    with atomic_write(args.out, "wb") as fh:
        fh.write(data.tobytes())
    print(f"wrote {args.out} (reference red, ours green; left limbs thick)")


if __name__ == "__main__":
    main()
