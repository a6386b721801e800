"""recon batch --cluster local: the LocalCluster and every process it started (worker
processes, the jobs they run, multiprocessing's resource tracker) are gone when recon batch
has ended, on every way out: a batch that ends, a job that fails or times out, an exception
while the executor is open, and Ctrl-C, SIGTERM and SIGHUP in the middle of a job.

The batches run as their own ``python -m recon_cli batch`` process; the test records the
processes below it while it runs (psutil, which distributed brings) and checks them the
moment it has exited. Waits poll with generous bounds (a loaded 2-core machine).
"""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

distributed = pytest.importorskip("distributed", reason="Dask is an optional extra: pip install 'recon-scan[cluster]'")
psutil = pytest.importorskip("psutil", reason="distributed brings psutil")

from recon_cli.batch.executors import DaskExecutor  # noqa: E402

pytestmark = pytest.mark.slow

QUICK = """\
jobs:
  - {name: first, validate: smoke.xml}
  - {name: second, validate: smoke.xml}
"""

FAILING = """\
jobs:
  - {name: broken, validate: bad.xml}        # the job's recon ends with an error (exit 1)
  - name: slow                               # killed at its timeout
    capture: {object: bottle, resolution: 0.1}
    timeout_s: 1
"""

LONG = """\
jobs:
  - {name: a, autoscan: {scans: 6, resolution: 0.1, pictures: false}}
  - {name: b, autoscan: {scans: 6, resolution: 0.1, pictures: false}}
"""

SMOKE = Path(__file__).resolve().parents[1] / "scripts_xml" / "smoke.xml"


def _reset_signals() -> None:  # runs in the child: stop signals as in a terminal, whatever pytest inherited
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, signal.SIG_DFL)


def _running(p: psutil.Process) -> bool:
    try:
        return p.is_running() and p.status() != psutil.STATUS_ZOMBIE
    except psutil.NoSuchProcess:
        return False


class Batch:
    """``recon batch FILE --cluster local --workers 2`` as a process, its descendants recorded."""

    def __init__(self, tmp_path: Path, text: str) -> None:
        (tmp_path / "smoke.xml").write_text(SMOKE.read_text())
        (tmp_path / "bad.xml").write_text("<script>\n  <nonsense/>\n</script>\n")
        path = tmp_path / "batch.yaml"
        path.write_text(text)
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "recon_cli", "batch", str(path), "--cluster", "local", "--workers", "2",
             "--out", str(tmp_path / "out")],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, preexec_fn=_reset_signals)
        self.seen: dict[int, tuple[psutil.Process, str]] = {}

    def watch(self) -> None:
        try:
            kids = psutil.Process(self.proc.pid).children(recursive=True)
        except psutil.NoSuchProcess:
            return
        for k in kids:
            if k.pid not in self.seen:
                try:
                    self.seen[k.pid] = (k, " ".join(k.cmdline()))
                except psutil.Error:
                    pass

    def jobs_running(self) -> bool:
        return any("recon_cli.batch.child" in cmd and _running(p) for p, cmd in self.seen.values())

    def run(self, until=None, timeout: float = 600.0) -> bool:
        """Watch until the batch exits, or until ``until()`` holds (then True)."""
        deadline = time.monotonic() + timeout
        while self.proc.poll() is None and time.monotonic() < deadline:
            self.watch()
            if until is not None and until():
                return True
            time.sleep(0.05)
        return False

    def finish(self, timeout: float = 180.0) -> tuple[int | None, str]:
        """Exit code and output once the batch has exited; the processes left are checked then."""
        deadline = time.monotonic() + timeout
        while self.proc.poll() is None and time.monotonic() < deadline:
            self.watch()
            time.sleep(0.05)
        if self.proc.poll() is None:
            return None, ""
        self.left = [f"{pid}: {cmd[:120]}" for pid, (p, cmd) in self.seen.items() if _running(p)]
        return self.proc.returncode, self.proc.stdout.read().decode(errors="replace")

    def cleanup(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()
        for p, _ in self.seen.values():
            try:
                p.kill()
            except psutil.Error:
                pass

    def workers_seen(self) -> int:
        return sum("multiprocessing.spawn" in cmd for _, cmd in self.seen.values())


@pytest.fixture(autouse=True)
def _environment(monkeypatch):
    monkeypatch.setenv("MUJOCO_GL", "egl")
    monkeypatch.delenv("DASK_SCHEDULER_ADDRESS", raising=False)


def test_a_batch_that_ends_leaves_no_process(tmp_path):
    b = Batch(tmp_path, QUICK)
    try:
        b.run()
        code, out = b.finish()
    finally:
        b.cleanup()
    assert code == 0, out
    assert "Dask LocalCluster" in out and b.workers_seen() == 2
    assert not b.left, f"processes outlived recon batch: {b.left}"


def test_failing_jobs_leave_no_process(tmp_path):
    b = Batch(tmp_path, FAILING)
    try:
        b.run()
        code, out = b.finish()
    finally:
        b.cleanup()
    assert code == 3, out
    assert "timed out after 1 s" in out and "exit code 1" in out
    assert b.workers_seen() == 2
    assert not b.left, f"processes outlived recon batch: {b.left}"


@pytest.mark.parametrize("sig, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143), (signal.SIGHUP, 129)])
def test_a_stopped_batch_leaves_no_process(tmp_path, sig, code):
    b = Batch(tmp_path, LONG)
    try:
        assert b.run(until=b.jobs_running), "no job started"
        b.proc.send_signal(sig)
        exit_code, out = b.finish()
    finally:
        b.cleanup()
    assert exit_code == code, out
    assert f"interrupted by {signal.Signals(sig).name}" in out
    assert b.workers_seen() == 2
    assert not b.left, f"processes outlived recon batch: {b.left}"


def test_an_exception_with_the_executor_open_closes_the_cluster():
    before = {p.pid for p in psutil.Process().children(recursive=True)}
    started: list[psutil.Process] = []
    with pytest.raises(RuntimeError, match="a bug"):
        with DaskExecutor(workers=1) as executor:
            assert "Dask LocalCluster" in executor.description
            started = [p for p in psutil.Process().children(recursive=True) if p.pid not in before]
            raise RuntimeError("a bug in the batch loop")
    assert started, "the LocalCluster started no process"
    left = [p.pid for p in started if _running(p)]
    assert not left, f"processes of the LocalCluster outlived it: {left}"
