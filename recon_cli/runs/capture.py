"""``capture_report.json`` of ``recon capture`` (schemas/capture_report.schema.json): how
the capture ended, views and scans, the views that were skipped and why."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from recon_cli.runs.files import read_model, target, write_model

CAPTURE_REPORT = "capture_report.json"
SCHEMA = "capture_report.schema.json"


@dataclass(frozen=True)
class ViewFailure:
    """A view that was not scanned (unreachable, no path) and why."""

    view: int  # 1-based
    message: str


@dataclass(frozen=True)
class CaptureReport:
    """``capture_report.json``."""

    command: str = "capture"
    status: str = "unknown"  # done | incomplete | failed | interrupted
    views: int = 0
    scans: int = 0
    seconds: float | None = None
    error: str | None = None  # the error that ended the capture early
    failures: tuple[ViewFailure, ...] = ()


def write(folder: Path, report: CaptureReport) -> Path:
    """``folder/capture_report.json``."""
    return write_model(Path(folder) / CAPTURE_REPORT, report)


def read(folder_or_path: Path, root: Path | None = None) -> CaptureReport:
    """The capture report of a scan store (or the file); a MetadataError when it cannot be
    read or does not match its schema.
    ``root``: the run folder it belongs to (default: the folder that holds it), which it
    may not leave through a link."""
    path = target(folder_or_path, CAPTURE_REPORT)
    return read_model(path, CaptureReport, SCHEMA, path.name, root)
