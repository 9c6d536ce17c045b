"""``data list``, ``data check`` and ``data fetch``: what motion capture is available, whether
an INDEX.csv holds together, and getting it."""

from __future__ import annotations

from pathlib import Path

import typer
from rich.table import Table

from markovmotion.cli.options import choice
from markovmotion.cli.tables import print_table
from markovmotion.data import MocapIndex
from markovmotion.data.fetch import BANDAI_BASE_URL, CMU_BASE_URL, INTERACTION_SUBJECTS, fetch
from markovmotion.data.kinds import KINDS, counted
from markovmotion.progress import err_console

app = typer.Typer(
    help="The motion-capture collection: list it, check it, fetch it.", no_args_is_help=True
)


@app.command("list")
def list_(
    data: Path = typer.Option(None, help="Folder with INDEX.csv (default: see README)."),
    category: str = typer.Option(None, help="Only this category (walk, style_walk, ...)."),
    label: str = typer.Option(None, help="Only this label (salsa, normal, sad, ...)."),
    source: str = typer.Option(None, help="Only this source (cmu, bandai, buetepage)."),
    kind: str = typer.Option(
        None,
        callback=choice(KINDS),
        help="Only 'skeleton' takes (BVH, ASF/AMC) or 'markers' (C3D).",
    ),
) -> None:
    """List the motions of the collection, with the kind of each (skeleton and its joint
    count, or markers and their count, read from the files' headers)."""
    from markovmotion.errors import MarkovMotionError
    from markovmotion.io import describe_take

    index = MocapIndex.load(data)
    rows = index.query(category=category, label=label, source=source, kind=kind)
    table = Table(title=f"{len(rows)} of {len(index)} motions in {index.root}")
    for col in ("file", "source", "subject", "category", "label", "kind", "fps", "frames"):
        table.add_column(col)
    for e in rows:
        try:
            what, count = describe_take(e.path)
            shape = f"{what}, {count} {'points' if what == 'markers' else 'joints'}"
        except MarkovMotionError as exc:  # listed but unreadable: say so, keep listing
            shape = f"{e.kind}, unreadable ({exc})"
        table.add_row(
            e.file, e.source, e.subject, e.category, e.label, shape, f"{e.fps:g}", str(e.frames)
        )
    print_table(table)


@app.command("check")
def check_(
    data: Path = typer.Option(None, help="Folder with INDEX.csv (default: see README)."),
    json_out: bool = typer.Option(False, "--json", help="Print the findings as JSON."),
) -> None:
    """Check an INDEX.csv against its files: every take read whole, its frames as listed,
    two-person takes paired both ways with as many frames, people named (exit 1 on an error)."""
    from markovmotion.cli.tables import print_json
    from markovmotion.data.check import check_index

    index = MocapIndex.load(data)
    found = check_index(index)
    errors = sum(f.level == "error" for f in found)
    if json_out:
        print_json({"index": str(index.root / "INDEX.csv"), "takes": len(index),
                    "errors": errors, "findings": [f.to_dict() for f in found]})  # fmt: skip
    else:
        if found:
            table = Table(title=f"{counted(len(found), 'findings')} in {index.root / 'INDEX.csv'}")
            for col in ("file", "level", "problem"):
                table.add_column(col)
            for f in found:
                table.add_row(f.file, f.level, f.problem)
            print_table(table)
        notes = len(found) - errors
        err_console.print(
            f"{index.root / 'INDEX.csv'}: {counted(len(index), 'takes')}, "
            f"{counted(errors, 'errors')}, {counted(notes, 'notes')}"
            + ("" if found else ": every take read whole, frames as listed, pairs paired")
        )
    if errors:
        raise typer.Exit(1)


def _subject_numbers(value: str) -> list[int]:
    try:
        numbers = [int(v) for v in value.replace(" ", "").split(",") if v]
    except ValueError:
        raise typer.BadParameter(f"{value!r} is not a comma-separated list of numbers") from None
    if any(n < 1 for n in numbers):
        raise typer.BadParameter(f"{value!r}: CMU subject numbers start at 1")
    return numbers


@app.command("fetch")
def fetch_(
    dest: Path = typer.Option(..., help="Folder to download into (created if needed)."),
    subjects: str = typer.Option(
        ",".join(str(s) for s in INTERACTION_SUBJECTS),
        help="CMU subjects, comma-separated ('' for none); 18-23 are the two-person takes.",
    ),
    bandai: bool = typer.Option(True, "--bandai/--no-bandai", help="Fetch the Bandai Namco walks."),
    base_url_cmu: str = typer.Option(CMU_BASE_URL, help="Where CMU's NN/NN_TT.amc files are."),
    base_url_bandai: str = typer.Option(
        BANDAI_BASE_URL, help="Where the Bandai Namco repository's dataset/ folder is."
    ),
    max_missing: int = typer.Option(
        3, min=1, help="Stop probing a subject or style after this many missing files in a row."
    ),
    retries: int = typer.Option(4, min=0, help="Retries of a failing download before giving up."),
) -> None:
    """Download CMU (ASF/AMC) and Bandai Namco (BVH) motion capture and index it in DEST/INDEX.csv.

    Re-running resumes partial downloads and adds only what is new. CMU asks
    users not to crawl its site: fetch the subjects you need.
    """
    report = fetch(
        dest,
        _subject_numbers(subjects),
        bandai,
        cmu_base_url=base_url_cmu,
        bandai_base_url=base_url_bandai,
        max_missing=max_missing,
        retries=retries,
    )
    for line in report.missing:
        err_console.print(f"[yellow]not found:[/] {line}", highlight=False, soft_wrap=True)
    for _, problem in report.rejected:
        err_console.print(f"[bold red]rejected:[/] {problem}", highlight=False, soft_wrap=True)
    err_console.print(
        f"{len(report.indexed)} new and {len(report.kept)} already present motions, "
        f"{len(report.rejected)} rejected; {report.dest / 'INDEX.csv'} lists {report.total}",
        highlight=False,
        soft_wrap=True,
    )
