"""Reading a run folder into :class:`~recon_cli.report.model.RunFolder`.

Which kind of folder it is follows from the report it holds (``run_report.json``,
``autoscan_report.json``, a registration ``report.json``, or a scan store's
``session.json`` / ``scan_NNNN`` folders). Everything else is read where it exists: a run
that ended early has fewer files, and a file that cannot be read becomes a note on the page
instead of an error, so a page can always show what is there.
"""

from __future__ import annotations

import os
from dataclasses import replace
from pathlib import Path
from typing import Any

from recon_cli.errors import FileError, MetadataError
from recon_cli.inputs.jsonfile import load_json
from recon_cli.report.model import (
    Autoscan,
    Capture,
    Command,
    Edge,
    Evaluation,
    Move,
    OutputFile,
    PoseError,
    Registration,
    RunFolder,
    RunKind,
    Scan,
    ScanPose,
    ScriptRun,
    Session,
    ViewFailure,
    ViewOutcome,
)

RUN_REPORT, AUTOSCAN_REPORT, CAPTURE_REPORT, REGISTER_REPORT = (
    "run_report.json", "autoscan_report.json", "capture_report.json", "report.json")
PAGE_FILES = "report_files"  # the page's own images, beside it
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


def _list(value: Any) -> list:
    return value if isinstance(value, list) else []


def _pose_error(value: Any) -> PoseError | None:
    d = _dict(value)
    t, r = _float(d.get("translation_mm")), _float(d.get("rotation_deg"))
    return None if t is None or r is None else PoseError(t, r)


class _Notes:
    """What could not be read, for the page."""

    def __init__(self) -> None:
        self.items: list[str] = []

    def load(self, path: Path, what: str) -> dict | None:
        if not path.is_file():
            return None
        try:
            data = load_json(path, what)
        except MetadataError as exc:
            self.items.append(exc.one_line())
            return None
        if not isinstance(data, dict):
            self.items.append(f"{path}: {what} holds no JSON object")
            return None
        return data


# ----------------------------------------------------------------------------- the kind of folder
def _is_registration_report(path: Path) -> bool:
    try:
        data = load_json(path, path.name)
    except MetadataError:
        return path.is_file()  # a broken report.json: still the register folder (the page says why)
    return isinstance(data, dict) and isinstance(data.get("scans"), list)


def _scan_folders(store: Path) -> list[tuple[int, Path]]:
    from recon_cli.reconstruction.scan_store import ScanStore

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
    if (folder / REGISTER_REPORT).is_file() and _is_registration_report(folder / REGISTER_REPORT):
        return RunKind.REGISTER
    if (folder / "session.json").is_file() or _scan_folders(folder):
        return RunKind.SCANS
    raise FileError(f"{folder} is not a run folder (no {RUN_REPORT}, {AUTOSCAN_REPORT}, registration "
                    f"{REGISTER_REPORT}, session.json or scan_NNNN folder in it)", hint=_HINT)


# ----------------------------------------------------------------------------- reports
def _session(data: dict | None) -> Session | None:
    if data is None:
        return None
    cell, obj, realism = _dict(data.get("cell")), _dict(data.get("object")), _dict(data.get("realism"))
    noise = data.get("noise")
    return Session(mode=_str(data.get("mode")), backend=_str(data.get("backend")), object_name=_str(obj.get("name")),
                   cell=_str(cell.get("kind")), sensor=_str(data.get("sensor")),
                   noise=noise if isinstance(noise, bool) else None, seed=_int(data.get("seed")),
                   realism=_str(realism.get("name")), created=_float(data.get("created")))


def _script_run(data: dict) -> tuple[ScriptRun, tuple[Move, ...]]:
    commands, moves = [], []
    for c in _list(data.get("commands")):
        c = _dict(c)
        cmd = Command(str(c.get("source", "")), str(c.get("command", "")), str(c.get("status", "")),
                      _float(c.get("seconds")) or 0.0, str(c.get("message", "")))
        commands.append(cmd)
        if "plan_time_s" in c or "trajectory_s" in c:  # a move (its command is in the commands table)
            moves.append(Move(cmd.source, _str(c.get("planner")), _float(c.get("plan_time_s")),
                              _float(c.get("trajectory_s"))))
    interrupted = _dict(data.get("interrupted"))
    run = ScriptRun(script=str(data.get("script", "")), name=str(data.get("name", "")),
                    dialect=str(data.get("dialect", "")), status=str(data.get("status", "unknown")),
                    exit_code=_int(data.get("exit_code")), seconds=_float(data.get("seconds")),
                    scans=_int(data.get("scans")), backend=_str(data.get("backend")), seed=_int(data.get("seed")),
                    dry_run=bool(data.get("dry_run", False)), on_failure=_str(data.get("on_failure")),
                    stopped=_str(interrupted.get("reason") or data.get("aborted")), commands=tuple(commands))
    return run, tuple(moves)


