"""Option ranges of the command line, declared once and enforced when the options are parsed.

Every numeric option of a kind (frame rates, seeds, window lengths, ...) is
declared with :func:`ranged`, which is ``typer.Option`` plus a check of the
value against :data:`RANGES`; a value outside is a usage error, printed as one
line (``error: markovmotion convert: Invalid value for '--resample': ...``)
with exit code 2 before any work starts. Frame-rate bounds follow
:data:`markovmotion.limits.MIN_FPS` and ``MAX_FPS`` (``MARKOVMOTION_MIN_FPS``,
``MARKOVMOTION_MAX_FPS``).

Usage::

    fps: float = ranged("fps", None, help="True frame rate, overriding the file's.")
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import typer

from markovmotion.limits import MAX_FPS, MAX_STEPS, MIN_FPS


@dataclass(frozen=True)
class Range:
    """Allowed values of one kind of option: ``lo < v`` (or ``<=``) and ``v <= hi``."""

    lo: float | Callable[[], float]
    hi: float | Callable[[], float] | None
    lo_open: bool = False
    unit: str = ""
    max_length: int | None = None  # for text options

    def high(self) -> float:
        return self.hi() if callable(self.hi) else self.hi  # type: ignore[return-value]

    def low(self) -> float:
        return self.lo() if callable(self.lo) else self.lo

    def describe(self) -> str:
        """The range as the help text shows it."""
        if self.max_length is not None:
            return f"at most {self.max_length} characters"
        unit = f" {self.unit}" if self.unit else ""
        low = f">{self.low():g}" if self.lo_open else f"{self.low():g}"
        return f"{low} to {self.high():g}{unit}"

    def problem(self, value: Any) -> str | None:
        """Why ``value`` is not allowed, or None."""
        if self.max_length is not None:
            if isinstance(value, str) and len(value) > self.max_length:
                return f"at most {self.max_length} characters, got {len(value)}"
            return None
        try:
            v = float(value)
        except (TypeError, ValueError):
            return f"must be a number, got {value!r}"
        lo, hi = self.low(), self.high()
        if isinstance(value, int) and not isinstance(value, bool):
            if lo <= value <= hi and not (self.lo_open and value == lo):
                return None
            return f"must be a whole number from {lo:.0f} to {hi:.0f}, got {value}"
        unit = f" {self.unit}" if self.unit else ""
        low = f"above {lo:g}" if self.lo_open else f"at least {lo:g}"
        span = f"{low} and at most {hi:g}{unit}"
        bad = not math.isfinite(v) or (v <= lo if self.lo_open else v < lo) or v > hi
        return f"must be a finite number {span}, got {value:g}" if bad else None


def _max_fps() -> float:
    return MAX_FPS.value


def _min_fps() -> float:
    return MIN_FPS.value


RANGES: dict[str, Range] = {
    # frame rates (a file's true rate, a resampling target, an animation's rate)
    "fps": Range(_min_fps, _max_fps, unit="fps"),
    # random seeds (NumPy takes 0 .. 2**32 - 1 for legacy seeding)
    "seed": Range(0, 2**32 - 1),
    # Viterbi slice / sliding window lengths in frames
    "window": Range(1, 1000, unit="frames"),
    # hidden states, prototypes, clusters
    "states": Range(1, 1024),
    # prediction horizons in seconds
    "horizon": Range(0, 600, lo_open=True, unit="s"),
    # time constants in seconds (0: none)
    "time_constant": Range(0, 600, unit="s"),
    # lengths of generated or rendered motion in seconds
    "seconds": Range(0, 3600, lo_open=True, unit="s"),
    # a person's height in mm
    "stature": Range(500, 2500, unit="mm"),
    # walking steps to synthesize or adapt on
    "steps": Range(1, int(MAX_STEPS.default)),  # the library's bound (limits.MAX_STEPS)
    # CONDENSATION hypotheses
    "hypotheses": Range(1, 100_000),
    # EM iterations
    "iterations": Range(1, 100_000),
    # trellis candidates and similar small counts
    "count": Range(1, 10_000),
    # fractions of variance (PCA energy) kept
    "fraction": Range(0, 1, lo_open=True),
    # weights of a blend, 0 (none) to 1
    "weight": Range(0, 1),
    # titles and labels drawn on pictures
    "title": Range(0, None, max_length=200),
}


def check_range(kind: str | Range, name: str, value: Any) -> Any:
    """``value`` if allowed for options of ``kind`` (a key of :data:`RANGES` or a
    :class:`Range`); else :class:`typer.BadParameter`."""
    if value is None:
        return value
    problem = (RANGES[kind] if isinstance(kind, str) else kind).problem(value)
    if problem:
        raise typer.BadParameter(problem, param_hint=f"'{name}'")
    return value


def _callback(allowed: Range):
    def check(param: typer.CallbackParam, value: Any) -> Any:
        name = (param.opts or [param.name or "value"])[0]
        if isinstance(value, list | tuple):
            for v in value:
                check_range(allowed, name, v)
            return value
        return check_range(allowed, name, value)

    return check


def ranged(
    kind: str,
    default: Any,
    *param_decls: str,
    min: float | None = None,  # noqa: A002 - typer.Option's names
    max: float | None = None,  # noqa: A002
    **kwargs: Any,
) -> Any:
    """``typer.Option(default, *param_decls, **kwargs)`` checked against ``RANGES[kind]``,
    narrowed by ``min`` / ``max``; the help text ends with the range, and every value out of
    it gets the same one-line message."""
    allowed = RANGES[kind]  # fail at import for an unknown kind
    if min is not None or max is not None:
        allowed = replace(
            allowed,
            lo=allowed.lo if min is None else min,
            hi=allowed.hi if max is None else max,
        )
    kwargs["help"] = f"{kwargs.get('help', '')} [{allowed.describe()}]".strip()
    return typer.Option(default, *param_decls, callback=_callback(allowed), **kwargs)


def choice(values: tuple[str, ...] | list[str]):
    """A callback for ``typer.Option(..., callback=choice(VALUES))``: one of ``values``,
    checked when the options are parsed (before any work)."""

    def check(param: typer.CallbackParam, value: Any) -> Any:
        if value is not None and value not in values:
            name = (param.opts or [param.name or "value"])[0]
            raise typer.BadParameter(
                f"must be one of {', '.join(values)}, got {value!r}", param_hint=f"'{name}'"
            )
        return value

    return check


def kind_option() -> Any:
    """``--kind skeleton|markers``, one name across the command line: which kind of take to
    learn from where a label or category holds both (default: the larger group, said in
    one line; :func:`markovmotion.data.kinds.choose_kind`)."""
    return typer.Option(
        None,
        "--kind",
        callback=choice(("skeleton", "markers")),
        help="Learn from 'skeleton' takes (BVH, ASF/AMC) or 'markers' takes (C3D) where the "
        "labels hold both (default: the larger group, said in one line).",
    )


def roles_option() -> Any:
    """``--roles one|both``, one name across the command line: learn each two-person take as
    listed, or also with the people swapped
    (:func:`markovmotion.evaluate.choose.both_roles`)."""
    return typer.Option(
        "one",
        callback=choice(("one", "both")),
        help="Learn each take as listed ('one': A answered by B) or also with the roles swapped "
        "('both': for interactions whose roles are alike, such as handshakes and waves).",
    )


def body_model_option() -> Any:
    """``--body-model``: what the tracker's body model learns its joints' axes and ranges from
    (``track`` and ``dualhmm respond --video``)."""
    return typer.Option(
        "interaction",
        callback=choice(("collection", "interaction")),
        help="interaction: the training handshake and pull takes alone (the template's own "
        "skeleton); collection: every skeleton take of --data, retargeted onto the template "
        "(built once, then cached; better on some motions the handshakes lack, worse on "
        "others: docs/video.md).",
    )


def guide_option() -> Any:
    """``--guide``: what guides the annealed particle filter besides the images (``track``
    and ``dualhmm respond --video``; :func:`markovmotion.video.multiview.resolve_guide`)."""
    return typer.Option(
        "auto",
        callback=choice(("auto", "none", "mediapipe")),
        help="mediapipe: MediaPipe Pose in every camera (needs the camera extra), triangulated to "
        "reject the views that disagree, pulls the particles' joints towards its landmarks "
        "and restarts some from its pose; none: the images alone; auto: mediapipe for real "
        "people, none for video made by 'video render' (MediaPipe misreads its people) or "
        "without the camera extra (said).",
    )


def person_option() -> Any:
    """``--person CAMERA:U,V``: of several people in view, the one MediaPipe follows across the
    views (``track`` and ``dualhmm respond --video``;
    :func:`markovmotion.video.triangulation.person_ray`)."""
    return typer.Option(
        None,
        help="With several people in view, MediaPipe in every camera follows the one at this "
        "pixel, CAMERA:U,V (a camera's name or number; e.g. cam0:135,240); default: the one "
        "the views agree on.",
    )


def guide_for(guide: str, doc: dict, views: int) -> tuple[bool, str | None]:
    """``--guide`` resolved for a camera file's document and the views tracked
    (:func:`markovmotion.video.multiview.resolve_guide`), a refusal as the option's error."""
    from markovmotion.video.multiview import resolve_guide

    try:
        return resolve_guide(guide, doc, views)
    except ValueError as exc:
        raise typer.BadParameter(str(exc).removeprefix("guide "), param_hint="--guide") from None


