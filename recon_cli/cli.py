"""The ``recon`` command line. Commands only parse options, call the library and print.

Heavy libraries (pinocchio, FCL, Open3D, MuJoCo, OMPL) are imported inside the commands
so that ``recon --help`` is instant. User errors (``ReconError`` and malformed options)
end as one line on stderr and a non-zero exit code, without a traceback (:func:`main`).
"""

from __future__ import annotations

import math
import os
import sys
from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from recon_cli.errors import InputError, ReconError, UnknownNameError

app = typer.Typer(
    name="recon",
    help="Robot-assisted 3D reconstruction of objects with a robot-held depth camera.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,  # help texts are plain: "[m]" and "[s]" are units, not markup
)
bench_app = typer.Typer(help="Benchmarks with results tables and figures.", no_args_is_help=True,
                        rich_markup_mode=None)
app.add_typer(bench_app, name="bench")

CellOpt = Annotated[str, typer.Option("--cell", help="gantry (9 DoF, linear axes) or ceiling (7 DoF).")]
SafetyOpt = Annotated[float, typer.Option("--safety", help="Safety distance [m] that inflates every collision shape.")]
SeedOpt = Annotated[int, typer.Option("--seed", min=0, max=2**32 - 1,
                                      help="Seed of the random number generator (0 ... 2^32-1).")]
FocusOpt = Annotated[str, typer.Option("--focus", help="Focus point f as x,y,z [m].")]
RadiusOpt = Annotated[float, typer.Option("--radius", "-r", help="Camera distance r from f [m].")]
ThetaOpt = Annotated[float, typer.Option("--theta", help="Polar angle from the vertical [deg].")]
PhiOpt = Annotated[float, typer.Option("--phi", help="Azimuth [deg].")]
AlphaOpt = Annotated[float, typer.Option("--alpha", help="Camera roll about its viewing axis [deg].")]
FrameOpt = Annotated[str, typer.Option("--frame", help="Frame of f and the angles: world or marker.")]


def parse_vector(text: str, n: int, option: str, unit: str) -> tuple[float, ...]:
    """Parse 'x,y,z' into n finite floats, or raise a one-line InputError."""
    parts = [p for p in text.replace(";", ",").split(",") if p.strip()]
    try:
        values = tuple(float(p) for p in parts)
    except ValueError:
        values = ()
    if len(values) != n or not all(math.isfinite(v) for v in values):
        example = ",".join(["0"] * (n - 1) + ["0.3"])
        raise InputError(f"{option} '{text}' is not {n} numbers",
                         hint=f"write {n} comma-separated values in {unit}, e.g. {example}")
    return values


def _cell(cell: str, safety: float, object_box: str | None = None):
    from recon_cli.robot.cell import Cell
    from recon_cli.robot.collision import ObjectBox
    from recon_cli.robot.description import CellConfig, CellKind

    config = CellConfig(kind=CellKind.parse(cell), safety_distance=safety)
    box = None
    if object_box:
        size = parse_vector(object_box, 3, "--object-box", "metres")
        if min(size) <= 0:
            raise InputError(f"--object-box '{object_box}' has a non-positive edge",
                             hint="give the box edges in metres, e.g. 0.3,0.3,0.3")
        box = ObjectBox.on_table(size, table_top_z=0.68 + config.table_lift)
    return Cell(config, box)


@app.command()
def cell(
    cell: CellOpt = "gantry",
    safety: SafetyOpt = 0.03,
    urdf: Annotated[Path | None, typer.Option(help="Also write the expanded URDF to this file.")] = None,
) -> None:
    """Print the loaded cell: joints, limits, collision shapes, camera and marker frames."""
    from recon_cli.console import console
    from recon_cli.render import cell_tables

    c = _cell(cell, safety)
    q_show, label = c.kin.neutral(), "q = 0"
    if "base_joint_1" in c.joint_names:
        from recon_cli.bench.scenarios import TABLE_4_1_START

        q_show, label = TABLE_4_1_START.copy(), "the Table 4.1 start"
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
    focus: FocusOpt = "0,0,0.78",
    radius: RadiusOpt = 0.6,
    theta: ThetaOpt = 70.0,
    phi: PhiOpt = 0.0,
    alpha: AlphaOpt = 0.0,
    frame: FrameOpt = "world",
    object_box: Annotated[
        str | None, typer.Option(help="Object bounding box on the table centre, sx,sy,sz [m]; 'none' for no box.")
    ] = "0.3,0.3,0.3",
    solutions: Annotated[int, typer.Option(min=1, max=32, help="How many distinct solutions to look for.")] = 4,
    cell: CellOpt = "gantry",
    safety: SafetyOpt = 0.03,
    seed: SeedOpt = 0,
) -> None:
    """Solve inverse kinematics for a camera view (f, r, theta, phi, alpha)."""

    from recon_cli.console import console
    from recon_cli.render import ik_table, pose_text
    from recon_cli.robot.ik import IKOptions

    view = _view(focus, radius, theta, phi, alpha, frame)
    c = _cell(cell, safety, object_box if object_box and object_box.lower() != "none" else None)
    T = c.view_pose(view)
    result = c.solve_pose(T, np.random.default_rng(seed),
                          options=IKOptions(max_solutions=solutions))
    console.print(f"camera goal: {pose_text(T)}")
    console.print(ik_table(c, result))


