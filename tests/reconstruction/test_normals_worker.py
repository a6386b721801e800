"""Scan clouds' normals estimated in a worker process: the same normals, bit for bit, as
estimated in the run's own process; the caller's cloud untouched; clouds the worker did not
finish (closed, or busy) estimated here; a memo keeps a pending cloud until it is asked for."""

from __future__ import annotations

import numpy as np
import open3d as o3d

from recon_cli.reconstruction.crop import CropBox
from recon_cli.reconstruction.normals_worker import NormalsWorker, PendingCloud
from recon_cli.reconstruction.options import SurfaceOptions
from recon_cli.reconstruction.pipeline import CloudMemo
from recon_cli.reconstruction.surface import oriented_cloud

CAMERA = np.array([0.1, -0.2, 0.5])


def _cloud(seed: int, n: int = 20000):
    rng = np.random.default_rng(seed)
    angle, z = rng.uniform(0.0, np.pi, n), rng.uniform(0.0, 0.1, n)
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.c_[0.04 * np.cos(angle), 0.04 * np.sin(angle), z]))
    cloud.colors = o3d.utility.Vector3dVector(rng.uniform(0.0, 1.0, (n, 3)))
    return cloud


def _here(cloud, surface: SurfaceOptions) -> np.ndarray:
    return np.asarray(oriented_cloud(o3d.geometry.PointCloud(cloud), CAMERA, surface).normals)


def test_the_workers_normals_are_those_estimated_here_bit_for_bit():
    surface = SurfaceOptions()
    clouds = [_cloud(seed) for seed in range(4)]
    with NormalsWorker() as worker:
        pending = [worker.oriented(c, CAMERA, surface) for c in clouds]
        assert [len(p) for p in pending] == [len(c.points) for c in clouds]  # the points are there at once
        results = [p.result() for p in pending]
    for cloud, result in zip(clouds, results, strict=True):
        assert not cloud.has_normals()  # the caller's cloud is not changed
        assert np.array_equal(np.asarray(result.points), np.asarray(cloud.points))
        assert np.array_equal(np.asarray(result.colors), np.asarray(cloud.colors))
        assert np.array_equal(np.asarray(result.normals), _here(cloud, surface))
        # turned toward the camera
        assert np.all(np.sum(np.asarray(result.normals) * (CAMERA - np.asarray(result.points)), axis=1) >= 0)


def test_clouds_the_worker_did_not_finish_are_estimated_here():
    surface = SurfaceOptions()
    clouds = [_cloud(seed, 60000) for seed in range(5)]
    worker = NormalsWorker()
    pending = [worker.oriented(c, CAMERA, surface) for c in clouds]
    worker.close()  # before anything was asked for: queued work is cancelled
    for cloud, p in zip(clouds, pending, strict=True):
        assert np.array_equal(np.asarray(p.result().normals), _here(cloud, surface))
    empty = NormalsWorker().oriented(o3d.geometry.PointCloud(), CAMERA, surface)
    assert len(empty) == 0 and len(empty.result().points) == 0


def test_a_memo_keeps_a_pending_cloud_until_it_is_asked_for():
    surface = SurfaceOptions()
    box = CropBox(np.eye(4), (0.2, 0.2, 0.2))
    cloud = _cloud(9)
    memo = CloudMemo()
    with NormalsWorker() as worker:
        pending = worker.oriented(cloud, CAMERA, surface)
        assert isinstance(pending, PendingCloud)
        memo.put("scan_0000", np.eye(4), box, surface, pending)
        got = memo.get("scan_0000", np.eye(4), box, surface)
    assert np.array_equal(np.asarray(got.normals), _here(cloud, surface))
    assert memo.get("scan_0000", np.eye(4), box, SurfaceOptions(normal_radius=0.01)) is None  # other options
