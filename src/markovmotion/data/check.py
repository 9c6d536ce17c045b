"""An INDEX.csv checked against its files: ``markovmotion data check``.

Every command trusts the index: its frame rate (a file's header may be wrong, CMU's salsa
conversions are), its pairs of people (``partner_file``), its people (``subject``, what a
leave-one-pair-out cross-validation groups by). A user's own collection is checked here
before a long training finds a wrong row: every file is read whole (a truncated file fails
here, not in the tenth fold), and

* its frame count is compared with ``frames`` (the file's own count, CMU's reference frame
  included; 0 or empty: not checked);
* a two-person take's ``partner_file`` must be listed, name this take back, and last as long
  (a pair is cut to the shorter when loaded, the partner first brought to this take's
  ``fps``: said as a note; two files at two rates are compared at one);
* a marker take (C3D) whose person is never seen is an error (nothing to learn or answer),
  one whose marker is never seen a note (a model trained on it leaves the marker out; one
  that uses the marker cannot answer it);
* a two-person take without ``subject`` cannot be held out by people (a note: cross-validation
  then leaves one take out at a time);
* a file listed twice is an error;
* a frame rate the file states (BVH, C3D) that INDEX.csv's ``fps`` contradicts is a note
  (INDEX.csv's is read), and so is what reading a file warns of (a skeleton in another
  length unit than it is read in).

Our own, not a schema library's: the checks are about the files, not the CSV's types, which
:meth:`~markovmotion.data.index.MocapIndex.load` already refuses with the line.
"""

from __future__ import annotations

import logging
from collections import Counter
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass

from markovmotion.core.markers import Markers, resampled_frames
from markovmotion.data.index import Entry, MocapIndex, rate_disagrees
from markovmotion.errors import MarkovMotionError
from markovmotion.io import base_suffix, read_motion
from markovmotion.io.c3d import read_c3d
from markovmotion.progress import notes_caught, track

#: How bad a finding is: an ``error`` stops a command that reads the take, a ``note`` does not.
LEVELS = ("error", "note")


@dataclass(frozen=True)
class Finding:
    """One thing found wrong with a row of INDEX.csv (``file``), ``level`` of :data:`LEVELS`."""

    file: str
    level: str
    problem: str

    def to_dict(self) -> dict[str, str]:
        return asdict(self)


