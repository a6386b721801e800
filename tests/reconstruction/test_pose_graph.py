"""Pieces of the pose graph (reconstruction.pose_graph) on small synthetic clouds: overlap
counts, pair choice, the regularized point-to-plane ICP, normals of the down-sampled copies."""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np
import open3d as o3d
import pytest

from recon_cli.geometry.transforms import pose, pose_error, transform_points
from recon_cli.reconstruction.pose_graph import (
    IcpCloud,
    MultiwayOptions,
    correspondence_counts,
    prepare,
    regularized_icp,
    select_pairs,
)


def _cloud(points: np.ndarray, normals: np.ndarray | None = None):
    c = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    if normals is not None:
        c.normals = o3d.utility.Vector3dVector(normals)
    return c


def _box_corner(rng, n: int = 6000, size: float = 0.05):
    """Points and outward normals on three faces of a box corner (fixes all six degrees of
    freedom of a point-to-plane ICP)."""
    face = rng.integers(0, 3, n)
    uv = rng.uniform(0.0, size, (n, 2))
    points = np.zeros((n, 3))
    normals = np.zeros((n, 3))
    for k in range(3):
        m = face == k
        others = [a for a in range(3) if a != k]
        points[np.ix_(m, others)] = uv[m]
        normals[m, k] = -1.0
    return points, normals


def test_correspondence_counts_match_brute_force():
    rng = np.random.default_rng(0)
    clouds = [rng.uniform(0, 0.05, (300, 3)) + shift for shift in ([0, 0, 0], [0.03, 0, 0], [0.5, 0, 0])]
    distance = 0.004
    counts = correspondence_counts([_cloud(c) for c in clouds], distance)
    for i in range(3):
        for j in range(3):
            if i == j:
                continue
            near = lambda a, b: int((np.linalg.norm(a[:, None] - b[None], axis=2).min(axis=1) <= distance).sum())  # noqa: E731
            assert counts[i, j] == min(near(clouds[i], clouds[j]), near(clouds[j], clouds[i]))
    assert counts[0, 1] > 0 and counts[0, 2] == 0  # far apart: bounding boxes skip the search


def test_select_pairs_keeps_the_tree_and_caps_loop_closures():
    n = 6
    overlapping = ~np.eye(n, dtype=bool)
    share = np.array([[1.0 / (1 + abs(i - j)) for j in range(n)] for i in range(n)])  # neighbours overlap most
    tree = {(i, i + 1) for i in range(n - 1)}
    assert len(select_pairs(overlapping, share, tree, 0)) == n * (n - 1) // 2
    capped = select_pairs(overlapping, share, tree, 1)
    assert tree <= set(capped) and (0, 5) not in capped  # each scan's best partner: its neighbour
    two = select_pairs(overlapping, share, tree, 2)
    assert (0, 2) in two and (0, 5) not in two


@pytest.mark.parametrize("subset", [200, 100_000])
def test_regularized_icp_recovers_a_small_offset(subset):
    rng = np.random.default_rng(1)
    points, normals = _box_corner(rng)
    offset = pose(cv2.Rodrigues(np.radians([0.05, -0.03, 0.04]))[0], [0.0004, -0.0003, 0.0002])
    source = IcpCloud.of(_cloud(transform_points(offset, points), normals @ offset[:3, :3].T))
    target = IcpCloud.of(_cloud(points, normals))
    # a weak prior (the default one pulls a 5 cm corner back by a few hundredths of a degree)
    options = replace(MultiwayOptions(), icp_points=subset, prior_sigma=(0.05, 5.0))
    result = regularized_icp(source, target, options)
    dt, dr = pose_error(result.transformation @ offset, np.eye(4))
    assert dt < 1e-7 and np.degrees(dr) < 2e-5  # noise free: to nanometres
    assert result.fitness > 0.95 and result.inlier_rmse < 1e-5
    assert np.all(np.linalg.eigvalsh(result.information) > 0)


def test_regularized_icp_keeps_a_sliding_plane_in_place():
    """A plane fixes only its normal offset and two tilts: the slide along it (drift on noise
    for a plain ICP) stays at zero, held by the prior."""
    rng = np.random.default_rng(2)
    points = np.column_stack([rng.uniform(0, 0.05, (4000, 2)), np.zeros(4000)])
    normals = np.tile([0.0, 0.0, 1.0], (4000, 1))
    shift = pose(None, [0.0003, 0.0, 0.0002])  # along the plane and off it
    source = IcpCloud.of(_cloud(transform_points(shift, points), normals))
    target = IcpCloud.of(_cloud(points, normals))
    T = regularized_icp(source, target, MultiwayOptions()).transformation
    assert abs(T[2, 3] + 0.0002) < 2e-6  # the normal offset is corrected
    assert abs(T[0, 3]) < 1e-5  # the slide is not "corrected" either way


def test_prepare_averages_the_clouds_own_normals():
    rng = np.random.default_rng(3)
    points = rng.uniform(0, 0.01, (2000, 3))
    normals = np.tile([0.0, 0.6, 0.8], (2000, 1)) + rng.normal(0, 0.05, (2000, 3))
    cloud = _cloud(points, normals / np.linalg.norm(normals, axis=1, keepdims=True))
    down = np.asarray(prepare(cloud, 0.002, own_normals=True).normals)
    assert np.allclose(np.linalg.norm(down, axis=1), 1.0)
    assert np.mean(down @ [0.0, 0.6, 0.8]) > 0.99
    estimated = np.asarray(prepare(_cloud(points), 0.002).normals)  # no normals: estimated
    assert len(estimated) == len(down)
