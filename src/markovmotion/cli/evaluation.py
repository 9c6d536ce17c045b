"""``evaluation``: build the stimuli of the perceptual studies and analyse their answers."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import typer
from rich.console import Console
from rich.table import Table

from markovmotion.cli.tables import print_table
from markovmotion.evaluate.interaction import summarise_interaction
from markovmotion.evaluate.perceptual import LABELS, RESEMBLANCE, TESTS, answers_csv, summarise
from markovmotion.evaluate.store import open_results
from markovmotion.io.files import atomic_write
from markovmotion.state import json_text

app = typer.Typer(
    help="Perceptual evaluation: synthesized walks (gait paper §6), generated interactions "
    "(dual-HMM paper §4.2).",
    no_args_is_help=True,
)


def _pct(v: float) -> str:
    return "–" if v != v else f"{v:.1f}"


def _pairs(values: list[str], what: str) -> dict[str, Path]:
    out = {}
    for v in values:
        style, sep, file = v.partition("=")
        if not sep or not style or not file:
            raise typer.BadParameter(f"{v!r}: expected STYLE=FILE", param_hint=what)
        out[style] = Path(file)
    return out


STUDIES = ("gait", "interaction")


def _study(value: str) -> str:
    if value not in STUDIES:
        raise typer.BadParameter(f"{value!r}: must be one of {', '.join(STUDIES)}")
    return value


@app.command()
def stimuli(
    out_arg: Path = typer.Argument(
        None, metavar="[OUT]", help="Folder to write the stimuli into (or --out)."
    ),
    out: Path = typer.Option(None, "--out", help="Folder to write the stimuli into."),
    study: str = typer.Option(
        "gait",
        callback=_study,
        help="gait: the walks of the gait paper (§6.1); interaction: the dual-HMM "
        "paper's observer study (§4.2) from --model.",
    ),
    real: list[str] = typer.Option([], help="STYLE=FILE of an original walk (repeat; gait)."),
    synthetic: list[str] = typer.Option(
        [],
        help="STYLE=FILE of a synthesized walk (repeat; style 'average' for the average model; "
        "gait).",
    ),
    model: Path = typer.Option(None, help="The dual-HMM model (.npz) generating B (interaction)."),
    test: Path = typer.Option(
        None,
        help="INDEX.csv (or its folder) whose two-person takes to show (interaction; default: "
        "the model's held-out takes). Takes the model trained on are left out.",
    ),
    videos: bool = typer.Option(
        False, "--videos", help="Also render each clip as a point-light MP4 (interaction)."
    ),
) -> None:
    """Gait: each walk with and without root displacement (§6.1). Interaction: per test take,
    the real clip and one with B generated from A. Anonymised, with a manifest."""
    if out is not None and out_arg is not None and out != out_arg:
        raise typer.BadParameter("give the folder once, as OUT or --out", param_hint="--out")
    folder = out or out_arg
    if folder is None:
        raise typer.BadParameter("where to write the stimuli: give --out DIR", param_hint="--out")
    if study == "interaction":
        if real or synthetic:
            raise typer.BadParameter("--real/--synthetic are walks: for --study gait")
        if model is None:
            raise typer.BadParameter("--study interaction needs --model M.npz (a dual HMM)")
        from markovmotion.evaluate.interaction import write_interaction_stimuli

        made = write_interaction_stimuli(folder, model, test, videos=videos)
        counts = {k: sum(c.kind == k for c in made.clips) for k in ("real", "generated")}
        Console(stderr=True).print(
            f"wrote {counts['real']} real and {counts['generated']} generated clips "
            f"({', '.join(made.labels)}) and {folder / 'interaction.json'}",
            highlight=False,
        )
        return
    if model is not None or test is not None or videos:
        raise typer.BadParameter(
            "--model/--test/--videos build interaction clips: add --study interaction"
        )
    from markovmotion.evaluate.stimuli import write_stimuli

    written = write_stimuli(folder, _pairs(real, "--real"), _pairs(synthetic, "--synthetic"))
    Console(stderr=True).print(f"wrote {len(written)} stimuli and {folder / 'manifest.csv'}")


@app.command()
def report(
    db: Path = typer.Argument(..., help="The results.sqlite of 'markovmotion serve'."),
    csv: Path = typer.Option(None, help="Also write every answer to this CSV file."),
    json_out: Path = typer.Option(None, "--json", help="Also write the figures to this JSON file."),
) -> None:
    """Recompute the figures of the paper's §6 from the answers in DB."""
    store = open_results(db)
    items = store.answered()
    rep = summarise([i for i in items if i.test in TESTS], store.styles)
    console = Console()
    if store.stimuli or store.interaction is None:
        _print_gait(store, rep, console)
    figures = rep.to_dict()
    if store.interaction is not None:
        figures["interaction"] = inter = summarise_interaction(
            items, store.interaction.labels, store.interaction.clips
        )
        _print_interaction(inter, console)
    if csv:
        with atomic_write(csv) as fh:
            fh.write(answers_csv(items))
    if json_out:
        with atomic_write(json_out) as fh:
            fh.write(json_text(figures, indent=1))


