"""A batch run: the batch folder, resuming, the executor, each job's verdict on disk, and
the reports.

The batch folder::

    <out>/
        batch.json        the expanded jobs (what ran, with which arguments and bounds)
        jobs/<name>/      one folder per job (recon_cli.batch.job)
        junit.xml         one testcase per job
        summary.json      every job's result
        summary.md        a table for a CI job summary
        index.html        a page linking every job's report page, with its verdict and checks

A job is done when its ``result.json`` is written (atomically, by this process, after the
job's process ended). ``resume`` keeps every done job whose command, environment and bounds
are unchanged and runs the others again from an empty folder.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

from recon_cli.batch.executors import make_executor
from recon_cli.batch.job import allow_runs
from recon_cli.batch.reports import write_reports
from recon_cli.batch.result import BatchResult, JobResult
from recon_cli.batch.spec import BatchSpec, JobSpec
from recon_cli.console import write_json
from recon_cli.errors import FileError, ReconError
from recon_cli.inputs.jsonfile import load_json
from recon_cli.interrupts import signal_name
from recon_cli.outputs import OutputMode, claim_output, remove_inside

RESULT = "result.json"


@dataclass(frozen=True)
class BatchOptions:
    out: Path | None = None  # the batch folder (default runs/batch-<time>)
    workers: int = 1  # local pool size, or workers of --cluster local
    scheduler: str | None = None  # address of a running Dask scheduler
    cluster: str | None = None  # "local": start a Dask LocalCluster
    resume: bool = False
    junit: Path | None = None  # extra copies of the reports
    json: Path | None = None
    markdown: Path | None = None
    force: bool = False  # a used --out: remove what recon wrote there first (recon_cli.outputs)


def _folder(options: BatchOptions) -> Path:
    """The batch folder, claimed (recon_cli.outputs): new or empty, the folder of the batch to
    resume (no link anywhere in it), or with --force what recon wrote there removed first."""
    mode = OutputMode.of(options.resume, options.force, append_option="--resume")
    out = options.out
    if options.resume and out is None:
        raise FileError("--resume needs the folder of the batch to resume", hint="give it with --out")
    if out is not None and options.resume and not (out / "batch.json").is_file():
        raise FileError(f"{out} holds no batch to resume (no batch.json)", hint="run it without --resume first")

    def claim() -> Path:
        return claim_output(out, mode, command="batch", append="--resume to finish the batch in it").path

    if mode is OutputMode.FORCE and out is not None and out.is_dir() and not (out / ".lock").is_symlink():
        with _Lock(out):  # not while another batch runs in it
            return claim()
    return claim()


class _Lock:
    """One batch at a time in a folder (released by the kernel when the process dies)."""

    def __init__(self, folder: Path) -> None:
        self.path = folder / ".lock"
        self.file = None

    def __enter__(self):
        try:
            import fcntl
        except ImportError:  # not POSIX: no lock
            return self
        try:
            fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_NOFOLLOW, 0o666)
        except OSError as exc:
            raise FileError(f"cannot lock {self.path} ({'it is a link' if self.path.is_symlink() else exc.strerror})",
                            hint="remove it, or choose another folder with --out") from None
        self.file = os.fdopen(fd, "w")  # held for the batch
        try:
            fcntl.flock(self.file, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            self.file.close()
            raise FileError(f"another recon batch is running in {self.path.parent}",
                            hint="wait for it, or choose another folder with --out") from None
        return self

    def __exit__(self, *exc) -> None:
        if self.file is not None:
            self.file.close()


def fingerprint(job: JobSpec) -> dict:
    """What must be equal for --resume to keep a job's earlier result."""
    return {**job.fingerprint(), "expect": job.expect.to_dict(), "timeout_s": job.timeout_s}


def _done(job: JobSpec, folder: Path) -> JobResult | None:
    """The earlier result of ``job`` in ``folder`` if it is the same job, else None."""
    try:
        data = load_json(folder / RESULT, "job result", root=folder)
        result = JobResult.from_dict(data)
    except (ReconError, ValueError, KeyError, TypeError, AttributeError):
        return None
    if result.fingerprint != fingerprint(job):
        return None
    return replace(result, resumed=True)


def run_batch(spec: BatchSpec, options: BatchOptions,
              update: Callable[[str, int, int], None] | None = None,
              on_result: Callable[[JobResult, int, int], None] | None = None) -> BatchResult:
    """Run every job of ``spec`` (resume: those not done yet) and write the reports."""
    out = _folder(options)
    t0, started = time.monotonic(), time.time()
    with _Lock(out):
        write_json(out / "batch.json", {"name": spec.name, "sources": list(spec.sources),
                                        "jobs": [j.to_dict() for j in spec.jobs]})
        results: dict[str, JobResult] = {}
        todo: list[tuple[JobSpec, Path]] = []
        for job in spec.jobs:
            folder = out / "jobs" / job.name
            earlier = _done(job, folder) if options.resume else None
            if earlier is not None:
                results[job.name] = earlier
                continue
            remove_inside(out, Path("jobs") / job.name)  # a job that did not finish, or another of the same name
            todo.append((job, folder))
        total, done = len(spec.jobs), len(results)
        for r in results.values():
            if on_result is not None:
                on_result(r, done, total)
        if update is not None:
            update("jobs", done, total)
        executor_text, workers, interrupted = "nothing to run", 0, None
        by_name = {job.name: job for job, _ in todo}
        if todo:
            allow_runs()
            executor = make_executor(options.workers, options.scheduler, options.cluster)
            executor_text, workers = executor.description, executor.workers
            try:
                with executor:
                    try:
                        for r in executor.results(todo):
                            r = replace(r, fingerprint=fingerprint(by_name[r.name]))
                            folder = out / "jobs" / r.name  # also when the job ran on another machine
                            folder.mkdir(parents=True, exist_ok=True)
                            write_json(folder / RESULT, r.to_dict())
                            results[r.name] = r
                            done += 1
                            if update is not None:
                                update("jobs", done, total)
                            if on_result is not None:
                                on_result(r, done, total)
                    except KeyboardInterrupt as exc:  # Ctrl-C, or SIGTERM (recon_cli.interrupts)
                        interrupted = signal_name(exc)
                        executor.interrupt()
            except KeyboardInterrupt as exc:  # a second Ctrl-C while stopping
                interrupted = interrupted or signal_name(exc)
        ordered = tuple(results[j.name] for j in spec.jobs if j.name in results)
        pending = tuple(j.name for j in spec.jobs if j.name not in results)
        result = BatchResult(spec.name, out, ordered, pending, time.monotonic() - t0, executor_text, workers,
                             started, interrupted)
        reports = write_reports(result, {"junit": options.junit, "json": options.json,
                                         "markdown": options.markdown})
    return replace(result, reports=reports)
