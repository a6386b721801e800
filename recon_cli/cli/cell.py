"""``recon cell``, ``recon ik``, ``recon objects``: what the cell and the objects are."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import numpy as np
import typer
from rich.table import Table

from recon_cli.cli.app import app
from recon_cli.cli.options import (
    FOCUS,
    RADIUS,
    THETA,
    AlphaOpt,
    CellOpt,
    D,
    FocusOpt,
    FrameOpt,
    PhiOpt,
    RadiusOpt,
    SafetyOpt,
    SeedOpt,
    ThetaOpt,
    make_cell,
    make_view,
)
from recon_cli.console import console
from recon_cli.errors import ReconError
from recon_cli.geometry.view import Frame
from recon_cli.objects import available_objects, load_object
from recon_cli.render import cell_tables, ik_table, pose_text
from recon_cli.robot.ik import IKOptions


@app.command()
def cell(
    cell: CellOpt = D.cell.kind,
    safety: SafetyOpt = None,
    urdf: Annotated[Path | None, typer.Option(help="Also write the expanded URDF to this file.")] = None,
) -> None:
    """Print the loaded cell: joints, limits, collision shapes, camera and marker frames."""

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


@app.command()
def ik(
    focus: FocusOpt = FOCUS,
    radius: RadiusOpt = RADIUS,
    theta: ThetaOpt = THETA,
    phi: PhiOpt = 0.0,
    alpha: AlphaOpt = 0.0,
    frame: FrameOpt = Frame.WORLD,
    object_box: Annotated[
        str | None, typer.Option(help="Object bounding box on the table centre, sx,sy,sz [m]; 'none' for no box.")
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
