"""Reading a run folder into :class:`~recon_cli.report.model.RunFolder`.

Which kind of folder it is follows from the report it holds (``run_report.json``,
``autoscan_report.json``, a registration ``report.json``, or a scan store's
``session.json`` / ``scan_NNNN`` folders). Everything else is read where it exists: a run
that ended early has fewer files, and a file that cannot be read becomes a note on the page
instead of an error, so a page can always show what is there.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any, TypeVar

from recon_cli.errors import FileError, MetadataError
from recon_cli.inputs.files import OUTSIDE, Refusal, link_out_of, outside_text
from recon_cli.inputs.jsonfile import load_json
from recon_cli.reconstruction.metadata import SessionInfo, read_session
from recon_cli.reconstruction.scan_store import ScanStore
from recon_cli.report.model import (
    Edge,
    Evaluation,
    Move,
    OutputFile,
    Registration,
    RunFolder,
    RunKind,
    Scan,
    ScanPose,
    Side,
    TwoSides,
)
from recon_cli.runs import autoscan as autoscan_file
from recon_cli.runs import capture as capture_file
from recon_cli.runs import evaluation as evaluation_file
from recon_cli.runs import register as register_file
from recon_cli.runs import script_run as run_file
from recon_cli.runs import sides as sides_file
from recon_cli.runs.autoscan import AutoscanReport
from recon_cli.runs.register import RegisterReport
from recon_cli.runs.script_run import ScriptRunReport
from recon_cli.runs.sides import SidesReport

RUN_REPORT, AUTOSCAN_REPORT, CAPTURE_REPORT, REGISTER_REPORT, SIDES_REPORT = (
    run_file.RUN_REPORT, autoscan_file.AUTOSCAN_REPORT, capture_file.CAPTURE_REPORT, register_file.REGISTER_REPORT,
    sides_file.SIDES_REPORT)
PAGE_FILES = "report_files"
T = TypeVar("T")  # the page's own images, beside it
_HINT = "give the folder a recon run, autoscan, capture or register wrote (its --out)"


# ----------------------------------------------------------------------------- small readers
def _float(value: Any) -> float | None:
    try:
        return None if value is None or isinstance(value, bool) else float(value)
    except (TypeError, ValueError):
        return None


def _int(value: Any) -> int | None:
    f = _float(value)
    return None if f is None else int(f)


def _str(value: Any) -> str | None:
    return None if value is None else str(value)


def _dict(value: Any) -> dict:
    return value if isinstance(value, dict) else {}


class _Notes:
    """What could not be read, for the page; ``root``: the run folder, which nothing read for
    the page may leave through a link."""

    def __init__(self, root: Path) -> None:
        self.items: list[str] = []
        self.root = root

    def root_of(self, store: Path) -> Path:
        """The folder a scan store's files may not leave: the run folder when the store lies in
        it, else the store (a registration's store elsewhere)."""
        inside = Path(os.path.abspath(store)).is_relative_to(os.path.abspath(self.root))
        return self.root if inside else store

    def outside(self, path: Path, what: str, root: Path | None = None) -> bool:
        """Whether ``path`` is (or lies behind) a link leading out of ``root`` (default: the run
        folder); then a note says so, naming the link, not where it leads."""
        root = self.root if root is None else root
        link = link_out_of(path, root)
        if link is None:
            return False
        self.items.append(outside_text(Refusal(OUTSIDE, path, 0, root=root, link=link), what))
        return True

    def read(self, path: Path, reader: Callable[[Path], T], root: Path | None = None) -> T | None:
        """``reader(path)``, or None (with the reason as a note) when the file cannot be read or
        leads out of ``root`` (default: the run folder) through a link."""
        if not (path.is_file() or path.is_symlink()) or self.outside(path, path.name, root):
            return None
        if not path.is_file():
            return None
        try:
            return reader(path)
        except MetadataError as exc:
            self.items.append(exc.one_line())
            return None


# ----------------------------------------------------------------------------- the kind of folder
def _scan_folders(store: Path) -> list[tuple[int, Path]]:

    return ScanStore(store).scan_folders()


def run_kind(folder: Path) -> RunKind:
    """The kind of a run folder, or a FileError that says what a run folder is."""
    folder = Path(folder)
    if not folder.exists():
        raise FileError(f"{folder} does not exist", hint=_HINT)
    if not folder.is_dir():
        raise FileError(f"{folder} is not a folder", hint=_HINT)
    if (folder / RUN_REPORT).is_file():
        return RunKind.RUN
    if (folder / AUTOSCAN_REPORT).is_file():
        return RunKind.AUTOSCAN
    if (folder / SIDES_REPORT).is_file():
        return RunKind.SIDES
    if (folder / REGISTER_REPORT).is_file() and register_file.is_registration(folder / REGISTER_REPORT):
        return RunKind.REGISTER
    if (folder / "session.json").is_file() or _scan_folders(folder):
        return RunKind.SCANS
    raise FileError(f"{folder} is not a run folder (no {RUN_REPORT}, {AUTOSCAN_REPORT}, {SIDES_REPORT}, "
                    f"registration {REGISTER_REPORT}, session.json or scan_NNNN folder in it)", hint=_HINT)


# ----------------------------------------------------------------------------- reports
def _script_moves(run: ScriptRunReport) -> tuple[Move, ...]:
    """The moves of a script run (its commands that planned a move)."""
    return tuple(Move(c.source, c.planner, c.number("plan_time_s"), c.number("trajectory_s")) for c in run.moves)


def _autoscan(path: Path, report: AutoscanReport, reg_dir: Path) -> tuple[tuple[Move, ...], Evaluation | None]:
    """The moves of an autoscan (one per completed view) and its evaluation against the
    truth (when the run got that far)."""
    moves = tuple(Move(f"iteration {v.iteration}", "view selection" if v.iteration else None, v.planning_s,
                       v.trajectory_s) for v in report.views if v.status == "completed" and v.trajectory_s is not None)
    evaluation = None
    accuracy = report.accuracy
    if report.coverage_1mm is not None and accuracy is not None:
        hist = reg_dir / "cloud_distances.png"
        mean, std = accuracy.mean_mm, accuracy.std_mm
        evaluation = Evaluation(
            report=path, name="cloud", reference=f"true {report.object or 'object'} surface",
            histogram=hist if hist.is_file() else None, points=accuracy.points, mean_mm=mean, std_mm=std,
            rms_mm=(mean**2 + std**2) ** 0.5, within=dict(accuracy.within), coverage=report.coverage_1mm,
            coverage_visible=None, tolerance_mm=1.0)
    return moves, evaluation


def _sides_evaluation(path: Path, report: SidesReport) -> Evaluation | None:
    """The merged model of both sides against the object's true whole surface (simulation)."""
    accuracy = _dict(report.accuracy)
    mean, std = _float(accuracy.get("mean_mm")), _float(accuracy.get("std_mm"))
    if report.coverage_whole is None or mean is None or std is None:
        return None
    within = {str(k): v for k, v in _dict(accuracy.get("within")).items() if _float(v) is not None}
    return Evaluation(report=path, name="cloud (both sides)", reference=f"true whole {report.object or 'object'} "
                      "surface", histogram=None, points=None, mean_mm=mean, std_mm=std,
                      rms_mm=(mean**2 + std**2) ** 0.5, within=within, coverage=report.coverage_whole,
                      coverage_visible=None, tolerance_mm=1.0)


def _two_sides(folder: Path, kind: RunKind, notes: _Notes) -> tuple[TwoSides | None, tuple[Move, ...]]:
    """Both sides of a folder with ``sides_report.json`` (a script run keeps each side's scan
    store in ``side_k/scans``, an autoscan's side is an autoscan folder), and the autoscan
    sides' moves."""
    report = notes.read(folder / SIDES_REPORT, sides_file.read)
    if report is None:
        return None, ()
    sides, moves = [], []
    for k in (1, 2):
        name = f"side_{k}"
        base = folder / name
        store = base / "scans" if kind is RunKind.RUN else base
        scans = _scans(store, notes) if store.is_dir() and not notes.outside(store, "scan store") else ()
        reg_path = base / "reconstruction" / REGISTER_REPORT
        rep = notes.read(reg_path, register_file.read)
        registration = None if rep is None else replace(_registration(reg_path, rep), scan_store=store)
        cloud = base / "reconstruction" / "cloud.ply"
        shown = cloud.is_file() and not notes.outside(cloud, f"{name} cloud")
        side = Side(name, base, scans, registration, cloud if shown else None,
                    report.side_seconds[k - 1] if len(report.side_seconds) >= k else None,
                    report.contributions.get(name))
        sides.append(side)
        autoscan = notes.read(base / AUTOSCAN_REPORT, autoscan_file.read)
        if autoscan is not None:
            side_moves, _ = _autoscan(base / AUTOSCAN_REPORT, autoscan, base / "reconstruction")
            moves += [replace(m, label=f"{side.label}, {m.label}") for m in side_moves]
    merged = folder / "reconstruction" / "cloud.ply"
    shown = report.cloud is not None and merged.is_file() and not notes.outside(merged, "merged cloud")
    return TwoSides(report, tuple(sides), merged if shown else None), \
        tuple(moves)


def _scan_store_of(report_dir: Path, text: str | None, names: set[str]) -> Path | None:
    """The scan store of a registration report: beside the report folder when the scans
    named in the report are there (the layouts of recon register and recon run, also after
    the folder was moved), else the path the report names (as given on the command line, so
    relative to where it ran)."""
    def folders(p: Path) -> set[str]:
        return {f.name for _, f in _scan_folders(p)} if p.is_dir() else set()

    nearby = [report_dir.parent, report_dir.parent / "scans"]
    for c in nearby:
        if names and names <= folders(c):
            return c
    stated = []
    if text:
        p = Path(text)
        stated = [p] if p.is_absolute() else [Path.cwd() / p, report_dir / p]
    return next((c for c in [*stated, *nearby] if folders(c)), None)


def _registration(path: Path, report: RegisterReport) -> Registration:
    poses = tuple(ScanPose(folder=s.name, source=None if s.pose is None else s.pose.source,
                           corners=None if s.pose is None else s.pose.corners,
                           reprojection_px=None if s.pose is None else s.pose.reprojection_px,
                           reason=("" if s.pose is None else s.pose.reason) or "", points=s.points,
                           skipped=s.skipped or None, charuco_error=s.charuco_error, final_error=s.final_pose_error)
                  for s in report.scans)
    used = [s.name for s in report.registered]
    graph = report.pose_graph
    edges = tuple(Edge(used[e.source], used[e.target], e.kind, e.correspondences, e.fitness,
                       None if e.rmse_m is None else e.rmse_m * 1e3, e.rejected)
                  for e in (graph.edges if graph else ()) if e.source < len(used) and e.target < len(used))
    mesh_name = report.outputs.mesh if report.outputs else None
    mesh = path.parent / mesh_name if mesh_name else None
    return Registration(
        report=path, scan_store=_scan_store_of(path.parent, report.scan_store, {p.folder for p in poses}),
        frame=report.frame, registered=report.scans_registered or len(used), skipped=report.scans_skipped or 0,
        pose_sources=dict(report.pose_sources), poses=poses, edges=edges,
        pruned_loop_closures=None if graph is None else graph.pruned_loop_closures,
        timings_s={k.removesuffix("_s"): v for k, v in report.timings.items()},
        fused_points=None if report.points is None else report.points.fused,
        charuco_error_mean=report.charuco_error_mean,
        final_error_mean=None if report.pose_error_mean is None else report.pose_error_mean.final,
        mesh=mesh if mesh is not None and mesh.is_file() else None)


def _evaluations(folder: Path, notes: _Notes) -> tuple[Evaluation, ...]:
    out = []
    for path in evaluation_file.reports(folder):
        e = notes.read(path, evaluation_file.read)
        if e is None:
            continue
        name = path.name.removesuffix(evaluation_file.SUFFIX)
        hist = folder / f"{name}_distances.png"
        out.append(Evaluation(
            report=path, name=name, reference=Path(e.reference).name, histogram=hist if hist.is_file() else None,
            points=e.points, mean_mm=e.mean_mm, std_mm=e.std_mm, rms_mm=e.rms_mm, within=dict(e.within),
            coverage=e.coverage, coverage_visible=e.coverage_visible, tolerance_mm=e.coverage_tolerance_mm))
    return tuple(out)


# ----------------------------------------------------------------------------- scans and files
def _scans(store: Path, notes: _Notes) -> tuple[Scan, ...]:
    """The scans of a store; what leads out of the run folder (or, for a store outside it, out
    of the store) through a link is not read."""
    root = notes.root_of(store)
    out = []
    for index, path in _scan_folders(store):
        color, depth = ((p if p.is_file() and link_out_of(p, root) is None else None)
                        for p in (path / "color.png", path / "depth.png"))
        try:
            meta = load_json(path / "scan.json", "scan.json", root=root)
            if not isinstance(meta, dict):
                raise MetadataError(f"{path / 'scan.json'}: holds no JSON object", path=str(path / "scan.json"))
        except MetadataError as exc:
            out.append(Scan(path.name, index, None, color, depth, None, None, None, problem=exc.one_line()))
            continue
        intr, move = _dict(meta.get("intrinsics")), meta.get("move")
        m = None
        if isinstance(move, dict):
            m = Move(path.name, _str(move.get("planner")), _float(move.get("planning_total_s")),
                     _float(move.get("trajectory_duration_s")))
        out.append(Scan(path.name, index, _str(meta.get("name")), color, depth, _int(intr.get("width")),
                        _int(intr.get("height")), m))
    return tuple(out)


_PLY = {"mesh.ply": "Poisson mesh", "cloud.ply": "fused cloud (after local registration)",
        "cloud_global.ply": "fused cloud of the global registration alone"}
_REPORTS = {RUN_REPORT: "the run: every command, its status, time and message",
            AUTOSCAN_REPORT: "the autoscan: views, planning, coverage and accuracy",
            CAPTURE_REPORT: "the capture: views, scans and skipped views",
            REGISTER_REPORT: "the registration: poses, pose graph, timings",
            "session.json": "what produced the scans (cell, sensor, object)",
            "config.yaml": "the effective configuration (repeat the run from it)",
            "script.expanded.xml": "the script after xacro",
            "realism.json": "what the realism profile drew (simulation; evaluation only)",
            "recording.rrd": "3D recording of the run (recon view shows it)"}


def _walk(folder: Path, suffixes: tuple[str, ...], depth: int = 3) -> list[Path]:
    """Files with these suffixes under ``folder`` (not in hidden folders, scan folders or the
    page's own folder; links not followed)."""
    out = []
    base = len(folder.parts)
    for root, dirs, files in os.walk(folder):
        level = len(Path(root).parts) - base
        dirs[:] = sorted(d for d in dirs if level < depth and not d.startswith(".") and d != PAGE_FILES
                         and not d.startswith("scan_"))
        out += [Path(root) / f for f in sorted(files) if f.endswith(suffixes) and not f.startswith(".")]
    return out


def _plys(folder: Path, exports: set[str]) -> tuple[OutputFile, ...]:
    out = []
    for path in _walk(folder, (".ply",)):
        if path.parent.name == "ground_truth":
            what = f"true surface of the {path.stem} (simulation; evaluation only)"
        elif path.name in exports:
            what = "export of the script"
        else:
            what = _PLY.get(path.name, "PLY file")
        out.append(OutputFile(path, what, path.stat().st_size))
    return tuple(out)


def _reports(folder: Path) -> tuple[OutputFile, ...]:
    out = []
    for path in _walk(folder, (".json", ".yaml", ".xml", ".rrd")):
        if path.name.endswith(evaluation_file.SUFFIX):
            what = f"evaluation of {path.name.removesuffix(evaluation_file.SUFFIX)} against the reference"
        else:
            what = _REPORTS.get(path.name, "")
        out.append(OutputFile(path, what, path.stat().st_size))
    return tuple(out)


# ----------------------------------------------------------------------------- the folder
def read_run_folder(folder: Path) -> RunFolder:
    """Everything the page of ``folder`` shows (see the module docstring)."""
    folder = Path(folder)
    kind = run_kind(folder)
    notes = _Notes(folder)
    script_run = autoscan = capture = None
    moves: tuple[Move, ...] = ()
    extra: tuple[Evaluation, ...] = ()  # an evaluation a run reports itself
    exports: set[str] = set()
    store: Path | None = folder
    reg_dir = folder / "reconstruction"
    if kind is RunKind.RUN:
        store = folder / "scans"
        script_run = notes.read(folder / RUN_REPORT, run_file.read)
        if script_run is not None:
            moves = _script_moves(script_run)
            exports = {Path(v).name for k, v in script_run.outputs.items() if k.startswith("export_")}
    elif kind is RunKind.AUTOSCAN:
        autoscan = notes.read(folder / AUTOSCAN_REPORT, autoscan_file.read)
        if autoscan is not None:
            moves, evaluation = _autoscan(folder / AUTOSCAN_REPORT, autoscan, reg_dir)
            extra = () if evaluation is None else (evaluation,)
    elif kind is RunKind.SCANS:
        capture = notes.read(folder / CAPTURE_REPORT, capture_file.read)
    elif kind is RunKind.SIDES:
        store = None
    else:
        reg_dir = folder
    report = notes.read(reg_dir / REGISTER_REPORT, register_file.read)
    registration = None if report is None else _registration(reg_dir / REGISTER_REPORT, report)
    if kind is RunKind.REGISTER:
        store = None if registration is None else registration.scan_store
        if store is None:
            notes.items.append("the scan store of this registration was not found (its scans are not shown)")
    elif registration is not None:  # the scans beside it, wherever the folder was moved
        registration = replace(registration, scan_store=store)
    session: SessionInfo | None = None
    scans: tuple[Scan, ...] = ()
    if store is not None and store.is_dir() and not notes.outside(store, "scan store", notes.root_of(store)):
        session = notes.read(store / "session.json", lambda path: read_session(path.parent), notes.root_of(store))
        scans = _scans(store, notes)
    two_sides, side_moves = _two_sides(folder, kind, notes) if (folder / SIDES_REPORT).is_file() else (None, ())
    if two_sides is not None:
        moves = moves or side_moves
        if session is None:  # what produced side 1's scans
            store_1 = folder / "side_1" / "scans" if kind is RunKind.RUN else folder / "side_1"
            session = notes.read(store_1 / "session.json", lambda path: read_session(path.parent))
        evaluation = _sides_evaluation(folder / SIDES_REPORT, two_sides.report)
        extra += () if evaluation is None else (evaluation,)
    if not moves:
        moves = tuple(s.move for s in scans if s.move is not None)
    pictures = tuple(sorted((folder / "iterations").glob("iteration_*.png"))) if kind is RunKind.AUTOSCAN else ()
    return RunFolder(kind=kind, folder=folder, session=session, script_run=script_run, autoscan=autoscan,
                     capture=capture, scans=scans, moves=moves, registration=registration,
                     evaluations=extra + (_evaluations(reg_dir, notes) if reg_dir.is_dir() else ()), pictures=pictures,
                     plys=_plys(folder, exports), reports=_reports(folder), notes=tuple(notes.items),
                     two_sides=two_sides)
