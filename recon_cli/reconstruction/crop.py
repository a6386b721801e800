"""Cropping a scan to the object (thesis 4.2): keep the points inside the object's bounding
box and above its support plane, which removes the table and the marker board."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from recon_cli.geometry.transforms import invert, transform_points
from recon_cli.randomness import open3d_draws


@dataclass(frozen=True)
class CropBox:
    """An oriented box: frame_T_box places the box (centre, axes) in the frame the points are
    given in; size is the full edge lengths [m]. ``support_margin`` [m] drops the points this
    close above the bottom face (the table the object stands on: measured table points
    scatter around it by the sensor noise)."""

    frame_T_box: np.ndarray
    size: tuple[float, float, float]
    support_margin: float = 0.0015

    def inside(self, points: np.ndarray) -> np.ndarray:
        local = transform_points(invert(self.frame_T_box), points)
        half = np.asarray(self.size) / 2.0
        ok = np.all(np.abs(local) <= half, axis=1)
        return ok & (local[:, 2] >= -half[2] + self.support_margin)

    def moved(self, new_T_frame: np.ndarray) -> CropBox:
        """The same box expressed in another frame."""
        return CropBox(new_T_frame @ self.frame_T_box, self.size, self.support_margin)


#: the support plane's points lie within this many noise standard deviations of it
PLANE_NOISE_SIGMAS = 4.0
#: [m] the points within this distance of the support plane measure its noise
PLANE_NOISE_WINDOW = 0.004
PLANE_SLAB = 0.006  # [m] above the box's bottom face, where crop_cloud looks for the support plane
#: the fixed seed of the support plane's RANSAC: a scan is cropped alike in every run
PLANE_RANSAC_SEED = 0


def box_pixels(box: CropBox, camera_T_frame: np.ndarray, intrinsics,
               plane_slab: float = PLANE_SLAB) -> tuple[int, int, int, int] | None:
    """Image rectangle (u0, v0, u1, v1; u1, v1 exclusive) of a pinhole camera (``intrinsics``,
    placed by ``camera_T_frame`` in the box's frame) outside which crop_cloud keeps no point:
    the projection of the box grown by ``plane_slab`` in z, plus a pixel. None when the box
    reaches behind the camera (no rectangle holds it) or its projection is not finite."""
    half = np.asarray(box.size) / 2.0 + np.array([0.0, 0.0, plane_slab])
    signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=float)
    corners = transform_points(camera_T_frame @ box.frame_T_box, signs * half)  # (8, 3) camera frame
    if np.any(corners[:, 2] <= 1e-6):
        return None
    u = corners[:, 0] / corners[:, 2] * intrinsics.fx + intrinsics.cx
    v = corners[:, 1] / corners[:, 2] * intrinsics.fy + intrinsics.cy
    if not (np.all(np.isfinite(u)) and np.all(np.isfinite(v))):
        return None
    u0 = int(np.clip(np.floor(u.min()) - 1, 0, intrinsics.width))
    v0 = int(np.clip(np.floor(v.min()) - 1, 0, intrinsics.height))
    u1 = int(np.clip(np.ceil(u.max()) + 2, 0, intrinsics.width))
    v1 = int(np.clip(np.ceil(v.max()) + 2, 0, intrinsics.height))
    return u0, v0, max(u1, u0), max(v1, v0)


def crop_cloud(cloud, box: CropBox, plane_slab: float = PLANE_SLAB, plane_tolerance: float = 0.0015):
    """The Open3D cloud's points inside the box (a new cloud), without the support surface.

    A scan placed with a slightly wrong pose (real global registration) lifts table points
    above the box's bottom face; so the support plane is also found in the data: RANSAC on
    the points within ``plane_slab`` of the bottom face, and the points within
    ``plane_tolerance`` of (or below) a plane found there that is nearly parallel to the
    bottom face are removed. A sensor noisier than that tolerance (a stereo camera seeing the
    table obliquely) scatters table points farther: the tolerance grows to
    :data:`PLANE_NOISE_SIGMAS` times the noise measured on the plane itself (its points'
    robust standard deviation about it)."""
    pts = np.asarray(cloud.points)
    local = transform_points(invert(box.frame_T_box), pts)
    half = np.asarray(box.size) / 2.0
    inside = np.all(np.abs(local) <= half + np.array([0, 0, plane_slab]), axis=1)
    keep = inside & (local[:, 2] >= -half[2] + box.support_margin)
    slab = inside & (local[:, 2] < -half[2] + plane_slab)
    if slab.sum() >= 200:
        import open3d as o3d


        sub = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(local[slab]))
        # on one thread with a fixed seed the planes RANSAC tries are fixed: a scan is cropped
        # the same way in every run and whatever ran before
        with open3d_draws(PLANE_RANSAC_SEED, single_thread=True):
            plane, inliers = sub.segment_plane(plane_tolerance / 2.0, 3, 200)
        n = np.asarray(plane[:3])
        if len(inliers) >= 100 and abs(n[2]) > np.cos(np.radians(5.0)):
            a, b, c, d = (v / np.linalg.norm(n) * np.sign(n[2]) for v in plane)
            height = local @ np.array([a, b, c]) + d  # above the plane (+z side of the box)
            on_plane = height[slab][np.abs(height[slab]) < PLANE_NOISE_WINDOW]
            sigma = 1.4826 * float(np.median(np.abs(on_plane))) if len(on_plane) >= 100 else 0.0
            tolerance = max(plane_tolerance, PLANE_NOISE_SIGMAS * sigma)
            keep = inside & (height > tolerance) & (local[:, 2] <= half[2])
    return cloud.select_by_index(np.nonzero(keep)[0])
