"""``vlmm``: behaviour models over prototypes (VLMM paper): train, generate, predict, evaluate."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import typer
from rich.console import Console
from rich.table import Table

from markovmotion.data import MocapIndex
from markovmotion.data.index import read_listed_motion
from markovmotion.errors import DataNotFoundError, SkeletonMismatchError
from markovmotion.io import check_motion_output, write_motion
from markovmotion.persist import check_model_output
from markovmotion.progress import err_console

app = typer.Typer(
    help="Variable-length Markov models of behaviour (VLMM paper): prototypes, a VLMM over "
    "them and the structured two-level model; synthesize routines, predict motion.",
    no_args_is_help=True,
)

#: The first-order Markov model: memory 1, every context kept.
FIRST_ORDER = (1, 0.0)


def _rng(stochastic: bool, seed: int) -> np.random.Generator | None:
    return np.random.default_rng(seed) if stochastic else None


def _memory_table(title: str, vlmm) -> Table:
    """Number of automaton states per memory length (paper Figs. 3 and 8)."""
    hist = vlmm.memory_length_histogram()
    tree = np.bincount(vlmm.memory_lengths_[vlmm.in_suffix_tree_], minlength=len(hist))
    table = Table(title=title)
    table.add_column("memory length")
    table.add_column("states")
    table.add_column("of which suffix-tree memories")
    for n, (a, b) in enumerate(zip(hist, tree, strict=True)):
        if a:
            table.add_row(str(n), str(a), str(b))
    table.caption = f"{vlmm.n_states} states, {int(vlmm.in_suffix_tree_.sum())} memories"
    return table


@app.command()
def train(
    out: Path = typer.Option(..., help="Model file to write (.npz)."),
    data: Path = typer.Option(None, help="Folder with INDEX.csv (default: see README)."),
    category: str = typer.Option("exercise", help="Category of the training takes."),
    label: list[str] = typer.Option(None, help="Only these labels (repeatable; default all)."),
    prototypes: int = typer.Option(100, min=2, help="Number of prototypes K."),
    max_memory: int = typer.Option(5, min=0, help="Maximum memory length N of the VLMM."),
    epsilon: float = typer.Option(1e-4, min=0.0, help="KL threshold (eq. 5)."),
    lam: float = typer.Option(10.0, min=0.0, help="Weight lambda of dC/dt (eq. 2)."),
    configuration: str = typer.Option("rotations", help="rotations or positions."),
    quantiser: str = typer.Option("kmeans", help="kmeans or competitive."),
    fps: float = typer.Option(30.0, min=1.0, help="Frame rate for modelling."),
    hold_out: bool = typer.Option(
        True, "--hold-out/--no-hold-out", help="Keep the last trial of each label for testing."
    ),
    structured: bool = typer.Option(False, help="Also learn the structured two-level model (§4)."),
    key_memory: int = typer.Option(4, min=0, help="Maximum memory of the key-prototype VLMM."),
    seed: int = typer.Option(0, help="Seed of the vector quantisation."),
) -> None:
    """Learn prototypes and a VLMM (optionally the structured model) from motion capture."""
    from markovmotion.data.splits import held_out_last
    from markovmotion.models.vlmm.behaviour import BehaviourModel, load_motions

    check_model_output(out)
    index = MocapIndex.load(data)
    entries = index.query(category=category, label=label or None)
    if not entries:
        which = f"{category} takes labelled {label}" if label else f"{category} takes"
        raise DataNotFoundError(f"no {which} in {index.root}")
    train_entries, test_entries = held_out_last(entries) if hold_out else (entries, [])
    motions, skipped = load_motions(index, train_entries, fps)
    used = [e for e in train_entries if e not in skipped]
    model = BehaviourModel(
        n_prototypes=prototypes,
        max_memory=max_memory,
        epsilon=epsilon,
        lam=lam,
        configuration=configuration,
        fps=fps,
        quantiser=quantiser,
        seed=seed,
    )
    if structured:
        from markovmotion.models.vlmm.structured import StructuredBehaviourModel

        model = StructuredBehaviourModel(model, max_memory=key_memory, epsilon=epsilon)
    model.fit(motions)
    header = {
        "train_files": [e.file for e in used],
        "test_files": [e.file for e in test_entries],
    }
    model.save(out, header)
    base = model.prototype_model_ if structured else model
    err_console.print(
        f"trained on {len(used)} takes ({sum(m.n_frames for m in motions)} frames at {fps:g} fps), "
        f"{len(base.train_tokens_)} prototype tokens; held out: "
        f"{', '.join(e.file for e in test_entries) or 'none'}"
    )
    if skipped:
        err_console.print(
            f"left out (another skeleton): {', '.join(e.file for e in skipped)}", highlight=False
        )
    err_console.print(_memory_table(f"prototype VLMM (N = {max_memory})", base.vlmm_))
    if structured:
        err_console.print(
            f"{len(model.keys_)} key prototypes, {model.n_atomic_behaviours} atomic behaviours, "
            f"{len(model.template_tokens_lengths_)} templates"
        )
        err_console.print(_memory_table(f"key-prototype VLMM (N = {key_memory})", model.vlmm_))
    err_console.print(f"wrote {out}")


@app.command()
def generate(
    model: Path = typer.Option(..., help="Model file from 'vlmm train'."),
    out: Path = typer.Option(..., help="Motion to write (.bvh or .bvh.gz)."),
    seconds: float = typer.Option(20.0, min=0.1, help="Length of the routine."),
    stochastic: bool = typer.Option(
        False, "--stochastic/--ml", help="Sample transitions (default: most likely ones)."
    ),
    seed: int = typer.Option(0, help="Seed of stochastic generation."),
) -> None:
    """Synthesize a new routine by traversing the automaton (§3.2.1, §4.3)."""
    from markovmotion.models.vlmm.behaviour import load_behaviour_model

    behaviour, _ = load_behaviour_model(model)
    motion = behaviour.generate(seconds, _rng(stochastic, seed))
    write_motion(motion, out)
    err_console.print(f"wrote {out}: {motion.n_frames} frames at {motion.fps:g} fps")


@app.command()
def predict(
    model: Path = typer.Option(..., help="Model file from 'vlmm train'."),
    input: Path = typer.Option(..., help="Observed motion (BVH or ASF/AMC)."),
    out: Path = typer.Option(..., help="Observed motion plus prediction (.bvh)."),
    horizon: float = typer.Option(3.0, min=0.05, help="Seconds to predict."),
    fps: float = typer.Option(None, help="True frame rate of the input, overriding the file's."),
    stochastic: bool = typer.Option(False, "--stochastic/--ml", help="Sample the prediction."),
    seed: int = typer.Option(0, help="Seed of a stochastic prediction."),
) -> None:
    """Recognise the observed motion's state and predict how it continues (§3.2.2, §4.4)."""
    from markovmotion.models.vlmm.behaviour import load_behaviour_model

    check_motion_output(out)
    behaviour, _ = load_behaviour_model(model)
    motion = read_listed_motion(input, fps=fps)
    try:
        behaviour.skeleton_.check_compatible(motion.skeleton, "input")
    except SkeletonMismatchError as exc:
        raise SkeletonMismatchError(f"{input}: {exc}") from None
    result = behaviour.predict(motion, horizon, _rng(stochastic, seed))
    write_motion(result, out)
    observed = result.n_frames - int(round(horizon * behaviour.fps))
    err_console.print(
        f"wrote {out}: {observed} observed frames then {result.n_frames - observed} predicted, "
        f"at {result.fps:g} fps"
    )


