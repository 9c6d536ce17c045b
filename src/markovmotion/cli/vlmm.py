"""``vlmm``: behaviour models over prototypes (VLMM paper): train, generate, predict, evaluate."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import typer
from rich.table import Table

from markovmotion.cli.options import choice, kind_option, ranged, split_labels
from markovmotion.cli.tables import print_json, print_table
from markovmotion.core.markers import Markers, find_markers, not_found
from markovmotion.data import MocapIndex
from markovmotion.data.index import read_listed, read_listed_motion
from markovmotion.data.kinds import counted
from markovmotion.errors import MarkovMotionError, MotionFormatError, SkeletonMismatchError
from markovmotion.io import check_motion_output, write_c3d, write_motion
from markovmotion.io.c3d import check_c3d_output
from markovmotion.io.files import base_suffix
from markovmotion.persist import check_model_output
from markovmotion.progress import err_console, note

app = typer.Typer(
    help="Variable-length Markov models of behaviour (VLMM paper): prototypes, a VLMM over "
    "them and the structured two-level model; synthesize routines, predict motion.",
    no_args_is_help=True,
)


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
    table.caption = (
        f"{counted(vlmm.n_states, 'states')}, "
        f"{counted(int(vlmm.in_suffix_tree_.sum()), 'memories')}"
    )
    return table


def _is_contour(behaviour) -> bool:
    base = getattr(behaviour, "prototype_model_", behaviour)
    return base.configuration == "contour"


def _is_markers(behaviour) -> bool:
    base = getattr(behaviour, "prototype_model_", behaviour)
    return base.configuration == "markers"


def _check_output(behaviour, out: Path) -> None:
    """``out`` suits what the model writes: BVH for a skeleton, C3D or an animation for markers;
    with ``behaviour`` None (before the model is read), one of those."""
    if behaviour is None:
        from markovmotion.viz.animation import OUTPUT_SUFFIXES

        if base_suffix(out) not in (".c3d", *OUTPUT_SUFFIXES):
            check_motion_output(out)
    elif not _is_markers(behaviour):
        check_motion_output(out)
    elif base_suffix(out) == ".c3d":
        check_c3d_output(out)
    else:
        from markovmotion.viz.animation import check_output

        try:
            check_output(out)
        except MarkovMotionError:
            raise MotionFormatError(
                out, "a markers model writes C3D (.c3d) or a point-light animation (.gif, .mp4)"
            ) from None


def _write(result, out: Path) -> None:
    """Write a generated motion (BVH) or markers (C3D, or a point-light GIF/MP4)."""
    if not isinstance(result, Markers):
        write_motion(result, out)
    elif base_suffix(out) == ".c3d":
        write_c3d(result, out)
    else:
        from markovmotion.viz.animation import render

        render(result, out, fps=min(result.fps, 25.0))


@app.command()
def train(
    out: Path = typer.Option(..., help="Model file to write (.npz)."),
    data: Path = typer.Option(None, help="Folder with INDEX.csv (default: see README)."),
    category: str = typer.Option("exercise", help="Category of the training takes."),
    label: list[str] = typer.Option(
        None,
        "--label",
        "--labels",
        help="Only these labels (repeat, or comma-separated; default all).",
    ),
    prototypes: int = ranged("states", 100, min=2, help="Number of prototypes K."),
    max_memory: int = typer.Option(5, min=0, help="Maximum memory length N of the VLMM."),
    epsilon: float = typer.Option(1e-4, min=0.0, help="KL threshold (eq. 5)."),
    lam: float = typer.Option(
        100.0, min=0.0, help="Weight lambda of dC/dt (eq. 2; the paper's 10 or 30)."
    ),
    source: str = typer.Option(
        "skeleton",
        callback=choice(("skeleton", "markers", "contour")),
        help="skeleton (joints, --configuration), markers (the paper's 13 body points) or "
        "contour (silhouette video rendered and tracked: the paper's data set 1, needs --cache).",
    ),
    cache: Path = typer.Option(
        None, help="For --source contour: folder for the rendered videos and their tracks."
    ),
    configuration: str = typer.Option(
        "positions",
        callback=choice(("rotations", "positions")),
        help="For --source skeleton: positions or rotations (the paper's).",
    ),
    quantiser: str = typer.Option(
        "kmeans", callback=choice(("kmeans", "competitive")), help="kmeans or competitive."
    ),
    fps: float = ranged("fps", 30.0, min=1.0, help="Frame rate for modelling."),
    join: float = ranged(
        "time_constant",
        2.0,
        help="Time constant (s) of the smooth join of predictions to the observed pose "
        "(0: the paper's; 2 chosen by cross-validation, docs/vlmm.md).",
    ),
    hold_out: bool = typer.Option(
        True, "--hold-out/--no-hold-out", help="Keep the last trial of each label for testing."
    ),
    structured: bool = typer.Option(False, help="Also learn the structured two-level model (§4)."),
    key_memory: int = typer.Option(4, min=0, help="Maximum memory of the key-prototype VLMM."),
    seed: int = ranged("seed", 0, help="Seed of the vector quantisation."),
    kind: str = kind_option(),
) -> None:
    """Learn prototypes and a VLMM (optionally the structured model) from motion capture."""
    label = split_labels(label)
    from markovmotion.models.vlmm.behaviour import BehaviourModel, fit_index

    check_model_output(out)
    if source == "contour":
        if cache is None:
            raise typer.BadParameter("--source contour needs --cache DIR", param_hint="--cache")
    elif cache is not None:
        raise typer.BadParameter("only with --source contour", param_hint="--cache")
    model = BehaviourModel(
        n_prototypes=prototypes,
        max_memory=max_memory,
        epsilon=epsilon,
        lam=lam,
        configuration=source if source in ("markers", "contour") else configuration,
        fps=fps,
        quantiser=quantiser,
        join=join,
        random_state=seed,
    )
    if structured:
        from markovmotion.models.vlmm.structured import StructuredBehaviourModel

        model = StructuredBehaviourModel(model, max_memory=key_memory, epsilon=epsilon)
    if source == "contour":
        from markovmotion.evaluate.takes import index_record
        from markovmotion.video.contours import fit_contours

        takes = fit_contours(model, data, cache, category, label, hold_out)
        model.save(out, data_index=index_record(MocapIndex.load(data)))
        base = model.prototype_model_ if structured else model
        err_console.print(
            f"trained on {counted(len(takes.train), 'tracked takes')} "
            f"({counted(sum(t.n_frames for t in takes.train), 'frames')} at {base.fps:g} fps), "
            f"{len(base.train_tokens_)} prototype tokens, scale {model.contour_scale_:.1f} px; "
            f"held out: {', '.join(e.file for e in takes.test_entries) or 'none'}",
            highlight=False,
        )
        if takes.left_out:
            err_console.print(
                "left out (no silhouette joints): " + ", ".join(e.file for e in takes.left_out),
                highlight=False,
            )
        err_console.print(_memory_table(f"prototype VLMM (N = {max_memory})", base.vlmm_))
        if structured:
            err_console.print(_memory_table(f"key-prototype VLMM (N = {key_memory})", model.vlmm_))
        err_console.print(f"wrote {out}")
        return
    from markovmotion.evaluate.takes import index_record

    index = MocapIndex.load(data)
    run = fit_index(model, index, category, label, hold_out, kind)
    model.save(out, data_index=index_record(index))  # where evaluate finds its held-out takes
    base = model.prototype_model_ if structured else model
    err_console.print(
        f"trained on {counted(len(run.used), 'takes')} "
        f"({counted(sum(m.n_frames for m in run.motions), 'frames')} at "
        f"{fps:g} fps), {len(base.train_tokens_)} prototype tokens; held out: "
        f"{', '.join(e.file for e in run.held_out) or 'none'}",
        highlight=False,
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
    out: Path = typer.Option(
        ...,
        help="Motion to write (.bvh or .bvh.gz; a markers model: .c3d or .gif; a contour "
        "model: .png, filled contours of the routine and of N = 1, paper Fig. 9).",
    ),
    seconds: float = ranged("seconds", 20.0, min=0.1, help="Length of the routine."),
    stochastic: bool = typer.Option(
        False, "--stochastic/--ml", help="Sample transitions (default: most likely ones)."
    ),
    seed: int = ranged("seed", 0, help="Seed of stochastic generation."),
) -> None:
    """Synthesize a new routine by traversing the automaton (§3.2.1, §4.3)."""
    from markovmotion.models.vlmm.structured import load_behaviour

    behaviour = load_behaviour(model)
    if _is_contour(behaviour):
        from markovmotion.video.contours import contour_strip

        if base_suffix(out) != ".png":
            raise typer.BadParameter("a contour model writes a PNG strip", param_hint="--out")
        first = (
            behaviour.with_key_memory(1, behaviour.epsilon)
            if hasattr(behaviour, "prototype_model_")
            else behaviour.with_vlmm(1, behaviour.epsilon)
        )
        routines = [
            m.generate(seconds, np.random.default_rng(seed), stochastic=stochastic)
            for m in (behaviour, first)
        ]
        contour_strip(
            routines,
            out,
            titles=[f"routine at memory N = {behaviour.max_memory}", "routine at memory N = 1"],
            fps=behaviour.fps,
        )
        err_console.print(
            f"wrote {out}: {counted(len(routines[0]), 'frames')} at {behaviour.fps:g} fps, "
            f"N = {behaviour.max_memory} and N = 1"
        )
        return
    _check_output(None, out)
    _check_output(behaviour, out)
    motion = behaviour.generate(seconds, np.random.default_rng(seed), stochastic=stochastic)
    _write(motion, out)
    err_console.print(f"wrote {out}: {counted(motion.n_frames, 'frames')} at {motion.fps:g} fps")


@app.command()
def predict(
    model: Path = typer.Option(..., help="Model file from 'vlmm train'."),
    input: Path = typer.Option(
        ..., help="Observed motion (BVH or ASF/AMC; a model learnt from C3D: a C3D file)."
    ),
    out: Path = typer.Option(
        ..., help="Observed motion plus prediction (.bvh; a markers model: .c3d or .gif)."
    ),
    horizon: float = ranged("horizon", 3.0, min=0.05, help="Seconds to predict."),
    fps: float = ranged(
        "fps",
        None,
        help="True frame rate of the input (default: INDEX.csv's for a file of the collection, else the file's).",
    ),
    stochastic: bool = typer.Option(False, "--stochastic/--ml", help="Sample the prediction."),
    seed: int = ranged("seed", 0, help="Seed of a stochastic prediction."),
    animation: Path = typer.Option(
        None,
        help="Also draw it (.gif, .mp4 or a .png strip): the last 5 s observed, then the "
        "prediction in a colour of its own.",
    ),
) -> None:
    """Recognise the observed motion's state and predict how it continues (§3.2.2, §4.4)."""
    from markovmotion.models.vlmm.structured import load_behaviour
    from markovmotion.viz.animation import check_output

    _check_output(None, out)
    if animation is not None:
        check_output(animation)
    behaviour = load_behaviour(model)
    if _is_contour(behaviour):
        raise typer.BadParameter(
            "a contour model predicts tracked contours: see 'vlmm evaluate --cache'",
            param_hint="--model",
        )
    _check_output(behaviour, out)
    if behaviour.skeleton_ is None:  # learnt from C3D markers
        if base_suffix(input) != ".c3d":
            raise SkeletonMismatchError(f"{input}: the model learnt markers: give a C3D file")
        motion = read_listed(input, fps)
        if not behaviour.fits(motion):
            missing = sorted(find_markers(motion.names, behaviour.marker_names)[1])
            raise SkeletonMismatchError(f"{input}: {not_found(motion.names, missing)}")
    else:
        if base_suffix(input) == ".c3d":
            raise SkeletonMismatchError(
                f"{input}: the model learnt a skeleton: give BVH or ASF/AMC"
            )
        motion = read_listed_motion(input, fps=fps)
        if not behaviour.fits(motion):  # its skeleton, or (markers) its body points by name
            why = behaviour.why_not(motion, "the input")
            if why.startswith("(") and why.endswith(")"):  # a difference, already in brackets
                why = why[1:-1]  # (not a reason ending "(looked for head ...)": one left open)
            raise SkeletonMismatchError(f"{input}: the input's skeleton does not match ({why})")
    result = behaviour.predict(motion, horizon, np.random.default_rng(seed), stochastic=stochastic)
    _write(result, out)
    observed = result.n_frames - int(round(horizon * behaviour.fps))
    err_console.print(
        f"wrote {out}: {counted(observed, 'observed frames')} then "
        f"{result.n_frames - observed} predicted, "
        f"at {result.fps:g} fps"
    )
    if animation is not None:
        from markovmotion.viz.animation import render_continuation

        render_continuation(
            result, observed, animation, title=f"{input.name}: {horizon:g} s predicted"
        )
        err_console.print(f"wrote {animation}")