def check_person(person: str | None, cameras: Sequence, usable: bool) -> None:
    """``--person``, given, must name a pixel of one of the ``cameras`` tracked (two or more)
    and be ``usable`` (MediaPipe in several views: triangulate, or the particle filter's
    guide); else one line."""
    if person is None:
        return
    if not usable or len(cameras) < 2:
        raise typer.BadParameter(
            "picks whom MediaPipe follows across two or more views: track's --method "
            "triangulate, or the particle filter guided by MediaPipe (--guide mediapipe; not "
            "--realtime)",
            param_hint="--person",
        )
    from markovmotion.video.triangulation import person_ray

    try:
        person_ray(cameras, person)
    except ValueError as exc:
        raise typer.BadParameter(str(exc), param_hint="--person") from None


def choose_option(family: str, criterion: str, example: str) -> Any:
    """``--choose GRID``, one option across the two-person families: settings to choose among
    by leaving one pair of people out on the training takes alone
    (:mod:`markovmotion.evaluate.choose`), checked when the options are parsed by
    ``markovmotion.evaluate.<family>.parse_grid`` (a bad grid: one line naming the parameter,
    exit 2, before any work)."""

    def check(param: typer.CallbackParam, value: str | None) -> str | None:
        _parsed(family, value)  # a bad grid before any work; the notes when it runs
        return value

    return typer.Option(
        None,
        "--choose",
        callback=check,
        help="Settings to choose among by leaving one pair of people out on the training takes "
        f"alone ({criterion}): 'param=v1,v2;param=v1,v2', every combination; 'a+b=v1,v2' sets "
        f"two parameters together; 'roles=one,both' too. E.g. {example!r} (crossval: each "
        "fold chooses on its own training takes, nested; train: the model file records the "
        "pick and every setting's error as 'chosen').",
    )


