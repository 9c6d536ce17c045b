"""``MIRROR_COST`` of :func:`~markovmotion.video.triangulation.views_sides`, chosen by leaving
one kind of motion out.

For each kind (as ``held_out_kind.py``: the first take of the label rendered to 3 cameras at
320x240, cached), MediaPipe Pose runs over every camera once; its landmarks are made to agree
across the views with each ``--costs`` value, triangulated (``triangulate_views``) and
compared with the capture over the 12 limb joints (mm, mean over the frames and joints
seen; the truth's own left and right are the oracle's row). Then, per kind, the cost with
the lowest mean error over the *other* kinds is taken and its error on the kind left out is
reported: the cross-validated error beside each fixed cost's.

    python3 benchmarks/mirror_cost.py [--data DIR] [--kinds A,B] [--costs 0,0.25,0.5,1,2,4]
"""

from __future__ import annotations

import numpy as np
from held_out_kind import ELEVEN_KINDS, LIMBS, kind_arguments, rendered_kinds
from rich.console import Console
from rich.table import Table

from markovmotion.features.body_points import body_points
from markovmotion.video.cameras import camera_videos, load_cameras
from markovmotion.video.triangulation import (
    MIRROR_COST,
    ViewLandmarks,
    landmarks_to_body_points,
    triangulate_views,
    views_sides,
)


def limb_error(views: ViewLandmarks, truth: np.ndarray) -> float:
    """Mean distance (mm) of the triangulated limb joints from the true ones (F, 19, 3)."""
    points = landmarks_to_body_points(triangulate_views(views).landmarks)[: len(truth)]
    err = np.linalg.norm(points[:, LIMBS] - truth[: len(points), LIMBS], axis=-1)
    return float(np.nanmean(err))


def main() -> None:
    parser = kind_arguments(
        "Choose MIRROR_COST (the cost of taking, of a left/right labelling of the views and its mirror, the one that swaps every view) by leaving one kind of motion out: triangulated limb-joint error (mm) per kind and cost, and the cross-validated choice. About 3 min; renders are cached in --cache.",
        ELEVEN_KINDS,
    )
    parser.add_argument("--costs", default="0,0.25,0.5,1,2,4", help="MIRROR_COST values")
    args = parser.parse_args()

    kinds = args.kinds.split(",")
    costs = [float(c) for c in args.costs.split(",")]
    errors = np.zeros((len(kinds), len(costs)))
    raw = np.zeros(len(kinds))
    for k, (_, folder, truth) in enumerate(rendered_kinds(args)):
        cams, _ = load_cameras(folder)
        views = ViewLandmarks.from_videos(camera_videos(folder, cams), cams)
        true = body_points(truth)
        raw[k] = limb_error(views, true)
        for c, cost in enumerate(costs):
            errors[k, c] = limb_error(views_sides(views, mirror_cost=cost)[0], true)
    table = Table(
        title="Triangulated limb joints (mm) by MIRROR_COST; 'chosen': the cost best on the "
        f"other kinds (now {MIRROR_COST:g})"
    )
    for col in ("kind", "MediaPipe's labels", *(f"{c:g}" for c in costs), "chosen (cost)"):
        table.add_column(col)
    chosen = []
    for k, kind in enumerate(kinds):
        others = np.delete(errors, k, axis=0).mean(axis=0)
        c = int(np.argmin(others))
        chosen.append(errors[k, c])
        table.add_row(
            kind,
            f"{raw[k]:.1f}",
            *(f"{e:.1f}" for e in errors[k]),
            f"{errors[k, c]:.1f} ({costs[c]:g})",
        )
    table.add_row(
        "mean",
        f"{raw.mean():.1f}",
        *(f"{e:.1f}" for e in errors.mean(axis=0)),
        f"{np.mean(chosen):.1f}",
    )
    Console().print(table)


if __name__ == "__main__":
    main()