def _view(focus: str, radius: float, theta: float, phi: float, alpha: float, frame: str):
    from recon_cli.geometry.view import Frame, View

    try:
        ref = Frame(frame.lower())
    except ValueError:
        raise UnknownNameError("frame", frame, [f.value for f in Frame]) from None
    return View.from_degrees(parse_vector(focus, 3, "--focus", "metres"), radius, theta, phi, alpha, ref)


@app.command()
def objects() -> None:
    """List the objects that can be scanned (built-in, YCB when present, or any mesh file)."""
    from rich.table import Table

    from recon_cli.console import console
    from recon_cli.objects import available_objects, load_object

    table = Table(title="objects")
    for col in ("name", "size x × y × z (m)", "description"):
        table.add_column(col)
    for name, description in available_objects().items():
        ext = load_object(name).extent
        table.add_row(name, " × ".join(f"{v:.3f}" for v in ext), description)
    console.print(table)
    console.print("any OBJ/PLY/STL file works too: recon capture --object path/to/mesh.stl --scale 0.001")


@app.command()
def capture(
    object_name: Annotated[
        str, typer.Option("--object", help="Built-in object, YCB object or mesh file; 'auto': the drill if the "
                                           "YCB data is here, else the built-in bottle.")] = "auto",
    scale: Annotated[float, typer.Option(help="Scale of a mesh file (0.001 for millimetres).")] = 1.0,
    focus: FocusOpt = "0,0,0.78",
    radius: RadiusOpt = 0.6,
    theta: ThetaOpt = 70.0,
    phi: PhiOpt = 0.0,
    alpha: AlphaOpt = 0.0,
    frame: FrameOpt = "world",
    out: Annotated[Path | None, typer.Option(help="Session folder (default runs/capture-<time>).")] = None,
    noise: Annotated[bool, typer.Option("--noise/--no-noise", help="Depth noise model on or off.")] = True,
    resolution: Annotated[float, typer.Option(min=0.05, max=1.0, help="Image size relative to 1600 x 1200.")] = 1.0,
    planner: Annotated[str, typer.Option(help="OMPL planner.")] = "RRTConnect",
    planning_time: Annotated[float, typer.Option(min=0.1, help="Planning time limit [s].")] = 5.0,
    cell: CellOpt = "gantry",
    safety: SafetyOpt = 0.03,
    seed: SeedOpt = 0,
    views: Annotated[str, typer.Option(help="'single' (the view given by --focus ... --alpha) or 'eq-4.1' "
                                            "(the thesis' 24 views around f = (0, 0, 0.78) m, r = 0.6 m).")] = "single",
    cover_board: Annotated[str, typer.Option(help="Views (1-based, comma-separated) with a sheet over the "
                                                  "ChArUco board, e.g. '3,7'.")] = "",
) -> None:
    """Move the simulated robot through views and write one scan per view into a scan store."""

    from dataclasses import replace

    from recon_cli.config import DEFAULTS, SceneConfig, SensorConfig
    from recon_cli.console import console, progress_bar, run_folder, styled
    from recon_cli.robot.description import CellConfig, CellKind
    from recon_cli.session import resolve_object_name
    from recon_cli.workflows.capture import CaptureOptions, run_capture

    object_name = resolve_object_name(object_name)
    if views == "single":
        view_list = (_view(focus, radius, theta, phi, alpha, frame),)
    elif views == "eq-4.1":
        from recon_cli.bench.scenarios import eq_4_1_views

        view_list = tuple(eq_4_1_views())
    else:
        raise UnknownNameError("view set", views, ("single", "eq-4.1"))
    covered = _index_list(cover_board, "--cover-board", len(view_list))
    if not math.isfinite(scale) or scale <= 0:
        raise InputError(f"--scale {scale} is not a positive number", hint="e.g. 0.001 for millimetres")
    config = DEFAULTS.replace(
        cell=CellConfig(kind=CellKind.parse(cell), safety_distance=safety),
        scene=SceneConfig(object_name, scale), sensor=SensorConfig(noise, resolution), seed=seed,
        planner=replace(DEFAULTS.planner, planner=planner, time_limit=planning_time))
    folder = run_folder(out, "capture")
    options = CaptureOptions(views=view_list, out=folder, config=config, cover_board=frozenset(covered),
                             run={"command": "capture", "views": views})
    with progress_bar() as update:
        result = run_capture(options, update)
    for m, scan, n_points, t_cap in zip(result.moves, result.scans, result.points, result.capture_seconds,
                                        strict=True):
        console.print(f"scan {scan.index}: planned with {m.plan.planner} in {m.plan.total_time:.2f} s "
                      f"({len(m.plan.path)} waypoints), trajectory {m.execution.duration:.2f} s, settled after "
                      f"{m.execution.settle_time:.3f} s (camera pose error from tracking "
                      f"{m.camera_position_error * 1e3:.4f} mm / {np.degrees(m.camera_rotation_error):.5f}°); "
                      f"{n_points} points in {t_cap:.2f} s")
    for f in result.failures:
        console.print(styled(f"view {f.view} skipped:", "yellow", f" {f.message}"))
    console.print(f"{len(result.scans)} of {len(view_list)} views scanned in {result.total_seconds:.1f} s; "
                  f"scan store: {folder}")
    if not result.scans:
        raise typer.Exit(1)


