"""markovmotion: statistical models of human behaviour learnt from motion capture.

The package mirrors the data flow of the design brief: ``io`` reads and writes
motion files into :class:`Motion`, ``features`` turns motions into model
observations and back, ``models`` learns from them, ``viz`` draws the results
and ``cli`` puts a command line on top.
"""

from markovmotion.core.motion import Motion
from markovmotion.core.skeleton import Skeleton
from markovmotion.errors import (
    DataNotFoundError,
    LimitError,
    MarkersNotFoundError,
    MarkovMotionError,
    ModelFormatError,
    MotionFormatError,
    SkeletonMismatchError,
    TooLittleDataError,
)
from markovmotion.io import read_motion, write_motion

__version__ = "0.1.0"

__all__ = [
    "DataNotFoundError",
    "LimitError",
    "MarkersNotFoundError",
    "MarkovMotionError",
    "ModelFormatError",
    "Motion",
    "MotionFormatError",
    "Skeleton",
    "SkeletonMismatchError",
    "TooLittleDataError",
    "__version__",
    "read_motion",
    "write_motion",
]