def grid_of(family: str, choose: str | None, preset: dict | None = None) -> list[dict] | None:
    """The settings of ``--choose`` for ``family`` (``hmm`` or ``chain``), None without
    (:func:`_parsed`), with a note per option of the command line (or value ``preset`` set,
    ``{option: value}``) that they replace."""
    grid = _parsed(family, choose)
    if grid:
        _note_replaced(grid, preset or {})
    return grid


def _parsed(family: str, choose: str | None) -> list[dict] | None:
    """``--choose`` parsed by ``markovmotion.evaluate.<family>.parse_grid``, None without;
    BadParameter naming ``--choose`` and the part at fault."""
    if not choose:
        return None
    import importlib

    parse = importlib.import_module(f"markovmotion.evaluate.{family}").parse_grid
    try:
        return parse(choose)
    except ValueError as exc:
        raise typer.BadParameter(str(exc), param_hint="--choose") from None


def _context() -> Any:
    """The running command's click context (None outside a command)."""
    try:  # Typer >= 0.26 vendors its own click (as cli.main)
        from typer._click.globals import get_current_context
    except ImportError:  # pragma: no cover - older Typer on the real click
        from click import get_current_context
    return get_current_context(silent=True)


def flag(name: str) -> str:
    """The command-line option of a parameter name: ``place_memory`` -> ``--place-memory``."""
    return "--" + name.replace("_", "-")