def _choices(text: str, allowed, what: str) -> list[str]:
    """Parse 'a,b' into names, each one of ``allowed`` (else a one-line error)."""
    chosen = [x.strip() for x in text.split(",") if x.strip()]
    for x in chosen:
        if x not in allowed:
            raise UnknownNameError(what, x, allowed)
    return chosen


def _index_list(text: str, option: str, n: int) -> list[int]:
    """Parse '3,7' into [3, 7] (1-based indices up to n)."""
    out = []
    for part in filter(None, (p.strip() for p in text.split(","))):
        if not part.isdigit() or not 1 <= int(part) <= n:
            raise InputError(f"{option} {text!r}: {part!r} is not a view number 1..{n}", hint="e.g. 3,7")
        out.append(int(part))
    return out


@app.command()
def register(
    folder: Annotated[Path, typer.Argument(help="Scan store folder (simulated or recorded).")],
    out: Annotated[Path | None, typer.Option(help="Output folder (default <folder>/reconstruction).")] = None,
    box: Annotated[str | None, typer.Option(help="Crop box cx,cy,cz,sx,sy,sz [m] (default: the session's "
                                                 "object box).")] = None,
    box_frame: Annotated[str, typer.Option(help="Frame of --box: world or marker.")] = "world",
    board: Annotated[bool, typer.Option("--board/--no-board", help="Use the ChArUco board (else kinematics "
                                                                   "for every scan).")] = True,
    local: Annotated[bool, typer.Option("--local/--global-only", help="Pose-graph local registration.")] = True,
    loop_closures: Annotated[str, typer.Option(help="Initialize loop closures by 'icp' or with the 'global' "
                                                    "alignment (the thesis).")] = "icp",
    voxel: Annotated[float, typer.Option(min=0.0001, help="Voxel of the fused cloud [m].")] = 0.001,
    depth: Annotated[int, typer.Option(min=5, max=12, help="Poisson octree depth.")] = 9,
    trim: Annotated[float, typer.Option(min=0.0, max=0.5, help="Poisson density quantile trimmed.")] = 0.02,
) -> None:
    """Register all scans of a folder (ChArUco or kinematics, pose-graph ICP), fuse, mesh."""
    from dataclasses import replace

    from recon_cli.console import console, progress_bar, styled
    from recon_cli.reconstruction.crop import CropBox
    from recon_cli.reconstruction.pipeline import RegisterOptions, run_register

    if box_frame not in ("world", "marker"):
        raise UnknownNameError("box frame", box_frame, ("world", "marker"))
    if loop_closures not in ("icp", "global"):
        raise UnknownNameError("loop closure initialization", loop_closures, ("icp", "global"))
    crop = None
    if box is not None:
        v = parse_vector(box, 6, "--box", "metres")
        T = np.eye(4)
        T[:3, 3] = v[:3]
        if min(v[3:]) <= 0:
            raise InputError(f"--box {box}: sizes must be positive", hint="cx,cy,cz,sx,sy,sz in metres")
        crop = CropBox(T, tuple(v[3:]))
    options = RegisterOptions(box=crop, box_frame=box_frame, use_board=board, local=local)
    options = replace(options, multiway=replace(options.multiway, loop_closure_init=loop_closures),
                      surface=replace(options.surface, voxel=voxel, poisson_depth=depth, density_quantile=trim))
    with progress_bar() as update:
        result = run_register(folder, out or Path(folder) / "reconstruction", options, update)
    sources = {k: v for k, v in result.pose_sources.items() if v}
    console.print(f"{len(result.used)} of {len(result.scans)} scans registered (pose sources: "
                  + ", ".join(f"{k} {v}" for k, v in sources.items()) + ")")
    for r in result.scans:
        if r.skipped:
            console.print(styled(f"scan {r.index} skipped:", "yellow", f" {r.skipped}"))
        elif r.pose.source.value == "kinematics":
            console.print(f"scan {r.index}: kinematics ({r.pose.reason})")
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


