"""Where the jobs of a batch run: a local pool, or a Dask cluster.

Every job is its own ``recon`` process either way (:func:`recon_cli.batch.job.run_job`);
an executor only decides where and how many at once, and hands the results back as they
come.

* :class:`LocalPool`: ``--workers N`` jobs at once on this machine. The pool's workers are
  threads that start a job's process and wait for it: the isolation (memory, crashes,
  MuJoCo contexts) comes from the job's own process, so a second process per job (a
  ``ProcessPoolExecutor``) would only add start-up time.
* :class:`DaskExecutor`: the jobs as tasks of a Dask cluster, reached through its scheduler
  (``--scheduler tcp://host:8786`` or ``DASK_SCHEDULER_ADDRESS``), or a ``LocalCluster``
  started here (``--cluster local``, ``--workers`` processes with one thread each). A
  worker unpickles :func:`run_job` by reference, so recon must be installed on every
  worker; the job folders must be on a file system the workers share with this machine.
  A LocalCluster started here ends with the executor, on every way out (the batch's end,
  an exception, Ctrl-C, SIGTERM, SIGHUP): :meth:`DaskExecutor.close` closes it and then
  waits until every process that started below recon since (worker processes, the jobs
  they ran, multiprocessing's resource tracker) is gone, killing what is left.
"""

from __future__ import annotations

import os
import signal
import time
import uuid
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor, as_completed
from multiprocessing import resource_tracker
from pathlib import Path
from typing import TYPE_CHECKING, Any

from recon_cli import install_hint
from recon_cli.batch.job import TERM_GRACE_S, lost_job, run_job, stop_all
from recon_cli.batch.result import JobResult
from recon_cli.batch.spec import JobSpec
from recon_cli.errors import InputError, ReconError, UnknownNameError

if TYPE_CHECKING:
    from distributed import Future

INSTALL_HINT = install_hint("cluster")
#: [s] after SIGKILL, until the processes a LocalCluster left are gone
GONE_TIMEOUT_S = 10.0


class DaskUnavailable(InputError):
    """Dask was asked for but is not installed here."""

    def __init__(self, missing: str) -> None:
        super().__init__(f"Dask is not installed (no module {missing})",
                         hint=f"{INSTALL_HINT} (or pip install 'dask[distributed]')")


class SchedulerUnreachable(ReconError):
    """No Dask scheduler answers at the address given."""


class Executor:
    """Runs jobs; :meth:`results` yields each job's result when it is done."""

    description = ""
    workers = 1

    def results(self, tasks: list[tuple[JobSpec, Path]]) -> Iterator[JobResult]:
        raise NotImplementedError

    def interrupt(self) -> None:
        """Stop what runs (Ctrl-C): no new job starts, running jobs are stopped where possible."""

    def close(self) -> None:
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class LocalPool(Executor):
    def __init__(self, workers: int) -> None:
        self.workers = max(1, int(workers))
        self.description = f"local pool, {self.workers} worker{'s' if self.workers > 1 else ''}"
        self._pool = ThreadPoolExecutor(max_workers=self.workers, thread_name_prefix="recon-batch")

    def results(self, tasks):
        futures = {self._pool.submit(run_job, job, folder): (job, folder, time.time()) for job, folder in tasks}
        for fut in as_completed(futures):
            job, folder, started = futures[fut]
            try:
                yield fut.result()
            except Exception as exc:  # a bug in run_job itself: the job gets an error, the batch goes on
                yield lost_job(job, folder, f"the worker failed: {type(exc).__name__}: {exc}", started)

    def interrupt(self) -> None:
        self._pool.shutdown(wait=False, cancel_futures=True)
        stop_all()

    def close(self) -> None:
        self._pool.shutdown(wait=True, cancel_futures=True)


def _import_distributed():
    try:
        import distributed
    except ImportError as exc:
        raise DaskUnavailable(exc.name or "distributed") from None
    return distributed


def _descendants() -> set[int]:
    """The pids of every process below this one (psutil comes with distributed)."""
    import psutil  # type: ignore[import-untyped]  # (distributed's dependency; types-psutil is not needed)

    try:
        return {p.pid for p in psutil.Process().children(recursive=True)}
    except psutil.Error:
        return set()


def _stop_resource_tracker() -> None:
    """End multiprocessing's resource tracker, which the LocalCluster's worker processes
    started (it ignores SIGINT and SIGTERM and would end only after recon): closing its pipe
    makes it clean up and exit, and it is waited for. A no-op where it is not running or
    Python has no such call."""
    try:

        stop = getattr(resource_tracker._resource_tracker, "_stop", None)
        if stop is not None:
            stop()
    except Exception:  # noqa: BLE001 (a tracker that is gone already)
        pass


