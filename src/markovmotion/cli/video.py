"""``video render`` and ``track``: multi-view video of a take, and 3-D tracking by annealed
particle filtering (dual-HMM paper, §3)."""

from __future__ import annotations

from pathlib import Path

import typer

from markovmotion.cli.options import (
    body_model_option,
    check_person,
    choice,
    guide_for,
    guide_option,
    method_for,
    method_option,
    person_option,
    ranged,
)
from markovmotion.cli.tables import print_json, print_notes
from markovmotion.defaults import MAX_CAMERAS
from markovmotion.progress import err_console

app = typer.Typer(
    help="Multi-view video of motion capture with calibrated cameras (cameras.json).",
    no_args_is_help=True,
)


@app.command("render")
def render(
    take: Path = typer.Argument(..., help="Person A's motion (BVH or ASF/AMC)."),
    out: Path = typer.Option(..., help="Folder for camK.mp4, camK_background.png, cameras.json."),
    views: int = ranged(
        "count", 3, min=1, max=MAX_CAMERAS, help="Cameras around the capture volume."
    ),
    seconds: float = ranged("seconds", None, help="Only this much of the take."),
    start: float = ranged(
        "time_constant", None, help="Start this far into the take (s; 0: its start)."
    ),
    fps: float = ranged("fps", None, help="Frame rate of the video (default: the take's)."),
    people: str = typer.Option(
        "a", callback=choice(("a", "both")), help="a: person A alone (B masked); both."
    ),
    width: int = ranged("count", 320, min=16, max=4096, help="Frame width (px)."),
    height: int = ranged("count", 240, min=16, max=4096, help="Frame height (px)."),
    noise: float = typer.Option(4.0, min=0.0, max=100.0, help="Sensor noise (grey levels, std)."),
    seed: int = ranged("seed", 0, help="Seed of the background and the noise."),
) -> None:
    """Render a take as one video per calibrated camera, and write the cameras beside them."""
    from markovmotion.video.multiview import render_multiview

    path = render_multiview(
        take, out, views, seconds, fps, people, (width, height), noise, seed, start or 0.0
    )
    err_console.print(f"wrote {views} videos and {path}", highlight=False)


@app.command("cameras")
def cameras(
    calibration: Path = typer.Argument(
        ..., help="Pose2Sim / Anipose calibration (Calib.toml) or Qualisys (.qca.txt)."
    ),
    videos: list[Path] = typer.Argument(..., help="One video per camera, in the file's order."),
    out: Path = typer.Option(
        None, help="Camera file to write (default: cameras.json beside the videos)."
    ),
    fps: float = ranged("fps", None, help="Frame rate (default: the first video's)."),
    up: str = typer.Option(
        "z", callback=choice(("z", "y", "-y")), help="The calibration's up axis (Pose2Sim: z)."
    ),
    units: str = typer.Option(
        "m",
        callback=choice(("m", "mm")),
        help="The TOML calibration's length unit (Pose2Sim: m; a .qca.txt is in mm).",
    ),
    force: bool = typer.Option(False, "--force", help="Replace an existing camera file."),
) -> None:
    """Write cameras.json for your videos from a Pose2Sim / Anipose or Qualisys calibration:
    the world turned to Y up in mm, the intrinsics scaled to the videos' size, the lens
    distortion kept."""
    from markovmotion.video.calibration import import_calibration

    path = import_calibration(calibration, videos, out, fps, up, units, force)
    err_console.print(f"wrote {path} ({len(videos)} cameras)", highlight=False)


