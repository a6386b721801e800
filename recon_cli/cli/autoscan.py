"""``recon autoscan``: scan an unknown object with the thesis' ellipsoid view planner."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from recon_cli.backends.station_file import load_station
from recon_cli.both_sides import confidence_line
from recon_cli.cli.app import app
from recon_cli.cli.options import (
    MAX_THETA,
    MAX_TURN,
    CellOpt,
    ConfigOpt,
    D,
    DcOpt,
    ForceOpt,
    RealismOpt,
    RecordOpt,
    ResolutionOpt,
    SafetyOpt,
    ScaleOpt,
    ScansOpt,
    SeedOpt,
    check_record,
    make_view,
    object_metavar,
    object_option,
    output_folder,
    parse_vector,
    realism_profile,
    run_base,
)
from recon_cli.config import VIEWPLAN_M, VIEWPLAN_SIGMA
from recon_cli.console import console, progress_bar
from recon_cli.errors import InputError
from recon_cli.objects import load_object
from recon_cli.perception.sensor import cell_sensor
from recon_cli.session import resolve_object_name
from recon_cli.workflows.autoscan import Autoscan, AutoscanOptions
from recon_cli.workflows.two_sided import TwoSided

_V = D.viewplan


@app.command()
def autoscan(
    ctx: typer.Context,
    dc: DcOpt = None,
    n: ScansOpt = _V.n,
    object_name: Annotated[str, typer.Option("--object", metavar=object_metavar(True), callback=object_option(True),
                                             help="Object to scan (built-in, YCB or mesh file; 'auto': the drill "
                                                  "if the YCB data is here, else the built-in bottle).")]
    = "bottle",
    scale: ScaleOpt = D.scene.object_scale,
    m: Annotated[int, typer.Option("--candidates", "-m", "--m", min=VIEWPLAN_M[0], max=VIEWPLAN_M[1],
                                   help="Preliminary samples (candidate views) per view (the thesis' m, "
                                        "eq. 2.7).")] = _V.m,
    sigma: Annotated[float, typer.Option(min=VIEWPLAN_SIGMA[0], max=VIEWPLAN_SIGMA[1],
                                         help="Potential-field regularization (eq. 2.6).")] = _V.sigma,
    initial: Annotated[str | None, typer.Option(help="Initial view 'theta,phi' in degrees around the object's box "
                                                     "centre at r = dc + 0.1 (default 45,0).")] = None,
    cell: CellOpt = D.cell.kind,
    safety: SafetyOpt = None,
    resolution: ResolutionOpt = D.sensor.resolution,
    pictures: Annotated[bool, typer.Option("--pictures/--no-pictures", help="A PNG per iteration.")] = True,
    out: Annotated[Path | None, typer.Option("--out", "-o", help="Output folder (default runs/autoscan-<time>).")]
    = None,
    seed: SeedOpt = D.seed,
    station: Annotated[Path | None, typer.Option(help="Station file: run on the robot and camera adapters it names "
                                                      "(docs/hardware.md); default: the simulation.")] = None,
    realism: RealismOpt = D.realism.name,
    record: RecordOpt = False,
    sides: Annotated[int, typer.Option(min=1, max=2, help="2: scan, turn the object over (by physics in "
                                                          "simulation, by the operator on a real cell), scan again "
                                                          "and merge both sides by shape (docs/two_sided.md).")] = 1,
    force: ForceOpt = False,
    config_file: ConfigOpt = None,
) -> None:
    """Scan an unknown object autonomously: the ellipsoid view planner of the thesis."""

    check_record(record)
    base = run_base(ctx, config_file, "autoscan")
    config = base.config.with_values(base.picked(
        cell=("cell.kind", cell), safety=("cell.safety_distance", safety),
        object_name=("scene.object_name", lambda: resolve_object_name(object_name)),
        scale=("scene.object_scale", scale),
        resolution=("sensor.resolution", resolution), seed=("seed", seed), n=("viewplan.n", n),
        **({} if dc is None else {"dc": ("viewplan.d_c", dc)}), m=("viewplan.m", m), sigma=("viewplan.sigma", sigma),
        realism=("realism", lambda: realism_profile(realism))))
    station = base.pick("station", station, base.stored("station"))
    station = None if station is None else Path(station)
    if station is not None:  # the station file's cell is the one scanned in
        config = config.replace(cell=load_station(station).cell)
    if dc is None and base.path is None:  # the camera distance of the cell's sensor
        config = config.with_values({"viewplan.d_c": cell_sensor(config.cell.cell_file).default_distance})
    object_name, scale, dc = config.scene.object_name, config.scene.object_scale, config.viewplan.d_c
    initial = base.pick("initial", initial, base.stored("initial"))
    pictures = base.pick("pictures", pictures, base.stored("pictures", pictures))
    view = None
    if initial is not None:
        theta, phi = parse_vector(initial, 2, "--initial", "degrees")
        if abs(theta) > MAX_THETA or abs(phi) > MAX_TURN:
            raise InputError(f"--initial '{initial}' is outside theta ±{MAX_THETA:g}°, phi ±{MAX_TURN:g}°",
                             hint="give 'theta,phi' in degrees, e.g. 45,0")

        center, _ = load_object(object_name, scale, config.cell.cell_file.object_position).crop_box(
            config.scene.box_margin)
        view = make_view(",".join(map(str, center)), dc + 0.1, theta, phi, 0.0, "world")
    folder = output_folder(out, "autoscan", force=force,
                           inputs=(station, Path(realism), Path(object_name))).path
    opts = AutoscanOptions(folder, config, view, pictures=pictures,
                           run={"command": "autoscan", "initial": initial, "pictures": pictures}, station=station,
                           record=record)
    if sides == 2:
        _two_sided(opts, object_name)
        return
    with progress_bar() as update:
        result = Autoscan(opts, update).run()
    if result.interrupted:
        console.print(f"interrupted after {result.scans} scans; they are in {folder} "
                      f"(recon register {folder} works on them)")
        if result.page is not None:
            console.print(f"page: {result.page}")
        raise typer.Exit(130)
    console.print(f"{result.scans} scans of the {object_name} ({result.infeasible} infeasible views sampled, "
                  f"{result.requests} planning requests, {result.trajectory_s:.1f} s of trajectories) "
                  f"in {result.seconds:.1f} s")
    if result.coverage is not None and result.accuracy is not None:
        console.print(f"ground truth: coverage {result.coverage * 100:.2f} % of the surface (1 mm), signed distance "
                      f"mean {result.accuracy.mean_mm:+.3f} mm, std {result.accuracy.std_mm:.3f} mm")
    console.print(f"mesh: {result.mesh}\ncloud: {result.cloud}\nreport: {result.report}")
    if result.pictures:
        console.print(f"pictures: {result.pictures[0].parent}")
    if record:
        console.print(f"recording: {folder / 'recording.rrd'} (recon view {folder})")
    if result.page is not None:
        console.print(f"page: {result.page}")


def _two_sided(opts: AutoscanOptions, object_name: str) -> None:
    with progress_bar() as update:
        result = TwoSided(opts, update).run()
    if result.interrupted:
        done = ", ".join(f"side {i + 1} ({s.scans} scans, {s.folder})" for i, s in enumerate(result.sides))
        console.print(f"interrupted; kept: {done}")
        raise typer.Exit(130)
    for i, side in enumerate(result.sides):
        console.print(f"side {i + 1}: {side.scans} scans in {side.seconds:.1f} s ({side.folder})")
    if result.registration is not None:
        console.print(confidence_line(result.registration))
    if result.coverage is not None:
        console.print(f"ground truth: coverage {result.coverage * 100:.2f} % of the whole surface (1 mm)")
    console.print(f"mesh: {result.mesh}\ncloud: {result.cloud}\nreport: {result.report}\n"
                  f"{object_name} on two sides in {result.seconds:.1f} s")
    if result.page is not None:
        console.print(f"page: {result.page}")
