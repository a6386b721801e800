"""``recon view``: open a run's 3D recording."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from recon_cli.cli.app import app
from recon_cli.console import console
from recon_cli.recording.readback import summarize
from recon_cli.recording.viewer import check_bind, elsewhere, find_recording, has_display, open_viewer


@app.command()
def view(
    run: Annotated[Path, typer.Argument(help="Run folder written with --record (or its recording.rrd).")],
    web: Annotated[bool, typer.Option("--web", help="Serve rerun's web viewer from here instead of opening a "
                                                    "window (open the printed address in a browser).")] = False,
    port: Annotated[int | None, typer.Option(min=1, max=65535, help="Port of the web viewer (with --web; "
                                                                    "default 9090).")] = None,
    bind: Annotated[str, typer.Option("--bind", metavar="ADDRESS", help="Address rerun's servers listen on: "
                                      "127.0.0.1 this machine only, 0.0.0.0 every interface, or one address "
                                      "of this machine.")] = "127.0.0.1",
    summary: Annotated[bool, typer.Option("--summary", help="Only print what the recording holds.")] = False,
) -> None:
    """Open a run's recording in rerun's viewer (or say how to open it where there is no display)."""

    bind = check_bind(bind)
    path = find_recording(run)
    console.print(summarize(path).describe(), markup=False)
    if summary:
        return
    if not web and not has_display():
        console.print(elsewhere(path), markup=False, soft_wrap=True)
        return
    code = open_viewer(path, web, port, bind, say=lambda line: console.print(line, markup=False, soft_wrap=True))
    if code:
        raise typer.Exit(code)
