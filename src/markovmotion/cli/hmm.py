"""``dualhmm``: train a dual HMM on two-person takes, respond to a person, evaluate (dual-HMM paper)."""

from __future__ import annotations

import json
import re
import tempfile
import time
from pathlib import Path

import numpy as np
import typer
from rich.console import Console

from markovmotion.data.index import listed_entry
from markovmotion.data.splits import select_pairs
from markovmotion.errors import MotionFormatError
from markovmotion.persist import check_model_output
from markovmotion.progress import err_console, track

app = typer.Typer(
    help="Virtual partner from a dual HMM with windowed Viterbi (dual-HMM paper).",
    no_args_is_help=True,
)


DATA = typer.Option(None, help="Folder with INDEX.csv (default: see README).")
LABELS = typer.Option(None, help="Comma-separated labels (default: every interaction).")
STATES = typer.Option(32, help="Hidden states N.")
MODE = typer.Option("paper", help="'paper' (EM on A) or 'joint' (EM on [A, B]).")
OBSERVATION = typer.Option(
    "motion", help="A as 'pose' (the paper's) or 'motion' (pose, its change and A's travel)."
)
CANDIDATES = typer.Option(10, help="Trellis candidates per frame (§3.2).")
PLACEMENT_WINDOW = typer.Option(
    19, help="Frames over which B's place relative to A is averaged (1: none)."
)
FPS = typer.Option(30.0, help="Model frame rate (takes are resampled).")
WINDOW = typer.Option(10, help="Windowed-Viterbi slice length.")
N_ITER = typer.Option(50, help="Most EM iterations.")
SEED = typer.Option(0, help="Random seed (k-means start).")
JOBS = typer.Option(
    1, "--jobs", min=0, help="Parallel jobs of EM's E-step over the takes (0: all cores)."
)
JSON = typer.Option(False, "--json", help="Print the results as JSON.")


def _split(values: str | None) -> list[str] | None:
    return [v.strip() for v in values.split(",") if v.strip()] if values else None


def new_model(
    states: int,
    mode: str,
    observation: str,
    candidates: int,
    placement_window: int,
    fps: float,
    window: int,
    n_iter: int,
    seed: int,
):
    """An unfitted DualHMM with the settings that ``train`` and ``crossval`` share."""
    from markovmotion.models.hmm.dual import DualHMM

    return DualHMM(
        n_states=states,
        mode=mode,
        observation=observation,
        candidates=candidates,
        placement_window=placement_window,
        fps=fps,
        window=window,
        n_iter=n_iter,
        random_state=seed,
    )


@app.command()
def train(
    out: Path = typer.Option(..., help="Model file to write (.npz)."),
    data: Path = DATA,
    labels: str = LABELS,
    test_trials: str = typer.Option(
        None, help="Comma-separated trials held out for testing (not trained on)."
    ),
    states: int = STATES,
    mode: str = MODE,
    observation: str = OBSERVATION,
    candidates: int = CANDIDATES,
    placement_window: int = PLACEMENT_WINDOW,
    fps: float = FPS,
    window: int = WINDOW,
    n_iter: int = N_ITER,
    seed: int = SEED,
    jobs: int = JOBS,
) -> None:
    """Train a dual HMM on the two-person takes of a motion-capture folder."""
    import joblib

    from markovmotion.data import MocapIndex

    check_model_output(out)
    index = MocapIndex.load(data)
    pairs = select_pairs(index, _split(labels), _split(test_trials), held_out=False)
    motions = [index.load_pair(a, b) for a, b in track(pairs, "loading takes")]
    start = time.perf_counter()
    model = new_model(
        states, mode, observation, candidates, placement_window, fps, window, n_iter, seed
    )
    frames = sum(len(a) for a, _ in motions)
    with err_console.status(f"EM on {frames} frames"), joblib.parallel_config(n_jobs=jobs or -1):
        model.fit(motions)
    model.save(out)
    hmm = model.lambda_a_
    err_console.print(
        f"wrote {out}: {len(pairs)} takes, {len(model.train_a_)} frames at {fps:g} fps, "
        f"N={states} ({mode}), PCA dims A={model.train_a_.shape[1]} B={model.train_b_.shape[1]}, "
        f"{hmm.n_iter_} EM iterations, log-likelihood {model.history_[-1]:.1f}, "
        f"{time.perf_counter() - start:.1f} s",
        highlight=False,
    )


def read_stream(path: Path, fps: float | None = None):
    """A BVH replayed as a stream: (Motion, broken) with ``broken`` (F,) marking frames whose
    line has NaN or missing values; their rotations are NaN, so the partner skips them.

    A file of the collection is read as INDEX.csv says (true frame rate, CMU's reference
    frame dropped) unless ``fps`` overrides the file's rate.
    """
    entry = listed_entry(path) if fps is None else None
    motion, broken = _repaired_bvh(path, entry.fps if entry else fps)
    if entry is not None and motion.n_frames > 1:
        motion, broken = motion.trim(entry.first_frame), broken[entry.first_frame :]
    return motion, broken