def given(name: str) -> bool:
    """Whether the running command's option ``name`` (its parameter's name) was given on the
    command line, not left at its default."""
    try:
        from typer._click.core import ParameterSource
    except ImportError:  # pragma: no cover - older Typer on the real click
        from click.core import ParameterSource
    ctx = _context()
    return ctx is not None and ctx.get_parameter_source(name) == ParameterSource.COMMANDLINE


#: ``--choose`` keys whose command-line option has another name.
_OPTION_OF = {"n_states": "states", "n_state_prototypes": "prototypes",
              "n_behaviour_prototypes": "behaviours"}  # fmt: skip


def _note_replaced(grid: list[dict], preset: dict) -> None:
    """One note per option given on the command line (or set by a ``preset``) that
    ``--choose`` also sets: the grid's values replace it (``--output regression`` with
    ``output=frames,...``)."""
    from markovmotion.progress import note

    for key in dict.fromkeys(k for setting in grid for k in setting):
        name = _OPTION_OF.get(key, key)
        if given(name) or name in preset:
            value = preset[name] if name in preset else _context().params[name]
            values = ", ".join(dict.fromkeys(str(s[key]) for s in grid if key in s))
            option = flag(name)
            by = " (--preset's)" if name in preset else ""
            note(f"{option} {value}{by} is replaced by --choose's {key} ({values})")


def chosen_line(chosen: dict, error: str) -> str:
    """The line saying what ``--choose`` picked (``chosen``: settings and ``inner_mm``) and
    its inner ``error`` (what the folds measured), with the worst setting's beside it."""
    inner = chosen["inner_mm"]
    picked = ", ".join(f"{k}={v}" for k, v in chosen["settings"].items())
    worst = (
        f"worst of {len(inner)}: {max(inner.values()):.1f} mm"
        if len(inner) > 1
        else "the only setting"
    )
    return f"chose {picked}: {error} {min(inner.values()):.1f} mm ({worst})"


def normalise_option(what: str) -> Any:
    """``--normalise``: the paper's features, or each person's relative to themselves
    (``dualhmm`` and ``chain``, ``what`` says what is made relative)."""
    return typer.Option(
        "none",
        callback=choice(("none", "person")),
        help=f"'person': {what}, for people the model has never seen; 'none': the paper's.",
    )


def split_labels(values: list[str] | None) -> list[str] | None:
    """Labels given as ``--label a --label b`` or ``--labels a,b`` (every command takes both
    spellings, as a new user wrote them): one list, None when none were given."""
    out = [v.strip() for value in values or [] for v in value.split(",") if v.strip()]
    return out or None


def stopped(played: Any, total: int, out: Any) -> None:
    """Ctrl-C during ``respond --realtime`` (``played``: the :class:`~markovmotion.models.online.Replay`):
    what was kept is said, and the exit code is an interrupt's (130), the partner's frames
    so far having been written to ``out``."""
    from markovmotion.progress import err_console

    err_console.print(
        f"interrupted after {played.streamed} of {total} frames of A: wrote the partner's "
        f"{played.motion.n_frames} frames so far to {out}",
        highlight=False,
    )
    raise SystemExit(130)


