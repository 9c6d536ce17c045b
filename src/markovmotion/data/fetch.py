"""Download the motion capture from its public sources into a folder with an INDEX.csv.

Sources and their layout (the base URLs are parameters, so mirrors and tests work):

- CMU Graphics Lab Motion Capture Database, native ASF/AMC at 120 fps:
  ``{cmu}/NN/NN.asf`` (the subject's skeleton) and ``{cmu}/NN/NN_TT.amc`` (trial TT).
  The site has no machine-readable listing, so a subject's trials are found by
  probing TT = 01, 02, ... until ``max_missing`` trials in a row are missing (HTTP 404).
  Subjects 18/19, 20/21 and 22/23 are the two people of one take: trial TT of one
  is trial TT of the other (category ``interaction``, ``partner_file`` set).
- Bandai Namco Research Motion Dataset (GitHub, served raw), BVH at 30 fps:
  ``{bandai}/Bandai-Namco-Research-Motiondataset-K/data/dataset-K_walk_STYLE_ID.bvh``
  for K = 1, 2, the styles of each dataset's ``cfg/style_label.txt`` and ID = 001,
  002, ... probed the same way.

Files land in the layout of the shared collection (``cmu/asfamc/NN/NN_TT.amc``,
``bandai/dataset-K/walk_STYLE_ID.bvh``), each through a ``.part`` file that a
re-run resumes with an HTTP Range request and that is renamed into place only when
complete. Every downloaded motion is read back (:func:`markovmotion.io.read_motion`);
one that does not parse is set aside as ``NAME.bad``, reported and not indexed.
The rows are merged into ``DEST/INDEX.csv``, so re-running resumes and never
duplicates. Standard library only (``urllib``).
"""

from __future__ import annotations

import csv
import http.client
import os
import time
import urllib.error
import urllib.request
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from rich.progress import Progress, TaskID

from markovmotion import __version__
from markovmotion.data.index import COLUMNS, INDEX_NAME
from markovmotion.errors import MarkovMotionError, MotionFormatError
from markovmotion.io import read_motion
from markovmotion.io.files import atomic_write
from markovmotion.progress import progress_bar

CMU_BASE_URL = "http://mocap.cs.cmu.edu/subjects"
BANDAI_BASE_URL = (
    "https://raw.githubusercontent.com/BandaiNamcoResearchInc/"
    "Bandai-Namco-Research-Motiondataset/master/dataset"
)
CMU_FPS = 120.0
BANDAI_FPS = 30.0
INTERACTION_SUBJECTS = (18, 19, 20, 21, 22, 23)
PARTNERS = {18: 19, 19: 18, 20: 21, 21: 20, 22: 23, 23: 22}

# Each dataset's cfg/style_label.txt, in its order.
BANDAI_STYLES = {
    1: (
        "normal",
        "happy",
        "sad",
        "angry",
        "proud",
        "not-confident",
        "masculinity",
        "feminine",
        "childish",
        "old",
        "tired",
        "active",
        "musical",
        "giant",
        "chimpira",
    ),
    2: ("active", "elderly", "exhausted", "feminine", "masculine", "normal", "youthful"),
}

