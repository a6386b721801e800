"""Cropping a scan to the object box: back-projecting only the image rectangle where the box
can appear gives exactly the points of the whole image cropped."""

from __future__ import annotations

import numpy as np
import pytest

from recon_cli.geometry.transforms import invert, pose, rot_x
from recon_cli.perception.camera_model import Intrinsics
from recon_cli.reconstruction.crop import CropBox, box_pixels, crop_cloud
from recon_cli.reconstruction.pipeline import in_box_pixels
from recon_cli.reconstruction.scan_store import Scan

K = Intrinsics(160, 120, 140.0, 140.0, 79.5, 59.5)


def _scan(rng) -> Scan:
    depth = rng.uniform(0.5, 0.7, size=(K.height, K.width))
    depth[rng.uniform(size=depth.shape) < 0.1] = 0.0  # no return
    color = rng.integers(0, 255, size=(K.height, K.width, 3), dtype=np.uint8)
    return Scan(0, color, depth, K, {}, np.eye(4))


@pytest.mark.parametrize("box_centre", [(0.0, 0.0, 0.6), (0.08, -0.05, 0.55), (0.3, 0.0, 0.6)])  # last: at the edge
def test_cut_scan_crops_to_the_same_points(box_centre):
    rng = np.random.default_rng(0)
    scan = _scan(rng)
    marker_T_camera = pose(rot_x(0.3), (0.01, 0.02, -0.03))
    box = CropBox(marker_T_camera @ pose(rot_x(-0.2), box_centre), (0.12, 0.1, 0.15))
    whole = crop_cloud(scan.to_open3d_cloud(marker_T_camera), box)
    cut = in_box_pixels(scan, box, marker_T_camera)
    assert cut.depth.size < scan.depth.size / 4
    part = crop_cloud(cut.to_open3d_cloud(marker_T_camera), box)
    assert len(whole.points) == len(part.points) > 100
    assert np.allclose(np.asarray(whole.points), np.asarray(part.points), atol=1e-12)
    assert np.array_equal(np.asarray(whole.colors), np.asarray(part.colors))


def test_box_behind_the_camera_has_no_rectangle():
    box = CropBox(pose(None, (0.0, 0.0, -0.5)), (0.1, 0.1, 0.1))
    assert box_pixels(box, np.eye(4), K) is None
    assert box_pixels(box, invert(pose(None, (0.0, 0.0, -1.0))), K) is not None


def test_support_plane_removal_repeats_exactly():
    """The support plane is found by Open3D's RANSAC, which draws its samples from several
    threads; crop_cloud runs it on one, so the same cloud always loses the same points."""
    import open3d as o3d

    rng = np.random.default_rng(1)
    table = np.c_[rng.uniform(-0.1, 0.1, (6000, 2)), rng.normal(0.0, 0.0007, 6000)]
    table[:900, 2] += rng.uniform(0.0, 0.01, 900)  # clutter above the table
    body = np.c_[rng.uniform(-0.03, 0.03, (3000, 2)), rng.uniform(0.0, 0.08, 3000)]
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.vstack([table, body])))
    box = CropBox(pose(np.eye(3), (0.0, 0.0, 0.05)), (0.2, 0.2, 0.1))
    kept = {tuple(np.round(np.asarray(crop_cloud(cloud, box).points).sum(axis=0), 12)) for _ in range(15)}
    assert len(kept) == 1
    assert o3d.utility.get_max_threads() >= 1  # Open3D's own thread count is restored
