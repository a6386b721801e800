"""``recon capture``, ``recon register``, ``recon evaluate``: scans, their registration and
the assessment of what came out."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Literal

import numpy as np
import typer

from recon_cli.cli.app import app
from recon_cli.cli.options import (
    FOCUS,
    MAX_BOX_EDGE,
    MAX_COORDINATE,
    RADIUS,
    THETA,
    AlphaOpt,
    CellOpt,
    ConfigOpt,
    D,
    FocusOpt,
    ForceOpt,
    FrameOpt,
    PhiOpt,
    PlannerName,
    PlanningTimeOpt,
    RadiusOpt,
    RealismOpt,
    RecordOpt,
    ResolutionOpt,
    SafetyOpt,
    ScaleOpt,
    SeedOpt,
    ThetaOpt,
    check_record,
    index_list,
    make_view,
    object_metavar,
    object_option,
    output_folder,
    parse_vector,
    positive,
    realism_profile,
    run_base,
)
from recon_cli.console import console, progress_bar, styled
from recon_cli.errors import FileError, InputError
from recon_cli.geometry.view import Frame, View
from recon_cli.outputs import OutputMode, claim_output
from recon_cli.reconstruction.assessment import run_evaluate
from recon_cli.reconstruction.crop import CropBox
from recon_cli.reconstruction.options import COVERAGE_TOLERANCE
from recon_cli.report import write_pages_after_register
from recon_cli.robot.description import CellName
from recon_cli.session import resolve_object_name
from recon_cli.thesis import eq_4_1_views
from recon_cli.workflows.capture import CaptureOptions, run_capture
from recon_cli.workflows.register import register_folder

#: the view sets of ``recon capture --views``
ViewSet = Literal["single", "eq-4.1"]
#: how ``recon register`` initializes loop closures (a checker sees the value of the configuration's
#: field; typer takes the choices from the Literal)
if TYPE_CHECKING:
    LoopClosureInit = str
else:
    LoopClosureInit = Literal["icp", "global"]


@app.command()
def capture(
    ctx: typer.Context,
    object_name: Annotated[
        str, typer.Option("--object", metavar=object_metavar(True), callback=object_option(True),
                          help="Built-in object, YCB object or mesh file; 'auto': the drill if the YCB data is here, "
                               "else the built-in bottle.")] = D.scene.object_name,
    scale: ScaleOpt = D.scene.object_scale,
    focus: FocusOpt = FOCUS,
    radius: RadiusOpt = RADIUS,
    theta: ThetaOpt = THETA,
    phi: PhiOpt = 0.0,
    alpha: AlphaOpt = 0.0,
    frame: FrameOpt = Frame.WORLD,
    out: Annotated[Path | None, typer.Option("--out", "-o", help="Session folder (default runs/capture-<time>).")]
    = None,
    noise: Annotated[bool, typer.Option("--noise/--no-noise", help="Depth noise model on or off.")] = D.sensor.noise,
    resolution: ResolutionOpt = D.sensor.resolution,
    planner: Annotated[PlannerName, typer.Option(help="OMPL planner.")] = D.planner.planner,
    planning_time: PlanningTimeOpt = D.planner.time_limit,
    cell: CellOpt = D.cell.kind,
    safety: SafetyOpt = None,
    seed: SeedOpt = D.seed,
    views: Annotated[ViewSet, typer.Option(help="'single' (the view given by --focus ... --alpha) or "
                                                           "'eq-4.1' (the thesis' 24 views around f = (0, 0, 0.78) "
                                                           "m, r = 0.6 m).")] = "single",
    cover_board: Annotated[str, typer.Option(help="Views (1-based, comma-separated) with a sheet over the "
                                                  "ChArUco board, e.g. '3,7'.")] = "",
    station: Annotated[Path | None, typer.Option(help="Station file: run on the robot and camera adapters it names "
                                                      "(docs/hardware.md); default: the simulation.")] = None,
    realism: RealismOpt = D.realism.name,
    record: RecordOpt = False,
    append: Annotated[bool, typer.Option("--append", help="Add this capture's scans to the scan store already in "
                                                          "--out (same cell and object); without it --out must be "
                                                          "new or empty.")] = False,
    force: ForceOpt = False,
    config_file: ConfigOpt = None,
) -> None:
    """Move the simulated robot through views and write one scan per view into a scan store."""


    check_record(record)
    base = run_base(ctx, config_file, "capture")
    stored_view = base.stored("view") or {}
    if not isinstance(stored_view, dict):
        raise InputError(f"{config_file}: run.view is not a mapping", hint="give the config.yaml of a capture run")
    focus, radius, theta, phi, alpha, frame = (
        base.pick(name, value, stored_view.get(name, value), at=f"run.view.{name}")
        for name, value in (("focus", focus), ("radius", radius), ("theta", theta), ("phi", phi), ("alpha", alpha),
                            ("frame", frame)))
    views = base.pick("views", views, base.stored("views", views))
    cover_board = base.pick("cover_board", cover_board, base.stored("cover_board", cover_board))
    frame = Frame(frame)
    station = base.pick("station", station, base.stored("station"))
    station = None if station is None else Path(station)
    if "object_name" in base.given or base.path is None:
        object_name = resolve_object_name(object_name)
    else:
        object_name = base.config.scene.object_name
    view_list: tuple[View, ...]
    if views == "single":
        view_list = (make_view(focus, radius, theta, phi, alpha, frame),)
    else:

        view_list = tuple(eq_4_1_views())
    covered = index_list(cover_board, "--cover-board", len(view_list))
    positive(scale, "--scale", "e.g. 0.001 for millimetres")
    config = base.config.with_values({"scene.object_name": object_name, **base.picked(
        cell=("cell.kind", lambda: CellName.parse(cell)), safety=("cell.safety_distance", safety),
        scale=("scene.object_scale", scale), noise=("sensor.noise", noise),
        resolution=("sensor.resolution", resolution), seed=("seed", seed), planner=("planner.planner", planner),
        planning_time=("planner.time_limit", planning_time), realism=("realism", lambda: realism_profile(realism)))})
    folder = output_folder(out, "capture", append=append, force=force,
                           append_hint="--append to add this capture's scans to the scan store in it",
                           inputs=(station, Path(realism), Path(object_name))).path
    options = CaptureOptions(views=view_list, out=folder, config=config, cover_board=frozenset(covered),
                             run={"command": "capture", "views": views, "cover_board": cover_board,
                                  "view": {"focus": focus, "radius": radius, "theta": theta, "phi": phi,
                                           "alpha": alpha, "frame": frame}}, station=station,
                             record=record, append=append)
    with progress_bar() as update:
        result = run_capture(options, update)
    for m, scan, n_points, t_cap in zip(result.moves, result.scans, result.points, result.capture_seconds,
                                        strict=True):
        waypoints = "-" if m.plan.path is None else len(m.plan.path)
        console.print(f"scan {scan.index}: planned with {m.plan.planner} in {m.plan.total_time:.2f} s "
                      f"({waypoints} waypoints), trajectory {m.execution.duration:.2f} s, settled after "
                      f"{m.execution.settle_time:.3f} s (camera pose error from tracking "
                      f"{m.camera_position_error * 1e3:.4f} mm / {np.degrees(m.camera_rotation_error):.5f}°); "
                      f"{n_points} points in {t_cap:.2f} s")
    for f in result.failures:
        console.print(styled(f"view {f.view} skipped:", "yellow", f" {f.message}"))
    console.print(f"{len(result.scans)} of {len(view_list)} views scanned in {result.total_seconds:.1f} s; "
                  f"scan store: {folder}")
    if record:
        console.print(f"recording: {folder / 'recording.rrd'} (recon view {folder})")
    if result.page is not None:
        console.print(f"page: {result.page}")
    if not result.scans:
        raise typer.Exit(1)


_R = D.registration
_CROP_FRAME = Frame(_R.box_frame)


@app.command()
def register(
    ctx: typer.Context,
    folder: Annotated[Path | None, typer.Argument(help="Scan store folder (simulated or recorded); with --config "
                                                       "the store the file names by default.")] = None,
    out: Annotated[Path | None, typer.Option("--out", "-o", help="Output folder (default "
                                                                 "<folder>/reconstruction).")] = None,
    crop_box: Annotated[str | None, typer.Option(help="Crop box cx,cy,cz,sx,sy,sz [m] (default: the session's "
                                                      "object box).")] = None,
    crop_frame: Annotated[Frame, typer.Option(help="Frame of --crop-box.")] = _CROP_FRAME,
    board: Annotated[bool, typer.Option("--board/--no-board", help="Use the ChArUco board (else kinematics "
                                                                   "for every scan).")] = _R.use_board,
    local: Annotated[bool, typer.Option("--local/--global-only", help="Pose-graph local registration.")]
    = _R.local,
    loop_closures: Annotated[LoopClosureInit, typer.Option(help="Initialize loop closures by 'icp' or "
                                                                         "with the 'global' alignment (the "
                                                                         "thesis).")]
    = _R.multiway.loop_closure_init,
    voxel: Annotated[float, typer.Option(min=0.0001, max=0.1, help="Voxel of the fused cloud [m].")] = _R.surface.voxel,
    depth: Annotated[int, typer.Option(min=5, max=12, help="Poisson octree depth.")] = _R.surface.poisson_depth,
    trim: Annotated[float, typer.Option(min=0.0, max=0.5, help="Poisson density quantile trimmed.")]
    = _R.surface.density_quantile,
    record: RecordOpt = False,
    force: ForceOpt = False,
    config_file: ConfigOpt = None,
) -> None:
    """Register all scans of a folder (ChArUco or kinematics, pose-graph ICP), fuse, mesh.

    Scans that cannot be read, or are links out of the folder, are skipped with their reason;
    the run fails only when no scan is usable. Its config.yaml names the store and holds the
    registration settings, so that --config repeats it."""


    check_record(record)
    base = run_base(ctx, config_file, "register")
    if folder is None:
        folder = base.stored("store")
        if folder is None:
            raise InputError("no scan store given",
                             hint="give the scan store folder (or --config FILE of a register run)")
        folder = Path(folder)
    crop = None
    if crop_box is not None:
        v = parse_vector(crop_box, 6, "--crop-box", "metres")
        if min(v[3:]) <= 0:
            raise InputError(f"--crop-box {crop_box}: sizes must be positive", hint="cx,cy,cz,sx,sy,sz in metres")
        if max(v[3:]) > MAX_BOX_EDGE or max(map(abs, v[:3])) > MAX_COORDINATE:
            raise InputError(f"--crop-box {crop_box}: the centre must lie within ±{MAX_COORDINATE:g} m and the sizes "
                             f"be at most {MAX_BOX_EDGE:g} m", hint="cx,cy,cz,sx,sy,sz in metres")
        T = np.eye(4)
        T[:3, 3] = v[:3]
        crop = CropBox(T, (v[3], v[4], v[5]))
    config = base.config.with_values(base.picked(
        crop_box=("registration.box", crop), crop_frame=("registration.box_frame", crop_frame.value),
        board=("registration.use_board", board), local=("registration.local", local),
        loop_closures=("registration.multiway.loop_closure_init", loop_closures),
        voxel=("registration.surface.voxel", voxel), depth=("registration.surface.poisson_depth", depth),
        trim=("registration.surface.density_quantile", trim)))
    if not Path(folder).is_dir():
        raise FileError(f"{folder} is not a folder", hint="point to a scan store (a folder of scan_NNNN)")
    target = output_folder(out or Path(folder) / "reconstruction", "register", force=force,
                           nested_in=None if out else Path(folder), inputs=(folder,), make=False)
    with progress_bar() as update:  # the folder is made when there is something to write
        result = register_folder(folder, target, config, record, update)
    page = write_pages_after_register(result.folder)
    sources = {k: v for k, v in result.pose_sources.items() if v}
    skipped = len(result.scans) - len(result.used)
    console.print(f"{len(result.used)} of {len(result.scans)} scans registered"
                  + (f" ({skipped} skipped)" if skipped else "") + " (pose sources: "
                  + ", ".join(f"{k} {v}" for k, v in sources.items()) + ")")
    for r in result.scans:
        if r.skipped:
            console.print(styled(f"{r.name} skipped:", "yellow", f" {r.skipped}"))
        elif r.placed_pose.source.value == "kinematics":
            console.print(f"{r.name}: kinematics ({r.placed_pose.reason})")
    errors = [r.charuco_error for r in result.scans if r.charuco_error is not None]
    if errors:
        console.print(f"ChArUco pose error vs ground truth: mean {np.mean([e[0] for e in errors]) * 1e3:.3f} mm / "
                      f"{np.degrees(np.mean([e[1] for e in errors])):.4f}° over {len(errors)} scans")
    if result.multiway is not None:
        e = result.multiway.edges
        console.print(f"pose graph: {sum(x.kind == 'odometry' for x in e)} odometry edges, "
                      f"{sum(x.kind == 'loop_closure' for x in e)} loop closures "
                      f"({result.multiway.pruned} pruned, {sum(x.rejected for x in e)} ICP results rejected)")
    console.print(f"done in {result.timings['total_s']:.1f} s; frame: {result.frame}")
    console.print(f"cloud: {result.cloud}\nmesh: {result.mesh}\nreport: {result.report}")
    if record:
        console.print(f"recording: {result.folder / 'recording.rrd'} (recon view {result.folder})")
    if page is not None:
        console.print(f"page: {page.path}")


#: how ``recon evaluate`` aligns the reconstruction to the reference
Alignment = Literal["none", "icp"]


@app.command()
def evaluate(
    reconstruction: Annotated[Path, typer.Argument(help="Reconstructed cloud or mesh (PLY, ...), or the folder "
                                                        "of a two-sided run (its merged cloud, and what each side "
                                                        "covers alone).")],
    reference: Annotated[Path | None, typer.Option(help="Reference mesh (ground truth); default for a two-sided "
                                                        "simulation run of a built-in or YCB object: the "
                                                        "simulated object.")] = None,
    tolerance: Annotated[float, typer.Option(min=1e-5, max=0.1, help="Coverage tolerance [m].")]
    = COVERAGE_TOLERANCE,
    scan_store: Annotated[Path | None, typer.Option(help="Scan store whose camera poses define the visible "
                                                         "surface (coverage of what could be seen).")] = None,
    align: Annotated[Alignment, typer.Option(help="'none' (frames agree) or 'icp' (register the "
                                                            "reconstruction to the reference first, reported).")]
    = "none",
    samples: Annotated[int, typer.Option(min=1000, max=5_000_000, help="Reference surface samples.")] = 200_000,
    out: Annotated[Path | None, typer.Option("--out", "-o", help="Output folder (default: beside the "
                                                                 "reconstruction).")] = None,
) -> None:
    """Signed distances to a reference mesh, their statistics and histogram, and coverage."""
    run = reconstruction if reconstruction.is_dir() else None
    merged = reconstruction / "reconstruction" / "cloud.ply" if run is not None else reconstruction
    target = out or merged.parent
    if target.is_dir() or target.is_symlink():  # beside another command's results: only its two files, never
        stem = merged.stem                       # through a link, nor out of a run folder through its links
        claim_output(target, OutputMode.APPEND, command="evaluate",
                     names=(f"{stem}_evaluation.json", f"{stem}_distances.png"), within=None if out else run)
    result = run_evaluate(reconstruction, reference, tolerance, scan_store, align, samples, target)
    e = result.evaluation
    console.print(f"{e.points} points: signed distance mean {e.mean * 1e3:+.4f} mm, std {e.std * 1e3:.4f} mm, "
                  f"RMS {e.rms * 1e3:.4f} mm; " + ", ".join(f"{k}: {v * 100:.1f} %" for k, v in e.within.items()))
    line = f"coverage (tolerance {e.tolerance * 1e3:g} mm): {e.coverage * 100:.2f} % of the reference surface"
    if e.coverage_visible is not None and e.visible_share is not None:
        line += (f", {e.coverage_visible * 100:.2f} % of the part the cameras could see "
                 f"({e.visible_share * 100:.1f} % of the surface)")
    console.print(line)
    if e.contributions:
        console.print("alone: " + ", ".join(f"{name.replace('_', ' ')} covers {share * 100:.2f} %"
                                            for name, share in e.contributions.items())
                      + f"; together {e.coverage * 100:.2f} %")
    if result.alignment is not None:
        console.print(f"aligned to the reference by ICP: moved {result.alignment[0] * 1e3:.3f} mm / "
                      f"{np.degrees(result.alignment[1]):.4f}°")
    console.print(f"report: {result.report}\nhistogram: {result.histogram}")


