"""``dualhmm``: train a dual HMM on two-person takes, respond to a person, evaluate (dual-HMM paper)."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import typer

from markovmotion.cli.options import (
    body_model_option,
    check_person,
    choice,
    choose_option,
    chosen_line,
    grid_of,
    guide_for,
    guide_option,
    kind_option,
    method_for,
    method_option,
    normalise_option,
    person_option,
    preset_option,
    ranged,
    roles_option,
    stopped,
    with_preset,
)
from markovmotion.cli.tables import (
    print_json,
    print_notes,
    say_people_trained_on,
    world_frame_note,
)
from markovmotion.data.index import read_listed
from markovmotion.defaults import DUALHMM_PRESETS, MAX_CAMERAS
from markovmotion.persist import check_model_output
from markovmotion.progress import err_console

app = typer.Typer(
    help="Virtual partner from a dual HMM with windowed Viterbi (dual-HMM paper).",
    no_args_is_help=True,
)


DATA = typer.Option(None, help="Folder with INDEX.csv (default: see README).")
LABELS = typer.Option(
    None, "--labels", "--label", help="Comma-separated labels (default: every interaction)."
)
STATES = ranged("states", 32, help="Hidden states N.")
# The choices of DualHMM's MODES and OBSERVATIONS (not imported: the models load lazily)
MODE = typer.Option(
    "paper",
    callback=choice(("paper", "joint")),
    help="'paper' (EM on A) or 'joint' (EM on [A, B]).",
)
OBSERVATION = typer.Option(
    "motion",
    callback=choice(("pose", "motion")),
    help="A as 'pose' (the paper's) or 'motion' (pose, its change and A's travel).",
)
CANDIDATES = ranged("count", 10, help="Trellis candidates per frame (§3.2).")
PLACEMENT_WINDOW = ranged(
    "window", 19, help="Frames over which B's place relative to A is averaged (1: none)."
)
PLACE_MEMORY = ranged(
    "window",
    0,
    min=0,
    max=3000,
    help="Frames before each frame over which A's ground frame, through which B is placed, "
    "is averaged (0: the placement window's; 300: what train --choose picks for new people "
    "on the collection's handshakes and waves, docs/hmm.md).",
)
CHOOSE = choose_option("hmm", "windowed world error", "roles=one,both;output=frames,regression")
BLEND_WINDOW = ranged(
    "window", 9, help="Frames over which B's pose is blended across cuts (1: none)."
)
TRELLIS = typer.Option(
    "path",
    callback=choice(("path", "paper")),
    help="Trellis of §3.2: 'path' (lowest-error path, following recordings) or 'paper' "
    "(E = (D1 + ... + DK) x D4 per column, as printed).",
)
POINTS = typer.Option(
    "body",
    callback=choice(("body", "all")),
    help="See people as 'body' points found by joint names (any skeleton) or 'all' joints "
    "of the training skeleton.",
)
FRAME = typer.Option(
    "auto",
    callback=choice(("auto", "heading", "world")),
    help="B's place measured in A's facing ('heading'), along the world's axes from A "
    "('world'), or whichever varies less on the training takes ('auto').",
)
ENERGY = ranged("fraction", 0.95, help="PCA energy kept per person (the paper's).")
MARKERS = typer.Option(
    0,
    "--markers",
    min=0,
    max=200,
    help="Learn on N virtual markers placed on each person's skeleton (13-200; the paper's "
    "suit has 30); 0: skeletons (takes listed as .c3d files are markers anyway).",
)
NORMALISE = normalise_option(
    "A's features relative to A's own running mean and (markers) B's frames on the "
    "average training body"
)
OUTPUT = typer.Option(
    "frames",
    callback=choice(("frames", "regression")),
    help="B as real training frames through the trellis ('frames', the paper's) or, on "
    "markers, as the state-conditional regression on A ('regression').",
)
CONTACT_WEIGHT = ranged(
    "weight",
    0.0,
    help="Where A's right hand is out to B's, how far B is moved toward where its hand meets "
    "A's as the training pairs' hands met (0: the paper's placement; docs/hmm.md, 'The "
    "hands' contact').",
)
PLACE_SCALE = typer.Option(
    "none",
    callback=choice(("none", "size")),
    help="B's distance from A as the training pairs' ('none', the paper's) or scaled by A's "
    "size, measured by A's markers, with B of the average size ('size'; markers; docs/hmm.md, "
    "'B's place and the pair's size').",
)
HEIGHTS = typer.Option(
    "capture",
    callback=choice(("capture", "lifted")),
    help="A marker A at the heights it comes with, as the training capture's ('capture'), or "
    "lifted to the training people's height, B moved down as much ('lifted': markers with "
    "another vertical origin; docs/hmm.md, 'Markers as input').",
)
FPS = ranged("fps", 30.0, help="Model frame rate (takes are resampled).")
WINDOW = ranged("window", 10, help="Windowed-Viterbi slice length.")
INITIAL = typer.Option(
    "prior",
    callback=choice(("prior", "middle")),
    help="Windowed Viterbi's first slice starts from the learnt pi ('prior') or one-hot on "
    "the middle state ('middle', eq. 3 as printed).",
)
N_ITER = ranged("iterations", 50, help="Most EM iterations.")
# The choices of algorithms.gaussian.COVARIANCE_TYPES (not imported: the models load lazily)
COVARIANCE = typer.Option(
    "full",
    "--covariance-type",
    callback=choice(("full", "diag", "spherical", "tied")),
    help="The states' Gaussians: 'full' (the paper's), 'diag', 'spherical' or 'tied'.",
)
VAR_FLOOR = ranged(
    "fraction",
    0.3,
    "--var-floor",
    help="Variance floor of each PCA feature, as a fraction of that feature's variance.",
)
SEED = ranged("seed", 0, help="Random seed (k-means start).")
JOBS = typer.Option(
    1, "--jobs", min=0, help="Parallel jobs of EM's E-step over the takes (0: all cores)."
)
JSON = typer.Option(False, "--json", help="Print the results as JSON.")
KIND = kind_option()
ROLES = roles_option()


PRESET = preset_option(DUALHMM_PRESETS, "docs/hmm.md")


def _split(values: str | None) -> list[str] | None:
    return [v.strip() for v in values.split(",") if v.strip()] if values else None


#: The options of ``train`` and ``crossval`` that set the model, as DualHMM's parameters.
MODEL_OPTIONS = {
    "states": "n_states",
    "seed": "random_state",
    **{
        k: k
        for k in (
            "mode", "observation", "candidates", "placement_window", "place_memory", "blend_window",
            "trellis",
            "points", "energy", "frame", "markers", "fps", "window", "initial", "n_iter",
            "normalise", "output", "contact_weight", "place_scale", "heights",
            "covariance_type", "var_floor",
        )
    },
}  # fmt: skip


def new_model(options: dict):
    """An unfitted DualHMM from a command's options (its ``locals()``: those of
    :data:`MODEL_OPTIONS`), the settings that ``train`` and ``crossval`` share."""
    from markovmotion.models.hmm.dual import DualHMM

    markers = options.get("markers", 0)
    if 0 < markers < 13:
        raise typer.BadParameter("--markers: 0 (skeletons) or 13 to 200 virtual markers")
    return DualHMM(**{param: options[opt] for opt, param in MODEL_OPTIONS.items()})


@app.command()
def train(
    out: Path = typer.Option(..., help="Model file to write (.npz)."),
    data: Path = DATA,
    labels: str = LABELS,
    test_trials: str = typer.Option(
        None, help="Comma-separated trials held out for testing (not trained on)."
    ),
    test_people: str = typer.Option(
        None,
        help="Comma-separated pairs of people (INDEX.csv's subject) held out for testing: "
        "their takes are not trained on, and evaluate without --test answers them.",
    ),
    states: int = STATES,
    mode: str = MODE,
    observation: str = OBSERVATION,
    candidates: int = CANDIDATES,
    placement_window: int = PLACEMENT_WINDOW,
    place_memory: int = PLACE_MEMORY,
    blend_window: int = BLEND_WINDOW,
    trellis: str = TRELLIS,
    points: str = POINTS,
    energy: float = ENERGY,
    frame: str = FRAME,
    markers: int = MARKERS,
    normalise: str = NORMALISE,
    output: str = OUTPUT,
    contact_weight: float = CONTACT_WEIGHT,
    place_scale: str = PLACE_SCALE,
    heights: str = HEIGHTS,
    fps: float = FPS,
    window: int = WINDOW,
    initial: str = INITIAL,
    n_iter: int = N_ITER,
    covariance_type: str = COVARIANCE,
    var_floor: float = VAR_FLOOR,
    seed: int = SEED,
    jobs: int = JOBS,
    kind: str = KIND,
    roles: str = ROLES,
    choose: str = CHOOSE,
    preset: str = PRESET,
) -> None:
    """Train a dual HMM on the two-person takes of a motion-capture folder."""
    import joblib

    from markovmotion.evaluate.hmm import fit_on_index

    check_model_output(out)
    start = time.perf_counter()
    options = with_preset(locals(), DUALHMM_PRESETS)
    model = new_model(options)
    grid = grid_of("hmm", choose, options["preset_set"])
    with joblib.parallel_config(n_jobs=jobs or -1):  # loading shows progress; EM is quiet
        model, extras, pairs = fit_on_index(
            model, data, _split(labels), _split(test_trials), kind, options["roles"], grid,
            _split(test_people),
        )  # fmt: skip
    model.save(out, **extras)
    if "chosen" in extras:
        err_console.print(
            chosen_line(extras["chosen"], "windowed world error on the folds left out"),
            highlight=False,
        )
    if model.contact_weight and model.contact is None:
        from markovmotion.models.hmm.contact import CONTACT_MM

        err_console.print(
            "note: --contact-weight: the training takes hold no frames whose right hands touch "
            f"(closer than {CONTACT_MM:g} mm): B is placed without the contact",
            highlight=False,
        )
    hmm = model.lambda_a_
    seen = f"{len(model.marker_names_b_)} markers, " if model.uses_markers else ""
    both = " in both roles" if extras["roles"] == "both" else ""
    if test_people:
        both += f" (held out: {', '.join(_split(test_people))})"
    if model.place_scale == "size":
        both += f", B's place scaled by A's size (mean {model.place_size_:.0f} mm)"
    takes = f"{len(pairs)} take{'' if len(pairs) == 1 else 's'}"
    err_console.print(
        f"wrote {out}: {takes}{both}, {seen}{len(model.train_a_)} frames at {fps:g} fps, "
        f"N={states} (EM mode {mode}), PCA dims A={model.train_a_.shape[1]} B={model.train_b_.shape[1]}, "
        f"{hmm.n_iter_} EM iterations "
        f"({'converged' if hmm.converged_ else f'stopped at --n-iter {n_iter}, not converged'}), "
        f"log-likelihood {model.history_[-1]:.1f}, "
        f"{time.perf_counter() - start:.1f} s",
        highlight=False,
    )


def read_stream(path: Path, fps: float | None = None):
    """Person A's take as a stream: ``(motion, missing)``, ``missing`` (F,) marking the frames
    with nothing recorded.

    A C3D file: (Markers, frames with a marker unseen), the marker system's own way of
    saying a sample is missing. A BVH or ASF/AMC file has no such mark: it is read by the
    same checked reader as every other command (a NaN, infinite, non-numeric or extra value
    is an error naming the file and line), so none of its frames is missing. A file of the
    collection is read as INDEX.csv says (true frame rate, CMU's reference frame dropped)
    unless ``fps`` overrides the file's rate.
    """
    from markovmotion.core.markers import Markers

    motion = read_listed(path, fps)
    if isinstance(motion, Markers):  # markers: unseen samples are NaN, their frames missing
        return motion, ~motion.visible().all(axis=1)
    return motion, np.zeros(motion.n_frames, dtype=bool)


#: ``respond --video``'s options that only the particle filter reads: given (or
#: ``--realtime``), ``--method auto`` is it.
FILTER_OPTIONS = ("particles", "layers", "data", "guide", "body_model")


@app.command()
def respond(
    ctx: typer.Context,
    model: Path = typer.Option(..., help="Dual-HMM model file (.npz)."),
    input: Path = typer.Option(
        None,
        help="Person A's motion (BVH, ASF/AMC), or markers (C3D) for a model trained on "
        "markers (which also reads a skeleton by the body points its markers name); or --video.",
    ),
    out: Path = typer.Option(
        ...,
        help="Person B's generated motion (.bvh), or markers (.c3d) from a marker model; "
        "with --video the composite (.mp4).",
    ),
    video: Path = typer.Option(
        None,
        help="Track A in this video (folder with cameras.json, or one .mp4 with --cameras) "
        "and draw B into it.",
    ),
    cameras: Path = typer.Option(None, help="Camera file of --video (default: its cameras.json)."),
    view: int = ranged(
        "count", 0, min=0, max=MAX_CAMERAS - 1, help="Camera whose video is composited."
    ),
    particles: int = ranged("count", 200, min=10, max=5000, help="Tracker particles per layer."),
    layers: int = ranged("count", 10, min=1, max=50, help="Tracker annealing layers."),
    max_frames: int = ranged("count", None, max=1_000_000, help="Only the first video frames."),
    data: Path = typer.Option(None, help="Motion capture for the tracker's body model."),
    window: int = ranged(
        "window", None, help="Windowed-Viterbi slice length (default: the model's)."
    ),
    standard: bool = typer.Option(False, help="Standard Viterbi over the whole input instead."),
    trellis: str = typer.Option(
        None, callback=choice(("path", "paper")), help="Trellis (default: the model's)."
    ),
    realtime: bool = typer.Option(
        False,
        help="Replay A as a stream at its frame rate (with --video: track frames as they "
        "arrive, skipping those it cannot keep up with); report per-frame latency.",
    ),
    fps: float = ranged(
        "fps",
        None,
        help="True frame rate of the input (default: INDEX.csv's for a file of the collection, else the file's).",
    ),
    animation: Path = typer.Option(None, help="Also animate A and B together (.gif/.mp4)."),
    method: str = method_option("respond"),
    guide: str = guide_option(),
    body_model: str = body_model_option(),
    person: str = person_option(),
) -> None:
    """Generate person B's response to person A's motion (or markers, for a marker model:
    a C3D file, or a BVH with the model's virtual markers placed on it; B comes out as C3D)."""
    from markovmotion.io import check_motion_output, write_motion
    from markovmotion.io.c3d import check_c3d_output, write_c3d
    from markovmotion.io.files import base_suffix
    from markovmotion.models.hmm.dual import DualHMM
    from markovmotion.viz import check_output, render

    if standard and (realtime or window):
        raise typer.BadParameter("--standard needs the whole input: no --window or --realtime")
    if (input is None) == (video is None):
        raise typer.BadParameter("give person A as --input MOTION or as --video VIDEO")
    if video is None and (method != "auto" or guide not in ("auto", "none") or person):
        raise typer.BadParameter("--method, --guide and --person are how A is tracked in --video")
    chose = None
    if video is not None:
        from markovmotion.video.cameras import read_camera_file

        cameras = read_camera_file(video, cameras)  # read once: every reader takes it so
        method, chose = method_for(
            ctx, method, video, cameras, None, FILTER_OPTIONS, realtime, "respond"
        )
    if guide == "mediapipe" and (method != "apf" or realtime):
        raise typer.BadParameter(
            "guides the particle filter over the whole video: --method apf, no --realtime",
            param_hint="--guide",
        )
    if video is not None:
        _respond_video(
            model, video, out, cameras, view, particles, layers, max_frames, data, standard,
            realtime, method, guide, body_model, person, chose,
        )  # fmt: skip
        return
    as_c3d = base_suffix(out) == ".c3d"
    (check_c3d_output if as_c3d else check_motion_output)(out)
    if animation is not None:
        check_output(animation)
    dual = DualHMM.load(model)
    _check_combination(dual, input, out, as_c3d)
    dual.trellis = trellis or dual.trellis
    motion, broken = read_stream(input, fps)
    dual.check_input(motion, input)
    if not np.isclose(motion.fps, dual.fps):
        err_console.print(f"resampling {input.name} from {motion.fps:g} to {dual.fps:g} fps")
        motion = _resample_stream(motion, broken, dual.fps)
    window = window or dual.window
    console = err_console
    if realtime:
        from markovmotion.models.online import replay

        played = replay(lambda: dual.partner(window), motion)
        b = played.motion
        console.print(
            f"streamed {played.streamed} frames at {motion.fps:g} fps: {played.summary()}; "
            f"skipped (NaN/missing) {int(broken[: played.streamed].sum())}",
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
        b = dual.respond(motion, "standard" if standard else "windowed")
    (write_c3d if as_c3d else write_motion)(b, out)
    console.print(f"wrote {out} ({b.n_frames} frames at {b.fps:g} fps)")
    if realtime and played.interrupted:
        stopped(played, motion.n_frames, out)
    if animation is not None:
        shown = motion.copy()
        if hasattr(shown, "rotations"):
            shown.rotations[~np.isfinite(shown.rotations).all(axis=(1, 2))] = [0, 0, 0, 1]
        render([shown, b], animation, names=["A (real)", "B (virtual partner)"])
        console.print(f"wrote {animation}")


def _respond_video(
    model, video, out, cameras, view, particles, layers, max_frames, data, standard, realtime,
    method, guide="none", body_model="interaction", person=None, chose=None,
):  # fmt: skip
    """``respond --video``: track A, generate B, composite B into the video (live with
    ``realtime``; A by MediaPipe with ``method="monocular"`` or ``"triangulate"``);
    ``chose``: ``--method auto``'s note."""
    from markovmotion.models.hmm.dual import DualHMM
    from markovmotion.video.cameras import camera_file, camera_videos, load_cameras, lone_video
    from markovmotion.video.composite import respond_in_video, respond_mediapipe
    from markovmotion.video.multiview import default_body_model

    if out.suffix.lower() != ".mp4":
        raise typer.BadParameter(f"{out}: the composite is an .mp4 file", param_hint="'--out'")
    if realtime and method != "apf":
        raise typer.BadParameter(
            f"--realtime tracks with the particle filter: no --method {method}"
        )
    where = camera_file(video, cameras)
    lone = lone_video(video)  # one camera's video file or folder of frames
    # one camera's video read alone: the other cameras' videos at rates of their own noted
    cams, doc = load_cameras(where, paired=not lone and method != "monocular")
    if not lone:
        camera_videos(where, cams)  # a missing video: fail before the work
    # the whole video's filter only (--realtime tracks frame by frame, monocular has its own)
    guided, note = False, None
    if method == "apf" and not realtime:
        guided, note = guide_for(guide, doc, 1 if lone else len(cams))
    check_person(person, cams[:1] if lone else cams, guided or method == "triangulate")
    world_frame_note(DualHMM.load(model), model, "this video's world")
    if method != "apf":
        summary = respond_mediapipe(
            model, video, out, cameras, view, max_frames, "standard" if standard else "windowed",
            method, person,
        )  # fmt: skip
        print_notes(([chose] if chose else []) + summary["notes"])
        named = f" ({summary['camera']})" if summary.get("camera") else " alone"
        where = (
            f"camera {summary['view']}{named}"
            if method == "monocular"
            else f"{summary['views']} views, triangulated"
        )
        err_console.print(
            f"tracked A over {summary['frames']} frames in {where} "
            f"({summary['frames_placed']} placed, {summary['fps']:.2f} frames/s), partner "
            f"{summary['partner_frames']} frames; wrote {summary['out']}",
            highlight=False,
        )
        return
    if realtime:
        live = respond_in_video(
            model, video, out, default_body_model(data, body_model), cameras, view, particles, layers,
            max_frames, live=True,
        )  # fmt: skip
        print_notes(live["background"] + live["notes"])
        err_console.print(
            f"live: {live['frames']} frames at the video's rate, {live['tracked']} tracked, "
            f"{live['skipped']} skipped; latency per frame median {live['latency_ms_median']} ms, "
            f"p99 {live['latency_ms_p99']} ms; partner lag {live['lag_frames']} frames; "
            f"wrote {live['out']}",
            highlight=False,
        )
        return
    summary = respond_in_video(
        model, video, out, default_body_model(data, body_model), cameras, view, particles, layers,
        max_frames, "standard" if standard else "windowed", guide=guided, person=person,
    )  # fmt: skip
    # the guide's note after the work, with the others (it had been printed before it)
    print_notes(summary["background"] + ([note] if note else []) + summary["notes"])
    err_console.print(
        f"tracked A over {summary['frames']} frames in {summary['views']} views "
        f"({summary['fps']:.2f} frames/s{', guided by MediaPipe' if guided else ''}), partner "
        f"{summary['partner_frames']} frames; wrote {summary['out']}",
        highlight=False,
    )


def _check_combination(dual, input: Path, out: Path, as_c3d: bool) -> None:
    """One line (exit 2) for a model and files that do not go together: markers in or out
    of a skeleton model, or a skeleton's output from a marker model (a BVH given to a model
    learnt from C3D markers is checked by ``check_input``: the body points its markers
    name)."""
    from markovmotion.errors import MotionFormatError, SkeletonMismatchError
    from markovmotion.io.files import base_suffix

    c3d_in = base_suffix(input) == ".c3d"
    if not dual.uses_markers and (c3d_in or as_c3d):
        raise SkeletonMismatchError(
            f"{input if c3d_in else out}: the model was trained on skeletons; it takes and "
            "gives motions (BVH), not markers (C3D)"
        )
    if dual.uses_markers and not as_c3d:
        raise MotionFormatError(out, "the model was trained on markers: write B to a .c3d file")


def _resample_stream(motion, broken: np.ndarray, fps: float):
    """Resample a stream whose broken frames are NaN; a new frame is broken if it touches one."""
    if not hasattr(motion, "rotations"):  # markers: a sample next to an unseen one is unseen
        return motion.resample(fps)
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
        None, help="Folder for the per-frame error plots (Figs. 6-8); none if not given."
    ),
    json_out: bool = JSON,
) -> None:
    """Error of the generated B against the real B on every test take, with baselines.

    With --test, the takes of that index that fit the model (its labels, person A's
    skeleton), leaving out (and listing) those it trained on, compared by content;
    without, the takes held out when it was trained (--test-trials of ``train``).
    """
    from markovmotion.evaluate.hmm import evaluate_model
    from markovmotion.models.hmm.dual import DualHMM

    dual = DualHMM.load(model)
    _report(*evaluate_model(dual, test, _split(labels), _split(test_trials), plots), json_out)


@app.command()
def crossval(
    data: Path = DATA,
    labels: str = LABELS,
    states: int = STATES,
    mode: str = MODE,
    observation: str = OBSERVATION,
    candidates: int = CANDIDATES,
    placement_window: int = PLACEMENT_WINDOW,
    place_memory: int = PLACE_MEMORY,
    blend_window: int = BLEND_WINDOW,
    trellis: str = TRELLIS,
    points: str = POINTS,
    energy: float = ENERGY,
    frame: str = FRAME,
    markers: int = MARKERS,
    normalise: str = NORMALISE,
    output: str = OUTPUT,
    contact_weight: float = CONTACT_WEIGHT,
    place_scale: str = PLACE_SCALE,
    heights: str = HEIGHTS,
    fps: float = FPS,
    window: int = WINDOW,
    initial: str = INITIAL,
    n_iter: int = N_ITER,
    covariance_type: str = COVARIANCE,
    var_floor: float = VAR_FLOOR,
    seed: int = SEED,
    jobs: int = JOBS,
    plots: Path = typer.Option(None, help="Folder for the per-frame error plots (Figs. 6-8)."),
    choose: str = CHOOSE,
    json_out: bool = JSON,
    kind: str = KIND,
    roles: str = ROLES,
    preset: str = PRESET,
) -> None:
    """Leave-one-out evaluation: train on all takes but those of one pair of people (INDEX.csv's
    subject; one take when all come from one pair), test on those, for every pair."""
    import joblib

    from markovmotion.evaluate.hmm import crossval_index

    options = with_preset(locals(), DUALHMM_PRESETS)
    model = new_model(options)
    grid = grid_of("hmm", choose, options["preset_set"])
    with joblib.parallel_config(n_jobs=jobs or -1):
        report, written = crossval_index(
            model, data, _split(labels), plots, grid, kind, options["roles"]
        )
    _report(report, written, json_out)


def _report(report: dict, written: list[Path], json_out: bool) -> None:
    """Print ``report`` as JSON (stdout) or as a table, and the plots written (stderr)."""
    if json_out:
        print_json(report, indent=2)
    else:
        _print_table(report)
    for key, what in (
        ("test_files", "test files"),
        ("left_out_training_files", "left out (training takes)"),
        ("left_out_other_kind", "left out (another kind of take)"),
        ("left_out_other_skeleton", "left out (not the model's joints or markers, or unseen)"),
    ):
        if report.get(key) and not json_out:
            err_console.print(f"{what}: {', '.join(report[key])}", highlight=False)
    for p in written:
        err_console.print(f"wrote {p}", highlight=False)


def _print_table(report: dict) -> None:
    from rich.table import Table

    from markovmotion.cli.tables import print_table
    from markovmotion.evaluate.hmm import PLACED

    table = Table(
        title="dual HMM: mean per-frame error of B (mm) and jumps (p90 of frame steps, mm)"
    )
    cols = ("standard_mm", "windowed_mm", "mean_pose_mm", "nearest_neighbour_mm")
    if "gmr_mm" in report["overall"]:
        cols = (*cols, "gmr_mm")
    jumps = ("standard_jump_p90_mm", "windowed_jump_p90_mm", "real_jump_p90_mm")
    rows = {
        "overall": report["overall"],
        **report["per_label"],
        **{f"people {p}": r for p, r in report.get("per_people", {}).items()},
        **report["per_pair"],
    }
    # the paper's trellis picks training frames: a model that regresses B has none to show
    paper = any(r["trellis"].get("paper") for r in rows.values())
    # every world column body-centred too: the aims compare with nearest neighbour and GMR
    body_head = "body-centred std/win/mean/nn" + ("/gmr" if "gmr_mm" in cols else "")
    heads = ("group", *cols, body_head, "known motion world/body")
    heads = (*heads, "at true place win/mean", "paper trellis std/win", *jumps)
    heads = (*heads, "hand gap real/win", "observer", "latency median/p99 (µs)")
    for c in heads:
        if paper or c != "paper trellis std/win":
            table.add_column(c)
    for name, r in rows.items():
        lat, body = r["latency_us"], r["body_centred"]
        gap, place, trellis = r.get("hand_gap_in_contact_median_mm"), r.get("place"), r["trellis"]
        seen = r.get("observer_accuracy")
        cells = [
            name,
            *(f"{r[c]:.1f}" for c in cols),
            "/".join(f"{body[k]:.1f}" for k in cols),
            f"{r['known_motion_mm']:.1f}/{body['known_motion_mm']:.1f}",
            "/".join(f"{place[f'{k}_at_true_place_mm']:.1f}" for k in PLACED) if place else "-",
        ]
        if paper:
            t = trellis.get("paper")
            cells.append(f"{t['standard_mm']:.1f}/{t['windowed_mm']:.1f}" if t else "-")
        cells += [
            *("-" if r[c] is None else f"{r[c]:.1f}" for c in jumps),
            f"{gap['real']:.0f}/{gap['windowed']:.0f}" if gap else "-",
            f"{seen:.2f}" if isinstance(seen, float) and np.isfinite(seen) else "-",
            f"{lat['median']:.0f}/{lat['p99']:.0f}",
        ]
        table.add_row(*cells)
    print_table(table)
    err_console.print(
        "observer: a classifier's accuracy telling the partner from the real B given A, "
        "folds by pair of people, by take when one pair is tested (0.5: it cannot tell them "
        "apart; '-': one take)",
        highlight=False,
    )
    err_console.print(
        "known motion: the real B's motion moved onto the training people's mean posture "
        "and place, a partner that knew B's every move but not B's posture or place "
        "(docs/hmm.md); at true place: the world error with B moved onto the real B's "
        "centroid (windowed/mean pose): what is left once B's place is right",
        highlight=False,
    )
    from markovmotion.evaluate.hmm import aims_line

    say_people_trained_on(report)
    for name, r in {"overall": report["overall"], **report["per_label"]}.items():
        err_console.print(
            f"aims for a partner for new people (docs/hmm.md), {name}, windowed: "
            + aims_line(r["aims"]),
            highlight=False,
        )
