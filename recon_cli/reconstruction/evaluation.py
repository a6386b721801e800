"""Accuracy and completeness of a reconstruction against a reference mesh (thesis 5.4,
what CloudCompare did there).

- Signed distance of every reconstructed point to the reference surface: the distance to
  the closest point of the mesh, positive on the side the closest triangle's normal points
  to (outside). Works on meshes that are not watertight.
- Coverage: the reference surface sampled uniformly; a sample is covered when a
  reconstructed point lies within ``tolerance`` of it. Optionally restricted to the samples
  some camera could see (in its field of view and range, facing it, not occluded by the
  object itself): "coverage of the visible surface".
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from recon_cli.outputs import atomic_write
from recon_cli.perception.camera_model import Intrinsics
from recon_cli.randomness import open3d_draws


@dataclass(frozen=True)
class CameraView:
    """A camera that looked at the object: pose (OpenCV axes), intrinsics, range [m]."""

    world_T_camera: np.ndarray
    intrinsics: Intrinsics
    near: float
    far: float
    max_incidence: float = np.radians(80.0)


@dataclass(frozen=True)
class Evaluation:
    points: int
    mean: float  # [m] signed distance
    std: float
    rms: float
    median_abs: float
    within: dict[str, float]  # "±0.5 mm": share of points
    coverage: float  # share of the reference surface samples covered
    coverage_visible: float | None  # same, among the samples a camera could see
    visible_share: float | None  # share of the reference samples a camera could see
    tolerance: float  # [m] coverage tolerance
    samples: int  # reference surface samples
    contributions: dict[str, float] = field(default_factory=dict)  # coverage of each part alone (both sides)

    def to_dict(self) -> dict:
        return {
            "points": self.points, "mean_mm": self.mean * 1e3, "std_mm": self.std * 1e3,
            "rms_mm": self.rms * 1e3, "median_abs_mm": self.median_abs * 1e3, "within": self.within,
            "coverage": self.coverage, "coverage_visible": self.coverage_visible,
            "visible_share": self.visible_share, "coverage_tolerance_mm": self.tolerance * 1e3,
            "reference_samples": self.samples, "contributions": self.contributions,
        }


def within_shares(distances: np.ndarray) -> dict[str, float]:
    """Share of the (signed) distances [m] within ±0.25, 0.5, 1 and 2 mm ("±0.5 mm": share)."""
    d = np.abs(np.asarray(distances, dtype=float))
    return {f"±{t:g} mm": float(np.mean(d <= t * 1e-3)) for t in (0.25, 0.5, 1.0, 2.0)}


def signed_distances(points: np.ndarray, reference) -> np.ndarray:
    """Signed distances [m] of points (N, 3) to an Open3D TriangleMesh."""
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(reference))
    # Open3D's stubs list Tensor(array) only with a dtype and a device; both default at run time
    q = o3d.core.Tensor(np.asarray(points, dtype=np.float32))  # type: ignore[call-overload]
    ans = scene.compute_closest_points(q)
    closest = ans["points"].numpy().astype(float)
    normals = ans["primitive_normals"].numpy().astype(float)
    diff = np.asarray(points, dtype=float) - closest
    dist = np.linalg.norm(diff, axis=1)
    sign = np.where(np.einsum("ij,ij->i", diff, normals) < 0.0, -1.0, 1.0)
    return sign * dist


def sample_surface(reference, n: int, seed: int = 0):
    """Uniform samples of a mesh's surface with their normals (points (n, 3), normals)."""
    import open3d as o3d

    mesh = o3d.geometry.TriangleMesh(reference)
    mesh.compute_triangle_normals()
    with open3d_draws(seed):
        cloud = mesh.sample_points_uniformly(number_of_points=n, use_triangle_normal=True)
    return np.asarray(cloud.points), np.asarray(cloud.normals)


