"""Exceptions for the errors a user can cause: bad files, missing data, wrong models.

The command line prints these as one line and exits with code 2; anything else
is a bug and keeps its traceback.
"""

from __future__ import annotations

from os import PathLike


class MarkovMotionError(Exception):
    """Base class of every expected error (bad input, not a bug)."""


class MotionFormatError(MarkovMotionError):
    """A motion file that cannot be read: names the file, the line and the problem."""

    def __init__(self, path: str | PathLike[str], problem: str, line: int | None = None):
        self.path = str(path)
        self.problem = problem
        self.line = line
        where = self.path if line is None else f"{self.path}:{line}"
        super().__init__(f"{where}: {problem}")


class ModelFormatError(MarkovMotionError):
    """A model file that is not ours, is damaged, or comes from another format version."""

    def __init__(self, path: str | PathLike[str], problem: str):
        self.path = str(path)
        self.problem = problem
        super().__init__(f"{self.path}: {problem}")


class DataNotFoundError(MarkovMotionError):
    """The motion-capture folder (or a file in it) could not be found."""


class SkeletonMismatchError(MarkovMotionError):
    """Two motions, or a motion and a model, do not share a skeleton.

    ``reason`` is what differs, without where (``markers not found: R_HAND``): a message
    that wraps another mismatch keeps the innermost one's, so a listing of left-out takes
    can say why beside each file without reading the message's text.
    """

    def __init__(self, message: str, reason: str | None = None):
        super().__init__(message)
        self.reason = reason or message


class MarkersNotFoundError(SkeletonMismatchError, ValueError):
    """Markers a model or a step needs are not among the take's (named in ``reason``).
    Also a :class:`ValueError`, as it was before it had a class of its own."""


class LimitError(MarkovMotionError, ValueError):
    """A value out of its range, or an input beyond a limit of :mod:`markovmotion.limits`.

    Also a :class:`ValueError`, so library callers that catch that keep working.
    """


class TooLittleDataError(MarkovMotionError, ValueError):
    """The training data are too few for the model asked for (fewer frames than
    prototypes or states). Also a :class:`ValueError`."""


class NothingRecordedError(MarkovMotionError, ValueError):
    """A take given to answer or score holds nothing: no frame, or NaN in every one (a
    capture whose tracker never found the person). Also a :class:`ValueError`, as it was
    before it had a class of its own."""