@contextmanager
def _warnings_caught() -> Iterator[list[str]]:
    """The library's log warnings while reading a file, as messages (not printed as notes as
    well: the findings list them, and the summary counts them)."""
    logger = logging.getLogger("markovmotion")
    caught: list[str] = []

    class Catch(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            caught.append(record.getMessage())

    handler, propagate, others = Catch(logging.WARNING), logger.propagate, logger.handlers[:]
    logger.handlers, logger.propagate = [handler], False
    try:
        yield caught
    finally:
        logger.handlers, logger.propagate = others, propagate


def file_frames(entry: Entry) -> tuple[int, float | None]:
    """The number of frames in ``entry``'s file, read whole (CMU's reference frame counted),
    and the frame rate the file states (None: ASF/AMC states none).

    Raises:
        MarkovMotionError: the file cannot be read (named, with the problem).
    """
    n, rate, _ = _read(entry)
    return n, rate


def _read(entry: Entry) -> tuple[int, float | None, list[Finding]]:
    """:func:`file_frames`, and what a marker take's unseen samples say (:func:`_unseen`)."""
    suffix = base_suffix(entry.file)
    if suffix == ".c3d":
        markers = read_c3d(entry.path)
        return markers.n_frames, markers.fps, _unseen(entry, markers)
    if suffix == ".bvh":
        try:
            motion = read_motion(entry.path)  # the header's rate
            return motion.n_frames, motion.fps, []
        except MarkovMotionError:  # e.g. a Frame Time of 0: the index's rate is read
            pass
    return read_motion(entry.path, fps=entry.fps).n_frames, None, []


def _unseen(entry: Entry, markers: Markers) -> list[Finding]:
    """A C3D take whose every sample is unseen (an error: no model can learn or answer it),
    or whose markers are each never seen (a note naming them)."""
    if not markers.visible().any():
        return [Finding(entry.file, "error", "no marker is seen in any frame: nothing recorded")]
    never = markers.never_seen()
    if never is None:
        return []
    them = "them" if never.startswith("markers") else "it"
    return [
        Finding(
            entry.file,
            "note",
            f"{never}: a model trained on this take leaves {them} out; one that uses {them} "
            "cannot answer it",
        )
    ]


def check_index(index: MocapIndex) -> list[Finding]:
    """What is wrong with ``index`` and its files (module docstring), in the index's order."""
    found: list[Finding] = []
    listed = {e.file: e for e in index.entries}
    for file, count in Counter(e.file for e in index.entries).items():
        if count > 1:
            found.append(Finding(file, "error", f"listed {count} times"))
    frames: dict[str, int] = {}
    for e in track(index.entries, "reading every take"):
        if not e.path.is_file():
            problem = "is a folder, not a motion file" if e.path.is_dir() else "file not found"
            found.append(Finding(e.file, "error", problem))
            continue
        try:
            # what reading it warns of (a unit) or notes (a C3D's axes): a finding, not printed
            with _warnings_caught() as caught, notes_caught() as noted:
                n, rate, unseen = _read(e)
            frames[e.file] = n
            found += [Finding(e.file, "note", w.removeprefix(f"{e.path}: ")) for w in caught]
            found += [Finding(e.file, "note", w.removeprefix(f"{e.path.name}: ")) for w in noted]
            found += unseen
        except MarkovMotionError as exc:  # the problem and line: the row names the file
            line = getattr(exc, "line", None)
            what = getattr(exc, "problem", str(exc)) + (f" (line {line})" if line else "")
            found.append(Finding(e.file, "error", f"unreadable: {what}"))
            continue
        if e.frames and n != e.frames:
            found.append(Finding(e.file, "error", f"{n} frames in the file, {e.frames} listed"))
        differs = None if rate is None else rate_disagrees(e, rate)
        if differs:
            found.append(Finding(e.file, "note", differs.removeprefix(f"{e.file}: ")))
    for e in index.entries:
        found += _pair_findings(e, listed, frames)
    return found


def _pair_findings(e: Entry, listed: dict[str, Entry], frames: dict[str, int]) -> list[Finding]:
    """What is wrong with ``e`` as one person of a two-person take."""
    if not e.partner_file:
        if e.category == "interaction":
            return [Finding(e.file, "error", "a two-person take without partner_file")]
        return []
    other = listed.get(e.partner_file)
    if other is None:
        return [Finding(e.file, "error", f"partner_file {e.partner_file} is not listed")]
    out = []
    if other.partner_file != e.file:
        out.append(
            Finding(
                e.file,
                "error",
                f"its partner {other.file} names {other.partner_file or 'no partner'} back",
            )
        )
    mine, theirs = frames.get(e.file), frames.get(other.file)
    if mine is not None and theirs is not None and e.file < other.file:
        one_rate = e.fps == other.fps or not (e.fps and other.fps)
        brought = theirs if one_rate else resampled_frames(theirs, other.fps, e.fps)
        if brought != mine:  # the partner at this take's rate, as loading brings it
            said = (
                f"{mine} frames, its partner {other.file} {theirs}"
                if one_rate
                else f"{mine} frames at {e.fps:g} fps, its partner {other.file} {theirs} at "
                f"{other.fps:g} ({brought} at {e.fps:g})"
            )
            out.append(Finding(e.file, "note", f"{said}: the pair is cut to the shorter"))
    if not e.subject:
        out.append(
            Finding(
                e.file,
                "note",
                "no subject: cross-validation cannot hold these people out (it leaves one "
                "take out at a time)",
            )
        )
    return out
