"""Printing results: tables (Rich boxes on a terminal, full text everywhere else) and JSON.

Rich squeezes a table into the console width and truncates cells with an
ellipsis. On a terminal that is what a reader wants; piped into a file or a
log (80 columns assumed) a truncated name is lost. So when standard output is
not a terminal and the table would be wider than 80 columns, it is printed as
CSV (title and caption as ``#`` comment lines), every cell whole.
"""

from __future__ import annotations

import csv
import io
import sys

from rich.console import Console
from rich.measure import Measurement
from rich.table import Table

from markovmotion.state import json_text

#: The width assumed for output that is not a terminal.
PLAIN_WIDTH = 80


def _plain(cell: object) -> str:
    text = getattr(cell, "plain", None)
    return str(cell) if text is None else text


def table_rows(table: Table) -> list[list[str]]:
    """The header and body of ``table`` as plain strings."""
    columns = table.columns
    header = [_plain(c.header) for c in columns]
    cells = [[_plain(c) for c in col.cells] for col in columns]
    return [header] + [list(row) for row in zip(*cells, strict=True)]


def table_as_csv(table: Table) -> str:
    """``table`` as CSV text, title and caption as ``#`` lines."""
    buf = io.StringIO()
    if table.title:
        buf.write(f"# {_plain(table.title)}\n")
    csv.writer(buf, lineterminator="\n").writerows(table_rows(table))
    if table.caption:
        buf.write(f"# {_plain(table.caption)}\n")
    return buf.getvalue()


def print_table(table: Table, console: Console | None = None) -> None:
    """Print ``table`` to standard output (see the module docstring)."""
    console = console or Console()
    if console.is_terminal:
        console.print(table)
        return
    wide = Console(width=10_000, file=io.StringIO())
    width = Measurement.get(wide, wide.options, table).maximum
    if width <= PLAIN_WIDTH:
        Console(width=PLAIN_WIDTH, file=console.file).print(table)
    else:
        (console.file or sys.stdout).write(table_as_csv(table))


def print_json(value: object, indent: int | None = None) -> None:
    """Print ``value`` as strict JSON on standard output (:func:`json_text`)."""
    print(json_text(value, indent))


def print_notes(lines: list[str]) -> None:
    """Print a summary's notes (stderr, with or without ``--json``), but those the camera
    file's reading printed already (:func:`~markovmotion.progress.say`): every note is
    in the JSON's ``notes``, and on the terminal once."""
    from markovmotion.progress import err_console, said

    for line in lines:
        if not said(line):
            err_console.print(line, highlight=False)


def world_frame_note(model: object, name: object, world: str) -> None:
    """A note (stderr) when ``model`` is a dual HMM placing B along its capture room's axes
    (``frame_`` 'world', as ``--frame auto`` picks for some takes), named ``name``, answering
    in ``world``, where those axes mean nothing: ``dualhmm respond --video`` and ``serve
    --partner`` say it alike (serve had said nothing)."""
    from markovmotion.progress import note

    if getattr(model, "frame_", "heading") == "world":
        note(
            f"{name} places B along its capture room's axes from A (frame 'world'), which "
            f"mean nothing in {world}: train it with --frame heading to place B by where A faces"
        )


def say_people_trained_on(report: dict) -> None:
    """A note when an evaluation's test people are people the model learnt other takes of
    (``people_trained_on``): its numbers, and the aims for new people, are then not about
    people it has never seen."""
    seen = report.get("people_trained_on")
    if seen:
        from markovmotion.progress import note

        note(
            f"the model learnt other takes of the test takes' people {', '.join(seen)}: these "
            "are not people it has never seen (train with --test-people to hold them out)"
        )