def _repaired_bvh(path: Path, fps: float | None):
    """(Motion, broken): the BVH with each bad frame line replaced by a good one, flagged."""
    from markovmotion.io.bvh import read_bvh
    from markovmotion.io.files import read_text

    lines = read_text(path).splitlines()
    at = next((i for i, ln in enumerate(lines) if ln.strip().upper() == "MOTION"), len(lines))
    n_channels = sum(int(n) for n in re.findall(r"CHANNELS\s+(\d+)", "\n".join(lines[:at])))
    body = lines[at + 3 :]

    def good(line: str) -> bool:
        try:
            values = [float(v) for v in line.split()]
        except ValueError:
            return False
        return len(values) == n_channels and bool(np.isfinite(values).all())

    broken = np.array([not good(ln) for ln in body], dtype=bool)
    if broken.all() or not broken.any():
        motion = read_bvh(path, fps=fps)  # all good, or nothing to stream: the reader's own errors
        return motion, np.zeros(motion.n_frames, dtype=bool)
    filler = body[int(np.argmin(broken))]
    fixed = lines[: at + 3] + [filler if b else ln for ln, b in zip(body, broken, strict=True)]
    with tempfile.TemporaryDirectory() as tmp:
        copy = Path(tmp) / Path(path).name.removesuffix(".gz")
        copy.write_text("\n".join(fixed) + "\n", encoding="utf-8")
        try:
            motion = read_bvh(copy, fps=fps)
        except MotionFormatError as exc:  # name the user's file, not the repaired copy
            raise MotionFormatError(path, exc.problem, exc.line) from None
    motion.name = Path(path).name
    motion.rotations[broken] = np.nan
    return motion, broken


def stream(model, motion, window: int):
    """Replay ``motion`` at its frame rate through an online partner.

    Returns B (a Motion), per-frame processing times (ms) and the number of
    frames dropped because processing fell behind (a frame is dropped when
    its successor is already due before it could start).
    """
    from markovmotion.core.motion import Motion

    model.partner(window).step(motion.trim(0, 1))  # load the compiled kernels before the clock
    partner = model.partner(window)
    period = 1.0 / motion.fps
    out, times, dropped = [], [], 0
    start = time.perf_counter()
    for t in range(motion.n_frames):
        now = time.perf_counter()
        due = start + t * period
        if now < due:
            time.sleep(due - now)
        tick = time.perf_counter()
        if tick > due + period:
            dropped += 1
            frame = partner.skip()
        else:
            frame = partner.step(motion.trim(t, t + 1))
            times.append((time.perf_counter() - tick) * 1e3)
        if frame is not None:
            out.append(frame)
    out.extend(partner.finish())
    b = Motion(
        out[0].skeleton,
        np.concatenate([f.rotations for f in out]),
        np.concatenate([f.translations for f in out]),
        model.fps,
        name="virtual partner",
    )
    return b, np.array(times), dropped


@app.command()
def respond(
    model: Path = typer.Option(..., help="Dual-HMM model file (.npz)."),
    input: Path = typer.Option(..., help="Person A's motion (BVH)."),
    out: Path = typer.Option(..., help="Person B's generated motion (.bvh)."),
    window: int = typer.Option(None, help="Windowed-Viterbi slice length (default: the model's)."),
    standard: bool = typer.Option(False, help="Standard Viterbi over the whole input instead."),
    realtime: bool = typer.Option(
        False, help="Replay A as a stream at its frame rate; report per-frame latency."
    ),
    fps: float = typer.Option(None, help="True frame rate of the input, overriding the file's."),
    animation: Path = typer.Option(None, help="Also animate A and B together (.gif/.mp4)."),
) -> None:
    """Generate person B's response to person A's motion."""
    from markovmotion.io import check_motion_output, write_motion
    from markovmotion.models.hmm.dual import DualHMM
    from markovmotion.viz import check_output, render

    if standard and (realtime or window):
        raise typer.BadParameter("--standard needs the whole input: no --window or --realtime")
    check_motion_output(out)
    if animation is not None:
        check_output(animation)
    dual = DualHMM.load(model)
    motion, broken = read_stream(input, fps)
    dual.check_input(motion, input)
    if not np.isclose(motion.fps, dual.fps):
        err_console.print(f"resampling {input.name} from {motion.fps:g} to {dual.fps:g} fps")
        motion = _resample_stream(motion, broken, dual.fps)
    window = window or dual.window
    console = Console(stderr=True)
    if realtime:
        b, times, dropped = stream(dual, motion, window)
        lag = window - 1
        console.print(
            f"streamed {motion.n_frames} frames at {motion.fps:g} fps: latency per frame median "
            f"{np.median(times):.2f} ms, p99 {np.percentile(times, 99):.2f} ms; dropped frames "
            f"{dropped}; skipped (NaN/missing) {int(broken.sum())}; lag {lag} frames "
            f"({lag / dual.fps:.2f} s)",
            highlight=False,
        )
    else:
        if broken.any():
            console.print(
                f"[yellow]warning:[/] {int(broken.sum())} frames of {input.name} hold NaN or "
                "missing values: treated as missing",
                highlight=False,
            )
        dual.window = window
        b = dual.generate(motion, "standard" if standard else "windowed")
    write_motion(b, out)
    console.print(f"wrote {out} ({b.n_frames} frames at {b.fps:g} fps)")
    if animation is not None:
        shown = motion.copy()
        shown.rotations[~np.isfinite(shown.rotations).all(axis=(1, 2))] = [0, 0, 0, 1]
        render([shown, b], animation, names=["A (real)", "B (virtual partner)"])
        console.print(f"wrote {animation}")


