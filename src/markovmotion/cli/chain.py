"""``chain``: interaction behaviour models and virtual partners (interaction paper).

Train the behaviour chain on two-person takes (3-D motion capture or tracked
silhouettes), answer a real person with a virtual partner, and evaluate it on
the held-out takes.
"""

from __future__ import annotations

import json
from pathlib import Path

import typer
from rich.console import Console
from rich.table import Table

from markovmotion.core.motion import Motion
from markovmotion.data import MocapIndex
from markovmotion.errors import DataNotFoundError, MarkovMotionError
from markovmotion.evaluate.chain import SOURCES, evaluate_partner, mocap_takes, salsa_split
from markovmotion.io import read_motion, write_motion
from markovmotion.io.files import base_suffix
from markovmotion.models.virtual_partner import VirtualPartner
from markovmotion.progress import err_console

app = typer.Typer(
    help="Interaction behaviour models (interaction paper): behaviour chain over two people's "
    "joint shapes, virtual partner by single- or multiple-hypothesis (CONDENSATION) propagation.",
    no_args_is_help=True,
)


def _check_source(source: str) -> None:
    if source not in SOURCES:
        raise typer.BadParameter(f"source must be one of {', '.join(SOURCES)}")


def _training_takes(data: Path | None, source: str, label: str):
    if source == "mocap":
        index = MocapIndex.load(data)
        train, _ = salsa_split(index, label)
        return mocap_takes(index, train)
    from markovmotion.video.dataset import silhouette_takes

    return silhouette_takes(data, split="train")


def _read_person(path: Path, fps: float | None) -> Motion:
    """A BVH input; a file of the motion-capture collection is read as INDEX.csv says
    (true frame rate, CMU's reference frame dropped)."""
    if fps is None:
        try:
            index = MocapIndex.load()
            return index.load_motion(index.find(path.resolve().relative_to(index.root).as_posix()))
        except (DataNotFoundError, ValueError):
            pass
    return read_motion(path, fps=fps)


@app.command()
def train(
    out: Path = typer.Option(..., help="Model file to write (.npz)."),
    data: Path = typer.Option(
        None,
        help="mocap: folder with INDEX.csv (default: see README); "
        "silhouette: folder written by 'silhouette render'.",
    ),
    source: str = typer.Option("mocap", help="mocap (3-D joints) or silhouette (tracked video)."),
    label: str = typer.Option("salsa", help="Label of the two-person takes (mocap)."),
    prototypes: int = typer.Option(300, min=2, help="State prototypes u (paper: 300)."),
    behaviours: int = typer.Option(300, min=2, help="Behaviour prototypes v (paper: 300)."),
    gamma: float = typer.Option(0.995, min=0.0, max=1.0, help="Decay constant of eq. 10."),
    lam: float = typer.Option(10.0, min=0.0, help="Weight lambda of dC (paper: 10)."),
    epochs: int = typer.Option(5, min=1, help="Passes of each competitive learning."),
    seed: int = typer.Option(0, help="Random seed of the quantisations."),
) -> None:
    """Learn a behaviour chain from the training takes (held-out trials excluded)."""
    _check_source(source)
    takes = _training_takes(data, source, label)
    model = VirtualPartner(
        lam=lam,
        n_state_prototypes=prototypes,
        n_behaviour_prototypes=behaviours,
        gamma=gamma,
        n_epochs=epochs,
        random_state=seed,
    )
    with err_console.status("learning prototypes and chain"):
        model.fit(takes)
    model.save(out, source=source)
    ch = model.chain_
    frames = sum(t.n_frames for t in takes)
    err_console.print(
        f"wrote {out}: {len(takes)} takes, {frames} frames at {model.fps_:g} fps, "
        f"{ch.state_prototypes_.shape} state prototypes, "
        f"{len(ch.behaviour_prototypes_) + 1}-state chain",
        highlight=False,
    )


@app.command()
def respond(
    model: Path = typer.Option(..., help="Model from 'chain train'."),
    input: Path = typer.Option(..., help="The real person: BVH (mocap model) or video."),
    out: Path = typer.Option(..., help="Output: .bvh (mocap partner) or .mp4 (video)."),
    hypotheses: int = typer.Option(200, min=1, help="Hypotheses N (1: single hypothesis)."),
    response: str = typer.Option("ml", help="ml or map (eq. 21) hypothesis as the response."),
    person: int = typer.Option(0, min=0, max=1, help="Mocap: the real person's half of the model."),
    fps: float = typer.Option(
        None, help="True frame rate of a BVH input (default: INDEX.csv's if it is listed there)."
    ),
    seed: int = typer.Option(0, help="Random seed."),
) -> None:
    """Drive a virtual partner from a real person's motion or video."""
    partner_model, source = VirtualPartner.load(model)
    options = {"n_hypotheses": hypotheses, "response": response, "seed": seed}
    suffix = base_suffix(out)
    if suffix not in (".bvh", ".mp4"):
        raise MarkovMotionError(f"{out}: write the partner as .bvh (mocap) or .mp4")
    if source == "mocap":
        motion = _read_person(input, fps).resample(partner_model.fps_)
        if suffix == ".bvh":
            partner = partner_model.respond_motion(motion, person, **options)
            write_motion(partner, out)
        else:
            from markovmotion.video.partner import respond_motion_video

            respond_motion_video(partner_model, motion, out, person, **options)
    elif suffix == ".mp4":
        from markovmotion.video.partner import respond_video

        respond_video(partner_model, input, out, **options)
    else:
        raise MarkovMotionError(f"{out}: a silhouette model writes the partner into an .mp4")
    err_console.print(f"wrote {out}", highlight=False)


@app.command()
def evaluate(
    model: Path = typer.Option(..., help="Model from 'chain train'."),
    test: Path = typer.Option(
        None,
        help="mocap: INDEX.csv or its folder; silhouette: folder written by 'silhouette render'.",
    ),
    hypotheses: int = typer.Option(200, min=2, help="Hypotheses N of the multiple-hypothesis run."),
    label: str = typer.Option("salsa", help="Label of the two-person takes (mocap)."),
    seed: int = typer.Option(0, help="Random seed."),
    as_json: bool = typer.Option(False, "--json", help="Print the result as JSON on stdout."),
) -> None:
    """Mask one partner of each held-out take, generate it, report the errors."""
    partner_model, source = VirtualPartner.load(model)
    if source == "mocap":
        index = MocapIndex.load(test)
        _, held_out = salsa_split(index, label)
        takes = mocap_takes(index, held_out, fps=partner_model.fps_)
    else:
        from markovmotion.video.dataset import silhouette_takes

        takes = silhouette_takes(test, split="test")
    result = evaluate_partner(partner_model, takes, source, hypotheses, seed)
    if as_json:
        typer.echo(json.dumps(result, indent=2))
        return
    table = Table(title=f"virtual partner on {len(takes)} held-out takes ({result['unit']})")
    table.add_column("partner")
    table.add_column("error")
    table.add_column("ms / frame")
    for key in (
        "mean_shape",
        "single_hypothesis",
        "multiple_hypotheses",
        "multiple_hypotheses_map",
    ):
        ms = result["per_frame_ms"].get(key)
        table.add_row(key, f"{result[key]:.4g}", "" if ms is None else f"{ms:.2f}")
    Console().print(table)
