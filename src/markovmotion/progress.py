"""Progress bars for long work, on stderr so that JSON on stdout stays clean.

On a terminal, Rich's live bar. Elsewhere (a log file, nohup, CI) a live bar
cannot redraw, so long work prints a plain line every :data:`LOG_EVERY`
seconds instead; work shorter than that prints nothing.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Iterable, Iterator, Sequence
from contextlib import contextmanager
from contextvars import ContextVar
from typing import TypeVar

from rich.console import Console
from rich.markup import escape
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TaskID,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)

T = TypeVar("T")

# soft_wrap: a long message stays one line when stderr is not a terminal (a log, a pipe),
# where Rich would otherwise wrap it at 80 columns mid-number
err_console = Console(stderr=True, soft_wrap=True)


def note(message: str) -> None:
    """One line to stderr about a choice the library made for the user (takes left out,
    a kind chosen): where commands and the demo show it, off stdout's JSON; inside
    :func:`notes_caught`, kept instead."""
    caught = _CAUGHT.get()
    if caught is not None:
        caught.append(message)
        return
    err_console.print(f"[yellow]note:[/] {escape(message)}", highlight=False)


#: Where :func:`note` keeps its lines inside :func:`notes_caught` (None: it prints them).
_CAUGHT: ContextVar[list[str] | None] = ContextVar("notes_caught", default=None)


@contextmanager
def notes_caught() -> Iterator[list[str]]:
    """The notes (:func:`note`, :func:`say`) made inside, kept rather than printed, for a
    caller that reports them its own way (``data check`` lists them as findings)."""
    caught: list[str] = []
    token = _CAUGHT.set(caught)
    try:
        yield caught
    finally:
        _CAUGHT.reset(token)


#: The notes printed in this command (:func:`say`), with the file each is about.
_SAID: set[tuple[str, str]] = set()


def say(lines: Sequence[str], notes: list[str] | None = None, about: object = "") -> None:
    """Print each note (``"note: ..."``) not printed before in this command about the same
    file (``about``), and add every one to ``notes`` if given: a command takes its camera
    file more than once (the CLI, then the tracker, then ``--truth``; read once,
    :func:`~markovmotion.video.cameras.read_camera_file`), and a summary's ``notes`` must
    hold them all the same."""
    for line in lines:
        key = (str(about), line)
        if key not in _SAID:
            _SAID.add(key)
            note(line.removeprefix("note: "))
        if notes is not None:
            notes.append(line)


def said(line: str) -> bool:
    """Whether :func:`say` printed this line in this command (a summary's notes that the
    command prints at its end leave them out)."""
    return any(line == printed for _, printed in _SAID)


def new_command() -> None:
    """Forget the notes said (:func:`say`): a command starts, and says them again (tests run
    many commands in one process)."""
    _SAID.clear()


class NoteOnce(logging.Handler):
    """The library's log warnings as notes (:func:`note`), each kind once per command: a
    cross-validation fits a model per fold and setting, and one line per fit ("Fitting a
    model with 3103 free scalar parameters with only 3060 data points ...") buried the
    results; the count of repeats is said at :meth:`close`. A kind is the message before
    its arguments (``"frame %d of A is missing"`` is one kind whatever the frame)."""

    def __init__(self) -> None:
        super().__init__(logging.WARNING)
        self.seen: dict[str, int] = {}
        self.first: dict[str, str] = {}

    def emit(self, record: logging.LogRecord) -> None:
        kind = str(record.msg)
        self.seen[kind] = self.seen.get(kind, 0) + 1
        if self.seen[kind] == 1:
            self.first[kind] = record.getMessage()
            note(self.first[kind])

    def close(self) -> None:
        for kind, count in self.seen.items():
            if count > 1:
                note(f"{count} times in all, the first: {self.first[kind]}")
        self.seen.clear()
        super().close()


#: Seconds between the plain progress lines printed off a terminal.
LOG_EVERY = 30.0


class _Progress(Progress):
    """Rich's progress display, which logs a line now and then where it cannot draw."""

    def __init__(self, *columns, **options):
        super().__init__(*columns, **options)
        self._logged_at = time.monotonic()
        self._logged: set[TaskID] = set()  # tasks that printed a line: they print their end too

    def advance(self, task_id: TaskID, advance: float = 1) -> None:
        super().advance(task_id, advance)
        self._log(task_id)

    def update(self, task_id: TaskID, **changes) -> None:
        super().update(task_id, **changes)
        self._log(task_id)

    def _log(self, task_id: TaskID) -> None:
        if not self.disable:
            return
        now = time.monotonic()
        task = self._tasks[task_id]
        ended = bool(task.total) and task.completed >= task.total and task_id in self._logged
        if now - self._logged_at < LOG_EVERY and not ended:
            return
        self._logged_at = now
        if bool(task.total) and task.completed >= task.total:
            self._logged.discard(task_id)  # its end is said once (a task reused prints anew)
        else:
            self._logged.add(task_id)
        done = f"{task.completed:g}/{task.total:g}" if task.total else f"{task.completed:g}"
        self.console.print(
            f"{task.description}: {done}, {task.elapsed or 0.0:.0f} s", highlight=False
        )


def progress_bar() -> Progress:
    """A Rich progress display with the columns used across markovmotion."""
    return _Progress(
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        console=err_console,
        disable=not err_console.is_terminal,
    )


def track(items: Iterable[T], description: str, total: int | None = None) -> Iterator[T]:
    """Iterate over ``items`` with a progress bar (shown only on a terminal)."""
    if total is None and hasattr(items, "__len__"):
        total = len(items)  # type: ignore[arg-type]
    with progress_bar() as bar:
        task = bar.add_task(description, total=total)
        for item in items:
            yield item
            bar.advance(task)