@app.command("sync")
def sync(
    video: Path = typer.Argument(..., help="Folder with cameras.json and the videos it names."),
    cameras: Path = typer.Option(None, help="Camera file (default: VIDEO/cameras.json)."),
    max_lag: float = ranged("seconds", 2.0, max=60.0, help="Largest offset tried (s)."),
    max_frames: int = ranged("count", None, max=1_000_000, help="Only the first frames."),
    write: bool = typer.Option(
        False, "--write", help="Record the offsets in the camera file (each camera's skip_frames)."
    ),
    json_out: bool = typer.Option(False, "--json", help="Print the offsets as JSON."),
) -> None:
    """Measure how many frames each camera's video is offset from the first camera's (cameras
    started one after another), by where MediaPipe's landmarks lie against their epipolar
    lines (needs scripts/install-camera); --write records it for every command that reads the
    videos."""
    from markovmotion.video.sync import sync_video, write_skips

    result, fps, where, notes = sync_video(video, cameras, max_lag, max_frames)
    summary = {
        "fps": fps,
        "cameras": result.summary(fps),
        "in_step": result.in_step,
        "measured": bool(result.measured.all()),
        "notes": notes,
    }
    if write:
        summary["wrote"] = str(write_skips(where, result))
    print_notes(notes)
    if json_out:
        print_json(summary)
        return
    for k, (name, c) in enumerate(summary["cameras"].items()):
        if k == 0:
            err_console.print(
                f"{name}: the camera the others are measured against", highlight=False
            )
            continue
        if c["offset_frames"] is None:
            err_console.print(
                f"{name}: not measured (too few landmarks seen in it and the first camera)",
                highlight=False,
            )
            continue
        px = "-" if c["epipolar_px"] is None else f"{c['epipolar_px']:.2f}"
        none = "-" if c["epipolar_px_in_step"] is None else f"{c['epipolar_px_in_step']:.2f}"
        weak = (
            f"; the best offset, {c['best_offset_frames']:+d} frames at "
            f"{c['best_offset_px']:.2f} px, is not clearly better than none, so none is taken"
            if c["best_offset_frames"] != c["offset_frames"]
            else ""
        )
        err_console.print(
            f"{name}: offset {c['offset_frames']:+d} frames ({c['offset_s']:+.3f} s); landmarks "
            f"{px} px from their epipolar lines so (as they are: {none} px){weak}",
            highlight=False,
        )
    if write:
        err_console.print(f"wrote {summary['wrote']}", highlight=False)
    elif not result.in_step and result.measured.all():
        err_console.print(f"--write records it in {where}", highlight=False)


def register(root: typer.Typer) -> None:
    """Attach ``track`` to the root command."""
    root.command("track")(track)


#: ``track``'s options that only the particle filter reads: given, ``--method auto`` is it.
FILTER_OPTIONS = (
    "particles", "layers", "data", "seed", "start", "body_size", "background", "sides", "guide",
    "body_model",
)  # fmt: skip