@app.command()
def evaluate(
    model: Path = typer.Option(..., help="Model file from 'vlmm train'."),
    test: Path = typer.Option(
        None, help="INDEX.csv (or its folder) holding the test takes (default: see README)."
    ),
    category: str = typer.Option(None, help="Test on this category instead of the held-out takes."),
    label: list[str] = typer.Option(
        None,
        "--label",
        "--labels",
        help="Test on these labels instead (repeat, or comma-separated).",
    ),
    samples: int = ranged("count", 50, min=1, help="Stochastic predictions per frame."),
    horizon: float = ranged("horizon", 3.0, min=0.1, help="Longest horizon in seconds."),
    stride: int = typer.Option(1, min=1, help="Predict from every stride-th frame (1: all)."),
    memories: str = typer.Option(
        "", help="Also VLMMs of these maximum memories on the same prototypes, e.g. '5,20'."
    ),
    plot: Path = typer.Option(None, help="Write E_T curves (paper Fig. 4) to this PNG."),
    space: str = typer.Option(
        None,
        callback=choice(("mm", "configuration", "pixels")),
        help="E_T in mm (the default), or in configuration space [0, 1]^d (eq. 9); a contour "
        "model: configuration (the default) or pixels.",
    ),
    cache: Path = typer.Option(
        None, help="A contour model: folder of rendered videos and tracks (as in training)."
    ),
    as_json: bool = typer.Option(False, "--json", help="Print E_T as JSON on stdout."),
    seed: int = ranged("seed", 0, help="Seed of the Monte Carlo predictions."),
) -> None:
    """E_T (eq. 9) in mm at 0.5, 1, 2 and 3 s against first-order Markov and zero velocity.

    With --test, on the takes of that index of the model's category and labels
    and skeleton, leaving out (and listing) the takes it trained on, whatever
    their names; without, on the takes the model held out in training.
    """
    label = split_labels(label)
    from markovmotion.evaluate.takes import evaluation_index
    from markovmotion.evaluate.vlmm import evaluate_model
    from markovmotion.models.vlmm.structured import load_behaviour
    from markovmotion.viz.plots import check_figure_output

    if plot:
        check_figure_output(plot)
    try:
        depths = [int(v) for v in memories.split(",") if v.strip()]
    except ValueError:
        raise typer.BadParameter(
            f"not a list of integers: {memories!r}", param_hint="--memories"
        ) from None
    behaviour = load_behaviour(model)
    if _is_contour(behaviour):
        _evaluate_contours(
            behaviour,
            test,
            cache,
            category or label,
            samples,
            horizon,
            stride,
            plot,
            space,
            as_json,
            seed,
        )
        return
    if cache is not None:
        raise typer.BadParameter("only for a contour model", param_hint="--cache")
    space = space or "mm"
    if space == "pixels":
        raise typer.BadParameter("pixels only for a contour model", param_hint="--space")
    result = evaluate_model(
        behaviour,
        evaluation_index(behaviour, test),
        held_out=test is None,
        category=category,
        labels=label,
        samples=samples,
        horizon=horizon,
        stride=stride,
        memories=depths,
        seed=seed,
        space=space,
    )
    if result.takes.left_out:
        err_console.print(
            "left out (trained on): " + ", ".join(result.takes.report()["left_out_training_files"]),
            highlight=False,
        )
    if result.other_skeleton:
        err_console.print(
            f"left out (another skeleton): {', '.join(e.file for e in result.other_skeleton)}",
            highlight=False,
        )
    for line in result.notes:  # takes too short for some horizons
        note(line)
    if plot:
        result.plot(plot)
        err_console.print(f"wrote {plot}")
    if as_json:
        print_json(result.result(), indent=2)
        return
    table = Table(
        title=f"E_T ({'mm' if space == 'mm' else 'configuration space'}) on {', '.join(m.name for m in result.motions)}, "
        f"{counted(samples, 'predictions')} per frame, stride {stride}"
    )
    table.add_column("model")
    for s in result.seconds:
        table.add_column(f"{s:g} s", justify="right")
    fmt = ".1f" if space == "mm" else ".4f"
    for name, c in result.curves.items():  # "-": no take as long as the horizon (a note)
        cells = (c.at(s) for s in result.seconds)
        table.add_row(name, *(f"{v:{fmt}}" if np.isfinite(v) else "-" for v in cells))
    print_table(table)


