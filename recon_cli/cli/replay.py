"""``recon replay``: register a recording (a scan store or a folder of colour/depth images
with intrinsics and poses) with its recorded poses as the kinematic ones, and report how
consistent the frames are."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from recon_cli.backends.hardware.replay import ReplayConfig
from recon_cli.cli.app import app
from recon_cli.cli.options import ForceOpt, output_folder, parse_vector
from recon_cli.console import console, progress_bar
from recon_cli.reconstruction.options import RECORDING_SCALE
from recon_cli.workflows.replay import ReplayOptions, run_replay


@app.command()
def replay(
    source: Annotated[Path, typer.Argument(help="Recording: a scan store or a folder of colour/depth images with "
                                                "intrinsics.json and a poses file.")],
    out: Annotated[Path | None, typer.Option("--out", "-o", help="Output folder (default runs/replay-<time>).")]
    = None,
    voxel: Annotated[float, typer.Option(min=0.0005, max=0.5, help="Registration voxel and finest ICP "
                                                                   "correspondence distance [m].")]
    = RECORDING_SCALE.voxel,
    depth_scale: Annotated[float, typer.Option(min=1e-6, max=1e6, help="Depth image units per metre (image folders).")]
    = 1000.0,
    intrinsics: Annotated[str | None, typer.Option(help="Pinhole intrinsics fx,fy,cx,cy [px] (image folders without "
                                                        "intrinsics.json).")] = None,
    local: Annotated[bool, typer.Option("--local/--global-only", help="Pose-graph local registration.")] = True,
    mesh: Annotated[bool, typer.Option("--mesh/--no-mesh", help="Poisson mesh of the fused cloud.")] = False,
    force: ForceOpt = False,
) -> None:
    """Register a recording at its recorded poses; overlap residuals between frames before and after."""

    mapping = {"source": str(source), "depth_scale": depth_scale}
    if intrinsics is not None:
        mapping["intrinsics"] = dict(zip(("fx", "fy", "cx", "cy"),
                                         parse_vector(intrinsics, 4, "--intrinsics", "pixels"), strict=True))
    cfg = ReplayConfig.from_mapping(mapping, "recon replay")
    folder = output_folder(out, "replay", force=force, inputs=(source,)).path
    with progress_bar() as update:
        result = run_replay(ReplayOptions(cfg, folder, voxel=voxel, local=local, mesh=mesh), update)
    s = result.summary
    console.print(f"{len(result.imported.scans)} frames imported into {result.imported.store}")
    for label in ("before", "after"):
        r = s[label]
        if r["median_m"] is None:
            console.print(f"{label}: no overlapping frames")
            continue
        console.print(f"overlap residual {label} registration: median {r['median_m'] * 1e3:.2f} mm, "
                      f"RMS {r['rms_m'] * 1e3:.2f} mm over {r['pairs']} consecutive pairs "
                      f"({r['overlap'] * 100:.0f} % overlap)")
    console.print(f"cloud: {result.register.cloud}\npicture: {result.picture}\nreport: {result.report}")