def _end_all(pids: set[int]) -> list[int]:
    """Wait until the processes ``pids`` are gone: TERM_GRACE_S for those still running
    (the workers' jobs stop as on SIGTERM), then SIGKILL to each one's process group (a
    job's group is its own) and to itself. Returns the pids still there after that
    (none, unless the system refuses to end them)."""
    import psutil  # type: ignore[import-untyped]  # (distributed's dependency; types-psutil is not needed)

    procs = []
    for pid in pids:
        try:
            procs.append(psutil.Process(pid))
        except psutil.NoSuchProcess:
            pass
    _, alive = psutil.wait_procs(procs, timeout=TERM_GRACE_S)
    for p in alive:
        try:
            if os.getpgid(p.pid) == p.pid:  # a group of its own (a job's): what it started goes too
                os.killpg(p.pid, signal.SIGKILL)
            p.kill()
        except (OSError, psutil.Error):
            pass
    _, alive = psutil.wait_procs(alive, timeout=GONE_TIMEOUT_S)
    return [p.pid for p in alive]


class DaskExecutor(Executor):
    """Jobs on a Dask cluster: an existing one (``address``) or a LocalCluster of
    ``workers`` processes (``address`` None), closed with the executor, its processes
    gone (:meth:`close`)."""

    def __init__(self, address: str | None = None, workers: int = 1, connect_timeout_s: float = 20.0) -> None:
        distributed = _import_distributed()
        self._cluster: Any = None
        self._client: Any = None
        self._before: set[int] | None = None  # the processes below recon before a LocalCluster started
        self._futures: list[Future] = []
        try:
            self._connect(distributed, address, workers, connect_timeout_s)
        except BaseException:  # a failed start, or Ctrl-C during it: nothing it started stays
            self.close()
            raise

    def _connect(self, distributed, address: str | None, workers: int, connect_timeout_s: float) -> None:
        if address:
            try:
                self._client = distributed.Client(address, timeout=connect_timeout_s)
            except (OSError, TimeoutError, ValueError) as exc:
                raise SchedulerUnreachable(f"no Dask scheduler answers at {address} ({type(exc).__name__}: {exc})",
                                           hint="start one (dask scheduler), check --scheduler / "
                                                "DASK_SCHEDULER_ADDRESS, or use --cluster local") from None
            where = f"Dask scheduler {address}"
        else:
            self._before = _descendants()
            self._cluster = distributed.LocalCluster(n_workers=max(1, workers), threads_per_worker=1, processes=True,
                                                     dashboard_address=":0")
            self._client = distributed.Client(self._cluster)
            where = f"Dask LocalCluster {self._cluster.scheduler_address}"
        info = self._client.scheduler_info()
        nthreads = [w.get("nthreads", 1) for w in info.get("workers", {}).values()]
        self.workers = sum(nthreads) or 0
        self.dashboard = getattr(self._client, "dashboard_link", None)
        self.description = f"{where}, {len(nthreads)} workers, {self.workers} threads"

    def results(self, tasks):
        distributed = _import_distributed()
        batch = uuid.uuid4().hex[:8]
        meta = {}
        for job, folder in tasks:
            fut = self._client.submit(run_job, job, folder, key=f"recon-batch-{batch}-{job.name}", pure=False)
            meta[fut.key] = (job, folder, time.time())
            self._futures.append(fut)
        for fut in distributed.as_completed(self._futures):
            job, folder, started = meta[fut.key]
            try:
                yield fut.result()
            except Exception as exc:  # KilledWorker (the worker died on every try), a lost connection
                yield lost_job(job, folder, f"Dask: {type(exc).__name__}: {exc}".strip(": "), started)

    def interrupt(self) -> None:
        try:
            self._client.cancel(self._futures)
        except Exception:  # noqa: BLE001 (the connection may be gone already)
            pass

    def close(self) -> None:
        """Close the client and a LocalCluster started here; then every process started
        below recon since the cluster's start is gone, killed if need be. A second Ctrl-C
        does not cut this short."""
        started = set() if self._before is None else _descendants() - self._before
        try:
            if self._client is not None:
                self._client.close()
        except Exception:  # noqa: BLE001 (a connection that is gone: the cluster is closed below)
            pass
        finally:
            self._client = None
            if self._before is not None:
                _finish(self._cluster, started | (_descendants() - self._before))
            self._cluster = None


def _finish(cluster, started: set[int]) -> None:
    """Close ``cluster`` (a LocalCluster) and end what it started. A Ctrl-C in between does
    not cut this short: the steps go on, then the interruption is raised."""
    interrupted: KeyboardInterrupt | None = None
    for step in ([cluster.close] if cluster is not None else []) + [_stop_resource_tracker]:
        try:
            step()
        except KeyboardInterrupt as exc:
            interrupted = interrupted or exc
        except Exception:  # noqa: BLE001 (a cluster that fails to close: its processes are ended below)
            pass
    while True:
        try:
            _end_all(started)
            break
        except KeyboardInterrupt as exc:  # each pass ends what it can: the next one has less to wait for
            interrupted = interrupted or exc
    if interrupted is not None:
        raise interrupted


def make_executor(workers: int, scheduler: str | None = None, cluster: str | None = None) -> Executor:
    """The executor of the command line: --scheduler, else --cluster local, else a local pool."""
    if scheduler and cluster:
        raise InputError("--scheduler and --cluster exclude each other",
                         hint="--scheduler ADDRESS for a running cluster, --cluster local to start one here")
    if scheduler:
        return DaskExecutor(address=scheduler)
    if cluster is not None:
        if cluster != "local":
            raise UnknownNameError("cluster", cluster, ["local"])
        return DaskExecutor(workers=workers)
    return LocalPool(workers)