# (label, CMU's description) of the two-person trials, the same for both people of a
# pair; from CMU's index (cmu-mocap-index-text.txt, B. Hahne, 2008). No trial of
# subjects 18-23 is a push: 22_12 "A stumbles into B" is the closest.
_PLAY = {
    1: ("handshake", "walk, shake hands"),
    2: ("handshake", "walk, shake hands"),
    3: ("pull", "A pulls B; B resists"),
    4: ("pull", "A pulls B; B resists"),
    5: ("pull", "A pulls B by the elbow; B resists"),
    6: ("pull", "A pulls B by the elbow; B resists"),
    7: ("lead_by_arm", "navigate busy sidewalk; A leads the way, takes B by the arm"),
    8: ("conversation", "conversation - explain with hand gestures"),
    9: ("conversation", "conversation - explain with hand gestures, walk"),
    10: ("quarrel", "quarrel - angry hand gestures"),
    11: ("quarrel", "quarrel - angry hand gestures"),
    12: ("hang_out", "friends meet, hang out; A sits, B joins A"),
    13: ("scramble_for_seat", "run, scramble for last seat"),
    14: ("scramble_for_seat", "run, scramble for last seat"),
    15: ("chicken_dance", "chicken dance"),
}
_FORMATIONS = {
    1: ("chicken_dance", "chicken dance"),
    2: ("link_arms", "link arms, walk"),
    3: ("link_arms", "link arms, walk"),
    4: ("synchronized_walk", "synchronized walk"),
    5: ("synchronized_walk", "synchronized walk"),
    6: ("soldiers_march", "soldiers march"),
    7: ("soldiers_march", "soldiers march"),
    8: ("zombie_march", "zombie march"),
    9: ("ring_around_the_rosey", "nursery rhyme - ring around the rosey"),
    10: ("two_person_whip", "360-degree two-person whip"),
    11: ("high_five", "high-five, walk"),
    12: ("low_five", "low-five, walk"),
    13: ("blind_mans_bluff", "blind man's bluff (blindfold tag)"),
}
_CARE = {
    1: ("pull_up", "B sits; A pulls up B"),
    2: ("pull_up", "A sits; B pulls up A"),
    3: ("comfort", "A sits, holds face in hands; B kneels, comforts A"),
    4: ("comfort", "B comforts A, puts one hand on A's shoulder"),
    5: ("comfort", "A comforts B, puts both hands on B's shoulders"),
    6: ("comfort", "B comforts A, puts both hands on A's shoulders"),
    7: ("comfort", "A comforts B, puts one hand on B's shoulder"),
    8: ("hold_hands_walk", "hold hands, swing arms, walk"),
    9: ("shoulder_rub", "A gives B a shoulder rub; B sits, A stands"),
    10: ("shelter", "A shelters B, a younger child, from harm"),
    11: ("shelter", "B shelters A, a younger child, from harm"),
    12: ("stumble_into", "A stumbles into B"),
    13: ("pass_drink", "A passes soda to B; both drink"),
    14: ("alternating_squats", "alternating squats"),
    15: ("alternating_jumping_jacks", "alternating jumping jacks"),
    16: ("synchronized_jumping_jacks", "synchronized jumping jacks"),
    17: ("arm_wrestle", "rush up, arm wrestle"),
    18: ("stare_down", "A stares down B, leans with hands on high stool"),
    19: ("stare_down", "B stares down A, leans with hands on high stool"),
    20: ("threaten", "violence - A picks up high stool, threatens to strike B"),
    21: ("conversation", "conversation - B pounds high stool, points at A"),
    22: ("throw_catch", "walk; B catches keys thrown by A"),
    23: ("throw_catch", "walk; A catches keys thrown by B"),
    24: ("throw_catch", "walk; B catches wallet thrown by A"),
    25: ("throw_catch", "walk; A catches wallet thrown by B"),
}
CMU_TRIALS = {18: _PLAY, 19: _PLAY, 20: _FORMATIONS, 21: _FORMATIONS, 22: _CARE, 23: _CARE}

_MISSING_STATUS = {404, 410}
_TRANSIENT_STATUS = {408, 425, 429, 500, 502, 503, 504}
_CHUNK = 1 << 16
_USER_AGENT = f"markovmotion/{__version__} (data fetch)"

Status = Literal["there", "downloaded", "missing"]


class DownloadError(MarkovMotionError):
    """A download that failed for good (after its retries), or a destination that cannot be used."""


@dataclass
class FetchReport:
    """What :func:`fetch` did: files newly indexed, kept from before, rejected, not found."""

    dest: Path
    indexed: list[str] = field(default_factory=list)
    kept: list[str] = field(default_factory=list)
    rejected: list[tuple[str, str]] = field(default_factory=list)
    missing: list[str] = field(default_factory=list)
    total: int = 0


@dataclass(frozen=True)
class _Item:
    """One motion file to have: where it goes, where it comes from, its INDEX row."""

    file: str
    url: str
    row: dict[str, str]


def cmu_skeleton_file(subject: int) -> str:
    return f"cmu/asfamc/{subject:02d}/{subject:02d}.asf"


def cmu_motion_file(subject: int, trial: int) -> str:
    return f"cmu/asfamc/{subject:02d}/{subject:02d}_{trial:02d}.amc"


