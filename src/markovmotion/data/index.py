"""The motion-capture collection: where it is, what INDEX.csv says, loading by query.

Root resolution order: an explicit path, then ``$MARKOVMOTION_DATA``, then
``../shared/data/mocap`` beside the project root (the folder holding
``pyproject.toml``, found from the working directory or from this package).
"""

from __future__ import annotations

import csv
import functools
import io
import logging
import os
from collections.abc import Iterable
from dataclasses import dataclass, fields
from pathlib import Path

from markovmotion.core.markers import Markers
from markovmotion.core.motion import Motion
from markovmotion.errors import DataNotFoundError, MarkovMotionError, MotionFormatError
from markovmotion.io import read_c3d, read_motion
from markovmotion.io.files import base_suffix, read_text
from markovmotion.limits import MAX_FRAMES, check_rate, exceeded, max_frames

log = logging.getLogger(__name__)

ENV_VAR = "MARKOVMOTION_DATA"
INDEX_NAME = "INDEX.csv"
COLUMNS = (
    "file",
    "source",
    "subject",
    "trial",
    "category",
    "label",
    "partner_file",
    "fps",
    "frames",
    "description",
)
HOW_TO_GET = (
    "get the data with 'markovmotion data fetch --dest DIR' (CMU and Bandai Namco) "
    f"and point {ENV_VAR} or --data at DIR"
)


def _project_roots() -> Iterable[Path]:
    here = Path.cwd().resolve()
    for p in (here, *here.parents):
        if (p / "pyproject.toml").is_file():
            yield p
    pkg = Path(__file__).resolve()
    for p in pkg.parents:
        if (p / "pyproject.toml").is_file():
            yield p


def candidate_roots(path: str | os.PathLike[str] | None = None) -> list[Path]:
    """Every folder looked at for the data, in order."""
    if path is not None:
        return [Path(path)]
    if os.environ.get(ENV_VAR):
        return [Path(os.environ[ENV_VAR])]
    return shared_roots()


def shared_roots() -> list[Path]:
    """Where the project's shared collection may be (``../shared/data/mocap`` beside the
    project), whatever ``MARKOVMOTION_DATA`` says."""
    seen: list[Path] = []
    for root in _project_roots():
        cand = (root.parent / "shared" / "data" / "mocap").resolve()
        if cand not in seen:
            seen.append(cand)
    return seen


def data_root(path: str | os.PathLike[str] | None = None) -> Path:
    """The folder holding ``INDEX.csv``; a clear error says where it looked."""
    looked = candidate_roots(path)
    for cand in looked:
        if cand.is_file() and cand.name == INDEX_NAME:
            return cand.parent
        if (cand / INDEX_NAME).is_file():
            return cand
    where = ", ".join(str(p) for p in looked) or "(nowhere: no project root found)"
    given = [p for p in looked if p.is_file() and p.name != INDEX_NAME]
    if path is not None and given:  # a take named where an index is asked for
        raise DataNotFoundError(
            f"{given[0]} is a file, not an {INDEX_NAME}: give the {INDEX_NAME} that lists it "
            "(or its folder)"
        )
    if path is not None:  # the user's own index, or a download of the collection
        raise DataNotFoundError(
            f"no {INDEX_NAME} at {where} (an index of your own captures: docs/data.md gives its "
            "columns; the public collection: 'markovmotion data fetch --dest DIR')"
        )
    raise DataNotFoundError(
        f"no motion-capture {INDEX_NAME} found (looked in {where}); {HOW_TO_GET}"
    )


@dataclass(frozen=True)
class Entry:
    """One row of INDEX.csv."""

    file: str
    source: str
    subject: str
    trial: str
    category: str
    label: str
    partner_file: str
    fps: float
    frames: int
    description: str
    root: Path

    @property
    def path(self) -> Path:
        return self.root / self.file

    @property
    def name(self) -> str:
        return Path(self.file).name.split(".")[0]

    @property
    def has_reference_frame(self) -> bool:
        """CMU's BVH conversions start with a reference pose in frame 0 (see the data README)."""
        return self.source == "cmu" and base_suffix(self.file) == ".bvh"

    @property
    def kind(self) -> str:
        """``"markers"`` for a C3D file (named points, no skeleton), else ``"skeleton"``."""
        return "markers" if base_suffix(self.file) == ".c3d" else "skeleton"

    @property
    def first_frame(self) -> int:
        """The first frame of the take proper: 1 after CMU's reference frame, else 0."""
        return int(self.has_reference_frame)

    def read(self) -> Motion:
        """The motion at its true frame rate (INDEX.csv's; a BVH header that says another is
        noted, :func:`rate_disagrees`), without CMU's reference frame."""
        motion = None
        if base_suffix(self.file) == ".bvh":  # the header's rate, to compare
            try:
                motion = read_motion(self.path)
            except MotionFormatError:  # e.g. a Frame Time of 0: read at the index's rate
                pass
        if motion is None:
            motion = read_motion(self.path, fps=self.fps)
        else:
            note_rate(self, motion.fps)
            motion.fps = self.fps
        return motion.trim(self.first_frame) if motion.n_frames > 1 else motion


