"""``serve``: the browser application (viewer, live partner, perceptual evaluation)."""

from __future__ import annotations

import signal
import sys
from dataclasses import replace
from pathlib import Path

import typer
from rich.console import Console


def serve(
    library: Path = typer.Option(..., help="Folder of motions to serve (BVH, ASF/AMC, C3D)."),
    host: str = typer.Option("127.0.0.1", help="Address to listen on."),
    port: int = typer.Option(8000, help="Port to listen on."),
    db: Path = typer.Option(Path("results.sqlite"), help="SQLite file of the evaluation answers."),
    stimuli: Path = typer.Option(
        None,
        help="Folder of evaluation stimuli: manifest.csv (walks) and/or interaction.json "
        "(interactions) (default: LIBRARY/stimuli).",
    ),
    partner: Path = typer.Option(
        None,
        help="Model (.npz) answering person A on the live page: a dual HMM ('dualhmm train') "
        "or a behaviour chain ('chain train').",
    ),
    admin_token: str = typer.Option(
        None, envvar="MARKOVMOTION_ADMIN_TOKEN", help="Token of the results page (default: random)."
    ),
    workers: int = typer.Option(
        1,
        help="Server processes sharing the port (live sessions spread over them; about one "
        "per core).",
    ),
    allow_host: list[str] = typer.Option(
        [],
        help="Also answer requests whose Host is NAME (repeat; default: 127.0.0.1, "
        "localhost, ::1 and --host).",
        metavar="NAME",
    ),
    drop_late: float = typer.Option(
        0.07,
        help="Seconds a live session may fall behind its clock before it drops frames "
        "(the partner told, no backlog sent); inf keeps every frame, however late.",
        metavar="SECONDS",
    ),
) -> None:
    """Serve the viewer, the live partner and the perceptual evaluation in a browser."""
    from markovmotion.cli import fail
    from markovmotion.web.server import (
        AppOptions,
        PortInUseError,
        listen,
        start_workers,
        stop_workers,
        uvicorn_server,
    )

    if not 0 <= port <= 65535:
        fail(f"--port {port}: must be between 0 and 65535")
    if not drop_late > 0:  # also NaN
        fail(f"--drop-late {drop_late}: must be a positive number of seconds (inf: never drop)")
    if not 1 <= workers <= 64:
        fail(f"--workers {workers}: must be between 1 and 64")
    try:
        sock = listen(host, port, workers)  # before anything is printed or opened: one line, exit 2
    except PortInUseError as exc:
        fail(str(exc))
    from markovmotion.video.webcam import WebcamTracker

    options = AppOptions(
        library,
        db,
        stimuli,
        admin_token,
        partner,
        (host, *allow_host),
        camera=WebcamTracker,
        drop_late=drop_late,
    )
    app = options.build()  # here first, so that a bad option is one line before any worker
    if partner is not None:  # the model is good: built above
        from markovmotion.cli.tables import world_frame_note
        from markovmotion.models import Model

        world_frame_note(Model.load(partner), partner, "a webcam's world (the camera page)")
    port = sock.getsockname()[1]
    url = f"http://[{host}]:{port}" if ":" in host else f"http://{host}:{port}"
    lines = [f"markovmotion serving {app.state.library.root} at {url}"]
    lines.append(f"admin token: {app.state.admin_token}")
    if app.state.store is not None:
        lines.append(f"evaluation: {url}/evaluation · results: {url}/results?token=...")
    console = Console(soft_wrap=True)
    try:
        if workers == 1:
            for line in lines:
                console.print(line, highlight=False)
            uvicorn_server(app).run(sockets=[sock])
            return
        token = app.state.admin_token  # the one printed, for every worker
        del app
        # stopped by a signal: the workers are stopped with it (the finally below)
        signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))
        procs: list = []
        try:
            procs = start_workers(replace(options, admin_token=token), sock, workers)
            for line in lines:  # once every worker answers
                console.print(line, highlight=False)
            for p in procs:
                p.join()
        except KeyboardInterrupt:
            pass
        finally:
            stop_workers(procs)
    finally:
        sock.close()


def register(app: typer.Typer) -> None:
    app.command()(serve)
