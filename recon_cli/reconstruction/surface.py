"""From registered scans to a surface (thesis 2.4.3): merge, voxel down-sampling, outlier
removal, normals oriented toward the cameras that saw them, Poisson reconstruction and
density-based trimming of the surface Poisson extrapolated where no points were."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from recon_cli.errors import FileError, InputError
from recon_cli.outputs import atomic_write
from recon_cli.reconstruction.options import SurfaceOptions  # noqa: F401 (re-exported)


def oriented_cloud(cloud, camera_position: np.ndarray, options: SurfaceOptions):
    """Normals of one scan's cloud, turned toward the camera that took it (a scanned
    surface faces its camera, so this orientation is never ambiguous)."""
    import open3d as o3d

    if len(cloud.points) == 0:
        return cloud
    cloud.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=options.normal_radius, max_nn=30))
    cloud.orient_normals_towards_camera_location(np.asarray(camera_position, dtype=float))
    return cloud


#: voxels along one axis of a voxel grid (Open3D indexes them with a C int)
MAX_GRID_VOXELS = 2**31 - 1


def _check_extent(cloud, voxel: float) -> None:
    """Refuse (InputError) a cloud with non-finite points or one too large for a voxel grid
    of ``voxel``: scans placed by poses that are far off."""
    pts = np.asarray(cloud.points)
    if not len(pts):
        return
    lo, hi = pts.min(axis=0), pts.max(axis=0)  # NaN and infinities reach the bounds
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        raise InputError("the scans' points hold NaN or infinite coordinates",
                         hint="check the scans' poses and intrinsics")
    span = float(np.max(hi - lo))
    if span > voxel * MAX_GRID_VOXELS / 2:
        raise InputError(f"the scans' points span {span:.3g} m, too far for a voxel grid of {voxel:g} m",
                         hint="check the scans' poses (a pose far off places its scan far away)")


def fuse(clouds: Sequence, options: SurfaceOptions, cameras: Sequence[np.ndarray]):
    """Merge posed clouds, down-sample on a voxel grid (which averages points, colours and
    the unit directions toward the cameras that saw each voxel), remove outliers
    (options.outlier_filter) and estimate the normals of the fused cloud, each turned toward
    the cameras that saw its voxel (a scanned surface faces its cameras, so this orientation
    is never ambiguous). ``cameras``: each cloud's camera position, in the clouds' frame.

    Estimating the normals once on the fused cloud, not on every full-resolution scan, costs
    a tenth of the time, and their neighbourhood (``normal_radius`` on the voxel grid) is
    that of the surface, not of one scan's noise."""
    import open3d as o3d

    if len(cameras) != len(clouds):
        raise ValueError(f"{len(clouds)} clouds but {len(cameras)} camera positions")
    points = [np.asarray(c.points) for c in clouds]
    merged = o3d.geometry.PointCloud()
    if sum(len(p) for p in points) == 0:
        return merged
    merged.points = o3d.utility.Vector3dVector(np.vstack(points))
    toward = [np.asarray(cam, dtype=float).reshape(1, 3) - p for p, cam in zip(points, cameras, strict=True)]
    merged.normals = o3d.utility.Vector3dVector(
        np.vstack([t / np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-12) for t in toward]))
    seen = [c for c, p in zip(clouds, points, strict=True) if len(p)]
    if all(c.has_colors() for c in seen):
        merged.colors = o3d.utility.Vector3dVector(np.vstack([np.asarray(c.colors) for c in seen]))
    _check_extent(merged, options.voxel)
    fused = merged.voxel_down_sample(options.voxel)
    if options.outlier_filter == "radius" and len(fused.points) > options.outlier_min_points:
        # in units of the cloud's own spacing where it is sparser than the voxel (low image
        # resolution): a fixed radius would call every point of a sparse cloud isolated
        spacing = max(options.voxel, float(np.median(np.asarray(fused.compute_nearest_neighbor_distance()))))
        fused, _ = fused.remove_radius_outlier(options.outlier_min_points, options.outlier_radius * spacing)
    elif options.outlier_filter == "statistical" and len(fused.points) > options.outlier_neighbors:
        fused, _ = fused.remove_statistical_outlier(options.outlier_neighbors, options.outlier_std_ratio)
    if not len(fused.points):
        return fused
    toward_cameras = np.asarray(fused.normals).copy()
    fused.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=options.normal_radius, max_nn=30))
    normals = np.asarray(fused.normals)
    flip = np.einsum("ij,ij->i", normals, toward_cameras) < 0.0
    if np.any(flip):
        normals[flip] *= -1.0
        fused.normals = o3d.utility.Vector3dVector(normals)
    return fused.normalize_normals()


def poisson_mesh(cloud, options: SurfaceOptions):
    """Poisson surface of an oriented cloud, with the low-density (extrapolated) part
    removed. Returns (mesh, densities of the kept vertices)."""
    import open3d as o3d

    with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error):
        mesh, densities = o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(
            cloud, depth=options.poisson_depth)
    density = np.asarray(densities)
    if len(density) and options.density_quantile > 0:
        drop = density < np.quantile(density, options.density_quantile)
        mesh.remove_vertices_by_mask(drop)
        density = density[~drop]
    mesh.compute_vertex_normals()
    return mesh, density


def write_cloud(path: Path, cloud, transform: np.ndarray | None = None) -> Path:
    """Write a point cloud (PLY/PCD/...) atomically, optionally transformed first."""
    import open3d as o3d

    c = o3d.geometry.PointCloud(cloud)
    if transform is not None:
        c.transform(transform)
    # Open3D's stubs name a PathLike; its writers take the path as text
    return _atomic(path, lambda tmp: o3d.io.write_point_cloud(str(tmp), c))  # type: ignore[arg-type]


def write_mesh(path: Path, mesh, transform: np.ndarray | None = None) -> Path:
    """Write a triangle mesh atomically, optionally transformed first."""
    import open3d as o3d

    m = o3d.geometry.TriangleMesh(mesh)
    if transform is not None:
        m.transform(transform)
    # Open3D's stubs name a PathLike; its writers take the path as text
    return _atomic(path, lambda tmp: o3d.io.write_triangle_mesh(str(tmp), m))  # type: ignore[arg-type]


def _atomic(path: Path, write) -> Path:
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise FileError(f"cannot create {path.parent} ({exc.strerror})", hint="choose a writable folder") from None

    def checked(tmp: Path) -> None:
        if not write(tmp):
            raise FileError(f"cannot write {path}", hint="use a .ply, .pcd, .obj or .stl name in a writable folder")

    return atomic_write(path, checked)