@app.command()
def evaluate(
    reconstruction: Annotated[Path, typer.Argument(help="Reconstructed cloud or mesh (PLY, ...).")],
    reference: Annotated[Path, typer.Option(help="Reference mesh (ground truth).")],
    tolerance: Annotated[float, typer.Option(min=1e-5, help="Coverage tolerance [m].")] = 0.001,
    views: Annotated[Path | None, typer.Option(help="Scan store whose camera poses define the visible "
                                                    "surface (coverage of what could be seen).")] = None,
    align: Annotated[str, typer.Option(help="'none' (frames agree) or 'icp' (register the reconstruction "
                                            "to the reference first, reported).")] = "none",
    samples: Annotated[int, typer.Option(min=1000, help="Reference surface samples.")] = 200_000,
    out: Annotated[Path | None, typer.Option(help="Output folder (default: beside the reconstruction).")] = None,
) -> None:
    """Signed distances to a reference mesh, their statistics and histogram, and coverage."""
    from recon_cli.console import console
    from recon_cli.reconstruction.assessment import run_evaluate

    if align not in ("none", "icp"):
        raise UnknownNameError("alignment", align, ("none", "icp"))
    result = run_evaluate(reconstruction, reference, tolerance, views, align, samples,
                          out or reconstruction.parent)
    e = result.evaluation
    console.print(f"{e.points} points: signed distance mean {e.mean * 1e3:+.4f} mm, std {e.std * 1e3:.4f} mm, "
                  f"RMS {e.rms * 1e3:.4f} mm; " + ", ".join(f"{k}: {v * 100:.1f} %" for k, v in e.within.items()))
    line = f"coverage (tolerance {e.tolerance * 1e3:g} mm): {e.coverage * 100:.2f} % of the reference surface"
    if e.coverage_visible is not None:
        line += (f", {e.coverage_visible * 100:.2f} % of the part the cameras could see "
                 f"({e.visible_share * 100:.1f} % of the surface)")
    console.print(line)
    if result.alignment is not None:
        console.print(f"aligned to the reference by ICP: moved {result.alignment[0] * 1e3:.3f} mm / "
                      f"{np.degrees(result.alignment[1]):.4f}°")
    console.print(f"report: {result.report}\nhistogram: {result.histogram}")


@app.command()
def validate(
    script: Annotated[Path, typer.Argument(help="Automation script (recon or thesis dialect).")],
) -> None:
    """Expand xacro, validate against the XSD and list the commands a script would run."""
    from recon_cli.console import console
    from recon_cli.scripts.checks import check_script
    from recon_cli.scripts.loader import load_script

    s = load_script(script)
    check_script(s)
    dialect = "recon (schemas/recon_script.xsd)" if s.dialect == "recon" else \
        "thesis system (schemas/thesis_script.xsd)"
    console.print(f"{script}: valid, dialect {dialect}, script {s.name!r}, {len(s.commands)} commands, "
                  f"on failure: {s.on_failure}" + (", sequence optimization requested" if s.optimize else ""))
    for k, cmd in enumerate(s.commands, start=1):
        console.print(f"{k:4d}  {cmd.source}  {cmd.describe()}")


RUN_EPILOG = ("Exit codes: 0 every command done; 1 error before or outside the commands (bad script, option or "
              "file); 2 usage error; 3 some commands failed (their scans skipped; --allow-failures gives 0); "
              "4 aborted by a failed command (on_failure=\"abort\"); 130 interrupted by Ctrl-C, 143 by SIGTERM "
              "(completed scans kept, the report says what was interrupted).")