def _resample_stream(motion, broken: np.ndarray, fps: float):
    """Resample a stream whose broken frames are NaN; a new frame is broken if it touches one."""
    clean = motion.copy()
    clean.rotations[broken] = [0.0, 0.0, 0.0, 1.0]
    out = clean.resample(fps)
    src = np.arange(out.n_frames) * motion.fps / fps
    lo = np.floor(src).astype(int)
    hi = np.minimum(np.ceil(src).astype(int), motion.n_frames - 1)
    out.rotations[broken[lo] | broken[hi]] = np.nan
    return out


@app.command()
def evaluate(
    model: Path = typer.Option(..., help="Dual-HMM model file (.npz)."),
    test: Path = typer.Option(None, help="Folder or INDEX.csv of the test takes."),
    labels: str = LABELS,
    test_trials: str = typer.Option(None, help="Only these comma-separated trials."),
    plots: Path = typer.Option(
        None, help="Folder for the per-frame error plots (Figs. 6-8); default: MODEL-plots."
    ),
    json_out: bool = JSON,
) -> None:
    """Error of the generated B against the real B on every test take, with baselines."""
    from markovmotion.data import MocapIndex
    from markovmotion.evaluate.hmm import evaluate_index
    from markovmotion.models.hmm.dual import DualHMM

    dual = DualHMM.load(model)
    index = MocapIndex.load(test)
    trials = _split(test_trials)
    pairs = select_pairs(index, _split(labels), trials, held_out=True)
    plots = plots or model.with_name(f"{model.name.split('.')[0]}-plots")
    _report(*evaluate_index(dual, index, pairs, plots), json_out)


@app.command()
def crossval(
    data: Path = DATA,
    labels: str = LABELS,
    states: int = STATES,
    mode: str = MODE,
    observation: str = OBSERVATION,
    candidates: int = CANDIDATES,
    placement_window: int = PLACEMENT_WINDOW,
    fps: float = FPS,
    window: int = WINDOW,
    n_iter: int = N_ITER,
    seed: int = SEED,
    jobs: int = JOBS,
    plots: Path = typer.Option(None, help="Folder for the per-frame error plots (Figs. 6-8)."),
    choose_placement: str = typer.Option(
        None,
        help="Comma-separated placement windows: each fold picks one on the other takes alone "
        "(nested leave-one-take-out; ~25 min for 1,9,15,19 on salsa).",
    ),
    json_out: bool = JSON,
) -> None:
    """Leave-one-take-out evaluation: train on all takes but one, test on it, for every take."""
    import joblib

    from markovmotion.data import MocapIndex
    from markovmotion.evaluate.hmm import cross_validate, summarise

    index = MocapIndex.load(data)
    pairs = select_pairs(index, _split(labels), None, held_out=False)
    takes = [
        (f"{a.name}+{b.name}", a.label, *index.load_pair(a, b))
        for a, b in track(pairs, "loading takes")
    ]
    model = new_model(
        states, mode, observation, candidates, placement_window, fps, window, n_iter, seed
    )
    windows = [int(w) for w in _split(choose_placement)] if choose_placement else None
    with joblib.parallel_config(n_jobs=jobs or -1):
        results, written = cross_validate(takes, model, plots, windows)
    _report(summarise(results, model), written, json_out)


def _report(report: dict, written: list[Path], json_out: bool) -> None:
    """Print ``report`` as JSON (stdout) or as a table, and the plots written (stderr)."""
    if json_out:
        typer.echo(json.dumps(report, indent=2))
    else:
        _print_table(report)
    for p in written:
        err_console.print(f"wrote {p}", highlight=False)


def _print_table(report: dict) -> None:
    from rich.table import Table

    table = Table(title="dual HMM: mean per-frame error of B (mm)")
    cols = ("standard_mm", "windowed_mm", "mean_pose_mm", "nearest_neighbour_mm")
    for c in ("group", *cols, "latency median/p99 (µs)"):
        table.add_column(c)
    rows = {"overall": report["overall"], **report["per_label"], **report["per_pair"]}
    for name, r in rows.items():
        lat = r["latency_us"]
        table.add_row(name, *(f"{r[c]:.1f}" for c in cols), f"{lat['median']:.0f}/{lat['p99']:.0f}")
    Console().print(table)
