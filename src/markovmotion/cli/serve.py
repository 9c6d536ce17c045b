"""``serve``: the browser application (viewer, live partner, perceptual evaluation)."""

from __future__ import annotations

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
    allow_host: list[str] = typer.Option(
        [],
        help="Also answer requests whose Host is NAME (repeat; default: 127.0.0.1, "
        "localhost, ::1 and --host).",
        metavar="NAME",
    ),
) -> None:
    """Serve the viewer, the live partner and the perceptual evaluation in a browser."""
    import uvicorn

    from markovmotion.cli import fail
    from markovmotion.web import create_app
    from markovmotion.web.live import model_partner
    from markovmotion.web.server import PortInUseError, listen

    if not 0 <= port <= 65535:
        fail(f"--port {port}: must be between 0 and 65535")
    try:
        sock = listen(host, port)  # before anything is printed or opened: one line, exit 2
    except PortInUseError as exc:
        fail(str(exc))
    factory = model_partner(partner) if partner else None
    app = create_app(
        library,
        db,
        stimuli=stimuli,
        admin_token=admin_token,
        partner=factory,
        allow_hosts=[host, *allow_host],
    )
    port = sock.getsockname()[1]
    url = f"http://[{host}]:{port}" if ":" in host else f"http://{host}:{port}"
    console = Console()
    console.print(f"markovmotion serving {app.state.library.root} at {url}", highlight=False)
    console.print(f"admin token: {app.state.admin_token}", highlight=False)
    if app.state.store is not None:
        console.print(
            f"evaluation: {url}/evaluation · results: {url}/results?token=...", highlight=False
        )
    server = uvicorn.Server(uvicorn.Config(app, log_level="warning"))
    try:
        server.run(sockets=[sock])
    finally:
        sock.close()


def register(app: typer.Typer) -> None:
    app.command()(serve)