class MocapIndex:
    """The entries of an INDEX.csv, with queries and loading."""

    def __init__(self, root: Path, entries: list[Entry]):
        self.root = root
        self.entries = entries

    @classmethod
    def load(cls, path: str | os.PathLike[str] | None = None) -> MocapIndex:
        """Read ``INDEX.csv`` from ``path`` (a folder or the CSV itself) or the default root."""
        root = data_root(path)
        csv_path = root / INDEX_NAME
        try:
            return cls._parse(root, csv_path, read_text(csv_path))
        except csv.Error as exc:
            raise MotionFormatError(csv_path, f"not a readable CSV file ({exc})") from None

    @classmethod
    def _parse(cls, root: Path, csv_path: Path, text: str) -> MocapIndex:
        """The entries of ``text`` (INDEX.csv read within the limits of :mod:`markovmotion.limits`)."""
        with io.StringIO(text, newline="") as fh:
            reader = csv.DictReader(fh, skipinitialspace=True)  # "file, source, ..." too
            header = [name.strip() for name in reader.fieldnames or []]
            reader.fieldnames = header
            missing = [c for c in ("file", "category", "label", "fps") if c not in header]
            if missing:
                raise MotionFormatError(
                    csv_path,
                    f"missing columns: {', '.join(missing)} (its first line reads "
                    f"{', '.join(header)[:200] or 'nothing'})",
                    1,
                )
            entries = []
            cap = max_frames()
            for line, row in enumerate(reader, start=2):
                if len(entries) >= cap:
                    raise MotionFormatError(csv_path, exceeded(MAX_FRAMES, "rows"), line)
                try:
                    entries.append(
                        Entry(
                            **{
                                f.name: row.get(f.name) or ""
                                for f in fields(Entry)
                                if f.name not in ("fps", "frames", "root")
                            },
                            fps=check_rate(row["fps"], "fps"),
                            frames=int(row.get("frames") or 0),
                            root=root,
                        )
                    )
                except ValueError as exc:
                    why = str(exc)
                    if None in row.values():  # fewer fields than the header: an open quote
                        why = (
                            f"{sum(v is not None for v in row.values())} of "
                            f"{len(reader.fieldnames or [])} columns: check its quotes and commas"
                        )
                    raise MotionFormatError(csv_path, f"bad row ({why})", line) from None
        return cls(root, entries)

    def __len__(self) -> int:
        return len(self.entries)

    def __iter__(self):
        return iter(self.entries)

    def query(
        self,
        category: str | Iterable[str] | None = None,
        label: str | Iterable[str] | None = None,
        source: str | None = None,
        subject: str | None = None,
        kind: str | None = None,
    ) -> list[Entry]:
        """Entries matching every criterion given (a criterion may be a list of values);
        ``kind``: ``"skeleton"`` or ``"markers"`` (:attr:`Entry.kind`)."""

        def ok(value: str, want: str | Iterable[str] | None) -> bool:
            if want is None:
                return True
            return value == want if isinstance(want, str) else value in set(want)

        return [
            e
            for e in self.entries
            if ok(e.category, category)
            and ok(e.label, label)
            and ok(e.source, source)
            and ok(e.subject, subject)
            and ok(e.kind, kind)
        ]

    def find(self, file: str) -> Entry:
        for e in self.entries:
            if e.file == file:
                return e
        raise DataNotFoundError(f"{file} is not in {self.root / INDEX_NAME}")

    def load_motion(self, entry: Entry) -> Motion:
        """Read an entry at its true frame rate, without CMU's reference frame."""
        return entry.read()

    def pairs(
        self, label: str | Iterable[str] | None = None, kind: str | None = None
    ) -> list[tuple[Entry, Entry]]:
        """Two-person takes as (A, B) entries, each take once (A is the file listed first);
        ``kind``: only skeleton or markers takes."""
        out = []
        seen: set[str] = set()
        for e in self.query(category="interaction", label=label, kind=kind):
            if not e.partner_file or e.file in seen:
                continue
            try:
                partner = self.find(e.partner_file)
            except DataNotFoundError:
                raise DataNotFoundError(
                    f"{e.partner_file}, the partner_file of {e.file}, is not in "
                    f"{self.root / INDEX_NAME}: give it a row of its own (its label, fps, "
                    f"frames, and partner_file {e.file})"
                ) from None
            seen.update({e.file, partner.file})
            out.append((e, partner))
        return out

    def load_take(self, entry: Entry) -> Motion | Markers:
        """An entry's motion (:meth:`load_motion`), or for a C3D file its markers at
        INDEX.csv's rate (unseen samples NaN): :func:`read_entry`."""
        return read_entry(entry)

    def load_pair(self, a: Entry, b: Entry) -> tuple[Motion, Motion] | tuple[Markers, Markers]:
        """Both people of a take, at the same frame rate and cut to the same frames: Motions,
        or Markers when both files are C3D (at INDEX.csv's rate)."""
        c3d = [base_suffix(e.file) == ".c3d" for e in (a, b)]
        if any(c3d):
            if not all(c3d):
                raise MotionFormatError(
                    self.root / INDEX_NAME, f"{a.file} and {b.file}: one C3D, one skeleton"
                )
        ma, mb = self.load_take(a), self.load_take(b)
        if not ma.fps == mb.fps:
            mb = mb.resample(ma.fps)
        n = min(ma.n_frames, mb.n_frames)
        return ma.trim(0, n), mb.trim(0, n)