def _print_interaction(s: dict, console: Console) -> None:
    """The observer study's tables (dual-HMM paper §4.2, Tables 1-2)."""
    console.print(
        f"Interactions: {s['observers']} observers, {s['answers']} answers", highlight=False
    )
    t = Table(title="Identification of the action, % (correct/answers); noticed something unusual")
    t.add_column("behaviour")
    for kind in s["kinds"]:
        t.add_column(f"identified, {kind}", justify="right")
        t.add_column(f"unusual, {kind}", justify="right")
    rows = [(label, s["rates"][label]) for label in s["labels"]] + [("all", s["overall"])]
    for label, row in rows:
        cells = []
        for kind in s["kinds"]:
            c = row[kind]
            rate = "–" if c["rate"] is None else f"{c['rate']:.1f}"
            cells += [f"{rate} ({c['correct']}/{c['n']})", f"{c['unusual']}/{c['n']}"]
        t.add_row(label, *cells)
    print_table(t, console)
    t = Table(title="Comments per video")
    for col in ("video", "behaviour", "kind", "take", "unusual", "comments"):
        t.add_column(col)
    for c in s["clips"]:
        t.add_row(
            c["clip"],
            c["label"],
            c["kind"],
            c["take"],
            f"{c['unusual']}/{c['n']}",
            " | ".join(c["comments"]) or "–",
        )
    print_table(t, console)


def _print_gait(store, rep, console: Console) -> None:
    """The gait study's tables (gait paper §6)."""
    console.print(
        f"{store.count_evaluators()} evaluators registered, {rep.evaluators} answered; "
        f"answers: {rep.answers['naturalness']} naturalness, {rep.answers['recognition']} style, "
        f"{rep.answers['resemblance']} resemblance",
        highlight=False,
    )
    t = Table(title="Naturalness (Fig. 5), % of answers")
    for col in ("", "real", "synthetic", "I don't know", "n"):
        t.add_column(col, justify="right")
    for kind, name in (("real", "original"), ("synthetic", "synthesized")):
        row = rep.naturalness[kind]
        t.add_row(name, *(_pct(row[c]) for c in ("real", "synthetic", "dont_know")), str(row["n"]))
    print_table(t, console)

    t = Table(title="Style recognition (Table 3), % correct")
    for col in ("", "original", "synthesized"):
        t.add_column(col, justify="right")
    for cond in ("static", "displacement", "all"):
        t.add_row(
            cond, _pct(rep.recognition["real"][cond]), _pct(rep.recognition["synthetic"][cond])
        )
    t.add_row(
        "efficiency η (eq. 16)",
        f"{rep.efficiency['real']:.2f}",
        f"{rep.efficiency['synthetic']:.2f}",
    )
    print_table(t, console)
    console.print(
        f"chance {rep.chance:.2f} %; Pearson correlation of per-style recognition, "
        f"original vs synthesized: {rep.correlation:.4f}",
        highlight=False,
    )
    for kind, name in (("real", "original"), ("synthetic", "synthesized")):
        c = rep.confusion[kind]
        t = Table(title=f"Confusion matrix (Table 2), {name}, % of the videos of each style")
        t.add_column("actual")
        for col in c.columns:
            t.add_column(LABELS.get(col, col), justify="right")
        for style, row in zip(c.rows, c.percent, strict=True):
            t.add_row(LABELS.get(style, style), *(_pct(v) for v in row))
        print_table(t, console)
    score = rep.resemblance_score
    shown = f"{score:.2f}" if np.isfinite(score) else "- (no answers yet)"
    t = Table(title=f"Resemblance (Fig. 8): mean score {shown} of 4")
    t.add_column("level")
    t.add_column("answers", justify="right")
    for level in range(len(RESEMBLANCE) - 1, -1, -1):
        t.add_row(f"{level} {RESEMBLANCE[level]}", str(rep.resemblance_histogram[level]))
    print_table(t, console)
