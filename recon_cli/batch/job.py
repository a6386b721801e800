"""One job of a batch: a ``recon`` process in its own folder, with a timeout, retries for
infrastructure failures only, and its verdict.

A job's folder::

    <batch>/jobs/<name>/
        output/        the command's --out (run folder, scan store, reports)
        log.txt        stdout and stderr of every attempt
        result.json    the verdict, written last by the batch (the "done" marker of --resume)

:func:`run_job` is what a worker executes (a thread of the local pool or a Dask worker);
it needs nothing but the job and the folder, and returns a :class:`JobResult` (picklable).

Retried: a process killed by a signal (the OOM killer's SIGKILL, a crash), stopped by
SIGTERM from outside (preemption), or a MemoryError; these say nothing about the job.
Not retried: exit codes 1, 2, 3, 4 (the job's own errors and failures), a timeout (it would
time out again), Ctrl-C.
"""

from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import threading
import time
from pathlib import Path

from recon_cli.batch.expectations import judge, measure
from recon_cli.batch.result import Attempt, JobResult, JobStatus
from recon_cli.batch.spec import JobSpec

TERM_GRACE_S = 10.0  # [s] between SIGTERM and SIGKILL of a job's process group
LOG_TAIL_LINES = 40
LOG_TAIL_CHARS = 6000

#: meaning of recon's exit codes (README, "Exit codes")
EXIT_MEANING = {1: "error before or outside the work", 2: "usage error", 3: "some commands failed",
                4: "aborted", 130: "interrupted (SIGINT)", 143: "stopped by SIGTERM"}


# ----------------------------------------------------------------------------- running processes
_RUNNING: dict[int, subprocess.Popen] = {}
_LOCK = threading.Lock()
_STOP = threading.Event()