#: How many folders above a file :func:`listed_entry` looks in for an INDEX.csv listing it.
INDEX_LEVELS = 4


def listed_entry(path: str | os.PathLike[str]) -> Entry | None:
    """The entry for a file given by path: in the collection (``--data``'s default, or
    ``$MARKOVMOTION_DATA``), else in an INDEX.csv of a folder above the file (a user's own
    collection, up to :data:`INDEX_LEVELS` folders up, links resolved); None if none lists it.
    An index that cannot be read is passed over: the file is then read as it is."""
    try:
        file = Path(path).resolve()
    except (OSError, RuntimeError):  # a link loop: the reader says
        return None
    roots: list[Path | None] = [None]
    roots += [f for f in list(file.parents)[:INDEX_LEVELS] if (f / INDEX_NAME).is_file()]
    for root in roots:
        try:
            index = _index_read(data_root(root))
            entry = index.find(file.relative_to(index.root.resolve()).as_posix())
        except (MarkovMotionError, ValueError, OSError, RuntimeError, KeyError):
            continue
        if entry is not None:
            return entry
    return None


def _index_read(root: Path) -> MocapIndex:
    """``root``'s index, parsed again only when its INDEX.csv changed (size or time): a
    command that reads many files by path looks each one up."""
    stat = (root / INDEX_NAME).stat()
    return _index_at(root, stat.st_mtime_ns, stat.st_size)


@functools.lru_cache(maxsize=8)
def _index_at(root: Path, mtime_ns: int, size: int) -> MocapIndex:
    return MocapIndex.load(root)


def read_listed_motion(path: str | os.PathLike[str], fps: float | None = None) -> Motion:
    """Read a motion file; one listed in the collection is read as INDEX.csv says (true frame
    rate, CMU's reference frame dropped) unless ``fps`` overrides the file's rate."""
    entry = None if fps is not None else listed_entry(path)
    return entry.read() if entry is not None else read_motion(path, fps=fps)


def read_listed(path: str | os.PathLike[str], fps: float | None = None) -> Motion | Markers:
    """:func:`read_listed_motion`, or for a C3D file its markers: a file an index lists
    (:func:`listed_entry`) as every command reads it (:func:`read_entry`) unless ``fps`` is
    given, else the file itself at ``fps`` or its own rate."""
    entry = None if fps is not None else listed_entry(path)
    if entry is not None:
        return read_entry(entry)
    if base_suffix(path) != ".c3d":
        return read_motion(path, fps=fps)
    markers = read_c3d(path)
    if fps is not None:
        markers.fps = float(fps)
    return markers


#: What is said of a file whose own frame rate INDEX.csv contradicts (file, its rate, the
#: index's): by every reader once per command (:func:`note_rate`) and by ``data check``.
RATE_NOTE = (
    "%s: the file says %g fps, INDEX.csv %g: read at INDEX.csv's rate (the index is trusted: "
    "correct it if it is the one wrong)"
)


def rate_disagrees(entry: Entry, file_fps: float) -> str | None:
    """:data:`RATE_NOTE` when ``entry``'s file states a frame rate ``file_fps`` that
    INDEX.csv's ``fps`` contradicts (by more than 1 %), else None. INDEX.csv's rate is the one
    read (a header may be wrong: CMU's salsa conversions say 120 fps for 60); a lab's index
    copied with another capture's rate would read every take slowed down or sped up."""
    if abs(file_fps - entry.fps) <= 0.01 * entry.fps:
        return None
    return RATE_NOTE % (entry.file, file_fps, entry.fps)


def note_rate(entry: Entry, file_fps: float) -> None:
    """:func:`rate_disagrees` as a log warning: a note once per command, with its count
    (:class:`~markovmotion.progress.NoteOnce`)."""
    if rate_disagrees(entry, file_fps):
        log.warning(RATE_NOTE, entry.file, file_fps, entry.fps)


def read_entry(entry: Entry) -> Motion | Markers:
    """An entry's take as every command reads it: its motion (:meth:`Entry.read`), or for a
    C3D file its markers at INDEX.csv's rate (unseen samples NaN)."""
    return _read_markers(entry) if base_suffix(entry.file) == ".c3d" else entry.read()


def _read_markers(entry: Entry) -> Markers:
    """A C3D entry's markers at INDEX.csv's frame rate (a note when the file says another:
    :func:`rate_disagrees`)."""
    markers = read_c3d(entry.path)
    note_rate(entry, markers.fps)
    markers.fps = entry.fps
    return markers
