"""The ``markovmotion`` command line: a thin Typer layer over the library.

Expected errors (bad files, missing data, wrong models) print one line on
stderr and exit with code 2; anything else is a bug and keeps its traceback.
"""

from __future__ import annotations

import contextlib
import logging
import os
import re
import sys
from collections.abc import Iterator

import typer
from rich.markup import escape

from markovmotion.errors import MarkovMotionError
from markovmotion.progress import NoteOnce, err_console, new_command

app = typer.Typer(
    name="markovmotion",
    help="Learn statistical models of human motion; synthesize, predict and interact.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)


def _register() -> None:
    """Attach every command group, in the order of the data flow (once per process)."""
    if getattr(app, "_markovmotion_registered", False):
        return
    from markovmotion.cli import (
        chain,
        data,
        demo,
        evaluation,
        gait,
        hmm,
        motion,
        render,
        serve,
        silhouette,
        video,
        vlmm,
    )

    motion.register(app)
    render.register(app)
    app.add_typer(data.app, name="data")
    demo.register(app)
    app.add_typer(hmm.app, name="dualhmm")
    app.add_typer(vlmm.app, name="vlmm")
    app.add_typer(gait.app, name="gait")
    app.add_typer(chain.app, name="chain")
    app.add_typer(silhouette.app, name="silhouette")
    app.add_typer(video.app, name="video")
    video.register(app)
    serve.register(app)
    app.add_typer(evaluation.app, name="evaluation")
    app._markovmotion_registered = True  # type: ignore[attr-defined]


#: The command line's own words: a path the user typed is shown as typed.
_GIVEN: set[str] = set()

#: An absolute path in a message: after its start, a space, a quote or a bracket.
_ABSOLUTE = re.compile(r"(?:^|(?<=[\s'\"(\[]))/[^\s'\"():,;\]]+")


def relative_paths(message: str) -> str:
    """``message`` with each absolute path of an existing file or folder written relative to
    the current folder when that is shorter, as the user gives paths
    (``../shared/data/mocap/...`` for the collection beside the project); an absolute path the
    user gave (on the command line, or outside: ``/data/x.bvh``) stays as it was."""

    def rel(match: re.Match[str]) -> str:
        path = match.group(0)
        if not os.path.exists(path) or path in _GIVEN:
            return path
        return min(path, os.path.relpath(path), key=len)

    return _ABSOLUTE.sub(rel, message)


def fail(message: str) -> None:
    """Print one error line (absolute paths made relative) and exit with code 2."""
    message = relative_paths(message)
    err_console.print(f"[bold red]error:[/] {escape(message)}", highlight=False, soft_wrap=True)
    raise SystemExit(2)


def main(argv: list[str] | None = None) -> None:
    """Entry point of the console script."""
    _register()
    _GIVEN.clear()
    _GIVEN.update(sys.argv[1:] if argv is None else argv)
    new_command()  # a camera file's notes are said once a command, every command
    with _log_as_notes():
        _run(argv)


@contextlib.contextmanager
def _log_as_notes() -> Iterator[None]:
    """The library's log warnings as notes, each kind once (:class:`~markovmotion.progress.NoteOnce`)."""
    logger, handler = logging.getLogger("markovmotion"), NoteOnce()
    logger.addHandler(handler)
    propagate, logger.propagate = logger.propagate, False
    try:
        yield
    finally:
        logger.removeHandler(handler)
        logger.propagate = propagate
        handler.close()


def _interrupt(exc: BaseException) -> bool:
    """Whether ``exc`` stands for the user's Ctrl-C: a KeyboardInterrupt itself, or an error
    raised while one was being handled (click's Abort, Numba's SystemError)."""
    seen: set[int] = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return True
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return False


def _interrupted() -> None:
    """Ctrl-C: one line, exit code 130 (128 + SIGINT), as shells do."""
    err_console.print("interrupted", highlight=False)
    raise SystemExit(130)


def _run(argv: list[str] | None) -> None:
    """Run the command line on ``argv``; expected errors as one line and exit code 2."""
    try:  # Typer >= 0.26 vendors its own click
        from typer._click.exceptions import ClickException, UsageError
    except ImportError:  # pragma: no cover - older Typer on the real click
        from click.exceptions import ClickException, UsageError

    try:
        code = app(args=argv, prog_name="markovmotion", standalone_mode=False)
    except SystemExit as exc:  # Typer exits even on success; return normally then
        if exc.code not in (0, None):
            raise
    except UsageError as exc:  # bad or missing options: one line, not a boxed panel
        where = exc.ctx.command_path if exc.ctx is not None else "markovmotion"
        fail(f"{where}: {exc.format_message()} (see {where} --help)")
    except ClickException as exc:
        fail(exc.format_message())
    except typer.Abort as exc:
        if _interrupt(exc):
            _interrupted()
        raise SystemExit(1) from None
    except MarkovMotionError as exc:
        fail(str(exc))
    except KeyboardInterrupt:
        _interrupted()
    except MemoryError as exc:  # NumPy's names the array it could not allocate
        fail(f"out of memory: {exc or 'an allocation failed'} (a shorter take, or fewer at once)")
    except SystemError as exc:  # a Numba kernel interrupted wraps the KeyboardInterrupt
        if not _interrupt(exc):
            raise
        _interrupted()
    except OSError as exc:
        fail(f"{exc.filename or ''}: {exc.strerror or exc}".lstrip(": "))
    else:
        if code == 130:  # Typer turns a KeyboardInterrupt into this exit code, silently
            _interrupted()
        if isinstance(code, int) and not isinstance(code, bool) and code != 0:
            raise SystemExit(code)
