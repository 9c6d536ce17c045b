"""The answers of the perceptual evaluation in SQLite (WAL mode), one commit per answer.

Each evaluator gets a random token and, per test, ten items drawn at random
from the stimuli (gait paper §6.1); answers are kept whether or not the tests
are finished, and an evaluator coming back with the token resumes. Item rows
copy the stimulus labels (style, kind, displacement) so that the analysis
needs nothing but the database.

An observer of the interaction study (dual-HMM paper §4.2,
:mod:`markovmotion.evaluate.interaction`) gets every clip once, in a random
order, as items of the test ``interaction`` (``file`` the clip's id, ``style``
its label, ``kind`` real or generated); with each answer go whether they
noticed something unusual and their comment (table ``remarks``).
"""

from __future__ import annotations

import os
import secrets
import sqlite3
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from markovmotion.errors import MarkovMotionError
from markovmotion.evaluate.interaction import (
    INTERACTION,
    MAX_COMMENT,
    Clip,
    InteractionStimuli,
)
from markovmotion.evaluate.perceptual import ITEMS_PER_TEST, TESTS, choices
from markovmotion.evaluate.stimuli import AVERAGE, Stimulus

SCHEMA = """
CREATE TABLE IF NOT EXISTS stimuli (
    file TEXT PRIMARY KEY, style TEXT NOT NULL, kind TEXT NOT NULL,
    displacement INTEGER NOT NULL);
CREATE TABLE IF NOT EXISTS evaluators (token TEXT PRIMARY KEY, created REAL NOT NULL);
CREATE TABLE IF NOT EXISTS items (
    token TEXT NOT NULL REFERENCES evaluators(token), test TEXT NOT NULL,
    position INTEGER NOT NULL, file TEXT NOT NULL, style TEXT NOT NULL, kind TEXT NOT NULL,
    displacement INTEGER NOT NULL, file_b TEXT,
    PRIMARY KEY (token, test, position));
CREATE TABLE IF NOT EXISTS answers (
    token TEXT NOT NULL, test TEXT NOT NULL, position INTEGER NOT NULL,
    answer TEXT NOT NULL, answered REAL NOT NULL,
    PRIMARY KEY (token, test, position),
    FOREIGN KEY (token, test, position) REFERENCES items(token, test, position));
CREATE TABLE IF NOT EXISTS clips (
    id TEXT PRIMARY KEY, file_a TEXT NOT NULL, file_b TEXT NOT NULL, label TEXT NOT NULL,
    kind TEXT NOT NULL, take TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS clip_labels (position INTEGER PRIMARY KEY, label TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS remarks (
    token TEXT NOT NULL, test TEXT NOT NULL, position INTEGER NOT NULL,
    unusual INTEGER NOT NULL, comment TEXT NOT NULL,
    PRIMARY KEY (token, test, position),
    FOREIGN KEY (token, test, position) REFERENCES items(token, test, position));
"""
STUDIES = ("gait", "interaction")
"""The studies an evaluator may take part in: the gait paper's three tests, the observer study."""


class EvaluationError(MarkovMotionError):
    """An answer that does not fit its item (unknown item, choice not offered)."""


@dataclass(frozen=True)
class Item:
    """One video (or, in the resemblance test, pair of videos) shown to one evaluator.

    For a resemblance pair, ``file`` is shown on the left and ``file_b`` on the
    right; ``kind`` is the kind of the left one. An interaction clip's item has
    its id in ``file``, its label in ``style``, and with its answer ``unusual``
    (the observer noticed something strange) and ``comment``.
    """

    token: str
    test: str
    position: int
    file: str
    style: str
    kind: str
    displacement: bool
    file_b: str | None = None
    answer: str | None = None
    unusual: bool | None = None
    comment: str | None = None


def _sample(pool: list, n: int, rng: np.random.Generator) -> list:
    """``n`` elements of ``pool`` in random order, each used once before any repeats."""
    out: list = []
    while pool and len(out) < n:
        out += [pool[i] for i in rng.permutation(len(pool))]
    return out[:n]


def draw_items(
    token: str, stimuli: list[Stimulus], rng: np.random.Generator, n: int = ITEMS_PER_TEST
) -> list[Item]:
    """Ten items per test: single videos for naturalness and recognition, and for
    resemblance an original and a synthesized walk of the same style, both static
    or both with displacement, in random left/right order (paper §6.2-6.4)."""
    items: list[Item] = []
    for test in TESTS[:2]:
        for pos, s in enumerate(_sample(stimuli, n, rng)):
            items.append(Item(token, test, pos, s.file, s.style, s.kind, s.displacement))
    pairs = [
        (r, s)
        for r in stimuli
        for s in stimuli
        if r.kind == "real"
        and s.kind == "synthetic"
        and r.style == s.style != AVERAGE
        and r.displacement == s.displacement
    ]
    for pos, pair in enumerate(_sample(pairs, n, rng)):
        left, right = pair if rng.random() < 0.5 else pair[::-1]
        items.append(
            Item(
                token,
                TESTS[2],
                pos,
                left.file,
                left.style,
                left.kind,
                left.displacement,
                right.file,
            )
        )
    return items