def _cmu_item(base_url: str, subject: int, trial: int) -> _Item:
    file = cmu_motion_file(subject, trial)
    known = CMU_TRIALS.get(subject, {}).get(trial)
    label, what = known if known else ("unknown", f"CMU subject {subject} trial {trial:02d}")
    if subject in PARTNERS:
        a, b = sorted((subject, PARTNERS[subject]))
        who = f"two-person take of CMU subjects {a}/{b}, person {'A' if subject == a else 'B'}; "
        category = "interaction"
    else:
        who, category = "", "activity"
    row = {
        "file": file,
        "source": "cmu",
        "subject": f"{subject:02d}",
        "trial": f"{trial:02d}",
        "category": category,
        "label": label,
        "partner_file": "",
        "fps": f"{CMU_FPS:g}",
        "description": f"{what} ({who}skeleton: {cmu_skeleton_file(subject)})",
    }
    return _Item(file, f"{base_url}/{subject:02d}/{subject:02d}_{trial:02d}.amc", row)


def _bandai_item(base_url: str, dataset: int, style: str, take: int) -> _Item:
    name = f"walk_{style}_{take:03d}.bvh"
    row = {
        "file": f"bandai/dataset-{dataset}/{name}",
        "source": "bandai",
        "subject": "",
        "trial": f"{dataset}-{take:03d}",
        "category": "walk" if style == "normal" else "style_walk",
        "label": style,
        "partner_file": "",
        "fps": f"{BANDAI_FPS:g}",
        "description": (
            f"Bandai Namco Research Motiondataset-{dataset}, content walk, style {style}"
        ),
    }
    url = f"{base_url}/Bandai-Namco-Research-Motiondataset-{dataset}/data/dataset-{dataset}_{name}"
    return _Item(row["file"], url, row)


def _content_range(value: str | None) -> tuple[int | None, int | None]:
    """(first byte, total size) of a ``Content-Range: bytes A-B/N`` or ``bytes */N`` header."""
    if not value or not value.startswith("bytes "):
        return None, None
    span, _, total = value[6:].partition("/")
    first = int(span.split("-")[0]) if span[:1].isdigit() else None
    return first, int(total) if total.isdigit() else None


def _receive(
    response: http.client.HTTPResponse,
    part: Path,
    have: int,
    on_bytes: Callable[[int, int | None], None] | None,
) -> None:
    """Write ``response`` into ``part`` (appending to a 206 that resumes at ``have``)."""
    if response.status == 206:
        first, total = _content_range(response.headers.get("Content-Range"))
        if first != have:
            raise http.client.HTTPException(f"resumed at byte {first}, expected {have}")
        mode = "ab"
    else:  # the whole file, whatever was asked
        length = response.headers.get("Content-Length")
        have, total, mode = 0, int(length) if length and length.isdigit() else None, "wb"
    with open(part, mode) as fh:
        if on_bytes:
            on_bytes(have, total)
        while chunk := response.read(_CHUNK):
            fh.write(chunk)
            have += len(chunk)
            if on_bytes:
                on_bytes(have, total)
    if total is not None and have != total:
        raise ConnectionError(f"connection closed after {have} of {total} bytes")


