"""Oriented normals of scan clouds, estimated in a worker process beside the run.

Estimating a full-resolution scan's normals (Open3D's KD-tree and per-point fits, about
0.3-0.5 s) holds the interpreter lock, so a thread cannot overlap it with anything; a
second process can. :class:`NormalsWorker` hands a cropped cloud's points to one worker
process and returns a :class:`PendingCloud` at once; the caller goes on (the view planner
needs only the points, the registration at the end needs the normals). When the worker
already has work queued, or could not start, the normals are estimated here instead, so
neither side waits long for the other. The normals are the same, bit for bit, wherever they
are estimated: the same function on the same points (:func:`~recon_cli.reconstruction.
surface.oriented_cloud`).
"""

from __future__ import annotations

import multiprocessing
import signal
from concurrent.futures import CancelledError, Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from typing import Any

import numpy as np

from recon_cli.reconstruction.options import SurfaceOptions
from recon_cli.reconstruction.surface import oriented_cloud

#: jobs the worker may have queued before a cloud's normals are estimated here instead
QUEUED = 2


def estimated_normals(points: np.ndarray, camera_position: np.ndarray, surface: SurfaceOptions) -> np.ndarray:
    """The normals (n, 3) of ``points`` (n, 3), turned toward ``camera_position``."""
    import open3d as o3d

    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    oriented_cloud(cloud, camera_position, surface)
    return np.asarray(cloud.normals)


def _ready() -> bool:
    """In the worker, once: import what the jobs need, so that the first job does not wait for it."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the process group; the run decides
    import open3d  # noqa: F401

    return True


class PendingCloud:
    """A cropped cloud whose normals are being estimated: its points are there now
    (``len(pending)``), :meth:`result` gives the cloud with its normals."""

    def __init__(self, cloud: Any, camera_position: np.ndarray, surface: SurfaceOptions,
                 future: Future | None) -> None:
        self._cloud = cloud
        self._camera = np.asarray(camera_position, dtype=float)
        self._surface = surface
        self._future = future
        self._done = future is None

    def __len__(self) -> int:
        return len(self._cloud.points)

    @property
    def done(self) -> bool:
        return self._done or (self._future is not None and self._future.done())

    def result(self):
        """The cloud with its oriented normals (estimated here when the worker has died)."""
        import open3d as o3d

        if not self._done:
            try:
                normals = self._future.result() if self._future is not None else None
            except (BrokenProcessPool, CancelledError, OSError):
                normals = None
            if normals is None:
                oriented_cloud(self._cloud, self._camera, self._surface)
            else:
                self._cloud.normals = o3d.utility.Vector3dVector(normals)
            self._done, self._future = True, None
        return self._cloud


class NormalsWorker:
    """One worker process for the normals of a run's scan clouds (started at the first
    cloud; :meth:`close` ends it). Use as a context manager."""

    def __init__(self) -> None:
        self._pool: ProcessPoolExecutor | None = None
        self._pending: list[PendingCloud] = []
        self._broken = False

    def oriented(self, cloud, camera_position: np.ndarray, surface: SurfaceOptions) -> PendingCloud:
        """``cloud`` (not changed) with normals turned toward ``camera_position``: a copy
        whose normals come from the worker, or are estimated here when the worker is busy."""
        import open3d as o3d

        mine = o3d.geometry.PointCloud(cloud)
        if len(mine.points) == 0:
            return PendingCloud(mine, camera_position, surface, None)
        self._pending = [p for p in self._pending if not p.done]
        future = None
        if not self._broken and len(self._pending) < QUEUED:
            try:
                if self._pool is None:  # a fresh interpreter: nothing of this process (threads, GL contexts) copied
                    self._pool = ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn"))
                    self._pool.submit(_ready)
                future = self._pool.submit(estimated_normals, np.asarray(mine.points), np.asarray(camera_position,
                                                                                                  dtype=float), surface)
            except (BrokenProcessPool, RuntimeError, OSError):
                self._broken = True
        if future is None:
            oriented_cloud(mine, camera_position, surface)
        pending = PendingCloud(mine, camera_position, surface, future)
        if future is not None:
            self._pending.append(pending)
        return pending

    def close(self) -> None:
        """End the worker (the normals of a cloud it had not finished are estimated here
        when the cloud is asked for)."""
        if self._pool is not None:
            self._pending = []
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None

    def __enter__(self) -> NormalsWorker:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