def track(
    ctx: typer.Context,
    video: Path = typer.Option(
        ..., help="Folder with cameras.json and the videos it names, or one camera's video."
    ),
    cameras: Path = typer.Option(
        None, help="Camera file (default: VIDEO/cameras.json); a lone video is its first camera."
    ),
    out: Path = typer.Option(
        None,
        help="Person A's tracked motion: .bvh (the particle filter's skeleton) or .c3d "
        "(MediaPipe's 13 markers, --method triangulate or monocular).",
    ),
    truth: Path = typer.Option(None, help="The true motion (BVH): report the error in mm."),
    json_out: bool = typer.Option(False, "--json", help="Print the summary as JSON."),
    particles: int = ranged("count", 200, min=10, max=5000, help="Particles per layer."),
    layers: int = ranged("count", 10, min=1, max=50, help="Annealing layers (1: plain PF)."),
    views: int = ranged("count", None, min=1, max=MAX_CAMERAS, help="Use only the first cameras."),
    max_frames: int = ranged("count", None, max=1_000_000, help="Only the first frames."),
    data: Path = typer.Option(None, help="Motion capture for the body model (default: README)."),
    seed: int = ranged("seed", 0, help="Random seed."),
    start: Path = typer.Option(
        None, help="First frame's pose (BVH on the body model's skeleton); default: searched."
    ),
    method: str = method_option("track"),
    stature: float = ranged(
        "stature",
        None,
        help="Monocular: the person's height (mm); default: estimated from the feet on the floor.",
    ),
    reference: Path = typer.Option(
        None, help="3-D reference CSV (frame, <joint>_x/_y/_z, mm): report the error against it."
    ),
    body_size: str = typer.Option(
        "template",
        help="The person's size: template (the body model's); video (legs and arms measured by "
        "MediaPipe in the first camera); views (upper arms, forearms, thighs, shins and the "
        "shoulders' width, by MediaPipe triangulated from every camera); both need "
        "scripts/install-camera; or SCALE,LEGS,ARMS (e.g. 0.97,0.95,1.05).",
    ),
    background: str = typer.Option(
        "learn",
        callback=choice(("learn", "median")),
        help="Cameras without an empty-scene image: learn: the median where MediaPipe finds "
        "no person, and say if the plain median holds them; median: the plain median.",
    ),
    sides: bool = typer.Option(
        False,
        help="Catch front/back flips with MediaPipe's left and right in every camera "
        "(needs scripts/install-camera): a flipped pose is searched again turned round, or its confidence "
        "lowered.",
    ),
    guide: str = guide_option(),
    body_model: str = body_model_option(),
    left_right: str | None = typer.Option(
        None,
        callback=choice(("mediapipe", "continuity", "facing", "online", "views", "both")),
        help="Monocular (default continuity): continuity: MediaPipe's left and right "
        "relabelled where they jump between frames (offline, whole video); online: the same "
        "frame by frame, causally (as the camera page does); facing: continuity, and the "
        "person faces the camera (a webcam's user); mediapipe: its own labels. Triangulate, "
        "--guide mediapipe and --sides (default views): views: made to agree across the views "
        "by triangulation; continuity: each view over time; both; mediapipe.",
    ),
    person: str = person_option(),
    smooth: str = typer.Option(
        None,
        help="Triangulate and monocular: the smoothing over time, auto (the default: chosen "
        "by leaving one camera out; monocular: 1/15 s, chosen on rendered video) or SECONDS "
        "(a Gaussian's sigma, 0: none).",
    ),
) -> None:
    """Track person A in video: MediaPipe Pose in every camera, triangulated, or in one
    camera placed by PnP (write the 13 markers as C3D), or multi-view annealed particle
    filtering (write A as BVH); ``--method auto`` picks (:func:`~markovmotion.video.
    multiview.resolve_method`)."""
    from markovmotion.io.files import base_suffix
    from markovmotion.video.cameras import read_camera_file

    cameras = read_camera_file(video, cameras)  # read once: every reader below takes it so
    method, chose = method_for(
        ctx, method, video, cameras, views, FILTER_OPTIONS,
        asked=out is not None and base_suffix(out) != ".c3d",
    )  # fmt: skip
    if method != "apf" and guide == "mediapipe":
        raise typer.BadParameter(
            "guides the particle filter: use it with --method apf", param_hint="--guide"
        )
    if sides and method != "apf":
        raise typer.BadParameter("is for the particle filter (--method apf)", param_hint="--sides")
    if smooth is not None and method == "apf":
        raise typer.BadParameter("is for --method triangulate or monocular", param_hint="--smooth")
    smoothing = _smoothing(smooth)
    if stature is not None and method != "monocular":
        raise typer.BadParameter("is for --method monocular", param_hint="--stature")
    if truth is not None:  # before minutes of tracking
        from markovmotion.video.multiview import check_truth

        said = check_truth(truth, video, cameras)
        if said:
            err_console.print(said, highlight=False)
    from markovmotion.video.cameras import camera_videos, load_cameras, lone_video

    guided, note, cams, first_skip = False, None, [], 0
    if method == "apf" or person is not None:  # a missing video: first
        cams, doc = load_cameras(cameras, paired=not lone_video(video) and views != 1)
        first_skip = cams[0].skip  # the reference is numbered in the first camera's frames
        if not lone_video(video):
            camera_videos(cameras, cams)
    if lone_video(video):  # one camera's video
        cams = [c for c in cams if Path(c.video).name == video.name][:1] or cams[:1]
    if views is not None and not cams:  # one camera's video read alone: others' rates noted
        cams, _ = load_cameras(cameras, paired=method != "monocular")
    if views is not None and views > len(cams):  # it had run on fewer without a word
        print_notes([f"note: --views {views}: the camera file has {len(cams)}, all used"])
    if method == "apf":
        guided, note = guide_for(guide, doc, min(len(cams), views or len(cams)))
    check_person(person, cams[:views] if views else cams, method == "triangulate" or guided)
    reads = "mediapipe" if guided else "sides" if sides else "none"
    left_right = _left_right_for(method, reads, left_right)
    if method in ("monocular", "triangulate"):
        _track_landmarks(
            method,
            video,
            cameras,
            out,
            max_frames,
            stature,
            views,
            reference,
            json_out,
            left_right,
            person,
            smoothing,
            truth,
            chose,
        )
        return
    from markovmotion.errors import MotionFormatError
    from markovmotion.io import check_motion_output, write_motion
    from markovmotion.io.files import check_writable
    from markovmotion.video.multiview import ONE_VIEW_NOTE, default_body_model, track_take

    if out is not None:
        check_motion_output(out)
        check_writable(out)  # before the tracking, not after
    if reference is not None and not reference.is_file():
        raise MotionFormatError(reference, "no such reference file")
    size = _body_size(body_size)
    body = default_body_model(data, body_model)
    if size == "video":
        from markovmotion.video.body_size import body_size_from_points
        from markovmotion.video.monocular import track_monocular_video

        tr, _ = track_monocular_video(video, cameras, max_frames)
        try:
            size = body_size_from_points(body, tr.points)
        except ValueError as exc:
            raise MotionFormatError(video, f"cannot measure the body size ({exc})") from None
    if size == "views" and lone_video(video):
        raise MotionFormatError(video, "--body-size views needs the folder of every camera")
    if size not in ("template", "views"):
        from markovmotion.video.body_size import scaled_body

        body = scaled_body(body, *size)
        err_console.print(
            "body size: scale {:.3f}, legs {:.3f}, arms {:.3f}".format(*size), highlight=False
        )
    motion, result, summary = track_take(
        video,
        body,
        cameras,
        truth,
        particles,
        layers,
        views,
        max_frames,
        seed,
        start,
        background == "learn",
        sides,
        guided,
        left_right or "views",
        person,
        size == "views",
    )
    summary["notes"] = [*([note] if note else []), *summary["notes"]]
    print_notes(summary["background"] + summary["notes"])
    if size == "views":
        summary["body_size"] = result.body_size
        err_console.print(
            "body size (person to template): "
            + ", ".join(f"{k} {v:.3f}" for k, v in result.body_size.items()),
            highlight=False,
        )
    later = []  # notes printed, and in the summary's
    if summary["views"] == 1 and ONE_VIEW_NOTE not in summary["notes"]:  # --guide auto's says it
        later.append(ONE_VIEW_NOTE)
    if reference is not None:
        from markovmotion.features.body_points import body_points
        from markovmotion.video.monocular import reference_report

        summary["reference"], said = reference_report(
            body_points(motion), reference, summary["video_fps"], first_skip, max_frames,
            cut_short=bool(summary["ended_early"]),
        )  # fmt: skip
        later += [said] if said else []
    print_notes(later)
    summary["notes"] += later
    if size not in ("template", "views"):
        summary["body_size"] = dict(zip(("scale", "legs", "arms"), size, strict=True))
    if out is not None:
        write_motion(motion, out)
        err_console.print(f"wrote {out}", highlight=False)
    _whom_notes(summary, person)
    if json_out:
        print_json(summary)
    else:
        err = f", MPJPE {summary['mpjpe_mm']:.1f} mm" if "mpjpe_mm" in summary else ""
        if "reference" in summary:
            err += f", {_mm(summary['reference']['mean_mm'])} mm from the reference"
        err_console.print(
            f"tracked {summary['frames']} frames in {_views(summary['views'])}"
            f"{' guided by MediaPipe' if guided else ''} at {summary['fps']:.2f} frames/s"
            # the filter's rate alone had read as the tracker's (22-29 against 8.5-11.5)
            + (f" ({summary['fps_with_guide']:.2f} with MediaPipe's time)" if guided else "")
            + f"{err}; "
            f"{summary['recoveries']} recoveries"
            + (
                f"; {summary['flips']} flipped frames searched again, "
                f"{summary['left_flipped']} left flipped (confidence lowered)"
                if sides
                else ""
            ),
            highlight=False,
        )