def download(
    url: str,
    path: str | os.PathLike[str],
    *,
    retries: int = 4,
    backoff: float = 1.0,
    timeout: float = 60.0,
    on_bytes: Callable[[int, int | None], None] | None = None,
) -> bool:
    """Fetch ``url`` into ``path``; False if the server has no such file (404/410).

    Bytes go to ``path.part``, resumed with an HTTP Range request on every retry
    and every later call, and renamed to ``path`` once complete. Connection
    errors, truncated bodies and HTTP 408/429/5xx are retried ``retries`` times
    in a row without progress, waiting ``backoff * 2**k`` seconds; then, or on
    any other HTTP error, :class:`DownloadError`. ``on_bytes(done, total)``
    reports progress.
    """
    path = Path(path)
    part = path.with_name(path.name + ".part")
    failures = 0
    while True:
        have = part.stat().st_size if part.exists() else 0
        request = urllib.request.Request(url, headers={"User-Agent": _USER_AGENT})
        if have:
            request.add_header("Range", f"bytes={have}-")
        try:
            with urllib.request.urlopen(request, timeout=timeout) as response:
                _receive(response, part, have, on_bytes)
            os.replace(part, path)
            return True
        except urllib.error.HTTPError as exc:
            if exc.code in _MISSING_STATUS:
                part.unlink(missing_ok=True)
                return False
            if exc.code == 416 and have:  # nothing left after ``have``: complete, or stale
                if _content_range(exc.headers.get("Content-Range"))[1] == have:
                    os.replace(part, path)
                    return True
                part.unlink()
            elif exc.code not in _TRANSIENT_STATUS:
                raise DownloadError(f"{url}: HTTP {exc.code} {exc.reason}") from None
            problem = f"HTTP {exc.code} {exc.reason}"
        except (OSError, http.client.HTTPException) as exc:
            problem = str(exc) or type(exc).__name__
        progressed = part.exists() and part.stat().st_size > have
        failures = 0 if progressed else failures + 1
        if failures > retries:
            raise DownloadError(f"{url}: {problem} (gave up after {retries} retries)")
        if not progressed:
            time.sleep(backoff * 2 ** (failures - 1))


def _read_index(path: Path) -> tuple[list[str], dict[str, dict[str, str]]]:
    """Column names and rows (by file, in order) of an existing INDEX.csv."""
    if not path.is_file():
        return list(COLUMNS), {}
    with open(path, newline="", encoding="utf-8") as fh:
        reader = csv.DictReader(fh)
        names = list(reader.fieldnames or [])
        if "file" not in names:
            raise MotionFormatError(path, "no 'file' column: not an INDEX.csv", 1)
        rows = {row["file"]: row for row in reader}
    return list(COLUMNS) + [c for c in names if c not in COLUMNS], rows


def _link_partners(rows: dict[str, dict[str, str]]) -> None:
    """Point each CMU two-person trial at the same trial of its partner, when indexed."""
    for file, row in rows.items():
        if row.get("source") != "cmu" or not row.get("subject", "").isdigit():
            continue
        subject, trial = int(row["subject"]), row.get("trial", "")
        if subject not in PARTNERS or not trial.isdigit():
            continue
        if file != cmu_motion_file(subject, int(trial)):
            continue
        partner = cmu_motion_file(PARTNERS[subject], int(trial))
        row["partner_file"] = partner if partner in rows else ""


def _write_index(path: Path, columns: list[str], rows: dict[str, dict[str, str]]) -> None:
    with atomic_write(path) as fh:
        writer = csv.DictWriter(fh, fieldnames=columns, lineterminator="\n", restval="")
        writer.writeheader()
        writer.writerows(rows.values())


@dataclass(frozen=True)
class _Group:
    """Numbered files probed 1, 2, ... (a CMU subject's trials, a Bandai style's takes)."""

    title: str
    item: Callable[[int], _Item]
    fps: float
    skeleton: tuple[str, str] | None = None  # (file, url) needed before any motion


def _groups(
    subjects: Iterable[int], bandai: bool, cmu_base_url: str, bandai_base_url: str
) -> list[_Group]:
    groups = [
        _Group(
            f"CMU subject {s:02d}",
            lambda t, s=s: _cmu_item(cmu_base_url, s, t),
            CMU_FPS,
            (cmu_skeleton_file(s), f"{cmu_base_url}/{s:02d}/{s:02d}.asf"),
        )
        for s in subjects
    ]
    if bandai:
        groups += [
            _Group(
                f"Bandai dataset-{k} walk {style}",
                lambda n, k=k, style=style: _bandai_item(bandai_base_url, k, style, n),
                BANDAI_FPS,
            )
            for k, styles in BANDAI_STYLES.items()
            for style in styles
        ]
    return groups


