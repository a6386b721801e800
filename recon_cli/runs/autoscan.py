"""``autoscan_report.json`` of ``recon autoscan`` (schemas/autoscan_report.schema.json):
the method and its parameters, how the run ended, the views of every iteration, planning
and trajectory totals, and (simulation) coverage and accuracy of the fused cloud."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from recon_cli.runs.codec import Matrix
from recon_cli.runs.files import read_model, target, write_model

AUTOSCAN_REPORT = "autoscan_report.json"
SCHEMA = "autoscan_report.schema.json"


@dataclass(frozen=True)
class ViewOutcome:
    """One view of an iteration: planned and scanned (completed), or found infeasible."""

    status: str  # completed | infeasible
    iteration: int
    world_T_camera: Matrix | None = None
    planning_s: float | None = None  # completed: planning of the move to it (view selection)
    trajectory_s: float | None = None  # completed: duration of that move


@dataclass(frozen=True)
class Accuracy:
    """Signed distances of the fused cloud to the ground truth (simulation)."""

    mean_mm: float
    std_mm: float
    points: int | None = None
    within: Mapping[str, float] = field(default_factory=dict)  # "±0.5 mm" -> share of the points


@dataclass(frozen=True)
class AutoscanOutputs:
    cloud: str | None = None
    mesh: str | None = None
    pictures: tuple[str, ...] = ()


@dataclass(frozen=True)
class AutoscanReport:
    """``autoscan_report.json``."""

    method: str = ""  # ellipsoid | sphere | random
    object: str | None = None
    cell: str | None = None
    n: int | None = None  # scans asked for
    d_c: float | None = None  # camera distance [m]
    m: int | None = None
    sigma: float | None = None
    seed: int | None = None
    scans: int = 0
    interrupted: bool = False
    error: str | None = None  # the error that ended the run early
    infeasible_views: int | None = None
    planning_requests: int | None = None
    trajectory_s: float | None = None
    coverage_1mm: float | None = None  # share of the true surface within 1 mm
    accuracy: Accuracy | None = None
    seconds_scanning: float | None = None
    seconds_total: float | None = None
    views: tuple[ViewOutcome, ...] = ()
    outputs: AutoscanOutputs | None = None

    @property
    def status(self) -> str:
        return "interrupted" if self.interrupted else "failed" if self.error else "done"


def write(folder: Path, report: AutoscanReport) -> Path:
    """``folder/autoscan_report.json``."""
    return write_model(Path(folder) / AUTOSCAN_REPORT, report)


def read(folder_or_path: Path, root: Path | None = None) -> AutoscanReport:
    """The autoscan report of a run folder (or the file); a MetadataError when it cannot be
    read or does not match its schema.
    ``root``: the run folder it belongs to (default: the folder that holds it), which it
    may not leave through a link."""
    path = target(folder_or_path, AUTOSCAN_REPORT)
    return read_model(path, AutoscanReport, SCHEMA, path.name, root)
