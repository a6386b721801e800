"""``recon cell``, ``recon ik``, ``recon objects``: what the cell and the objects are."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import numpy as np
import typer
from rich.table import Table

from recon_cli.cell_check import check_cell, reachability_png
from recon_cli.cli.app import HELP, app
from recon_cli.cli.options import (
    FOCUS,
    RADIUS,
    THETA,
    AlphaOpt,
    CellOpt,
    D,
    FocusOpt,
    ForceOpt,
    FrameOpt,
    PhiOpt,
    RadiusOpt,
    SafetyOpt,
    SeedOpt,
    ThetaOpt,
    make_cell,
    make_view,
    output_folder,
)
from recon_cli.console import console, progress_bar
from recon_cli.errors import ReconError
from recon_cli.geometry.view import Frame
from recon_cli.objects import available_objects, load_object
from recon_cli.render import cell_check_report, cell_tables, ik_table, pose_text
from recon_cli.robot.ik import IKOptions

cell_app = typer.Typer(help="The cell: print it (recon cell [--cell NAME|FILE]) or check a cell file "
                            "(recon cell check FILE).", invoke_without_command=True, rich_markup_mode=None,
                       context_settings=HELP)
app.add_typer(cell_app, name="cell")


@cell_app.callback()
def cell(
    ctx: typer.Context,
    cell: CellOpt = D.cell.kind,
    safety: SafetyOpt = None,
    urdf: Annotated[Path | None, typer.Option(help="Also write the expanded URDF to this file.")] = None,
) -> None:
    """Print the loaded cell: joints, limits, collision shapes, camera and marker frames."""

    if ctx.invoked_subcommand is not None:
        return
    c = make_cell(cell, safety)
    q_show, label = c.kin.neutral(), "q = 0"
    if "home" in dict(c.config.cell_file.poses):
        q_show, label = c.config.cell_file.pose("home", c.joint_names), "home"
    for table in cell_tables(c, q_show, label):
        console.print(table)
    if urdf is not None:
        try:
            urdf.write_text(c.urdf)
        except OSError as exc:
            raise ReconError(f"cannot write {urdf}: {exc.strerror}",
                             hint="choose a writable path for --urdf") from None
        console.print(f"expanded URDF written to {urdf}")


@cell_app.command("check")
def check(
    file: Annotated[str, typer.Argument(metavar="FILE|NAME", help="A cell file (or a shipped cell's name).")],
    safety: SafetyOpt = None,
    step: Annotated[float, typer.Option(min=0.03, max=0.5, help="Spacing of the reachability grid over the "
                                                                 "table top [m].")] = 0.1,
    seed: SeedOpt = D.seed,
    out: Annotated[Path | None, typer.Option("--out", "-o", help="Output folder (default runs/cell-check-<time>).")]
    = None,
    force: ForceOpt = False,
) -> None:
    """Check a cell file: joints and limits, the home pose (limits, collisions), the board in
    view, and where on the table an object can be scanned from how many directions (a picture).
    Exits 1 when the cell is not ready to scan."""

    c = make_cell(file, safety)
    folder = output_folder(out, "cell check", force=force).path
    with progress_bar() as update:
        c.ik.seed_library(progress=lambda i, n: update("IK seed library", i, n))
        result = check_cell(c, np.random.default_rng(seed), step,
                            progress=lambda i, n: update("reachability", i, n))
    picture = folder / "reachability.png"
    reachability_png(picture, result)
    for item in cell_check_report(result):
        console.print(item)
    console.print(f"picture: {picture}")
    if result.problems:
        for problem in result.problems:
            console.print(f"problem: {problem}")
        raise typer.Exit(1)
    console.print(f"{result.name}: no problems found; the cell is ready to scan (recon autoscan --cell {file})")


@app.command()
def ik(
    focus: FocusOpt = FOCUS,
    radius: RadiusOpt = RADIUS,
    theta: ThetaOpt = THETA,
    phi: PhiOpt = 0.0,
    alpha: AlphaOpt = 0.0,
    frame: FrameOpt = Frame.WORLD,
    object_box: Annotated[
        str | None, typer.Option(help="Object bounding box where the cell's objects stand, sx,sy,sz [m]; "
                                      "'none' for no box.")
    ] = "0.3,0.3,0.3",
    solutions: Annotated[int, typer.Option(min=1, max=32, help="How many distinct solutions to look for.")]
    = D.planner.ik_solutions,
    cell: CellOpt = D.cell.kind,
    safety: SafetyOpt = None,
    seed: SeedOpt = D.seed,
) -> None:
    """Solve inverse kinematics for a camera view (f, r, theta, phi, alpha)."""


    view = make_view(focus, radius, theta, phi, alpha, frame)
    c = make_cell(cell, safety, object_box if object_box and object_box.lower() != "none" else None)
    T = c.view_pose(view)
    result = c.solve_pose(T, np.random.default_rng(seed), options=IKOptions(max_solutions=solutions))
    console.print(f"camera goal: {pose_text(T)}")
    console.print(ik_table(c, result))


@app.command()
def objects() -> None:
    """List the objects that can be scanned (built-in, YCB when present, or any mesh file)."""


    table = Table(title="objects")
    for col in ("name", "size x × y × z (m)", "description"):
        table.add_column(col)
    for name, description in available_objects().items():
        ext = load_object(name).extent
        table.add_row(name, " × ".join(f"{v:.3f}" for v in ext), description)
    console.print(table)
    console.print("any OBJ/PLY/STL file works too: recon capture --object path/to/mesh.stl --scale 0.001")
