"""How well registered scans agree where they overlap, without ground truth (real data).

For a pair of clouds in one frame, every point of the source with a target point within
``max_distance`` is in the overlap; its residual is the point-to-plane distance to that
nearest target point along the target's normal. The pair's numbers: the overlap share, the
median and the RMS of the residuals [m]. Consecutive scans are the default pairs (a
recording's neighbours overlap most). A picture of a fused cloud (``cloud_png``) goes with
the numbers.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np


@dataclass(frozen=True)
class PairResidual:
    """Overlap residual of cloud ``source`` against cloud ``target``."""

    source: int
    target: int
    overlap: float  # share of source points with a target point within max_distance
    points: int  # source points in the overlap
    median: float  # [m] median |point-to-plane distance| in the overlap
    rms: float  # [m] RMS point-to-plane distance in the overlap

    def to_dict(self) -> dict:
        return {"source": self.source, "target": self.target, "overlap": self.overlap, "points": self.points,
                "median_m": self.median, "rms_m": self.rms}


def _normals(cloud, radius: float) -> np.ndarray:
    import open3d as o3d

    if not cloud.has_normals():
        cloud = o3d.geometry.PointCloud(cloud)
        cloud.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=radius, max_nn=30))
    return np.asarray(cloud.normals)


def pair_residual(source, target, max_distance: float, source_index: int = 0, target_index: int = 1,
                  normal_radius: float | None = None) -> PairResidual:
    """The overlap residual of two Open3D clouds in one frame (see the module docstring)."""
    from scipy.spatial import cKDTree

    p = np.asarray(source.points)
    q = np.asarray(target.points)
    if len(p) == 0 or len(q) == 0:
        return PairResidual(source_index, target_index, 0.0, 0, float("nan"), float("nan"))
    n = _normals(target, normal_radius or 3.0 * max_distance)
    d, j = map(np.asarray, cKDTree(q).query(p, distance_upper_bound=max_distance))  # (N,) each for points (N, 3)
    found = np.isfinite(d)
    if not found.any():
        return PairResidual(source_index, target_index, 0.0, 0, float("nan"), float("nan"))
    r = np.abs(np.einsum("ij,ij->i", p[found] - q[j[found]], n[j[found]]))
    return PairResidual(source_index, target_index, float(found.mean()), int(found.sum()), float(np.median(r)),
                        float(np.sqrt(np.mean(r * r))))


def overlap_residuals(clouds: list, max_distance: float, pairs: list[tuple[int, int]] | None = None,
                      voxel: float | None = None) -> list[PairResidual]:
    """Residuals of ``pairs`` (default: consecutive clouds) of Open3D clouds in one frame;
    with ``voxel`` the clouds are down-sampled first (faster, normals re-estimated)."""
    if voxel:
        clouds = [c.voxel_down_sample(voxel) for c in clouds]
    pairs = pairs if pairs is not None else [(i, i + 1) for i in range(len(clouds) - 1)]
    return [pair_residual(clouds[i], clouds[j], max_distance, i, j) for i, j in pairs]


def summary(residuals: list[PairResidual]) -> dict:
    """Median of the pairs' medians, RMS over every overlap point [m], mean overlap share."""
    ok = [r for r in residuals if r.points]
    if not ok:
        return {"pairs": len(residuals), "median_m": None, "rms_m": None, "overlap": 0.0}
    total = sum(r.points for r in ok)
    return {"pairs": len(residuals), "median_m": float(np.median([r.median for r in ok])),
            "rms_m": float(np.sqrt(sum(r.rms**2 * r.points for r in ok) / total)),
            "overlap": float(np.mean([r.overlap for r in residuals]))}


def splat(uv: np.ndarray, depth: np.ndarray, colors: np.ndarray, size: tuple[int, int], radius: int = 1,
          background: float = 0.12) -> np.ndarray:
    """An (H, W, 3) float image of points at pixels ``uv`` (N, 2): each drawn as a square of
    (2 radius + 1) pixels, nearer points (smaller ``depth``) over farther ones."""
    w, h = size
    image = np.full((h, w, 3), background)
    order = np.argsort(-depth)  # far first, near ones overwrite them
    uv, colors = np.round(uv[order]).astype(int), colors[order]
    for du in range(-radius, radius + 1):
        for dv in range(-radius, radius + 1):
            u, v = uv[:, 0] + du, uv[:, 1] + dv
            ok = (u >= 0) & (u < w) & (v >= 0) & (v < h)
            image[v[ok], u[ok]] = colors[ok]
    return image


def cloud_png(path: Path, cloud, camera_T_world: np.ndarray | None = None, title: str = "",
              size: tuple[int, int] = (640, 480), pull_back: float = 0.5) -> Path:
    """A picture of a coloured cloud: rendered (point splats, z-buffered) by a pinhole
    camera ``pull_back`` [m] behind ``camera_T_world`` (default: the cloud's frame; x right,
    y down, z forward), and from above (that camera's x-z plane, the topmost point of each
    cell shown)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    pts = np.asarray(cloud.points)
    cols = np.asarray(cloud.colors) if cloud.has_colors() else np.full((len(pts), 3), 0.7)
    T = np.eye(4) if camera_T_world is None else np.asarray(camera_T_world, dtype=float)
    c = pts @ T[:3, :3].T + T[:3, 3]
    w, h = size
    f = 0.8 * w  # about 64 degrees across
    z = c[:, 2] + pull_back
    front = z > 0.05
    uv = np.column_stack([f * c[front, 0] / z[front] + w / 2, f * c[front, 1] / z[front] + h / 2])
    view = splat(uv, z[front], cols[front], size)
    lo, hi = np.quantile(c[:, [0, 2]], [0.002, 0.998], axis=0)
    scale = min((w - 1) / max(hi[0] - lo[0], 1e-6), (h - 1) / max(hi[1] - lo[1], 1e-6))
    top_uv = np.column_stack([(c[:, 0] - lo[0]) * scale, (hi[1] - c[:, 2]) * scale])
    top = splat(top_uv, c[:, 1], cols, size, radius=0)  # camera y points down: smallest y on top
    fig, axes = plt.subplots(1, 2, figsize=(13, 5.2))
    axes[0].imshow(view)
    axes[0].set_title(f"seen from {pull_back:g} m behind the first camera")
    axes[1].imshow(top, extent=(lo[0], lo[0] + w / scale, hi[1] - h / scale, hi[1]))
    axes[1].set_xlabel("x [m]")
    axes[1].set_ylabel("z [m] (viewing direction)")
    axes[1].set_title("from above")
    axes[0].axis("off")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
