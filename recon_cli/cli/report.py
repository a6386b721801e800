"""``recon report``: (re)build the report page of a run folder."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Annotated

import typer

from recon_cli.cli.app import app
from recon_cli.console import console, styled
from recon_cli.errors import FileError
from recon_cli.outputs import OutputMode, claim_output
from recon_cli.report import write_page
from recon_cli.report.options import ReportOptions
from recon_cli.report.page import PAGE, PAGE_FILES

_R = ReportOptions()


@app.command()
def report(
    run_folder: Annotated[Path, typer.Argument(help="Folder a recon run, autoscan, capture or register wrote "
                                                    "(its --out; for register the folder of its report.json).")],
    render: Annotated[bool, typer.Option("--render/--no-render", help="Pictures of the mesh from 4 directions "
                                                                      "(CPU ray casting, no display needed).")]
    = _R.render,
    width: Annotated[int, typer.Option(min=64, max=2000, help="Width of each mesh picture [px] (height 3/4 of "
                                                              "it).")] = _R.image_width,
) -> None:
    """Write the report page of a run folder (report.html, pictures in report_files/): summary, tables,
    figures, the scans with their pose sources and ICP residuals, pictures of the mesh, links to the files."""


    if run_folder.exists() and not run_folder.is_dir():
        raise FileError(f"{run_folder} is not a folder", hint="give the --out folder of a recon run, autoscan, "
                                                                "capture or register")
    folder = claim_output(run_folder, OutputMode.APPEND, command="report", names=(PAGE, PAGE_FILES))
    page = write_page(folder.path, replace(_R, render=render, image_width=width))
    console.print(f"{page.kind.value} folder, status {page.status}: {len(page.pictures)} pictures"
                  + (f", the mesh from {len(page.mesh_views)} directions" if page.mesh_views else ""))
    for line in page.notes:
        console.print(styled("note:", "yellow", f" {line}"))
    console.print(f"page: {page.path}")