def _autoscan(path: Path, data: dict, reg_dir: Path) -> tuple[Autoscan, tuple[Move, ...], Evaluation | None]:
    """The autoscan, its moves (one per completed view) and its evaluation against the truth
    (when the run got that far)."""
    accuracy = _dict(data.get("accuracy"))
    views = tuple(ViewOutcome(_int(v.get("iteration")) or 0, str(v.get("status", "")), _float(v.get("planning_s")),
                              _float(v.get("trajectory_s")))
                  for v in map(_dict, _list(data.get("views"))))
    moves = tuple(Move(f"iteration {v.iteration}", "view selection" if v.iteration else None, v.planning_s,
                       v.trajectory_s) for v in views if v.status == "completed" and v.trajectory_s is not None)
    evaluation = None
    coverage, mean, std = _float(data.get("coverage_1mm")), _float(accuracy.get("mean_mm")), \
        _float(accuracy.get("std_mm"))
    if coverage is not None and mean is not None:
        hist = reg_dir / "cloud_distances.png"
        evaluation = Evaluation(
            report=path, name="cloud", reference=f"true {data.get('object', 'object')} surface",
            histogram=hist if hist.is_file() else None, points=_int(accuracy.get("points")), mean_mm=mean,
            std_mm=std, rms_mm=None if std is None else (mean**2 + std**2) ** 0.5,
            within={str(k): f for k, v in _dict(accuracy.get("within")).items() if (f := _float(v)) is not None},
            coverage=coverage, coverage_visible=None, tolerance_mm=1.0)
    return Autoscan(method=str(data.get("method", "")), object_name=_str(data.get("object")),
                    cell=_str(data.get("cell")), n=_int(data.get("n")), d_c_m=_float(data.get("d_c")),
                    seed=_int(data.get("seed")), scans=_int(data.get("scans")) or 0,
                    interrupted=bool(data.get("interrupted", False)), error=_str(data.get("error")),
                    infeasible_views=_int(data.get("infeasible_views")),
                    planning_requests=_int(data.get("planning_requests")),
                    trajectory_s=_float(data.get("trajectory_s")), coverage_1mm=_float(data.get("coverage_1mm")),
                    accuracy_mean_mm=_float(accuracy.get("mean_mm")), accuracy_std_mm=_float(accuracy.get("std_mm")),
                    seconds_total=_float(data.get("seconds_total")), views=views), moves, evaluation


def _capture(data: dict) -> Capture:
    failures = tuple(ViewFailure(_int(f.get("view")) or 0, str(f.get("message", "")))
                     for f in map(_dict, _list(data.get("failures"))))
    return Capture(status=str(data.get("status", "unknown")), views=_int(data.get("views")) or 0,
                   scans=_int(data.get("scans")) or 0, seconds=_float(data.get("seconds")), failures=failures,
                   error=_str(data.get("error")))


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


def _registration(path: Path, data: dict) -> Registration:
    poses, used = [], []
    for s in map(_dict, _list(data.get("scans"))):
        pose = _dict(s.get("pose"))
        folder = _str(s.get("folder")) or f"scan_{_int(s.get('scan')) or 0:04d}"
        skipped = _str(s.get("skipped"))
        poses.append(ScanPose(folder=folder, source=_str(pose.get("source")), corners=_int(pose.get("corners")),
                              reprojection_px=_float(pose.get("reprojection_px")), reason=str(pose.get("reason") or ""),
                              points=_int(s.get("points")) or 0, skipped=skipped,
                              charuco_error=_pose_error(s.get("charuco_error")),
                              final_error=_pose_error(s.get("final_pose_error"))))
        if not skipped:
            used.append(folder)
    graph = _dict(data.get("pose_graph"))
    edges = []
    for e in map(_dict, _list(graph.get("edges"))):
        i, j = _int(e.get("source")), _int(e.get("target"))
        if i is None or j is None or not (0 <= i < len(used) and 0 <= j < len(used)):
            continue  # edges index the registered scans
        rmse = _float(e.get("rmse_m"))
        edges.append(Edge(used[i], used[j], str(e.get("kind", "")), _int(e.get("correspondences")),
                          _float(e.get("fitness")), None if rmse is None else rmse * 1e3, bool(e.get("rejected"))))
    mesh_name = _dict(data.get("outputs")).get("mesh")
    mesh = path.parent / str(mesh_name) if mesh_name else None
    return Registration(
        report=path, scan_store=_scan_store_of(path.parent, _str(data.get("scan_store")), {p.folder for p in poses}),
        frame=str(data.get("frame", "")), registered=_int(data.get("scans_registered")) or len(used),
        skipped=_int(data.get("scans_skipped")) or 0,
        pose_sources={str(k): _int(v) or 0 for k, v in _dict(data.get("pose_sources")).items()},
        poses=tuple(poses), edges=tuple(edges), pruned_loop_closures=_int(graph.get("pruned_loop_closures")),
        timings_s={str(k).removesuffix("_s"): f for k, v in _dict(data.get("timings")).items()
                   if (f := _float(v)) is not None},
        fused_points=_int(_dict(data.get("points")).get("fused")),
        charuco_error_mean=_pose_error(data.get("charuco_error_mean")),
        final_error_mean=_pose_error(_dict(data.get("pose_error_mean")).get("final")),
        mesh=mesh if mesh is not None and mesh.is_file() else None)


