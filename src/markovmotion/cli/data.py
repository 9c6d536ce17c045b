"""``data list``: what motion capture is available."""

from __future__ import annotations

from pathlib import Path

import typer
from rich.console import Console
from rich.table import Table

from markovmotion.data import MocapIndex

app = typer.Typer(help="The motion-capture collection: list it, fetch it.", no_args_is_help=True)


@app.command("list")
def list_(
    data: Path = typer.Option(None, help="Folder with INDEX.csv (default: see README)."),
    category: str = typer.Option(None, help="Only this category (walk, style_walk, ...)."),
    label: str = typer.Option(None, help="Only this label (salsa, normal, sad, ...)."),
    source: str = typer.Option(None, help="Only this source (cmu, bandai)."),
) -> None:
    """List the motions of the collection."""
    index = MocapIndex.load(data)
    rows = index.query(category=category, label=label, source=source)
    table = Table(title=f"{len(rows)} of {len(index)} motions in {index.root}")
    for col in ("file", "source", "category", "label", "fps", "frames"):
        table.add_column(col)
    for e in rows:
        table.add_row(e.file, e.source, e.category, e.label, f"{e.fps:g}", str(e.frames))
    Console().print(table)
