"""``run_report.json`` of ``recon run`` (schemas/run_report.schema.json): the script, how
the run ended, the outputs it wrote, the sequence optimizations and every command with its
status, time, message and what its handler measured.

An appending run keeps the earlier reports as ``run_report-1.json``, ``run_report-2.json``,
... (:data:`EARLIER`); :func:`read` reads any of them.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from recon_cli.runs.codec import REST, JsonValue
from recon_cli.runs.files import read_model, target, write_model

RUN_REPORT = "run_report.json"
EARLIER = "run_report-[0-9]*.json"
SCHEMA = "run_report.schema.json"


@dataclass(frozen=True)
class Command:
    """One command of the run; ``details``: what its handler measured (a move's planner,
    ``plan_time_s`` and ``trajectory_s``, a scan's ``points``, an evaluation's ``coverage``
    and ``std_mm``, ...)."""

    source: str  # file:line
    command: str
    status: str  # done | failed | skipped | planned | recorded | interrupted
    seconds: float = 0.0
    message: str = ""
    details: Mapping[str, JsonValue] = field(default_factory=dict, metadata=REST)

    @property
    def is_move(self) -> bool:
        """A planned move (its planning time or trajectory duration is reported)."""
        return "plan_time_s" in self.details or "trajectory_s" in self.details

    def number(self, name: str) -> float | None:
        """A measured number of the details (None: not reported)."""
        value = self.details.get(name)
        return float(value) if isinstance(value, int | float) and not isinstance(value, bool) else None

    @property
    def planner(self) -> str | None:
        value = self.details.get("planner")
        return value if isinstance(value, str) else None


@dataclass(frozen=True)
class Interruption:
    """What stopped the run (Ctrl-C, SIGTERM) and where."""

    signal: str
    reason: str
    command: str | None  # file:line of the command in progress
    scans_kept: int


@dataclass(frozen=True)
class SequenceOptimization:
    """One run of moves reordered by the sequence optimizer."""

    moves: int
    method: str  # ours | thesis
    ik_draws: int
    order: tuple[str, ...]
    planned_duration_s: float
    planning_requests: int
    script_order_lower_bound_s: float
    seconds: float


@dataclass(frozen=True)
class ScriptRunReport:
    """``run_report.json``."""

    script: str = ""
    name: str = ""
    dialect: str = ""
    on_failure: str | None = None  # skip | abort
    dry_run: bool = False
    backend: str | None = None
    seed: int | None = None
    seconds: float | None = None
    scans: int | None = None
    status: str = "unknown"  # done | failed | aborted | interrupted
    exit_code: int | None = None
    aborted: str | None = None  # the failed command that stopped the run
    interrupted: Interruption | None = None
    append: bool = False
    outputs: Mapping[str, str] = field(default_factory=dict)  # cloud, mesh, registration_report, export_...
    sequence_optimization: tuple[SequenceOptimization, ...] = ()
    commands: tuple[Command, ...] = ()

    @property
    def stopped(self) -> str | None:
        """Why the run ended early (aborted or interrupted), else None."""
        return (self.interrupted.reason if self.interrupted else None) or self.aborted

    @property
    def moves(self) -> tuple[Command, ...]:
        return tuple(c for c in self.commands if c.is_move)


def write(folder: Path, report: ScriptRunReport) -> Path:
    """``folder/run_report.json``."""
    return write_model(Path(folder) / RUN_REPORT, report)


def read(folder_or_path: Path, root: Path | None = None) -> ScriptRunReport:
    """The run report of a run folder (or the report file itself, e.g. ``run_report-1.json``);
    a MetadataError when it cannot be read or does not match its schema.
    ``root``: the run folder it belongs to (default: the folder that holds it), which it
    may not leave through a link."""
    path = target(folder_or_path, RUN_REPORT)
    return read_model(path, ScriptRunReport, SCHEMA, path.name, root)

