"""``sides_report.json`` of ``recon autoscan --sides 2`` and of scripts with ``<turn_over/>``
(schemas/sides_report.schema.json): how the object was turned over, each side's scans and
time, the registration of the sides by shape with its confidence (and, in simulation, its
error against the truth), and the merged model's coverage of the whole surface with each
side's share."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from recon_cli.runs.files import read_model, target, write_model

SIDES_REPORT = "sides_report.json"
SCHEMA = "sides_report.schema.json"


@dataclass(frozen=True)
class SidesReport:
    """``sides_report.json``."""

    object: str | None = None
    sides: int = 2
    turn: Mapping[str, Any] = field(default_factory=dict)  # by physics (tilt, settle time) or by the operator (pause)
    seconds: float = 0.0  # wall clock of both sides, the registration and the merge
    side_seconds: list[float] = field(default_factory=list)
    side_scans: list[int] = field(default_factory=list)
    side_2_prior: Mapping[str, Any] | None = None  # side 1 registered onto side 2's partial model: when, how well
    registration: Mapping[str, Any] = field(default_factory=dict)  # SideRegistration.to_dict() (+ "truth")
    coverage_whole: float | None = None  # share of the whole surface, resting faces included (simulation)
    contributions: Mapping[str, float] = field(default_factory=dict)  # the same per side alone
    accuracy: Mapping[str, Any] | None = None  # signed distances of the merged cloud to the truth [mm]
    error: str | None = None  # why the sides were not merged
    cloud: str | None = None
    mesh: str | None = None


def registration_entry(registration: Mapping[str, Any], truth: dict[str, float] | None) -> dict[str, Any]:
    """The registration's confidence (``SideRegistration.to_dict()``) as the report keeps it,
    with its error against the simulation's truth (rotation [deg], translation at the
    object's centre [mm]) when known."""
    out: dict[str, Any] = dict(registration)
    out["side1_T_side2"] = [[float(v) for v in row] for row in out["side1_T_side2"]]
    for alt in out.get("alternatives", []):
        for key, value in list(alt.items()):
            if hasattr(value, "tolist"):
                alt[key] = value.tolist()
    out["truth"] = truth
    return out


def write(folder: Path, report: SidesReport) -> Path:
    """``folder/sides_report.json``."""
    return write_model(Path(folder) / SIDES_REPORT, report)


def read(folder_or_path: Path, root: Path | None = None) -> SidesReport:
    """The sides report of a run folder (or the file); a MetadataError when it cannot be read
    or does not match its schema.
    ``root``: the run folder it belongs to (default: the folder that holds it), which it
    may not leave through a link."""
    path = target(folder_or_path, SIDES_REPORT)
    return read_model(path, SidesReport, SCHEMA, path.name, root)