def preset_flags(values: dict) -> str:
    """``--roles both --energy 0.99 ...``: option values as the command line writes them."""
    return " ".join(
        f"{flag(k)} {format(v, 'g') if isinstance(v, float) else v}" for k, v in values.items()
    )


def preset_option(presets: dict[str, dict[str, object]], docs: str) -> Any:
    """``--preset`` of a family whose ``presets`` (``paper``: none, ``new-people``: ...) are
    documented in ``docs``: the values are spelt out in its help."""
    return typer.Option(
        "paper",
        callback=choice(tuple(presets)),
        help="'new-people': the partner for people the model has never seen ("
        + preset_flags(presets["new-people"])
        + f"; {docs}), each replaced by the option if given. 'paper': none.",
    )


def with_preset(options: dict, presets: dict[str, dict[str, object]]) -> dict:
    """A command's options (its ``locals()``) with ``--preset``'s values (of ``presets``)
    where the command line left them at their defaults, and those values as ``preset_set``;
    a note says what it set, so that an error about an option it set names where that came
    from."""
    from markovmotion.progress import note

    preset = presets[options["preset"]]
    set_ = {k: v for k, v in preset.items() if not given(k)}
    if preset:
        kept = [flag(k) for k in preset if k not in set_]
        note(
            f"--preset {options['preset']}: {preset_flags(set_)}"
            + (f" ({', '.join(kept)} given)" if kept else "")
        )
    return {**options, **set_, "preset_set": set_}


def method_option(command: str) -> Any:
    """``--method``: how person A is followed in video (``track`` and ``dualhmm respond
    --video``; :func:`markovmotion.video.multiview.resolve_method`)."""
    from markovmotion.defaults import TRACK_METHODS  # not video.multiview: --help stays light

    return typer.Option(
        "auto",
        callback=choice(TRACK_METHODS),
        help=f"How A is tracked{' in --video' if command == 'respond' else ''}: triangulate "
        "(MediaPipe Pose in every camera, triangulated; the most accurate, docs/video.md), "
        "monocular (MediaPipe Pose in one camera, placed by PnP), apf (annealed particle "
        "filter on the images, all views: a skeleton on the body model) or auto (the "
        "default: triangulate, or monocular for one view, where scripts/install-camera "
        "installed MediaPipe; apf for "
        + ("--realtime, " if command == "respond" else "a .bvh --out, ")
        + "the filter's own options, or without MediaPipe).",
    )


def method_for(
    ctx: typer.Context,
    method: str,
    video: Path,
    cameras: Path | None,
    views: int | None,
    filter_options: Sequence[str],
    asked: bool = False,
    command: str = "track",
) -> tuple[str, str | None]:
    """``--method`` resolved (:func:`markovmotion.video.multiview.resolve_method`) for the
    views of ``--video`` tracked (one for a lone video, else the camera file's, at most
    ``views``), the particle filter's own options (``filter_options``, parameter names)
    given on the command line or otherwise ``asked`` for, and the note saying what ``auto``
    chose (for the summary's notes: printed after the work, so that a refusal before it
    stays one line); ``command``: ``track`` or ``respond``, whose note it is. The camera
    file's cameras are counted, its notes left to the reader that takes it (said here, they
    had come before the refusal of a tracker that reads every view: two lines)."""
    from markovmotion.video.cameras import lone_video, read_camera_file
    from markovmotion.video.multiview import resolve_method

    if method != "auto":
        return method, None
    reading = read_camera_file(video, cameras).reading
    n = 1 if lone_video(video) or reading is None else len(reading.cameras)
    given = any(  # by the source's name: Typer 0.2x carries a click of its own
        getattr(ctx.get_parameter_source(name), "name", "DEFAULT") != "DEFAULT"
        for name in filter_options
    )
    return resolve_method(method, min(n, views or n), asked or given, command)