def _evaluations(folder: Path, notes: _Notes) -> tuple[Evaluation, ...]:
    out = []
    for path in sorted(folder.glob("*_evaluation.json")):
        data = notes.load(path, path.name)
        if data is None:
            continue
        name = path.name.removesuffix("_evaluation.json")
        hist = folder / f"{name}_distances.png"
        out.append(Evaluation(
            report=path, name=name, reference=Path(str(data.get("reference", ""))).name,
            histogram=hist if hist.is_file() else None, points=_int(data.get("points")),
            mean_mm=_float(data.get("mean_mm")), std_mm=_float(data.get("std_mm")), rms_mm=_float(data.get("rms_mm")),
            within={str(k): f for k, v in _dict(data.get("within")).items() if (f := _float(v)) is not None},
            coverage=_float(data.get("coverage")), coverage_visible=_float(data.get("coverage_visible")),
            tolerance_mm=_float(data.get("coverage_tolerance_mm"))))
    return tuple(out)


# ----------------------------------------------------------------------------- scans and files
def _scans(store: Path, notes: _Notes) -> tuple[Scan, ...]:
    out = []
    for index, path in _scan_folders(store):
        color = path / "color.png" if (path / "color.png").is_file() else None
        depth = path / "depth.png" if (path / "depth.png").is_file() else None
        try:
            meta = load_json(path / "scan.json", "scan.json")
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
        if path.name.endswith("_evaluation.json"):
            what = f"evaluation of {path.name.removesuffix('_evaluation.json')} against the reference"
        else:
            what = _REPORTS.get(path.name, "")
        out.append(OutputFile(path, what, path.stat().st_size))
    return tuple(out)


# ----------------------------------------------------------------------------- the folder
def read_run_folder(folder: Path) -> RunFolder:
    """Everything the page of ``folder`` shows (see the module docstring)."""
    folder = Path(folder)
    kind = run_kind(folder)
    notes = _Notes()
    script_run = autoscan = capture = None
    moves: tuple[Move, ...] = ()
    extra: tuple[Evaluation, ...] = ()  # an evaluation a run reports itself
    exports: set[str] = set()
    store: Path | None = folder
    reg_dir = folder / "reconstruction"
    if kind is RunKind.RUN:
        store = folder / "scans"
        data = notes.load(folder / RUN_REPORT, RUN_REPORT)
        if data is not None:
            script_run, moves = _script_run(data)
            exports = {Path(str(v)).name for k, v in _dict(data.get("outputs")).items() if k.startswith("export_")}
    elif kind is RunKind.AUTOSCAN:
        data = notes.load(folder / AUTOSCAN_REPORT, AUTOSCAN_REPORT)
        if data is not None:
            autoscan, moves, evaluation = _autoscan(folder / AUTOSCAN_REPORT, data, reg_dir)
            extra = () if evaluation is None else (evaluation,)
    elif kind is RunKind.SCANS:
        data = notes.load(folder / CAPTURE_REPORT, CAPTURE_REPORT)
        capture = None if data is None else _capture(data)
    else:
        reg_dir = folder
    data = notes.load(reg_dir / REGISTER_REPORT, REGISTER_REPORT)
    registration = None if data is None else _registration(reg_dir / REGISTER_REPORT, data)
    if kind is RunKind.REGISTER:
        store = None if registration is None else registration.scan_store
        if store is None:
            notes.items.append("the scan store of this registration was not found (its scans are not shown)")
    elif registration is not None:  # the scans beside it, wherever the folder was moved
        registration = replace(registration, scan_store=store)
    session = None
    scans: tuple[Scan, ...] = ()
    if store is not None and store.is_dir():
        session = _session(notes.load(store / "session.json", "session.json"))
        scans = _scans(store, notes)
    if not moves:
        moves = tuple(s.move for s in scans if s.move is not None)
    pictures = tuple(sorted((folder / "iterations").glob("iteration_*.png"))) if kind is RunKind.AUTOSCAN else ()
    return RunFolder(kind=kind, folder=folder, session=session, script_run=script_run, autoscan=autoscan,
                     capture=capture, scans=scans, moves=moves, registration=registration,
                     evaluations=extra + (_evaluations(reg_dir, notes) if reg_dir.is_dir() else ()), pictures=pictures,
                     plys=_plys(folder, exports), reports=_reports(folder), notes=tuple(notes.items))