def stop_all() -> None:
    """Stop every job process of this process (SIGTERM to its group, SIGKILL after the
    grace time) and start no new attempt: the batch was interrupted."""
    _STOP.set()
    with _LOCK:
        procs = list(_RUNNING.values())
    for p in procs:
        _signal_group(p, signal.SIGTERM)
    deadline = time.monotonic() + TERM_GRACE_S
    for p in procs:
        try:
            p.wait(max(0.0, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            _signal_group(p, signal.SIGKILL)


def allow_runs() -> None:
    """Undo :func:`stop_all` (a new batch in the same process)."""
    _STOP.clear()


def _signal_group(proc: subprocess.Popen, sig: int) -> None:
    try:
        os.killpg(proc.pid, sig)  # the job started its own session: its group is its pid
    except (ProcessLookupError, PermissionError):
        pass


def display_command(job: JobSpec, out: Path | None = None) -> tuple[str, ...]:
    """The job's command as a user would type it (``recon ...``; ``out``: its --out, default
    'output' in the job's folder)."""
    return ("recon", *job.command(out or Path("output"))[3:])


def _environment(job: JobSpec) -> dict[str, str]:
    env = dict(os.environ)
    env.setdefault("MUJOCO_GL", "egl")  # offscreen rendering: every simulated job needs a GL backend
    env.pop("RECON_PROGRESS", None)  # no progress bars in the logs
    env["PYTHONUNBUFFERED"] = "1"  # the log is complete up to a kill
    env.update(dict(job.env))
    return env


def _classify(code: int | None, log: Path) -> str | None:
    """Why an exit is an infrastructure failure (then it is retried), else None."""
    if code is None:
        return "no process"
    if code < 0:
        name = signal.Signals(-code).name if -code in signal.Signals._value2member_map_ else f"signal {-code}"
        return f"killed by {name}" + (" (out of memory?)" if -code == signal.SIGKILL else "")
    if code == 128 + signal.SIGKILL:
        return "killed by SIGKILL (out of memory?)"
    if code == 128 + signal.SIGTERM:
        return "stopped by SIGTERM from outside (preempted?)"
    if code == 1 and any(s in _tail(log, 10) for s in ("MemoryError", "std::bad_alloc", "Cannot allocate memory")):
        return "out of memory"
    return None


def _tail(log: Path, lines: int = LOG_TAIL_LINES) -> str:
    try:
        with open(log, "rb") as f:
            f.seek(0, os.SEEK_END)
            size = f.tell()
            f.seek(max(0, size - 64 * 1024))
            text = f.read().decode("utf-8", "replace")
    except OSError:
        return ""
    return "\n".join(text.splitlines()[-lines:])[-LOG_TAIL_CHARS:]


def _attempt(job: JobSpec, out: Path, log: Path, number: int) -> Attempt:
    python, _, module, *args = job.command(out)  # python -m ENTRY_MODULE ARGS...
    argv = [python, "-m", "recon_cli.batch.child", str(os.getpid()), module, *args]
    t0 = time.monotonic()
    with open(log, "ab") as f:
        f.write(f"$ {' '.join(display_command(job, out))}   # attempt {number}, {socket.gethostname()}, "
                f"{time.strftime('%Y-%m-%d %H:%M:%S')}\n".encode())
        f.flush()
        try:
            proc = subprocess.Popen(argv, cwd=job.cwd, env=_environment(job), stdin=subprocess.DEVNULL, stdout=f,
                                    stderr=subprocess.STDOUT, start_new_session=True)
        except OSError as exc:
            return Attempt(None, time.monotonic() - t0, infrastructure=f"could not start the process ({exc})")
        with _LOCK:
            _RUNNING[proc.pid] = proc
        timed_out = False
        try:
            try:
                code = proc.wait(job.timeout_s)
            except subprocess.TimeoutExpired:
                timed_out = True
                _signal_group(proc, signal.SIGTERM)
                try:
                    proc.wait(TERM_GRACE_S)
                except subprocess.TimeoutExpired:
                    _signal_group(proc, signal.SIGKILL)
                code = proc.wait()
            finally:
                _signal_group(proc, signal.SIGKILL)  # nothing the job started outlives it
        finally:
            with _LOCK:
                _RUNNING.pop(proc.pid, None)
        seconds = time.monotonic() - t0
        if timed_out:
            f.write(f"--- timed out after {job.timeout_s:g} s: process group killed\n".encode())
    if timed_out:
        return Attempt(code, seconds, timed_out=True)
    return Attempt(code, seconds, infrastructure=_classify(code, log))


def _last_error(log_tail: str) -> str:
    lines = [ln.strip() for ln in log_tail.splitlines() if ln.strip() and not ln.startswith(("$ ", "--- "))]
    for ln in reversed(lines):
        if ln.split(":", 1)[0] in ("error", "aborted", "interrupted", "robot stopped") or "Error" in ln:
            return ln[:300]
    return lines[-1][:300] if lines else ""


def run_job(job: JobSpec, folder: Path) -> JobResult:
    """Run ``job`` in ``folder`` (made if missing, its output/ and log replaced): attempts
    until one says something about the job or the retries are used up; then measure and
    judge. Never raises for a job's failure."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    out, log = folder / "output", folder / "log.txt"
    log.unlink(missing_ok=True)
    started = time.time()
    attempts: list[Attempt] = []
    for number in range(1, job.retries + 2):
        if _STOP.is_set():
            break
        if out.exists():
            shutil.rmtree(out)
        attempts.append(_attempt(job, out, log, number))
        a = attempts[-1]
        if a.infrastructure is None:
            break
        if number <= job.retries:
            with open(log, "ab") as f:
                f.write(f"--- attempt {number}: {a.infrastructure}; retrying\n".encode())
    last = attempts[-1] if attempts else Attempt(None, 0.0, infrastructure="the batch was stopped")
    tail = _tail(log)
    measured = measure(job, out, last.seconds)
    checks = judge(job.expect, measured)
    failed_checks = [c.describe() for c in checks if not c.passed]
    if last.timed_out:
        status, reason = JobStatus.TIMEOUT, f"timed out after {job.timeout_s:g} s (process group killed)"
    elif last.infrastructure is not None:
        tries = f" ({len(attempts)} attempts)" if len(attempts) > 1 else ""
        status, reason = JobStatus.ERROR, f"{last.infrastructure}{tries}"
    elif last.exit_code != 0:
        meaning = "" if last.exit_code is None else EXIT_MEANING.get(last.exit_code, "")
        detail = _last_error(tail)
        status = JobStatus.FAILED
        reason = f"exit code {last.exit_code}" + (f" ({meaning})" if meaning else "") + (f": {detail}" if detail
                                                                                       else "")
    elif measured.commands_ok is False:
        status, reason = JobStatus.FAILED, "some commands failed (run_report.json)"
    elif failed_checks:
        status, reason = JobStatus.FAILED, "; ".join(failed_checks)
    else:
        status, reason = JobStatus.PASSED, ""
    if status is JobStatus.FAILED and failed_checks and not reason.startswith(failed_checks[0]):
        reason += "; " + "; ".join(failed_checks)
    return JobResult(job.name, job.kind.value, status, reason, last.exit_code, last.seconds, tuple(attempts), measured,
                     checks, str(folder), display_command(job, out), tail, socket.gethostname(), started,
                     job.fingerprint())


def lost_job(job: JobSpec, folder: Path, message: str, started: float) -> JobResult:
    """The result of a job whose worker failed (an exception instead of a result)."""
    folder = Path(folder)
    attempt = Attempt(None, 0.0, infrastructure=message)
    measured = measure(job, folder / "output", 0.0)
    return JobResult(job.name, job.kind.value, JobStatus.ERROR, message, None, 0.0, (attempt,), measured,
                     judge(job.expect, measured), str(folder), display_command(job, folder / "output"),
                     _tail(folder / "log.txt"), "", started, job.fingerprint())
