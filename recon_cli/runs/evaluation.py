"""``<name>_evaluation.json`` of ``recon evaluate`` and a script's ``<evaluate>``
(schemas/evaluation_report.schema.json): the reconstruction against its reference, signed
distances, coverage, and the alignment that was applied first."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from recon_cli.runs.codec import Matrix
from recon_cli.runs.files import read_model, write_model

SUFFIX = "_evaluation.json"
PATTERN = f"*{SUFFIX}"
SCHEMA = "evaluation_report.schema.json"


def file_name(stem: str) -> str:
    """The report of the reconstruction ``stem`` (``cloud`` -> ``cloud_evaluation.json``)."""
    return f"{stem}{SUFFIX}"


@dataclass(frozen=True)
class EvaluationReport:
    """``<name>_evaluation.json``."""

    reconstruction: str = ""
    reference: str = ""
    alignment: str = "none"  # none | icp
    alignment_transform: Matrix | None = None
    points: int | None = None
    mean_mm: float | None = None
    std_mm: float | None = None
    rms_mm: float | None = None
    median_abs_mm: float | None = None
    within: Mapping[str, float] = field(default_factory=dict)  # "±0.5 mm" -> share of the points
    coverage: float | None = None  # share of the reference surface
    contributions: Mapping[str, float] = field(default_factory=dict)  # two sides: each one's coverage alone
    coverage_visible: float | None = None  # among the samples a camera could see
    visible_share: float | None = None
    coverage_tolerance_mm: float | None = None
    reference_samples: int | None = None

    @property
    def name(self) -> str:
        return Path(self.reconstruction).stem


def write(folder: Path, report: EvaluationReport) -> Path:
    """``folder/<reconstruction stem>_evaluation.json``."""
    return write_model(Path(folder) / file_name(report.name), report)


def read(path: Path, root: Path | None = None) -> EvaluationReport:
    """An evaluation report; a MetadataError when it cannot be read or does not match its
    schema. ``root``: the run folder it belongs to (default: the folder that holds it),
    which it may not leave through a link."""
    path = Path(path)
    return read_model(path, EvaluationReport, SCHEMA, path.name, root)


def reports(folder: Path) -> list[Path]:
    """The evaluation reports of a folder."""
    return sorted(Path(folder).glob(PATTERN))