def draw_clips(token: str, clips: list[Clip], rng: np.random.Generator) -> list[Item]:
    """Every clip of the interaction study once, in a random order (paper §4.2)."""
    return [
        Item(token, INTERACTION, pos, c.id, c.label, c.kind, False)
        for pos, c in enumerate(_sample(clips, len(clips), rng))
    ]


ALL_TESTS = (*TESTS, INTERACTION)


def write_ahead(con: sqlite3.Connection, seconds: float = 30.0) -> None:
    """Put ``con``'s database in WAL mode, trying again while it is locked: a change of
    journal mode can fail at once with "database is locked" rather than wait in SQLite's
    busy handler, and two server workers opening a new database together met that once in
    CI (``serve --workers 2``)."""
    deadline = time.monotonic() + seconds
    while True:
        try:
            con.execute("PRAGMA journal_mode=WAL")
            return
        except sqlite3.OperationalError as exc:
            if "locked" not in str(exc) or time.monotonic() > deadline:
                raise
            time.sleep(0.05)


class EvaluationStore:
    """The evaluation database: evaluators, their drawn items and their answers.

    Safe to share between threads (one connection per thread); every write is
    its own committed transaction. ``interaction`` (the observer study's clips and
    labels) replaces those stored before; without it they are read from the database.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        stimuli: list[Stimulus] | None = None,
        interaction: InteractionStimuli | None = None,
    ):
        self.path = Path(path)
        self._local = threading.local()
        # one writer at a time in this process: threads queue on the lock instead
        # of sleeping in SQLite's busy handler (its back-off reaches 100 ms)
        self._write = threading.Lock()
        con = self._con()
        write_ahead(con)
        con.executescript(SCHEMA)
        if stimuli:
            with self._transaction() as c:
                c.executemany(
                    "INSERT OR REPLACE INTO stimuli VALUES (?, ?, ?, ?)",
                    [(s.file, s.style, s.kind, int(s.displacement)) for s in stimuli],
                )
        self.stimuli = stimuli or self._stored_stimuli()
        if interaction is not None:
            with self._transaction() as c:
                c.execute("DELETE FROM clip_labels")
                c.executemany(
                    "INSERT INTO clip_labels VALUES (?, ?)", list(enumerate(interaction.labels))
                )
                c.executemany(
                    "INSERT OR REPLACE INTO clips VALUES (?, ?, ?, ?, ?, ?)",
                    [
                        (k.id, k.file_a, k.file_b, k.label, k.kind, k.take)
                        for k in interaction.clips
                    ],
                )
        self.interaction = interaction or self._stored_interaction()

    def _con(self) -> sqlite3.Connection:
        con = getattr(self._local, "con", None)
        if con is None:
            con = sqlite3.connect(self.path, timeout=60, isolation_level=None)
            con.execute("PRAGMA foreign_keys=ON")
            self._local.con = con
        return con

    @contextmanager
    def _transaction(self) -> Iterator[sqlite3.Connection]:
        """``BEGIN IMMEDIATE`` ... ``COMMIT`` (``ROLLBACK`` on error), one writer at a time."""
        con = self._con()
        with self._write:
            con.execute("BEGIN IMMEDIATE")
            try:
                yield con
            except BaseException:
                con.execute("ROLLBACK")
                raise
            con.execute("COMMIT")

    def _stored_stimuli(self) -> list[Stimulus]:
        rows = self._con().execute(
            "SELECT file, style, kind, displacement FROM stimuli ORDER BY file"
        )
        return [Stimulus(f, s, k, bool(d)) for f, s, k, d in rows]

    def _stored_interaction(self) -> InteractionStimuli | None:
        con = self._con()
        labels = [r[0] for r in con.execute("SELECT label FROM clip_labels ORDER BY position")]
        clips = [Clip(*row) for row in con.execute("SELECT * FROM clips ORDER BY id")]
        return InteractionStimuli(labels, clips) if labels and clips else None

    def studies(self) -> list[str]:
        """The studies this database has stimuli for, of :data:`STUDIES`."""
        return [
            s
            for s, ok in zip(
                STUDIES, (bool(self.stimuli), self.interaction is not None), strict=True
            )
            if ok
        ]

    @property
    def styles(self) -> list[str]:
        """The walk styles of the stimuli, sorted, without the average walk."""
        return sorted({s.style for s in self.stimuli} - {AVERAGE})

    def create_evaluator(self, rng: np.random.Generator | None = None, study: str = "gait") -> str:
        """A new evaluator of ``study`` (gait or interaction) with their items drawn; returns
        the evaluator's token."""
        rng = rng or np.random.default_rng()
        token = secrets.token_urlsafe(16)
        if study == "interaction" and self.interaction is not None:
            items = draw_clips(token, self.interaction.clips, rng)
        elif study == "gait" and self.stimuli:
            items = draw_items(token, self.stimuli, rng)
        else:
            raise EvaluationError(f"{self.path}: no stimuli for the {study} study")
        with self._transaction() as c:
            c.execute("INSERT INTO evaluators VALUES (?, ?)", (token, time.time()))
            c.executemany(
                "INSERT INTO items VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
                [
                    (i.token, i.test, i.position, i.file, i.style, i.kind, i.displacement, i.file_b)
                    for i in items
                ],
            )
        return token

    def exists(self, token: str) -> bool:
        row = self._con().execute("SELECT 1 FROM evaluators WHERE token = ?", (token,)).fetchone()
        return row is not None

    def study(self, token: str) -> str:
        """The study the evaluator takes part in."""
        row = self._con().execute(
            "SELECT 1 FROM items WHERE token = ? AND test = ? LIMIT 1", (token, INTERACTION)
        )
        return "interaction" if row.fetchone() is not None else "gait"

    def items(self, token: str) -> list[Item]:
        """The evaluator's items in test order, each with its answer (``None`` if unanswered)."""
        return self._items("WHERE i.token = ?", (token,))

    def answered(self) -> list[Item]:
        """Every answered item of every evaluator: the rows the analysis reads."""
        return self._items("WHERE a.answer IS NOT NULL", ())

    def _items(self, where: str, args: tuple) -> list[Item]:
        rows = self._con().execute(
            "SELECT i.token, i.test, i.position, i.file, i.style, i.kind, i.displacement, "
            "i.file_b, a.answer, r.unusual, r.comment FROM items i LEFT JOIN answers a "
            "ON a.token = i.token AND a.test = i.test AND a.position = i.position "
            "LEFT JOIN remarks r "
            "ON r.token = i.token AND r.test = i.test AND r.position = i.position "
            f"{where} ORDER BY i.token, i.test, i.position",
            args,
        )
        out = [
            Item(t, te, p, f, s, k, bool(d), fb, a, None if u is None else bool(u), c)
            for t, te, p, f, s, k, d, fb, a, u, c in rows
        ]
        order = {t: n for n, t in enumerate(ALL_TESTS)}
        return sorted(out, key=lambda i: (i.token, order.get(i.test, len(order)), i.position))

    def item(self, token: str, test: str, position: int) -> Item | None:
        found = self._items(
            "WHERE i.token = ? AND i.test = ? AND i.position = ?", (token, test, position)
        )
        return found[0] if found else None

    def answer(
        self,
        token: str,
        test: str,
        position: int,
        answer: str,
        unusual: bool = False,
        comment: str | None = None,
    ) -> None:
        """Record (or change) an answer, committed at once; in the interaction study with
        whether the observer noticed something unusual and their comment (stripped)."""
        if test == INTERACTION:
            offered = self.interaction.choices() if self.interaction else ()
        elif test in TESTS:
            offered = choices(test, self.styles)
        else:
            raise EvaluationError(f"unknown test {test!r}; expected one of {ALL_TESTS}")
        if answer not in offered:
            raise EvaluationError(f"{answer!r} is not a choice of the {test} test")
        text = (comment or "").strip()
        if len(text) > MAX_COMMENT:
            raise EvaluationError(f"the comment is longer than {MAX_COMMENT} characters")
        try:
            with self._transaction() as con:
                con.execute(
                    "INSERT INTO answers VALUES (?, ?, ?, ?, ?) "
                    "ON CONFLICT (token, test, position) DO UPDATE SET answer = excluded.answer, answered = excluded.answered",
                    (token, test, position, answer, time.time()),
                )
                if test == INTERACTION:
                    con.execute(
                        "INSERT INTO remarks VALUES (?, ?, ?, ?, ?) "
                        "ON CONFLICT (token, test, position) DO UPDATE SET "
                        "unusual = excluded.unusual, comment = excluded.comment",
                        (token, test, position, int(bool(unusual)), text),
                    )
        except sqlite3.IntegrityError:  # the foreign key: no such item
            raise EvaluationError(f"no item {test} #{position} for this evaluator") from None

    def count_answers(self) -> int:
        return self._con().execute("SELECT COUNT(*) FROM answers").fetchone()[0]

    def count_evaluators(self) -> int:
        return self._con().execute("SELECT COUNT(*) FROM evaluators").fetchone()[0]


FORMULA_STARTS = ("=", "+", "-", "@", "\t", "\r")
"""First characters that make a spreadsheet read a CSV cell as a formula (OWASP CSV injection)."""


def csv_safe(value: object) -> object:
    """``value`` for a CSV cell opened by a spreadsheet: a string beginning with one of
    :data:`FORMULA_STARTS` gets a leading single quote so it stays text; numbers and
    other strings are unchanged."""
    if isinstance(value, str) and value.startswith(FORMULA_STARTS):
        return "'" + value
    return value


def open_results(path: str | os.PathLike[str]) -> EvaluationStore:
    """An existing evaluation database, for the offline report."""
    if not Path(path).is_file():
        raise EvaluationError(f"{path}: no such evaluation database")
    if Path(path).stat().st_size == 0:  # SQLite would turn an empty file into a database
        raise EvaluationError(f"{path}: not an evaluation database (the file is empty)")
    try:
        return EvaluationStore(path)
    except sqlite3.DatabaseError as exc:
        raise EvaluationError(f"{path}: not an evaluation database ({exc})") from None
