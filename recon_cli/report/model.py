"""What a run folder holds, as the page shows it: read by :mod:`recon_cli.report.read`,
shown by :mod:`recon_cli.report.sections`.

The report files are the models of :mod:`recon_cli.runs` and ``session.json`` is
:class:`~recon_cli.reconstruction.metadata.SessionInfo`; what is defined here is what the
page puts together from them (moves, scans with their registration, the pose graph's edges
by scan folder, evaluations with their histograms, the files of the folder).

Lengths here are in millimetres and times in seconds (the reports' own units), shares in
[0, 1]. ``None`` means the folder does not say (not measured, not recorded).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path

from recon_cli.reconstruction.metadata import SessionInfo
from recon_cli.runs.autoscan import AutoscanReport
from recon_cli.runs.capture import CaptureReport
from recon_cli.runs.register import PoseError
from recon_cli.runs.script_run import ScriptRunReport
from recon_cli.runs.sides import SidesReport


class RunKind(StrEnum):
    """What made a run folder."""

    RUN = "run"  # recon run: run_report.json, scans/, reconstruction/
    AUTOSCAN = "autoscan"  # recon autoscan: autoscan_report.json, iterations/*.png, reconstruction/
    SCANS = "scans"  # a scan store (recon capture, or any store): session.json, scan_NNNN/
    REGISTER = "register"  # recon register's output folder: report.json
    SIDES = "sides"  # recon autoscan --sides 2: sides_report.json, side_1/ and side_2/ (autoscans), reconstruction/

    @property
    def label(self) -> str:
        return {RunKind.RUN: "recon run", RunKind.AUTOSCAN: "recon autoscan",
                RunKind.SCANS: "scan store (recon capture)", RunKind.REGISTER: "recon register",
                RunKind.SIDES: "recon autoscan --sides 2"}[self]


@dataclass(frozen=True)
class Move:
    """One planned (and usually executed) move."""

    label: str  # the command or the scan it led to
    planner: str | None
    plan_s: float | None  # planning time (with simplification)
    trajectory_s: float | None  # duration of the timed trajectory


@dataclass(frozen=True)
class Scan:
    """One scan folder of the store."""

    folder: str  # scan_NNNN
    index: int
    name: str | None  # the script's name for it
    color: Path | None  # color.png (None: no colour image)
    depth: Path | None  # depth.png
    width: int | None  # [px]
    height: int | None
    move: Move | None  # the move that led to it (when the scan records it)
    problem: str | None = None  # why its scan.json cannot be read


@dataclass(frozen=True)
class ScanPose:
    """The registration of one scan (report.json)."""

    folder: str
    source: str | None  # charuco | kinematics (None: no pose)
    corners: int | None  # ChArUco corners found
    reprojection_px: float | None
    reason: str  # why the board was not used
    points: int  # after cropping
    skipped: str | None  # why the scan is not in the result
    charuco_error: PoseError | None  # the board's pose against the truth (simulation)
    final_error: PoseError | None  # the registered pose against the truth (simulation)


@dataclass(frozen=True)
class Edge:
    """One pairwise ICP result of the pose graph."""

    source: str  # scan folder
    target: str
    kind: str  # odometry | loop_closure
    correspondences: int | None
    fitness: float | None  # share of source points with a correspondence
    rmse_mm: float | None  # inlier RMSE
    rejected: bool


@dataclass(frozen=True)
class Registration:
    """``report.json`` of ``recon register`` (also inside run and autoscan folders)."""

    report: Path
    scan_store: Path | None  # where the scans are (None: not found)
    frame: str
    registered: int
    skipped: int
    pose_sources: dict[str, int]
    poses: tuple[ScanPose, ...]
    edges: tuple[Edge, ...]
    pruned_loop_closures: int | None
    timings_s: dict[str, float]  # global, local, surface, total
    fused_points: int | None
    charuco_error_mean: PoseError | None
    final_error_mean: PoseError | None
    mesh: Path | None

    def pose_of(self, folder: str) -> ScanPose | None:
        return next((p for p in self.poses if p.folder == folder), None)

    def edges_of(self, folder: str) -> tuple[Edge, ...]:
        return tuple(e for e in self.edges if folder in (e.source, e.target))


@dataclass(frozen=True)
class Evaluation:
    """``<name>_evaluation.json`` of ``recon evaluate`` / ``<evaluate>``, with its histogram."""

    report: Path
    name: str  # the evaluated file's stem
    reference: str
    histogram: Path | None  # <name>_distances.png
    points: int | None
    mean_mm: float | None
    std_mm: float | None
    rms_mm: float | None
    within: dict[str, float]  # "±0.5 mm" -> share of points
    coverage: float | None
    coverage_visible: float | None
    tolerance_mm: float | None


@dataclass(frozen=True)
class OutputFile:
    path: Path
    what: str
    bytes: int


@dataclass(frozen=True)
class Side:
    """One side of an object scanned on both sides: its own scans and registration."""

    name: str  # side_1, side_2 (its folder's name)
    folder: Path
    scans: tuple[Scan, ...]
    registration: Registration | None  # the side's own (its reconstruction/report.json)
    cloud: Path | None  # its registered cloud (world frame of the side)
    seconds: float | None  # wall clock of the side
    coverage: float | None  # share of the whole surface this side covers alone (simulation)

    @property
    def label(self) -> str:
        return self.name.replace("_", " ")


@dataclass(frozen=True)
class TwoSides:
    """``sides_report.json`` and the two sides of a folder: a script with ``<turn_over/>`` or
    ``recon autoscan --sides 2``."""

    report: SidesReport
    sides: tuple[Side, ...]
    cloud: Path | None  # the merged cloud (None: the sides were not merged)


@dataclass(frozen=True)
class RunFolder:
    """Everything a page shows about one folder."""

    kind: RunKind
    folder: Path  # where the page is written
    session: SessionInfo | None = None
    script_run: ScriptRunReport | None = None
    autoscan: AutoscanReport | None = None
    capture: CaptureReport | None = None
    scans: tuple[Scan, ...] = ()
    moves: tuple[Move, ...] = ()  # a script run's move commands, else the moves the scans record
    registration: Registration | None = None
    evaluations: tuple[Evaluation, ...] = ()
    pictures: tuple[Path, ...] = ()  # autoscan: one per iteration
    plys: tuple[OutputFile, ...] = ()
    reports: tuple[OutputFile, ...] = ()  # JSON reports, configuration, expanded script
    notes: tuple[str, ...] = ()  # what the folder lacks or could not be read
    two_sides: TwoSides | None = None  # an object scanned on both sides

    @property
    def status(self) -> str:
        if self.script_run is not None:
            return self.script_run.status
        if self.autoscan is not None:
            return self.autoscan.status
        if self.capture is not None:
            return self.capture.status
        if self.two_sides is not None and self.two_sides.cloud is None:
            return "failed"
        return "done"

    @property
    def title(self) -> str:
        if self.script_run is not None:
            return f"{self.kind.label}: {self.script_run.name}"
        obj = (self.autoscan.object if self.autoscan else None) or (
            self.two_sides.report.object if self.two_sides else None) or (
            self.session.object_name if self.session else None)
        return f"{self.kind.label}" + (f": {obj}" if obj else "")