def _mm(value: float | None) -> str:
    """A reference error as printed: "-" where no joint could be compared (None)."""
    return "-" if value is None else f"{value:.1f}"


def _left_right_for(method: str, guide: str | None, left_right: str | None) -> str | None:
    """``track``'s --left-right, defaulted or checked against what reads the landmarks:
    one camera (``--method monocular``: ``monocular.LEFT_RIGHT``, default continuity) or
    several views (``triangulate``, ``--guide mediapipe``, the particle filter's ``--sides``,
    given here as ``guide="sides"``: ``triangulation.LEFT_RIGHT``, default views); the
    particle filter alone reads none."""
    from markovmotion.video import monocular, triangulation

    if method == "triangulate" or guide in ("mediapipe", "sides"):
        choices, default, other = triangulation.LEFT_RIGHT, "views", "monocular"
    elif method == "monocular":
        choices, default = monocular.LEFT_RIGHT, "continuity"
        other = "triangulate, --guide mediapipe or --sides"
    elif left_right is None:
        return None
    else:
        raise typer.BadParameter(
            "is for --method monocular, triangulate, --guide mediapipe or --sides",
            param_hint="--left-right",
        )
    if left_right is None:
        return default
    if left_right not in choices:  # a choice of the other way of reading them
        raise typer.BadParameter(f"{left_right} is for --method {other}", param_hint="--left-right")
    return left_right