@app.command("run", epilog=RUN_EPILOG)
def run_script(
    script: Annotated[Path, typer.Argument(help="Automation script (recon or thesis dialect).")],
    out: Annotated[Path | None, typer.Option(help="Output folder (default runs/run-<time>).")] = None,
    backend: Annotated[str | None, typer.Option(help="'sim' or 'hardware' (overrides the script).")] = None,
    dry_run: Annotated[bool, typer.Option("--dry-run", help="Plan every move, move nothing, scan nothing.")] = False,
    object_name: Annotated[str | None, typer.Option("--object", help="Simulated object (overrides the script; "
                                                                     "default: the drill if present).")] = None,
    optimize: Annotated[bool | None, typer.Option("--optimize/--no-optimize", help="Reorder independent moves "
                                                  "and scans (default: as the script says).")] = None,
    sequence_method: Annotated[str, typer.Option(help="'ours' (local search) or 'thesis' (Tables 2.2/2.3).")] = "ours",
    seed: SeedOpt = 0,
    append: Annotated[bool, typer.Option("--append", help="Add this run's scans to the scan store already in "
                                                          "--out (same cell and object); without it --out must "
                                                          "be new or empty.")] = False,
    allow_failures: Annotated[bool, typer.Option("--allow-failures", help="Exit 0 even when some commands "
                                                                          "failed (default: exit 3).")] = False,
) -> None:
    """Run an automation script: moves, scans, registration, reconstruction, exports."""
    from recon_cli.console import console, progress_bar, run_folder, styled
    from recon_cli.interrupts import stop_signals
    from recon_cli.scripts.checks import check_script
    from recon_cli.scripts.loader import load_script
    from recon_cli.scripts.state import RunOptions, SequenceMethod
    from recon_cli.session import Backend
    from recon_cli.workflows.script_run import ScriptRunner

    if backend is not None and backend not in ("sim", "hardware"):
        raise UnknownNameError("backend", backend, ("sim", "hardware"))
    if sequence_method not in ("ours", "thesis"):
        raise UnknownNameError("sequence method", sequence_method, ("ours", "thesis"))
    s = load_script(script)
    check_script(s, object_override=object_name)  # before the output folder is made
    folder = run_folder(out, "run", fresh=not append)
    options = RunOptions(folder, None if backend is None else Backend(backend), seed, dry_run, object_name, optimize,
                         SequenceMethod(sequence_method), append)
    with stop_signals(), progress_bar() as update:
        result = ScriptRunner(s, options, update).run()
    counts: dict[str, int] = {}
    for r in result.reports:
        counts[r.status.value] = counts.get(r.status.value, 0) + 1
    console.print(f"{s.name}: {len(result.reports)} commands (" + ", ".join(f"{v} {k}" for k, v in counts.items())
                  + f"), {result.scans} scans, {result.seconds:.1f} s")
    for r in result.reports:
        if r.status in ("failed", "skipped") and r.message != "dry run":
            console.print(styled(r.status.value, "yellow", f" {r.source} {r.command}: {r.message}"))
    for seq in result.sequences:
        console.print(f"sequence of {seq.moves} moves ({seq.method.value}): planned trajectory time "
                      f"{seq.planned_duration_s:.1f} s with {seq.planning_requests} planning requests "
                      f"({seq.seconds:.1f} s)")
    for k, v in result.outputs.items():
        console.print(f"{k}: {v}")
    console.print(f"report: {folder / 'run_report.json'}")
    if result.exit_code and not allow_failures:
        raise typer.Exit(result.exit_code)