def _evaluate_contours(
    behaviour, test, cache, other_takes, samples, horizon, stride, plot, space, as_json, seed
) -> None:
    """``vlmm evaluate`` of a contour model: E_T on its held-out takes (rendered, tracked)."""
    from markovmotion.evaluate.vlmm import plot_horizon_curves
    from markovmotion.video.contours import evaluate_contours, held_out_contours

    if cache is None:
        raise typer.BadParameter("a contour model needs --cache DIR", param_hint="--cache")
    if other_takes:
        raise typer.BadParameter(
            "a contour model is evaluated on its held-out takes", param_hint="--category/--label"
        )
    space = space or "configuration"
    if space == "mm":
        raise typer.BadParameter(
            "a contour model: --space configuration or pixels", param_hint="--space"
        )
    sequences, entries = held_out_contours(behaviour, test, cache)
    curves = evaluate_contours(
        behaviour, sequences, behaviour.contour_scale_, samples, horizon, stride, seed, space
    )
    seconds = [s for s in (0.5, 1.0, 2.0, 3.0) if s <= horizon + 1e-9]
    unit = "pixels" if space == "pixels" else "configuration space"
    if plot:
        from markovmotion.viz.plots import ordinal

        every = f", every {ordinal(stride)} frame" if stride > 1 else ""
        plot_horizon_curves(
            list(curves.values()),
            plot,
            ylabel=f"E_T ({unit})",
            title=f"contour VLMM on {counted(len(entries), 'held-out takes')} "
            f"({counted(samples, 'samples')}{every})",
        )
        err_console.print(f"wrote {plot}")
    if as_json:
        out = {
            "space": space,
            "test_files": [e.file for e in entries],
            "E_T": {n: {f"{s:g}": c.at(s) for s in seconds} for n, c in curves.items()},
        }
        print_json(out, indent=2)
        return
    table = Table(title=f"E_T ({unit}) on {', '.join(e.file for e in entries)}")
    table.add_column("model")
    for s in seconds:
        table.add_column(f"{s:g} s", justify="right")
    for name, c in curves.items():
        table.add_row(name, *(f"{c.at(s):.{1 if space == 'pixels' else 3}f}" for s in seconds))
    print_table(table)
