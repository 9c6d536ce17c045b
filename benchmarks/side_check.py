"""How often the front/back check of ``track --sides`` is wrong, and how often it is right.

For each kind (as ``held_out_kind.py``: the first take of the label, rendered to 3 cameras at
320x240, cached), MediaPipe Pose runs over every camera once; the check
(:class:`~markovmotion.video.sides.SideCheck`) is then asked about the *true* body points of
every frame (``false alarms``: frames it calls flipped) and about the true body turned round
(``caught``: turned by pi about the vertical through the pelvis, frames it calls flipped),
reading MediaPipe's own left and right per camera (``mediapipe``) or the labels the views
agree on (``views``: :func:`~markovmotion.video.triangulation.consistent_views`, what
``track --sides`` reads). A camera behind the person, whose MediaPipe sees the body mirrored,
raises false alarms with its own labels.

    python3 benchmarks/side_check.py [--data DIR] [--kinds pull,run] [--seconds 3] [--start 1]
"""

from __future__ import annotations

import numpy as np
from held_out_kind import default_kinds, kind_arguments, rendered
from rich.console import Console
from rich.table import Table
from scipy.spatial.transform import Rotation

from markovmotion.data import MocapIndex
from markovmotion.features.body_points import body_points
from markovmotion.video.cameras import camera_videos, load_cameras
from markovmotion.video.sides import SideCheck
from markovmotion.video.triangulation import ViewLandmarks, consistent_views


def turned_round(points: np.ndarray) -> np.ndarray:
    """Body points (F, P, 3) turned by pi about the vertical through each frame's pelvis."""
    pelvis = points[:, :1]
    return (
        Rotation.from_rotvec([0.0, np.pi, 0.0])
        .apply((points - pelvis).reshape(-1, 3))
        .reshape(points.shape)
        + pelvis
    )


def main() -> None:
    parser = kind_arguments(
        "How often track --sides's front/back check is wrong (false alarms on the true poses) and right (the true poses turned round, caught), on rendered held-out kinds, with MediaPipe's own left and right or the views' agreed ones. About 2 min (MediaPipe over 3 views per kind); renders are cached in --cache."
    )
    args = parser.parse_args()

    index = MocapIndex.load(args.data)
    kinds = args.kinds.split(",") if args.kinds else default_kinds(index)
    table = Table(title="front/back check on the true poses: false alarms / turned round caught")
    for col in ("kind", "frames", "mediapipe's labels", "the views' agreed labels"):
        table.add_column(col)
    totals = np.zeros((2, 2), dtype=int)
    frames_all = 0
    for kind in kinds:
        _, folder, truth = rendered(index, kind, args.seconds, args.start, args.cache)
        cams, _ = load_cameras(folder)
        views = ViewLandmarks.from_videos(camera_videos(folder, cams), cams)
        n = min(views.pixels.shape[1], truth.n_frames)
        points = body_points(truth)[:n]
        turned = turned_round(points)
        cells = [kind, str(n)]
        for k, lm in enumerate((views, consistent_views(views, "views"))):
            check = SideCheck.from_landmarks(lm)
            false = sum(check.flipped(points[f], f) for f in range(n))
            caught = sum(check.flipped(turned[f], f) for f in range(n))
            totals[k] += (false, caught)
            cells.append(f"{false} / {caught}")
        frames_all += n
        table.add_row(*cells)
    table.add_row("all", str(frames_all), *(f"{a} / {b}" for a, b in totals))
    Console().print(table)


if __name__ == "__main__":
    main()