@app.command()
def autoscan(
    dc: Annotated[float, typer.Option("--dc", min=0.2, max=1.5, help="Camera distance to the ellipsoid [m].")] = 0.55,
    n: Annotated[int, typer.Option("--n", min=2, max=200, help="Scans in total (the initial one included).")] = 16,
    object_name: Annotated[str, typer.Option("--object", help="Object to scan (built-in, YCB or mesh file).")]
    = "bottle",
    scale: Annotated[float, typer.Option(help="Scale of a mesh file.")] = 1.0,
    m: Annotated[int, typer.Option("--m", min=1, help="Preliminary samples per view (eq. 2.7).")] = 200,
    sigma: Annotated[float, typer.Option(min=1e-12, help="Potential-field regularization (eq. 2.6).")] = 1e-5,
    initial: Annotated[str | None, typer.Option(help="Initial view 'theta,phi' in degrees around the object's box "
                                                     "centre at r = dc + 0.1 (default 45,0).")] = None,
    cell: CellOpt = "gantry",
    safety: SafetyOpt = 0.03,
    resolution: Annotated[float, typer.Option(min=0.05, max=1.0, help="Image size relative to 1600 x 1200.")] = 1.0,
    pictures: Annotated[bool, typer.Option("--pictures/--no-pictures", help="A PNG per iteration.")] = True,
    out: Annotated[Path | None, typer.Option(help="Output folder (default runs/autoscan-<time>).")] = None,
    seed: SeedOpt = 0,
) -> None:
    """Scan an unknown object autonomously: the ellipsoid view planner of the thesis."""
    from recon_cli.config import DEFAULTS, SceneConfig, SensorConfig, ViewPlanConfig
    from recon_cli.console import console, progress_bar, run_folder
    from recon_cli.robot.description import CellConfig, CellKind
    from recon_cli.workflows.autoscan import Autoscan, AutoscanOptions

    config = DEFAULTS.replace(
        cell=CellConfig(kind=CellKind.parse(cell), safety_distance=safety),
        scene=SceneConfig(object_name, scale), sensor=SensorConfig(DEFAULTS.sensor.noise, resolution), seed=seed,
        viewplan=ViewPlanConfig(n=n, d_c=dc, m=m, sigma=sigma))
    folder = run_folder(out, "autoscan")
    view = None
    if initial is not None:
        theta, phi = parse_vector(initial, 2, "--initial", "degrees")
        from recon_cli.objects import load_object

        center, _ = load_object(object_name, scale).crop_box(config.scene.box_margin)
        view = _view(",".join(map(str, center)), dc + 0.1, theta, phi, 0.0, "world")
    opts = AutoscanOptions(folder, config, view, pictures=pictures, run={"command": "autoscan"})
    with progress_bar() as update:
        result = Autoscan(opts, update).run()
    if result.interrupted:
        console.print(f"interrupted after {result.scans} scans; they are in {folder} "
                      f"(recon register {folder} works on them)")
        raise typer.Exit(130)
    console.print(f"{result.scans} scans of the {object_name} ({result.infeasible} infeasible views sampled, "
                  f"{result.requests} planning requests, {result.trajectory_s:.1f} s of trajectories) "
                  f"in {result.seconds:.1f} s")
    if result.coverage is not None:
        console.print(f"ground truth: coverage {result.coverage * 100:.2f} % of the surface (1 mm), signed distance "
                      f"mean {result.accuracy.mean_mm:+.3f} mm, std {result.accuracy.std_mm:.3f} mm")
    console.print(f"mesh: {result.mesh}\ncloud: {result.cloud}\nreport: {result.report}")
    if result.pictures:
        console.print(f"pictures: {result.pictures[0].parent}")


@bench_app.command("ik")
def bench_ik(
    n: Annotated[int, typer.Option("--n", min=1, help="Number of camera poses.")] = 500,
    solutions: Annotated[int, typer.Option(min=1, max=32, help="Solutions asked per pose in the second run.")] = 4,
    cell: CellOpt = "gantry",
    safety: SafetyOpt = 0.03,
    seed: SeedOpt = 0,
    out: Annotated[Path | None, typer.Option(help="Output folder (default runs/bench-ik-<time>).")] = None,
) -> None:
    """IK success rate and time on random reachable camera poses around the table."""
    from recon_cli.bench import render
    from recon_cli.bench.ik import IKBenchConfig, run_ik_bench
    from recon_cli.console import console, progress_bar, run_folder, write_json

    folder = run_folder(out, "bench-ik")
    c = _cell(cell, safety)
    cfg = IKBenchConfig(n_poses=n, solutions=solutions, seed=seed)
    with progress_bar() as update:
        result = run_ik_bench(c, cfg, update)
    write_json(folder / "bench_ik.json", {"config": cfg.__dict__, "safety_distance": safety,
                                          "result": result.to_dict()})
    for item in render.ik_report(result, c.config.kind.value, solutions):
        console.print(item)
    console.print(f"results: {folder / 'bench_ik.json'}")


@bench_app.command("sim")
def bench_sim(
    object_name: Annotated[str, typer.Option("--object", help="Object on the board.")] = "drill",
    seed: SeedOpt = 0,
    out: Annotated[Path | None, typer.Option(help="Output folder (default runs/bench-sim-<time>).")] = None,
) -> None:
    """Board detection in the 24 views of eq. 4.1, capture time, execution precision."""
    from dataclasses import asdict

    from recon_cli.bench import render
    from recon_cli.bench.sim import run_sim_bench
    from recon_cli.console import console, progress_bar, run_folder, write_json

    folder = run_folder(out, "bench-sim")
    with progress_bar() as update:
        result = run_sim_bench(folder, object_name, seed, update)
    write_json(folder / "bench_sim.json", {"object": result.object_name, "views": [asdict(r) for r in result.rows],
                                           "move": result.move})
    for item in render.sim_report(result):
        console.print(item)
    console.print(f"results: {folder / 'bench_sim.json'}, picture: {folder / 'eq_4_1_views.png'}")


