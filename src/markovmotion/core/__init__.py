"""The motion types everything else builds on: :class:`Skeleton` (the kinematic tree),
:class:`Motion` (a skeleton animated over frames) and :class:`Markers` (labelled 3-D marker
trajectories), in mm, Y up."""

from markovmotion.core.markers import Markers
from markovmotion.core.motion import Motion
from markovmotion.core.skeleton import Skeleton

__all__ = ["Markers", "Motion", "Skeleton"]