def _track_landmarks(
    method: str,
    video: Path,
    cameras: Path | None,
    out: Path | None,
    max_frames: int | None,
    stature: float | None,
    views: int | None,
    reference: Path | None,
    json_out: bool,
    left_right: str = "continuity",
    person: str | None = None,
    smooth: float | None = None,
    truth: Path | None = None,
    chose: str | None = None,
) -> None:
    """``--method monocular`` (one camera, PnP) or ``triangulate`` (every camera): MediaPipe's
    body points, written as the 13 markers; ``chose``: ``--method auto``'s note."""
    from markovmotion.errors import MotionFormatError
    from markovmotion.io.c3d import write_c3d
    from markovmotion.video.monocular import monocular_markers, track_monocular_video

    if out is not None and out.suffix.lower() != ".c3d":
        raise MotionFormatError(out, f"{method} tracking writes markers: use a .c3d name")
    if out is not None:
        from markovmotion.io.files import check_writable

        check_writable(out)  # before the tracking, not after
    if reference is not None and not reference.is_file():
        raise MotionFormatError(reference, "no such reference file")
    if method == "triangulate":
        if stature is not None:
            raise typer.BadParameter("is for --method monocular", param_hint="--stature")
        from markovmotion.video.triangulation import track_triangulated_video

        tr, summary = track_triangulated_video(
            video, cameras, max_frames, reference, views, left_right, person, smooth
        )
        where = f"{_views(summary['views'])}, {_smoothed(summary)}"
    else:
        tr, summary = track_monocular_video(
            video, cameras, max_frames, stature, reference, left_right, smooth
        )
        where = f"{summary['camera']}, scale {summary['scale']:.3f}, {_smoothed(summary)}"
    if truth is not None:
        from markovmotion.video.multiview import truth_errors

        summary.update(truth_errors(tr.points, tr.fps, truth, video, cameras))
    if chose:
        summary["notes"] = [chose, *summary["notes"]]
    if out is not None:
        write_c3d(monocular_markers(tr.points, tr.fps, video.name), out)
        err_console.print(f"wrote {out}", highlight=False)
    print_notes(summary["notes"])
    _whom_notes(summary, person)
    if json_out:
        print_json(summary)
    else:
        err = (
            f", {_mm(summary['aligned_mean_mm'])} mm after rigid alignment "
            f"({_mm(summary['mean_mm'])} mm without)"
            if "aligned_mean_mm" in summary
            else ""
        )
        if "mpjpe_mm" in summary:
            err += f", MPJPE {_mm(summary['mpjpe_mm'])} mm"
        err_console.print(
            f"tracked {summary['frames']} frames ({summary['frames_placed']} with all 19 body "
            f"points) of {where} at {summary['fps']:.2f} frames/s{err}",
            highlight=False,
        )


def _smoothed(summary: dict) -> str:
    """How a MediaPipe track was smoothed over time, as the command's line says it."""
    return (
        f"smoothed over sigma {1000 * summary['smoothing_s']:.1f} ms "
        f"({summary['smoothing_chosen_by']})"
    )


def _views(n: int) -> str:
    return f"{n} view" + ("s" if n != 1 else "")


def _whom_notes(summary: dict, person: str | None) -> None:
    """Print the lines that say whom MediaPipe followed (stderr, with or without ``--json``;
    :func:`~markovmotion.video.triangulation.whom_notes`), and add them to the summary's
    notes."""
    from markovmotion.video.triangulation import whom_notes

    lines = whom_notes(summary, named=person is not None)
    print_notes(lines)
    summary["notes"] = [*summary.get("notes", []), *lines]


def _smoothing(text: str | None) -> float | None:
    """``--smooth``: None (not given) and auto choose; else seconds, 0 to 1."""
    if text is None or text == "auto":
        return None
    try:
        seconds = float(text)
    except ValueError:
        seconds = -1.0
    if not 0.0 <= seconds <= 1.0:
        raise typer.BadParameter("auto or SECONDS (0 to 1)", param_hint="--smooth")
    return seconds


def _body_size(text: str) -> str | tuple[float, float, float]:
    """``--body-size``: template, video, views, or three factors; bad values are one usage
    error."""
    if text in ("template", "video", "views"):
        return text
    try:
        size = tuple(float(v) for v in text.split(","))
    except ValueError:
        size = ()
    if len(size) != 3 or not all(0.5 <= v <= 2.0 for v in size):
        raise typer.BadParameter(
            "template, video, views or SCALE,LEGS,ARMS (three numbers 0.5 to 2)",
            param_hint="--body-size",
        )
    return size  # type: ignore[return-value]
