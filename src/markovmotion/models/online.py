"""The online partner protocol, and a real-time replay of a motion through any partner.

An online partner (the dual HMM's windowed-Viterbi partner, the behaviour
chain's CONDENSATION partner) takes person A one frame at a time and answers
with person B's frame for ``lag`` frames ago:

- ``step(frame)``: ``frame`` is a one-frame :class:`Motion` of A (or None when
  the frame is missing); returns B's one-frame Motion, or None while the
  partner's look-ahead fills;
- ``skip()``: a frame the caller could not deliver in time (dropped); B's frame
  for ``lag`` frames ago comes out as from ``step``;
- ``drop()``: a frame the caller dropped and will not show B's answer for (a
  live session behind its clock): ``skip()`` at the least cost, nothing returned;
- ``finish()``: B's frames still owed at the end of the stream, which ends it (a later
  call is a ValueError, :data:`FINISHED`: a new stream is a new ``model.partner()``);
- ``lag`` (frames), ``fps`` (the partner's rate; A is resampled to it),
  ``skeleton`` (B's skeleton).

A model offers one through ``model.partner()``; ``respond --realtime``, the
``/live`` page and ``serve --partner`` take any model that does.

A frame of A that is missing (None, or NaN: a marker unseen) is skipped with a logged
warning, once per stream (:class:`MissingFrames`; logger ``markovmotion``, which the
command line shows as a note).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from markovmotion.core.markers import Markers
from markovmotion.core.motion import Motion
from markovmotion.core.skeleton import Skeleton


@runtime_checkable
class OnlinePartner(Protocol):
    """What every online partner offers (module docstring)."""

    lag: int
    fps: float

    @property
    def skeleton(self) -> Skeleton: ...

    def step(self, frame: Motion | None) -> Motion | None: ...

    def skip(self) -> Motion | None: ...

    def drop(self) -> None: ...

    def finish(self) -> list[Motion]: ...


log = logging.getLogger(__name__)

#: The warning an online partner logs for the first frame of A missing in a stream (the
#: frame's index in the stream); the dual HMM's partner says the same.
MISSING = "frame %d of A is missing or holds NaN: skipped"


class MissingFrames:
    """A stream's frames of A that were missing (None, or NaN), the first logged as a
    warning (:data:`MISSING`), the others counted (``count``): once per stream, as the
    contract says, so that a camera that loses a person for a minute does not log 1,500
    lines. One per partner, called with each missing frame's index in the stream."""

    def __init__(self) -> None:
        self.count = 0

    def __call__(self, frame: int) -> None:
        if not self.count:
            log.warning(MISSING, frame)
        self.count += 1


class CheckedOnce:
    """A stream's frames of A checked against the model (``check``, its ``check_input``) once
    per kind of A: a skeleton (the same object), or markers' names (equal, whatever list
    holds them: a live source gives a new one with each frame). One per partner."""

    def __init__(self, check: Callable[[Motion | Markers], None]) -> None:
        self._check = check
        self._kind: Skeleton | tuple[str, ...] | None = None

    def __call__(self, frame: Motion | Markers) -> None:
        kind = tuple(frame.names) if isinstance(frame, Markers) else frame.skeleton
        if not (kind is self._kind or (isinstance(kind, tuple) and kind == self._kind)):
            self._check(frame)
            self._kind = kind


#: What a partner says when stepped after :meth:`OnlinePartner.finish` (a ValueError).
FINISHED = (
    "the partner's stream is finished (finish() was called): start another with model.partner()"
)


def check_frame(frame: object, fps: float) -> None:
    """Raise ValueError (one line) unless ``frame`` is one frame of A (a one-frame Motion
    or Markers) at the partner's ``fps`` (TypeError for anything else). Frames are taken one
    per tick of the partner's clock: a 60 fps take streamed into a 30 fps partner was
    answered in slow motion, and a five-frame Motion as one frame answered wrongly, both
    without a word. The caller resamples A first (``motion.resample(partner.fps)``), as
    ``respond --realtime``, the live pages and ``respond --video`` do, and gives a whole take
    to ``respond`` or :func:`run`."""
    if not isinstance(frame, (Motion, Markers)):
        raise TypeError(
            f"a frame of A is a one-frame Motion or Markers (or None when missing), not "
            f"{type(frame).__name__}"
        )
    if frame.n_frames != 1:
        raise ValueError(
            f"step takes one frame of A, got {frame.n_frames}: give motion.trim(t, t + 1), "
            "or the whole take to respond (models.online.run)"
        )
    if abs(float(frame.fps) - fps) > 1e-3 * fps:
        raise ValueError(
            f"A's frame is at {float(frame.fps):g} fps and the partner answers at {fps:g}: "
            "resample A to the partner's rate first (motion.resample(partner.fps))"
        )


