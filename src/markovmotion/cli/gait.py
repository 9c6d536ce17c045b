"""``gait``: stylistic walk synthesis with HSMMs (train, adapt, synthesize, evaluate, steps)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import typer
from rich.table import Table

from markovmotion.cli.options import ranged
from markovmotion.cli.tables import print_json, print_table
from markovmotion.data.kinds import counted
from markovmotion.data.walks import SPLITS, load_walks, walks_index
from markovmotion.io import write_motion
from markovmotion.persist import check_model_output
from markovmotion.progress import err_console

app = typer.Typer(
    help="Stylistic walks with hidden semi-Markov models (gait paper): train an average walk, "
    "adapt it to a style, synthesize, evaluate.",
    no_args_is_help=True,
)


def _split(value: str) -> str:
    if value not in SPLITS:
        raise typer.BadParameter(f"{value!r}: must be one of {', '.join(SPLITS)}")
    return value


SPLIT = typer.Option("train", callback=_split, help="Takes from an index: train, test or all.")


def _index_extras(paths: list[Path] | None) -> dict:
    """``data_index`` for a model file: the index its walks were read from, which ``gait
    evaluate`` then takes its walks from by default; none for walks given as files."""
    from markovmotion.evaluate.takes import index_record

    index = walks_index(paths)
    return {} if index is None else {"data_index": index_record(index)}


@app.command()
def train(
    data: list[Path] = typer.Option(
        None, help="INDEX.csv (or its folder), or BVH files of neutral walks; repeatable."
    ),
    out: Path = typer.Option(..., help="Average model to write (.npz)."),
    label: str = typer.Option("normal", help="Label of the walks to train on, from an index."),
    subset: str | None = typer.Option(
        None,
        help="Index files starting with this (default: Bandai dataset-2 where the index has "
        "it, else every walk; '' for every walk).",
    ),
    split: str = SPLIT,
    n_iter: int = ranged("iterations", 10, min=1, help="EM iterations."),
    mdl_factor: float = typer.Option(1.0, min=0.0, help="MDL weight of context clustering."),
    wat: str = typer.Option(
        "none", help="Walker-adaptive training unit: none, take, or dataset (the file's folder)."
    ),
    jobs: int = typer.Option(
        1, "--jobs", min=0, help="Parallel jobs of EM's E-step over the walks (0: all cores)."
    ),
) -> None:
    """Train an average walk HSMM on neutral walks (gait paper §5.1.2)."""
    import joblib

    from markovmotion.models.gait.synthesizer import GaitSynthesizer, walks_with_steps

    if wat not in ("none", "take", "dataset"):
        raise typer.BadParameter("--wat must be none, take or dataset")
    check_model_output(out)
    folders: list[str] = []
    motions = load_walks(data, label, split, subset, folders)
    stepped = walks_with_steps(motions)  # a take without steps left out in a note
    motions, folders = [motions[i] for i in stepped], [folders[i] for i in stepped]
    model = GaitSynthesizer(
        n_iter=n_iter, mdl_factor=mdl_factor, wat="unit" if wat == "dataset" else wat
    )
    with joblib.parallel_config(n_jobs=jobs or -1):
        model.fit(motions, style=label, units=folders)
    model.save(out, **_index_extras(data))
    h = model.hsmm_
    err_console.print(
        f"wrote {out}: {counted(len(motions), 'walks')}, {counted(model.n_steps_, 'steps')}, "
        f"{len(h.means_)} output and {len(h.dur_means_)} duration densities, "
        f"log-likelihood {h.log_likelihood_[-1]:.1f} per frame"
    )


@app.command()
def adapt(
    model: Path = typer.Option(..., help="Average model (.npz) from 'gait train'."),
    style_data: list[Path] = typer.Option(
        None,
        "--style-data",
        "--data",
        help="INDEX.csv (or its folder), or BVH files of the style's walks; repeatable "
        "(--data, as train and evaluate call it, is the same).",
    ),
    label: str = typer.Option(..., help="The style (its label in an index)."),
    out: Path = typer.Option(..., help="Style model to write (.npz)."),
    steps: int = ranged(
        "steps", None, min=1, help="Adapt on the first K steps only (default all)."
    ),
    method: str = typer.Option("csmaplr", help="csmaplr (tree + structural MAP prior) or cmllr."),
    structure: str = typer.Option("stream", help="stream (full per block) or diagonal transforms."),
    tau: float = typer.Option(20.0, min=0.0, help="CSMAPLR prior weight (frames)."),
    tau_map: float = typer.Option(5.0, min=0.0, help="MAP prior weight of the means (frames)."),
    no_map: bool = typer.Option(False, "--no-map", help="Transforms only, no MAP step."),
    scratch: bool = typer.Option(
        False, "--scratch", help="Train a style model from scratch on the same steps instead."
    ),
    subset: str | None = typer.Option(
        None,
        help="Index files starting with this (default: Bandai dataset-2 where the index has "
        "it, else every walk; '' for every walk).",
    ),
    split: str = SPLIT,
) -> None:
    """Adapt the average model to a style from a few steps (CSMAPLR/CMLLR + MAP, §5.1.3)."""
    from markovmotion.models.gait.adaptation import METHODS, STRUCTURES
    from markovmotion.models.gait.synthesizer import GaitSynthesizer, walks_with_steps

    if method not in METHODS:
        raise typer.BadParameter(f"--method must be one of {', '.join(METHODS)}")
    if structure not in STRUCTURES:
        raise typer.BadParameter(f"--structure must be one of {', '.join(STRUCTURES)}")
    check_model_output(out)
    average = GaitSynthesizer.load(model)
    motions = load_walks(style_data, label, split, subset)
    motions = [motions[i] for i in walks_with_steps(motions)]  # without steps: in a note
    if scratch:
        result = average.scratch(motions, label, steps)
    else:
        result = average.adapt(
            motions,
            label,
            steps,
            method=method,
            structure=structure,
            tau=tau,
            tau_map=tau_map,
            map_step=not no_map,
        )
    result.save(out, **_index_extras(style_data))
    err_console.print(
        f"wrote {out}: {result.role_} {label} model from {counted(result.n_steps_, 'steps')} "
        f"of {counted(len(result.own_files), 'walks')}: " + ", ".join(result.own_files),
        highlight=False,
    )


@app.command()
def synthesize(
    model: Path = typer.Option(..., help="Gait model (.npz) from 'gait train' or 'gait adapt'."),
    out: Path = typer.Option(..., help="Walk to write (.bvh or .bvh.gz)."),
    steps: int = ranged("steps", 12, min=1, help="Number of steps."),
    speed: float = typer.Option(1.0, min=0.05, help="Pace relative to the model's mean durations."),
    gv: bool = typer.Option(True, "--gv/--no-gv", help="Global-variance generation (eqs. 12-15)."),
    first_side: str = typer.Option("R", help="Foot that lands at the end of the first step (L/R)."),
    seed: int = ranged(
        "seed",
        None,
        help="Draw state durations from the duration densities with this seed "
        "(default: the most likely durations).",
    ),
) -> None:
    """Synthesize a walk of any length from a gait model and write it as BVH (§5.1.4)."""
    from markovmotion.models.gait.synthesizer import GaitSynthesizer

    if first_side not in ("L", "R"):
        raise typer.BadParameter("--first-side must be L or R")
    synth = GaitSynthesizer.load(model)
    rng = None if seed is None else np.random.default_rng(seed)
    motion = synth.generate(
        steps, speed=speed, gv=gv, first_side=first_side, rng=rng, stochastic=seed is not None
    )
    write_motion(motion, out)
    err_console.print(
        f"wrote {out}: {synth.style_} walk, {counted(steps, 'steps')}, "
        f"{counted(motion.n_frames, 'frames')} "
        f"at {motion.fps:g} fps"
    )


def _rate(value: float, ci: list[float] | None = None) -> str:
    return f"{value:.2f}" + (f" [{ci[0]:.2f}, {ci[1]:.2f}]" if ci else "")


#: Rows of the evaluation table: (label, key in the results, format).
METRICS = (
    ("eta (eq. 16) of the column's steps", "eta_synthesized", "{:.2f}"),
    ("walk recognition, synthesized", "synthesized_walk_rate", "{:.2f}"),
    ("full classifier: real / synthesized steps", "full", "{}"),
    ("DTW exp-map RMSE (rad)", "dtw_expmap_rmse", "{:.3f}"),
    ("DTW joint error (mm)", "dtw_joint_mm", "{:.1f}"),
    ("foot slide (mm/step)", "foot_slide_mm", "{:.1f}"),
    ("GV ratio synthesized/real", "gv_ratio", "{:.2f}"),
    ("told from real test steps (0.5: never)", "real_vs_synthesized", "{:.2f}"),
    ("test log-likelihood/frame", "test_log_likelihood", "{:.0f}"),
)


def _table(title: str, columns: dict[str, dict]) -> Table:
    table = Table(title=title)
    table.add_column("measure")
    for name in columns:
        table.add_column(name, justify="right")
    for key in ("real_rate", "synthesized_rate"):
        cells = [_rate(c[key], c.get(f"{key}_ci")) if key in c else "-" for c in columns.values()]
        table.add_row(f"step recognition, {key.split('_')[0]} (95% CI)", *cells)
    for label, key, fmt in METRICS:
        cells = []
        for c in columns.values():
            if key == "full":
                synth = c.get("synthesized_rate_full")
                cells.append(
                    f"{c['real_rate_full']:.2f} / " + ("-" if synth is None else f"{synth:.2f}")
                )
            else:
                cells.append(fmt.format(c[key]) if c.get(key) is not None else "-")
        if any(c != "-" for c in cells):
            table.add_row(label, *cells)
    return table


def _sweep_table(sweep: dict[str, dict], average: dict | None) -> Table:
    table = Table(title="synthesized step recognition vs adaptation steps (95% CI)")
    columns = ("steps", "adapted", "scratch", "adapted - scratch", "average")
    more = ("DTW mm a/s", "told from real a/s", "a told from s", "log-lik/frame a/s")
    for col in (*columns, *more):
        table.add_column(col, justify="right")
    for k, roles in sweep.items():
        a, s, d = roles["adapted"], roles["scratch"], roles["adapted_minus_scratch"]
        table.add_row(
            k,
            _rate(a["synthesized_rate"], a["synthesized_rate_ci"]),
            _rate(s["synthesized_rate"], s["synthesized_rate_ci"]),
            f"{d['synthesized_rate']:+.2f} [{d['synthesized_rate_ci'][0]:+.2f}, "
            f"{d['synthesized_rate_ci'][1]:+.2f}]",
            _rate(average["synthesized_rate"], average["synthesized_rate_ci"]) if average else "-",
            f"{a['dtw_joint_mm']:.1f} / {s['dtw_joint_mm']:.1f}",
            f"{a['real_vs_synthesized']:.2f} / {s['real_vs_synthesized']:.2f}",
            f"{d['told_apart']:.2f}",
            f"{a['test_log_likelihood']:.0f} / {s['test_log_likelihood']:.0f}",
        )
    return table


def _components(value: str) -> int | str | None:
    if value == "auto":
        return value
    try:
        n = int(value)
    except ValueError:
        raise typer.BadParameter(f"--components {value!r}: 'auto' or a number") from None
    if n < 0:
        raise typer.BadParameter("--components must be 'auto', 0 (all) or positive")
    return n or None


@app.command()
def evaluate(
    models: Path = typer.Option(
        ...,
        "--model",
        "--models",
        help="A gait model (.npz), or a folder with the average and adapted/scratch models.",
    ),
    test: Path = typer.Option(
        None,
        help="INDEX.csv (or its folder) to evaluate on: its walks of the models' styles and "
        "skeleton, less those the models trained on (default: the held-out takes of --data).",
    ),
    data: Path = typer.Option(
        None,
        help="INDEX.csv (or its folder) whose training takes teach the style classifier "
        "(default: the one the models were trained on, else the shared collection).",
    ),
    as_json: bool = typer.Option(False, "--json", help="Print the results as JSON on stdout."),
    sweep: str = typer.Option(
        "",
        help="Also adapt and train from scratch on K steps, e.g. '3,6,12,24' (needs the average).",
    ),
    walks: int = typer.Option(8, min=1, help="Synthesized walks per model and style."),
    replicates: int = typer.Option(
        3, min=1, help="Sweep: models per style and K, each adapted on other training takes."
    ),
    walk_steps: int = ranged("steps", 12, min=3, help="Steps per synthesized walk."),
    components: str = typer.Option(
        "auto",
        help="Principal components the style classifier keeps: 'auto' (fewest reaching 90% "
        "cross-validated on training takes), or N (0: all statistics).",
    ),
    seed: int = ranged("seed", 0, help="Seed of the synthesized durations and the bootstrap."),
    bootstrap: int = typer.Option(2000, min=100, help="Bootstrap replicates of the intervals."),
    subset: str | None = typer.Option(
        None,
        help="Index files starting with this (default: Bandai dataset-2 where the index has "
        "it, else every walk; '' for every walk).",
    ),
) -> None:
    """Objective evaluation (§6 replacement): recognition, real vs synthesized, DTW, foot slide, GV.

    A style classifier is trained on the steps of the training takes of every
    style of --data; every fourth take is held out. Without --test the models
    are evaluated on those held-out takes, which they must not have seen;
    with --test on the walks of that index that fit them, leaving out (and
    listing) those they trained on, by content. The style of the average
    model (its training walks) is a class of the classifier but not a target
    of the models.
    """

    from markovmotion.evaluate.gait import ROLES, StyleClassifier, evaluate_models, load_models
    from markovmotion.progress import progress_bar

    try:
        ks = [int(k) for k in sweep.replace(" ", "").split(",") if k]
    except ValueError:
        raise typer.BadParameter(
            f"--sweep {sweep!r} is not a comma-separated list of numbers"
        ) from None
    classifier = StyleClassifier(n_components=_components(components))
    found = load_models(models)
    bar = progress_bar()  # started at the first model: reading walks shows its own
    tasks: list = []

    def advance(what: str, total: int) -> None:
        if not tasks:
            bar.start()
            tasks.append(bar.add_task(what, total=total))
        bar.update(tasks[0], advance=1, description=what, total=total)

    try:
        result = evaluate_models(
            found,
            test,
            data=data,
            sweep=ks,
            classifier=classifier,
            n_walks=walks,
            walk_steps=walk_steps,
            replicates=replicates,
            seed=seed,
            n_boot=bootstrap,
            subset=subset,
            progress=advance,
        )
    finally:
        bar.stop()
    if as_json:
        print_json(result, indent=1)
        return
    real = result["real"]
    columns = {
        "real (all styles)": {
            "real_rate": real["rate"],
            "real_rate_ci": real["rate_ci"],
            "real_rate_full": real["rate_full"],
            "eta_synthesized": real["eta"],
            "dtw_expmap_rmse": real["dtw_expmap_rmse"],
            "dtw_joint_mm": real["dtw_joint_mm"],
            "foot_slide_mm": real["foot_slide_mm"],
            "real_vs_synthesized": real["real_vs_synthesized"],
        },
        **{role: result[role] for role in ROLES if role in result},
    }
    left = result["left_out_training_files"]
    print_table(
        _table(
            f"gait models in {models}: "
            f"{counted(real['walks'], 'test walks' if test else 'held-out walks')}, "
            f"{counted(real['steps'], 'steps')}; classifier on "
            f"{real['classifier']['components'] or 'all'} "
            "components",
            columns,
        )
    )
    if left:
        print(f"left out (the models trained on them): {', '.join(left)}")
    if "sweep" in result:
        print_table(_sweep_table(result["sweep"], result.get("average")))


@app.command("steps")
def steps_(
    data: list[Path] = typer.Option(None, help="INDEX.csv (or its folder) or walk files."),
    label: list[str] = typer.Option(None, help="Labels to list from an index (default all)."),
    subset: str | None = typer.Option(
        None,
        help="Index files starting with this (default: Bandai dataset-2 where the index has "
        "it, else every walk; '' for every walk).",
    ),
) -> None:
    """Heel strikes and steps found in each walk (gait paper §4)."""
    from markovmotion.features.gait import align_walk, detect_steps

    motions = load_walks(data, label or None, "all", subset)
    table = Table(title="steps cut at heel strikes")
    for col in ("walk", "frames", "steps", "left", "right", "mean frames/step", "dropped"):
        table.add_column(col)
    total = 0
    for m in motions:
        s = detect_steps(align_walk(m))
        total += s.n_steps
        mean = f"{(s.boundaries[-1] - s.boundaries[0]) / s.n_steps:.1f}" if s.n_steps else "-"
        table.add_row(
            m.name,
            str(m.n_frames),
            str(s.n_steps),
            str(s.sides.count("L")),
            str(s.sides.count("R")),
            mean,
            str(s.dropped),
        )
    table.caption = f"{counted(total, 'steps')} in {counted(len(motions), 'walks')}"
    print_table(table)