def visible_from(samples: np.ndarray, normals: np.ndarray, reference, views: list[CameraView]) -> np.ndarray:
    """Which surface samples at least one camera could measure: inside the image and the
    depth range, facing the camera within the incidence limit, and the first surface hit
    by the ray from the camera (occlusion by the object itself)."""
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(reference))
    seen = np.zeros(len(samples), dtype=bool)
    for v in views:
        T = np.asarray(v.world_T_camera)
        c = T[:3, 3]
        local = (samples - c) @ T[:3, :3]  # camera frame
        z = local[:, 2]
        K = v.intrinsics
        with np.errstate(divide="ignore", invalid="ignore"):
            u = K.fx * local[:, 0] / z + K.cx
            w = K.fy * local[:, 1] / z + K.cy
        to_cam = c - samples
        dist = np.linalg.norm(to_cam, axis=1)
        cos_inc = np.einsum("ij,ij->i", to_cam, normals) / np.maximum(dist, 1e-12)
        ok = (z > v.near) & (z < v.far) & (u >= 0) & (u <= K.width - 1) & (w >= 0) & (w <= K.height - 1)
        ok &= cos_inc > np.cos(v.max_incidence)
        idx = np.nonzero(ok & ~seen)[0]
        if len(idx) == 0:
            continue
        dirs = -to_cam[idx] / dist[idx, None]
        rays = np.hstack([np.repeat(c[None], len(idx), axis=0), dirs]).astype(np.float32)
        # Open3D's stubs list Tensor(array) only with a dtype and a device; both default at run time
        hit = scene.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy()  # type: ignore[call-overload]
        seen[idx[hit >= dist[idx] - 1e-4]] = True
    return seen


def evaluate(points: np.ndarray, reference, tolerance: float = 0.001, samples: int = 200_000,
             views: list[CameraView] | None = None, seed: int = 0,
             parts: dict[str, np.ndarray] | None = None, surface: np.ndarray | None = None) -> Evaluation:
    """Accuracy (signed distances) and coverage of points (N, 3) against a reference mesh;
    ``parts``: clouds the points were merged from (an object's two sides), whose coverage
    alone is measured on the same surface samples; ``surface``: samples (M, 3) of the
    reference surface to measure coverage on (default: ``samples`` drawn from the mesh; not
    with ``views``, which need the samples' normals)."""
    import open3d as o3d

    points = np.asarray(points, dtype=float)
    d = signed_distances(points, reference)
    within = within_shares(d)
    if surface is None:
        surf, normals = sample_surface(reference, samples, seed)
    elif views:
        raise ValueError("coverage of the visible part needs the normals of the surface samples")
    else:
        surf, samples = np.asarray(surface, dtype=float), len(surface)
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    ref = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(surf))
    nearest = np.asarray(ref.compute_point_cloud_distance(cloud))
    covered = nearest <= tolerance
    contributions = {name: float(np.mean(np.asarray(ref.compute_point_cloud_distance(
        o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(part, dtype=float))))) <= tolerance))
        for name, part in (parts or {}).items()}
    cov_vis = vis_share = None
    if views:
        vis = visible_from(surf, normals, reference, views)
        vis_share = float(vis.mean())
        cov_vis = float(covered[vis].mean()) if vis.any() else 0.0
    return Evaluation(len(points), float(d.mean()), float(d.std()), float(np.sqrt(np.mean(d**2))),
                      float(np.median(np.abs(d))), within, float(covered.mean()), cov_vis, vis_share,
                      tolerance, samples, contributions)


def histogram_png(path: Path, distances_by_label: dict[str, np.ndarray], title: str,
                  limit: float = 0.002) -> None:
    """Histogram(s) of signed distances [m] like the thesis' Figures 5.8-5.10, written
    atomically (a fresh file renamed into place: never through a link)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    bins = np.linspace(-limit * 1e3, limit * 1e3, 81)
    for label, d in distances_by_label.items():
        d = np.asarray(d) * 1e3
        ax.hist(np.clip(d, bins[0], bins[-1]), bins=bins.tolist(), histtype="step", linewidth=1.5,
                label=f"{label}: mean {d.mean():+.3f} mm, std {d.std():.3f} mm")
    ax.set_xlabel("signed distance to the reference [mm]")
    ax.set_ylabel("points")
    ax.set_title(title)
    ax.legend(fontsize=8)
    fig.tight_layout()
    try:
        atomic_write(Path(path), lambda tmp: fig.savefig(tmp, dpi=120, format="png"))
    finally:
        plt.close(fig)
