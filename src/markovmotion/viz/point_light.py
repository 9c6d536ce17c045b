"""Point-light displays (Johansson, 1973): only a few points of each body, no bones.

The dual-HMM paper's observers (§4.2) watched two people as the motion of
"certain points on the body": :func:`point_lights` turns the people of one
take into one marker cloud of :data:`~markovmotion.features.body_points.MARKER_POINTS`
per person (head, shoulders, elbows, wrists, hips, knees, ankles), found by
joint names on any skeleton, at one frame rate and over the frames all of
them have. The cloud is a :class:`~markovmotion.core.markers.Markers`, so
:func:`markovmotion.viz.render` draws it as points (GIF, MP4) and the
browser's evaluation page draws it as white dots on black.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from markovmotion.core.markers import Markers
from markovmotion.core.motion import Motion
from markovmotion.features.body_points import MARKER_POINTS, body_points


def point_lights(
    people: Sequence[Motion],
    points: Sequence[str] = MARKER_POINTS,
    fps: float | None = None,
    name: str = "",
) -> Markers:
    """One marker cloud of ``points`` on each of ``people`` (world positions, mm).

    Every person is resampled to ``fps`` (default: the first person's rate) and
    cut to the frames they all have; markers are named ``P<k> <point>``
    (``P1 head``, ``P2 head`` ...), which says nothing about where the motion
    came from.

    Raises:
        ValueError: no people.
        SkeletonMismatchError: a skeleton lacks one of ``points`` (one line naming them).
    """
    if not people:
        raise ValueError("no people to draw")
    rate = float(fps if fps is not None else people[0].fps)
    same = [p if np.isclose(p.fps, rate) else p.resample(rate) for p in people]
    n = min(p.n_frames for p in same)
    clouds = [body_points(p.trim(0, n), points) for p in same]
    names = tuple(f"P{k + 1} {point}" for k in range(len(same)) for point in points)
    return Markers(names, np.concatenate(clouds, axis=1), rate, name)
