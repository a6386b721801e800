"""Fusing registered clouds: the outlier filter drops isolated points and keeps whole faces."""

from __future__ import annotations

import numpy as np
import open3d as o3d
import pytest

from recon_cli.errors import InputError
from recon_cli.reconstruction.options import SurfaceOptions
from recon_cli.reconstruction.surface import fuse


def _box_scans(rng: np.random.Generator) -> list:
    """Two noisy 'scans' of the top (z = 30 mm) and one side of a 60 x 40 x 30 mm box, plus
    20 flying points each above it."""
    clouds = []
    for _ in range(2):
        top = np.c_[rng.uniform(0, 0.06, (20000, 1)), rng.uniform(0, 0.04, (20000, 1)),
                    0.0300 + rng.normal(0, 0.00005, (20000, 1))]
        side = np.c_[rng.uniform(0, 0.06, (20000, 1)), np.zeros((20000, 1)) + rng.normal(0, 0.0002, (20000, 1)),
                     rng.uniform(0, 0.03, (20000, 1))]
        flying = rng.uniform(-0.05, 0.1, (20, 3)) + np.array([0, 0, 0.08])
        clouds.append(o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.vstack([top, side, flying]))))
    return clouds


#: where the two 'scans' were taken from: in front of the side face (y = 0) and above the top
CAMERAS = [np.array([0.03, -0.3, 0.3]), np.array([0.03, -0.2, 0.4])]


def test_fused_normals_face_the_cameras_that_saw_them():
    """The normals are estimated on the fused cloud and turned toward the cameras of the
    points in each voxel: the top's up, the side's toward -y, also where the surface is seen
    at a slant."""
    fused = fuse(_box_scans(np.random.default_rng(0)), SurfaceOptions(), CAMERAS)
    p, n = np.asarray(fused.points), np.asarray(fused.normals)
    assert np.allclose(np.linalg.norm(n, axis=1), 1.0)
    inner = (p[:, 0] > 0.005) & (p[:, 0] < 0.055)  # away from the box's edges
    top = inner & (np.abs(p[:, 2] - 0.030) < 0.0006) & (p[:, 1] > 0.005) & (p[:, 1] < 0.035)
    side = inner & (np.abs(p[:, 1]) < 0.0006) & (p[:, 2] > 0.005) & (p[:, 2] < 0.025)
    assert top.sum() > 1000 and side.sum() > 1000
    assert np.all(n[top] @ np.array([0.0, 0.0, 1.0]) > 0.95)
    assert np.all(n[side] @ np.array([0.0, -1.0, 0.0]) > 0.95)
    with pytest.raises(ValueError, match="2 clouds but 1 camera positions"):
        fuse(_box_scans(np.random.default_rng(0)), SurfaceOptions(), CAMERAS[:1])


def test_radius_filter_drops_flying_points_and_keeps_the_faces():
    def counts(kind):
        p = np.asarray(fuse(_box_scans(np.random.default_rng(0)), SurfaceOptions(outlier_filter=kind),
                            CAMERAS).points)
        return np.sum(np.abs(p[:, 2] - 0.030) < 0.0006), np.sum(p[:, 2] > 0.035)

    top_none, flying_none = counts("none")
    top, flying = counts("radius")
    assert flying_none == 40 and flying == 0
    assert top == top_none > 0.97 * 60 * 40  # every 1 mm cell of the top face stays


def test_unknown_outlier_filter():
    with pytest.raises(InputError, match="outlier filter 'median' is not one of radius, statistical, none"):
        SurfaceOptions(outlier_filter="median")
