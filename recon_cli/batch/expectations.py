"""Pass criteria of a job: what its reports measured, and the checks against its bounds.

What each kind of job measures (read from the files the command wrote into its folder):

| metric | ``recon run`` | ``recon autoscan`` | ``recon capture`` |
| --- | --- | --- | --- |
| coverage [%] | last ``<evaluate>`` of run_report.json | coverage_1mm of autoscan_report.json | - |
| std [mm] | its std_mm | accuracy.std_mm | - |
| pose error [mm] | pose_error_mean.final of the registration report | the same of reconstruction/report.json | - |
| planning failures | failed ``move ...`` commands | infeasible_views | views without a scan |

The reports are read through :mod:`recon_cli.runs`; one that cannot be read measures
nothing. Wall time [s] is the job's own, measured around its process. A metric that a job's
outputs do not hold (a script without ``<evaluate>``) fails its check as "not measured".
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TypeVar

from recon_cli.batch.spec import LABELS, METRICS, Expectations, JobKind, JobSpec
from recon_cli.errors import ReconError
from recon_cli.runs import autoscan, register, script_run

T = TypeVar("T")


@dataclass(frozen=True)
class Measured:
    """What a job's reports say. None: not measured."""

    coverage: float | None = None  # [%] of the reference surface within 1 mm
    std: float | None = None  # [mm] std of the fused cloud's signed distances
    pose_error: float | None = None  # [mm] mean final camera pose error against the truth
    planning_failures: int | None = None
    wall_time: float | None = None  # [s]
    scans: int | None = None
    commands_ok: bool | None = None  # run: the report says every command did its work

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True)
class Check:
    """One bound of a job against what it measured."""

    key: str  # the expectation, e.g. "min_coverage_pct"
    bound: float
    value: float | None  # None: not measured
    passed: bool

    @property
    def unit(self) -> str:
        return METRICS[self.key][1]

    def describe(self) -> str:
        """'coverage 39.8 % < 60 %' (failed) or 'coverage 61.2 % >= 60 %' (passed)."""
        metric, unit, at_least = METRICS[self.key]
        metric = LABELS[metric]
        u = f" {unit}" if unit else ""
        if self.value is None:
            return f"{metric} not measured (expected {'>=' if at_least else '<='} {self.bound:g}{u})"
        op = (">=" if self.passed else "<") if at_least else ("<=" if self.passed else ">")
        return f"{metric} {_fmt(self.value)}{u} {op} {self.bound:g}{u}"

    def to_dict(self) -> dict:
        return {"key": self.key, "bound": self.bound, "value": self.value, "passed": self.passed,
                "unit": self.unit, "text": self.describe()}


def _fmt(value: float) -> str:
    return f"{value:d}" if isinstance(value, int) else f"{value:.4g}" if abs(value) < 1000 else f"{value:.1f}"


def _read(reader: Callable[[Path], T], path: Path) -> T | None:
    """A report read through :mod:`recon_cli.runs`, or None when it cannot be read."""

    try:
        return reader(Path(path))
    except ReconError:
        return None


def _pose_error(path: Path | None) -> float | None:
    """The mean final pose error [mm] of a registration report."""

    report = None if path is None else _read(register.read, path)
    mean = None if report is None else report.pose_error_mean
    return None if mean is None or mean.final is None else mean.final.translation_mm


def measure(job: JobSpec, out: Path, wall_time: float) -> Measured:
    """What the outputs of ``job`` in ``out`` (its recon output folder) say."""

    out = Path(out)
    if job.kind is JobKind.RUN:
        run = _read(script_run.read, out / script_run.RUN_REPORT)
        if run is None:
            return Measured(wall_time=wall_time)
        evaluation = next((c for c in reversed(run.commands) if "coverage" in c.details and c.status == "done"), None)
        failures = sum(1 for c in run.commands if c.status == "failed" and c.command.startswith("move"))
        reg = run.outputs.get("registration_report")
        coverage = None if evaluation is None else evaluation.number("coverage")
        return Measured(coverage=None if coverage is None else coverage * 100,
                        std=None if evaluation is None else evaluation.number("std_mm"),
                        pose_error=_pose_error(Path(reg) if reg else None), planning_failures=failures,
                        wall_time=wall_time, scans=run.scans, commands_ok=run.status == "done")
    if job.kind is JobKind.AUTOSCAN:
        report = _read(autoscan.read, out / autoscan.AUTOSCAN_REPORT)
        if report is None:
            return Measured(wall_time=wall_time)
        coverage = report.coverage_1mm
        return Measured(coverage=None if coverage is None else coverage * 100,
                        std=None if report.accuracy is None else report.accuracy.std_mm,
                        pose_error=_pose_error(out / "reconstruction" / "report.json"),
                        planning_failures=report.infeasible_views, wall_time=wall_time, scans=report.scans)
    if job.kind is JobKind.CAPTURE:
        scans = sum(1 for p in out.glob("scan_*") if (p / "scan.json").is_file()) if out.is_dir() else 0
        return Measured(planning_failures=max(0, (job.views or 0) - scans), wall_time=wall_time, scans=scans)
    return Measured(wall_time=wall_time)


def judge(expect: Expectations, measured: Measured) -> tuple[Check, ...]:
    """Every bound of ``expect`` checked against ``measured``."""
    checks = []
    for key, bound in expect.items():
        metric, _, at_least = METRICS[key]
        value = getattr(measured, metric)
        ok = value is not None and (value >= bound if at_least else value <= bound)
        checks.append(Check(key, bound, value, ok))
    return tuple(checks)