def _test_entries(index: MocapIndex, header: dict, category, label) -> list:
    if category or label:
        return index.query(category=category, label=label or None)
    listed = set(header.get("test_files", []))
    entries = [e for e in index if e.file in listed]
    if not entries:
        raise DataNotFoundError(
            f"the model lists no held-out takes found in {index.root}: "
            "choose them with --category/--label"
        )
    return entries


@app.command()
def evaluate(
    model: Path = typer.Option(..., help="Model file from 'vlmm train'."),
    test: Path = typer.Option(
        None, help="INDEX.csv (or its folder) holding the test takes (default: see README)."
    ),
    category: str = typer.Option(None, help="Test on this category instead of the held-out takes."),
    label: list[str] = typer.Option(None, help="Test on these labels instead (repeatable)."),
    samples: int = typer.Option(50, min=1, help="Stochastic predictions per frame."),
    horizon: float = typer.Option(3.0, min=0.1, help="Longest horizon in seconds."),
    stride: int = typer.Option(1, min=1, help="Predict from every stride-th frame (1: all)."),
    memories: str = typer.Option(
        "", help="Also VLMMs of these maximum memories on the same prototypes, e.g. '5,20'."
    ),
    plot: Path = typer.Option(None, help="Write E_T curves (paper Fig. 4) to this PNG."),
    as_json: bool = typer.Option(False, "--json", help="Print E_T as JSON on stdout."),
    seed: int = typer.Option(0, help="Seed of the Monte Carlo predictions."),
) -> None:
    """E_T (eq. 9) in mm at 0.5, 1, 2 and 3 s against first-order Markov and zero velocity."""
    from markovmotion.evaluate.vlmm import (
        REPORT_SECONDS,
        ZeroVelocity,
        evaluate_horizon,
        plot_horizon_curves,
    )
    from markovmotion.models.vlmm.behaviour import load_behaviour_model, load_motions
    from markovmotion.viz.plots import check_figure_output

    if plot:
        check_figure_output(plot)
    behaviour, header = load_behaviour_model(model)
    structured = hasattr(behaviour, "prototype_model_")
    base = behaviour.prototype_model_ if structured else behaviour
    index = MocapIndex.load(test)
    entries = _test_entries(index, header, category, label)
    motions, skipped = load_motions(index, entries, base.fps)
    left_out = [e.file for e in skipped]
    left_out += [m.name for m in motions if not m.skeleton.same_topology(base.skeleton_)]
    motions = [m for m in motions if m.skeleton.same_topology(base.skeleton_)]
    if not motions:
        raise SkeletonMismatchError("no test take has the model's skeleton")
    if left_out:
        err_console.print(f"left out (another skeleton): {', '.join(left_out)}", highlight=False)
    features = base.observe(motions)
    predictors = {
        "vlmm": base,
        "first_order": base.with_vlmm(*FIRST_ORDER),
        "zero_velocity": ZeroVelocity(base),
    }
    for n in (int(v) for v in memories.split(",") if v.strip()):
        predictors[f"vlmm_N{n}"] = base if n == base.max_memory else base.with_vlmm(n, base.epsilon)
    if structured:
        predictors["structured"] = behaviour
    n_frames = int(round(horizon * base.fps))
    curves, by_model = {}, {}
    for name, p in predictors.items():  # a model asked for twice is evaluated once
        if id(p) not in by_model:
            by_model[id(p)] = evaluate_horizon(
                p, features, n_frames, base.fps, samples, stride, seed=seed, name=name
            )
        curves[name] = by_model[id(p)]
    seconds = [s for s in REPORT_SECONDS if s <= horizon]
    result = {
        f"E_T_mm.{name}.{s:g}": round(c.at(s), 2) for name, c in curves.items() for s in seconds
    }
    if plot:
        plot_horizon_curves(
            list(by_model.values()),
            plot,
            f"E_T on {len(motions)} held-out takes ({sum(len(f) for f in features)} frames)",
        )
        err_console.print(f"wrote {plot}")
    if as_json:
        typer.echo(json.dumps(result, indent=2))
        return
    table = Table(
        title=f"E_T (mm) on {', '.join(m.name for m in motions)}, "
        f"{samples} predictions per frame, stride {stride}"
    )
    table.add_column("model")
    for s in seconds:
        table.add_column(f"{s:g} s", justify="right")
    for name, c in curves.items():
        table.add_row(name, *(f"{c.at(s):.1f}" for s in seconds))
    Console().print(table)
