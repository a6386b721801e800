"""What a batch produced: each job's attempts and verdict, and the batch's counts and exit
code. Plain values (picklable: a Dask worker sends a :class:`JobResult` back), read by the
runner, the reports and the index page alike."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path

from recon_cli.batch.expectations import Check, Measured
from recon_cli.interrupts import exit_code as interrupted_exit_code

EXIT_FAILED = 3  # like recon run: the batch finished, but some jobs failed


class JobStatus(StrEnum):
    PASSED = "passed"  # the command succeeded and every expectation holds
    FAILED = "failed"  # the command failed, or an expectation does not hold
    TIMEOUT = "timeout"  # the job ran longer than its timeout and was killed
    ERROR = "error"  # an infrastructure failure on every attempt (killed, lost worker, no process)


@dataclass(frozen=True)
class Attempt:
    exit_code: int | None  # None: no process (it could not be started, or the worker was lost)
    seconds: float  # [s] wall time
    timed_out: bool = False
    infrastructure: str | None = None  # why this attempt says nothing about the job (then it is retried)


@dataclass(frozen=True)
class JobResult:
    name: str
    kind: str
    status: JobStatus
    reason: str  # one line: why it failed ("" when it passed)
    exit_code: int | None
    wall_s: float  # [s] of the last attempt
    attempts: tuple[Attempt, ...]
    measured: Measured
    checks: tuple[Check, ...]
    folder: str
    command: tuple[str, ...]  # as the user would type it
    log_tail: str
    host: str
    started: float  # [s since the epoch]
    fingerprint: dict = dataclasses.field(default_factory=dict)
    resumed: bool = False  # read back from an earlier run of the batch (--resume)

    @property
    def passed(self) -> bool:
        return self.status is JobStatus.PASSED

    def to_dict(self) -> dict:
        d = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        d["status"] = self.status.value
        d["attempts"] = [dataclasses.asdict(a) for a in self.attempts]
        d["measured"] = self.measured.to_dict()
        d["checks"] = [c.to_dict() for c in self.checks]
        d["command"] = list(self.command)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> JobResult:
        return cls(name=d["name"], kind=d["kind"], status=JobStatus(d["status"]), reason=d.get("reason", ""),
                   exit_code=d.get("exit_code"), wall_s=float(d.get("wall_s", 0.0)),
                   attempts=tuple(Attempt(**a) for a in d.get("attempts", [])),
                   measured=Measured(**d.get("measured", {})),
                   checks=tuple(Check(c["key"], c["bound"], c["value"], c["passed"]) for c in d.get("checks", [])),
                   folder=d.get("folder", ""), command=tuple(d.get("command", ())), log_tail=d.get("log_tail", ""),
                   host=d.get("host", ""), started=float(d.get("started", 0.0)),
                   fingerprint=d.get("fingerprint", {}), resumed=bool(d.get("resumed", False)))


def measured_text(r: JobResult) -> str:
    """What a job measured, in one line ('coverage 61.20 %, std 0.210 mm'; '-': nothing)."""
    m = r.measured
    parts = []
    if m.coverage is not None:
        parts.append(f"coverage {m.coverage:.2f} %")
    if m.std is not None:
        parts.append(f"std {m.std:.3f} mm")
    if m.pose_error is not None:
        parts.append(f"pose {m.pose_error:.3f} mm")
    if m.planning_failures is not None:
        parts.append(f"planning failures {m.planning_failures}")
    return ", ".join(parts) or "-"


@dataclass(frozen=True)
class BatchResult:
    name: str
    folder: Path
    jobs: tuple[JobResult, ...]  # in the order of the batch; only the jobs that finished
    pending: tuple[str, ...]  # jobs that did not finish (the batch was interrupted)
    wall_s: float  # [s]
    executor: str
    workers: int
    started: float  # [s since the epoch]
    interrupted: str | None = None  # the signal that stopped the batch (SIGINT, SIGTERM)
    reports: dict[str, Path] = field(default_factory=dict)

    @property
    def counts(self) -> dict[str, int]:
        out = {s.value: 0 for s in JobStatus}
        for r in self.jobs:
            out[r.status.value] += 1
        return out

    @property
    def failed(self) -> list[JobResult]:
        return [r for r in self.jobs if not r.passed]

    @property
    def exit_code(self) -> int:
        if self.interrupted:
            return interrupted_exit_code(self.interrupted)
        return EXIT_FAILED if self.failed or self.pending else 0
