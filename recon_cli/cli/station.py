"""``recon station check``: connect to a cell's robot and camera, read the joints, grab a frame."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from recon_cli.backends.hardware.station import check_station, recover_robot, refuse_unready
from recon_cli.backends.station_file import load_station
from recon_cli.cli.app import app
from recon_cli.cli.options import D
from recon_cli.console import console

station_app = typer.Typer(help="Station files: the robot and camera adapters of a real cell.", no_args_is_help=True,
                          rich_markup_mode=None)
app.add_typer(station_app, name="station")


@station_app.command("check")
def check(
    station: Annotated[Path, typer.Argument(help="Station file (YAML; docs/hardware.md).")],
) -> None:
    """Connect to the robot and the camera of a station file, print the joints and one frame's size."""


    sf = load_station(station)
    console.print(f"station {sf.name!r} ({station}): robot {sf.robot_adapter}, camera {sf.camera_adapter}, "
                  f"cell {sf.cell.kind.value}, backend {sf.capabilities.backend.value}")
    result = check_station(sf, D.seed)  # a robot it cannot reach: exit 1 (the file or the network), not 4
    console.print("joints: " + ", ".join(f"{k} {v:.4f} m" if result.prismatic[k] else f"{k} {np.degrees(v):.3f}°"
                                         for k, v in result.joints.items())
                  + ("" if result.within_limits else "  (outside the soft limits!)"))
    rng = "no depth" if result.depth_range is None else \
        f"depth {result.depth_range[0]:.3f} ... {result.depth_range[1]:.3f} m"
    console.print(f"frame: {result.width} x {result.height} px, {result.valid_depth * 100:.1f} % with depth, {rng}; "
                  f"fx {result.intrinsics['fx']:.1f} px, fy {result.intrinsics['fy']:.1f} px")
    refuse_unready(sf, result)
    console.print(f"station ok in {result.seconds:.2f} s")


@station_app.command("recover")
def recover(
    station: Annotated[Path, typer.Argument(help="Station file (YAML; docs/hardware.md).")],
) -> None:
    """Clear the robot controller's error state after a reflex or control error (libfranka's
    automatic error recovery); recon never does it by itself. Find the cause first."""

    sf = load_station(station)
    cleared = recover_robot(sf)
    console.print(f"station {sf.name!r}: the {sf.robot_adapter} robot's errors cleared"
                  + (f" ({', '.join(cleared)})" if cleared else " (none were set)"))
