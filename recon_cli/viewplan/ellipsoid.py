"""The ellipsoid of the non-model-based mode (thesis 2.1.3, eqs. 2.3-2.8).

An ellipsoid is a frame E in the world (``world_T_E``: centre and principal axes) and its
semi-axes e = (e1, e2, e3). It is estimated from an oriented bounding box of the partially
scanned object with the extents scaled by sqrt(3) (the ellipsoid through the box corners).
Views sit at distance d_c from its surface along the normal, looking at it; the nearest point
on the surface to any point is computed with Eberly's robust algorithm ("Distance from a
Point to an Ellipse, an Ellipsoid, or a Hyperellipsoid", the thesis' reference [19]).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

SQRT3 = math.sqrt(3.0)


@dataclass(frozen=True)
class Ellipsoid:
    world_T_E: np.ndarray  # 4x4: centre and principal axes
    axes: np.ndarray  # (3,) semi-axes e1, e2, e3 [m]

    @classmethod
    def from_box(cls, center, R, extent) -> Ellipsoid:
        """The ellipsoid of a box (centre, rotation, full extents): semi-axes sqrt(3)/2 x
        extent, so its surface passes through the box's corners."""
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = np.asarray(R, float), np.asarray(center, float)
        return cls(T, np.maximum(np.asarray(extent, float), 1e-4) * SQRT3 / 2.0)

    @classmethod
    def from_cloud(cls, points: np.ndarray, minimal: bool = True) -> Ellipsoid:
        """From Open3D's oriented bounding box of the points (the minimal one by default;
        ``minimal=False``: the PCA box the thesis used)."""
        import open3d as o3d

        pts = np.asarray(points, float)
        cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
        box = cloud.get_minimal_oriented_bounding_box() if minimal else cloud.get_oriented_bounding_box()
        span = float(np.max(np.ptp(pts, axis=0))) if len(pts) else 0.0
        if minimal and (np.max(box.extent) < 0.5 * span or
                        np.linalg.norm(np.asarray(box.center) - pts.mean(axis=0)) > span):
            return cls.upright_from_cloud(pts)  # Open3D's minimal box degenerates on some clouds
        R = np.asarray(box.R)
        if np.linalg.det(R) < 0:
            R = R.copy()
            R[:, 2] *= -1
        return cls.from_box(box.center, R, box.extent)

    @classmethod
    def upright_from_cloud(cls, points: np.ndarray) -> Ellipsoid:
        """From the smallest box with a vertical axis (an object standing on the table):
        OpenCV's minimum-area rectangle of the points seen from above, their height range."""
        import cv2

        pts = np.asarray(points, float)
        (cx, cy), (w, h), angle = cv2.minAreaRect(pts[:, :2].astype(np.float32))
        a = np.radians(angle)
        R = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])
        lo, hi = pts[:, 2].min(), pts[:, 2].max()
        return cls.from_box([cx, cy, (lo + hi) / 2.0], R, [w, h, hi - lo])

    def with_min_ratio(self, ratio: float) -> Ellipsoid:
        """The same ellipsoid with every semi-axis at least ``ratio`` times the largest: a
        partial object seen from one side only (a flat face) would otherwise give a flat
        disc, whose views crowd in front of and behind the face."""
        return Ellipsoid(self.world_T_E, np.maximum(self.axes, ratio * float(np.max(self.axes))))

    # ------------------------------------------------------------------ frames
    def to_local(self, p: np.ndarray) -> np.ndarray:
        T = self.world_T_E
        return (np.asarray(p, float) - T[:3, 3]) @ T[:3, :3]

    def to_world(self, p: np.ndarray) -> np.ndarray:
        T = self.world_T_E
        return np.asarray(p, float) @ T[:3, :3].T + T[:3, 3]

    # ------------------------------------------------------------------ geometry (frame E)
    def norm(self, p: np.ndarray) -> np.ndarray:
        """Eq. 2.8: sqrt(x^2/e1^2 + y^2/e2^2 + z^2/e3^2) (points in E)."""
        return np.sqrt(np.sum((np.asarray(p, float) / self.axes) ** 2, axis=-1))

    def normal(self, p: np.ndarray) -> np.ndarray:
        """Unit outward normal at surface points p (E), eq. 2.4 normalized."""
        g = 2.0 * np.asarray(p, float) / self.axes**2
        return g / np.linalg.norm(g, axis=-1, keepdims=True)

    def surface_from_directions(self, u: np.ndarray) -> np.ndarray:
        """Points e * u on the surface for unit vectors u (the affine image of the unit
        sphere: distances in the norm of eq. 2.8 are distances between the u)."""
        u = np.asarray(u, float)
        return u / np.linalg.norm(u, axis=-1, keepdims=True) * self.axes

    def nearest_point(self, y: np.ndarray) -> np.ndarray:
        """The surface point (E) closest to a point y (E), inside or outside (Eberly)."""
        return nearest_point_on_ellipsoid(self.axes, np.asarray(y, float))