class _Fetcher:
    """Downloads into ``dest`` with one progress display: files done, bytes of the current one."""

    def __init__(self, dest: Path, bar: Progress, **download_options: float):
        self.dest = dest
        self.bar = bar
        self.options = download_options
        self.files: TaskID = bar.add_task("files", total=None)
        self.bytes: TaskID = bar.add_task("", total=None, visible=False)

    def get(self, url: str, file: str) -> Status:
        """Make ``file`` be in ``dest``: already there, downloaded from ``url``, or missing."""
        target = self.dest / file
        if target.is_file():
            return "there"
        target.parent.mkdir(parents=True, exist_ok=True)
        self.bar.update(self.bytes, description=file, completed=0, total=None, visible=True)
        try:
            found = download(url, target, on_bytes=self._on_bytes, **self.options)
        finally:
            self.bar.update(self.bytes, visible=False)
        return "downloaded" if found else "missing"

    def _on_bytes(self, done: int, total: int | None) -> None:
        self.bar.update(self.bytes, completed=done, total=total)


def fetch(
    dest: str | os.PathLike[str],
    subjects: Iterable[int] = INTERACTION_SUBJECTS,
    bandai: bool = True,
    *,
    cmu_base_url: str = CMU_BASE_URL,
    bandai_base_url: str = BANDAI_BASE_URL,
    max_missing: int = 3,
    retries: int = 4,
    backoff: float = 1.0,
    timeout: float = 60.0,
) -> FetchReport:
    """Download CMU ``subjects`` (ASF/AMC) and, if ``bandai``, the Bandai Namco walks into ``dest``.

    Probing a CMU subject's trials or a Bandai style's takes stops after
    ``max_missing`` missing files in a row. Files already in ``dest`` are not
    fetched again, ``.part`` files are resumed, and ``dest/INDEX.csv`` is merged
    with, never duplicated; it is written even when a download fails for good,
    so that the next run resumes.

    Raises:
        DownloadError: ``dest`` is not a folder, or a file could not be fetched.
        MotionFormatError: ``dest`` holds an INDEX.csv that is not one.
    """
    dest = Path(dest)
    if dest.exists() and not dest.is_dir():
        raise DownloadError(f"{dest}: not a folder (the destination must be a folder)")
    if max_missing < 1:
        raise ValueError(f"max_missing must be at least 1, not {max_missing}")
    dest.mkdir(parents=True, exist_ok=True)
    index_path = dest / INDEX_NAME
    columns, rows = _read_index(index_path)
    report = FetchReport(dest)
    groups = _groups(subjects, bandai, cmu_base_url.rstrip("/"), bandai_base_url.rstrip("/"))
    with progress_bar() as bar:
        fetcher = _Fetcher(dest, bar, retries=retries, backoff=backoff, timeout=timeout)
        try:
            for group in groups:
                bar.update(fetcher.files, description=group.title)
                if group.skeleton:
                    file, url = group.skeleton
                    if fetcher.get(url, file) == "missing":
                        report.missing.append(f"{group.title}: no skeleton at {url}")
                        continue
                missing, number = 0, 1
                while missing < max_missing:
                    item = group.item(number)
                    number += 1
                    status = fetcher.get(item.url, item.file)
                    # a file that is not a motion (say, a site's "not found" page) counts as missing
                    if status != "missing" and _check_and_index(
                        dest, item, group.fps, status, rows, report
                    ):
                        missing = 0
                        bar.advance(fetcher.files)
                    else:
                        missing += 1
        finally:
            _link_partners(rows)
            _write_index(index_path, columns, rows)
    report.total = len(rows)
    return report


def _check_and_index(
    dest: Path,
    item: _Item,
    fps: float,
    status: Status,
    rows: dict[str, dict[str, str]],
    report: FetchReport,
) -> bool:
    """Index a file now in ``dest`` if it reads as a motion, else set it aside as ``.bad``.

    A file that was already there and is indexed keeps its frame count unread.
    """
    before = rows.get(item.file, {})
    if status == "there" and before.get("frames"):
        rows[item.file] = {**before, **item.row, "frames": before["frames"]}
        report.kept.append(item.file)
        return True
    path = dest / item.file
    try:
        frames = read_motion(path, fps=fps).n_frames
    except MarkovMotionError as exc:
        bad = path.with_name(path.name + ".bad")
        os.replace(path, bad)
        rows.pop(item.file, None)
        report.rejected.append((item.file, f"{exc} (set aside as {bad.name})"))
        return False
    rows[item.file] = {**before, **item.row, "frames": str(frames)}
    report.indexed.append(item.file)
    return True