@bench_app.command("registration")
def bench_registration(
    object_name: Annotated[str, typer.Option("--object", help="Object ('auto': the drill if the YCB data is "
                                                              "here, else the bottle).")] = "auto",
    resolution: Annotated[float, typer.Option(min=0.1, max=1.0, help="Image size relative to 1600 x 1200.")] = 1.0,
    seed: SeedOpt = 0,
    out: Annotated[Path | None, typer.Option(help="Output folder (default runs/bench-registration-<time>).")] = None,
) -> None:
    """Thesis 4.2: ChArUco pose errors (Table 4.2) and global vs local registration accuracy."""
    from recon_cli.bench import render
    from recon_cli.bench.registration import run_registration_bench
    from recon_cli.console import console, progress_bar, run_folder, write_json

    folder = run_folder(out, "bench-registration")
    with progress_bar() as update:
        data = run_registration_bench(folder, object_name, seed, resolution, update)
    write_json(folder / "bench_registration.json", data)
    for item in render.registration_report(data):
        console.print(item)
    console.print(f"results: {folder / 'bench_registration.json'}, histogram: {folder / 'distances.png'}, "
                  f"mesh: {data['mesh']}")


@bench_app.command("sequence")
def bench_sequence(
    runs: Annotated[int, typer.Option("--runs", min=1, help="Runs per case.")] = 500,
    quick: Annotated[bool, typer.Option("--quick", help="CI mode: 3 runs per case.")] = False,
    cases: Annotated[str, typer.Option(help="Comma-separated cases: A, B, C, D (ours), A0 (recon run's "
                                            "default order).")] = "A,B,C,D,A0",
    seed: SeedOpt = 0,
    out: Annotated[Path | None, typer.Option(help="Output folder (default runs/bench-sequence-<time>).")] = None,
) -> None:
    """Thesis 4.3: total trajectory time and planning requests of the 24 views of eq. 4.1."""
    from dataclasses import asdict

    from recon_cli.bench import render
    from recon_cli.bench.sequence import CASES, ecdf_png, run_sequence_bench, summarize
    from recon_cli.config import DEFAULTS
    from recon_cli.console import console, progress_bar, run_folder, write_json

    chosen = _choices(cases, CASES, "case")
    folder = run_folder(out, "bench-sequence")
    n = 3 if quick else runs
    plan = DEFAULTS.planner
    with progress_bar() as update:
        rows = run_sequence_bench(n, seed, chosen, update, plan)
    summary = summarize(rows)
    write_json(folder / "bench_sequence.json", {"runs_per_case": n, "seed": seed, "planner": plan,
                                                "velocity_scale": plan.velocity_scale,
                                                "acceleration_scale": plan.acceleration_scale, "summary": summary,
                                                "runs": [asdict(r) for r in rows]})
    ecdf_png(folder / "t_p_ecdf.png", rows)
    for item in render.sequence_report(summary, n, plan.velocity_scale, plan.acceleration_scale):
        console.print(item)
    console.print(f"results: {folder / 'bench_sequence.json'}, plot: {folder / 't_p_ecdf.png'}")


@bench_app.command("viewplan")
def bench_viewplan(
    objects: Annotated[str, typer.Option(help="Comma-separated objects (default: the built-ins).")]
    = "wood_block,toy_blocks,bottle,mug",
    methods: Annotated[str, typer.Option(help="Comma-separated: ellipsoid, sphere, random.")] \
        = "ellipsoid,sphere,random",
    n: Annotated[int, typer.Option("--n", min=2, help="Scans per run.")] = 16,
    dc: Annotated[float, typer.Option("--dc", help="Camera distance to the ellipsoid [m].")] = 0.55,
    cell: CellOpt = "gantry",
    resolution: Annotated[float, typer.Option(min=0.05, max=1.0, help="Image size relative to 1600 x 1200.")] = 1.0,
    seed: SeedOpt = 0,
    out: Annotated[Path | None, typer.Option(help="Output folder (default runs/bench-viewplan-<time>).")] = None,
) -> None:
    """Thesis 4.4: ellipsoid view planner vs evenly spread and random views, every object."""
    from dataclasses import asdict

    from recon_cli.bench import render
    from recon_cli.bench.viewplan import coverage_png, run_viewplan_bench
    from recon_cli.console import console, progress_bar, run_folder, write_json
    from recon_cli.robot.description import CellConfig, CellKind
    from recon_cli.workflows.autoscan import METHODS

    chosen = _choices(methods, METHODS, "method")
    folder = run_folder(out, "bench-viewplan")
    with progress_bar() as update:
        rows = run_viewplan_bench(folder, [o.strip() for o in objects.split(",") if o.strip()], chosen, n, dc, seed,
                                  resolution, CellConfig(kind=CellKind.parse(cell)), update)
    write_json(folder / "bench_viewplan.json", {"n": n, "d_c": dc, "cell": cell, "rows": [asdict(r) for r in rows]})
    coverage_png(folder / "coverage.png", rows)
    for item in render.viewplan_report(rows, n, dc, cell):
        console.print(item)
    console.print(f"results: {folder / 'bench_viewplan.json'}, plot: {folder / 'coverage.png'}")