@dataclass
class Replay:
    """What a real-time replay gave: B, per-frame processing times and dropped frames.

    Attributes:
        motion: B's frames, at the partner's rate.
        times_ms: (n,) processing time of each frame that was processed.
        dropped: frames skipped because processing fell behind (a frame is
            dropped when its successor is already due before it could start).
        lag: the partner's lag in frames.
        streamed: frames of A streamed (all of them, unless interrupted).
        interrupted: the replay was stopped by Ctrl-C; ``motion`` is B so far.
    """

    motion: Motion
    times_ms: np.ndarray
    dropped: int
    lag: int
    streamed: int = 0
    interrupted: bool = False

    def summary(self) -> str:
        """One line: latency median and p99, dropped frames, lag."""
        times = self.times_ms if len(self.times_ms) else np.zeros(1)
        return (
            f"latency per frame median {np.median(times):.2f} ms, p99 "
            f"{np.percentile(times, 99):.2f} ms; dropped frames {self.dropped}; lag {self.lag} "
            f"frames ({self.lag / self.motion.fps:.2f} s)"
        )


def concatenate(
    frames: list[Motion] | list[Markers], fps: float, name: str = "virtual partner"
) -> Motion | Markers:
    """One Motion (or Markers) from a partner's one-frame Motions (or Markers)."""
    if not frames:
        raise ValueError("the partner produced no frames")
    if isinstance(frames[0], Markers):
        return Markers(frames[0].names, np.concatenate([f.positions for f in frames]), fps, name)
    return Motion(
        frames[0].skeleton,
        np.concatenate([f.rotations for f in frames]),
        np.concatenate([f.translations for f in frames]),
        fps,
        name=name,
    )


def run(partner: OnlinePartner, motion: Motion) -> Motion:
    """B for the whole of ``motion`` through ``partner`` as fast as possible (no clock),
    ``motion`` first resampled to the partner's rate (as ``respond`` does)."""
    if abs(float(motion.fps) - partner.fps) > 1e-3 * partner.fps:
        motion = motion.resample(partner.fps)
    out = [f for t in range(motion.n_frames) if (f := partner.step(motion.trim(t, t + 1)))]
    out.extend(partner.finish())
    return concatenate(out, partner.fps)


def replay(make_partner: Callable[[], OnlinePartner], motion: Motion) -> Replay:
    """Replay ``motion`` at its frame rate through a fresh partner from ``make_partner()``.

    ``motion`` must be at the partner's rate. A frame whose successor is
    already due is dropped (:meth:`OnlinePartner.skip`), never queued. A first
    partner is stepped once before the clock starts, so compiled kernels are
    loaded before the first timed frame.
    """
    make_partner().step(motion.trim(0, 1))
    partner = make_partner()
    period = 1.0 / motion.fps
    out, times, dropped, streamed = [], [], 0, 0
    start = time.perf_counter()
    try:
        for t in range(motion.n_frames):
            now = time.perf_counter()
            due = start + t * period
            if now < due:
                time.sleep(due - now)
            tick = time.perf_counter()
            if tick > due + period:
                dropped += 1
                frame = partner.skip()
            else:
                frame = partner.step(motion.trim(t, t + 1))
                times.append((time.perf_counter() - tick) * 1e3)
            streamed = t + 1
            if frame is not None:
                out.append(frame)
    except KeyboardInterrupt:  # Ctrl-C on a long stream: B so far is kept (the caller says so)
        out.extend(partner.finish())
        if not out:
            raise
        return Replay(
            concatenate(out, partner.fps), np.array(times), dropped, int(partner.lag),
            streamed, interrupted=True,
        )  # fmt: skip
    out.extend(partner.finish())
    return Replay(
        concatenate(out, partner.fps), np.array(times), dropped, int(partner.lag), streamed
    )
