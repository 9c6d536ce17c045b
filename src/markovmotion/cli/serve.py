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
        None, help="Folder of evaluation stimuli with manifest.csv (default: LIBRARY/stimuli)."
    ),
    partner: Path = typer.Option(
        None, help="Dual HMM model (.npz) answering person A on the live page."
    ),
    admin_token: str = typer.Option(
        None, envvar="MARKOVMOTION_ADMIN_TOKEN", help="Token of the results page (default: random)."
    ),
) -> None:
    """Serve the viewer, the live partner and the perceptual evaluation in a browser."""
    import uvicorn

    from markovmotion.web import create_app
    from markovmotion.web.live import dual_hmm_partner

    factory = dual_hmm_partner(partner) if partner else None
    app = create_app(library, db, stimuli=stimuli, admin_token=admin_token, partner=factory)
    url = f"http://{host}:{port}"
    console = Console()
    console.print(f"markovmotion serving {app.state.library.root} at {url}", highlight=False)
    console.print(f"admin token: {app.state.admin_token}", highlight=False)
    if app.state.store is not None:
        console.print(
            f"evaluation: {url}/evaluation · results: {url}/results?token=...", highlight=False
        )
    uvicorn.run(app, host=host, port=port, log_level="warning")


def register(app: typer.Typer) -> None:
    app.command()(serve)