@bench_app.command("planners")
def bench_planners(
    n: Annotated[int, typer.Option("--n", min=1, help="Requests per planner.")] = 1000,
    planners: Annotated[str, typer.Option(help="Comma-separated OMPL planners, or 'default'.")] = "default",
    time_limit: Annotated[float, typer.Option(min=0.1, help="Time limit per request [s].")] = 5.0,
    quick: Annotated[bool, typer.Option(help="CI mode: 10 requests of RRTConnect and RRT.")] = False,
    peer: Annotated[str, typer.Option(help="Also run a peer on the same problem: 'mplib' or 'none'.")] = "none",
    peer_n: Annotated[int, typer.Option(min=1, help="Requests for the peer (per RRT range tried).")] = 200,
    simplify: Annotated[str, typer.Option(help="Path simplification: shortcut, reduce, full or none.")] = "shortcut",
    shortcut_rounds: Annotated[int, typer.Option(min=1, help="Rounds of per-joint shortcuts (shortcut).")] = 1,
    seed: SeedOpt = 0,
    out: Annotated[Path | None, typer.Option(help="Output folder (default runs/bench-planners-<time>).")] = None,
) -> None:
    """The Table 4.1 planning benchmark (thesis 4.1): success, plan times, path lengths."""
    from recon_cli.bench import render
    from recon_cli.bench.planners import DEFAULT_PLANNERS, run_planner_bench, thesis_times, write_results
    from recon_cli.console import console, progress_bar, run_folder
    from recon_cli.planning.planner import PLANNERS, PlanOptions

    options = PlanOptions(simplify=simplify, shortcut_rounds=shortcut_rounds)
    names = list(DEFAULT_PLANNERS) if planners == "default" else [p.strip() for p in planners.split(",") if p.strip()]
    if quick:
        names, n = ["RRTConnect", "RRT"], min(n, 10)
    for name in names:
        if name not in PLANNERS:

            raise UnknownNameError("planner", name, PLANNERS)
    if peer not in ("none", "mplib"):
        raise InputError(f"--peer '{peer}' is not known", hint="use mplib or none")
    folder = run_folder(out, "bench-planners")
    with progress_bar() as update:
        rows = run_planner_bench(names, n, time_limit, seed, update, options)
    peer_summary = None
    if peer == "mplib":
        from recon_cli.bench.mplib_peer import run_mplib

        with console.status("mplib 0.2.1 on the same problem ..."):
            peer_summary = run_mplib(folder, peer_n, time_limit)
    meta = {"n": n, "time_limit": time_limit, "seed": seed, "planners": names, "problem": "Table 4.1",
            "simplify": simplify, "shortcut_rounds": shortcut_rounds,
            "plan_time": "search + simplification, one core"}
    summary = write_results(folder, rows, meta, peer_summary)
    for item in render.planners_report(summary, n, time_limit, thesis_times(), peer_summary):
        console.print(item)
    console.print(f"results: {folder / 'bench_planners.json'}, {folder / 'requests.csv'}, "
                  f"plot: {folder / 'plan_times.png'}")


def main(argv: list[str] | None = None) -> int:
    """Run the app and return the exit code; user errors become one line on stderr."""
    from recon_cli.console import err_console

    command = typer.main.get_command(app)
    try:
        result = command.main(args=argv, prog_name="recon", standalone_mode=False)
    except ReconError as exc:
        err_console.print(f"{exc.label}: {exc.one_line()}", markup=False, soft_wrap=True)
        return exc.exit_code
    except typer.Exit as exc:
        return exc.exit_code
    except (typer.Abort, KeyboardInterrupt):
        err_console.print("interrupted", markup=False)
        return 130
    except typer.TyperException as exc:  # usage errors: bad option values, unknown options
        ctx = getattr(exc, "ctx", None)
        if type(exc).__name__ == "NoArgsIsHelpError":  # typer has printed the help already
            return 0
        where = f" (see '{ctx.command_path} --help')" if ctx is not None else ""
        message = exc.format_message() if hasattr(exc, "format_message") else str(exc)
        err_console.print(f"error: {message}{where}", markup=False, soft_wrap=True)
        return int(getattr(exc, "exit_code", 2))
    return result if isinstance(result, int) else 0


def entry() -> None:
    """Console-script entry point."""
    code = main()
    if "ompl" in sys.modules:
        # the OMPL wheel's nanobind bindings print spurious "leaked" reports at interpreter
        # teardown; everything is written and flushed by now, so leave without a teardown
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    sys.exit(code)


if __name__ == "__main__":
    entry()