def _root(r: np.ndarray, z: np.ndarray, g: float) -> float:
    """Eberly's bisection for the root s of sum((r_i z_i / (s + r_i))^2) - 1, the last r = 1."""
    n = r * z
    s0 = z[-1] - 1.0
    s1 = 0.0 if g < 0 else float(np.linalg.norm(n)) - 1.0
    s = s0
    for _ in range(2048):
        s = 0.5 * (s0 + s1)
        if s == s0 or s == s1:
            break
        val = float(np.sum((n / (s + r)) ** 2)) - 1.0
        if val > 0:
            s0 = s
        elif val < 0:
            s1 = s
        else:
            break
    return s


def _ellipse(e0: float, e1: float, y0: float, y1: float) -> tuple[float, float]:
    """Nearest point on the ellipse (x/e0)^2 + (y/e1)^2 = 1, e0 >= e1, y in the first quadrant."""
    if y1 > 0:
        if y0 > 0:
            z = np.array([y0 / e0, y1 / e1])
            g = float(np.sum(z * z)) - 1.0
            if g == 0:
                return y0, y1
            r = np.array([(e0 / e1) ** 2, 1.0])
            s = _root(r, z, g)
            return r[0] * y0 / (s + r[0]), y1 / (s + 1.0)
        return 0.0, e1
    numer, denom = e0 * y0, e0 * e0 - e1 * e1
    if numer < denom:
        xde = numer / denom
        return e0 * xde, e1 * math.sqrt(max(1.0 - xde * xde, 0.0))
    return e0, 0.0


def _ellipsoid(e: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Eberly's algorithm for e0 >= e1 >= e2 > 0 and y in the first octant."""
    e0, e1, e2 = e
    y0, y1, y2 = y
    if y2 > 0:
        if y1 > 0:
            if y0 > 0:
                z = y / e
                g = float(np.sum(z * z)) - 1.0
                if g == 0:
                    return y.copy()
                r = (e / e2) ** 2
                s = _root(r, z, g)
                return r * y / (s + r)
            x1, x2 = _ellipse(e1, e2, y1, y2)
            return np.array([0.0, x1, x2])
        if y0 > 0:
            x0, x2 = _ellipse(e0, e2, y0, y2)
            return np.array([x0, 0.0, x2])
        return np.array([0.0, 0.0, e2])
    d0, d1 = e0 * e0 - e2 * e2, e1 * e1 - e2 * e2
    if e0 * y0 < d0 and e1 * y1 < d1:
        a, b = e0 * y0 / d0, e1 * y1 / d1
        discr = 1.0 - a * a - b * b
        if discr > 0:
            return np.array([e0 * a, e1 * b, e2 * math.sqrt(discr)])
    x0, x1 = _ellipse(e0, e1, y0, y1)
    return np.array([x0, x1, 0.0])


def nearest_point_on_ellipsoid(axes: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Closest point to y on the ellipsoid with semi-axes ``axes`` (any order, any octant)."""
    axes = np.asarray(axes, float)
    sign = np.where(y < 0, -1.0, 1.0)
    order = np.argsort(-axes, kind="stable")
    x_sorted = _ellipsoid(axes[order], np.abs(y)[order])
    x = np.empty(3)
    x[order] = x_sorted
    return x * sign
