"""Where a rigid object can rest on a plane: the stable faces of its convex hull.

A rigid body touches a plane only where its convex hull does, so it can rest on a facet of
its hull (coplanar hull triangles merged into one polygon), and quasi-statically it stays
there when the centre of mass, projected onto the facet's plane along the facet's normal,
lies inside the polygon: gravity's moment about every edge then presses the facet down. How
far inside (the **margin**, to the nearest edge) over the centre of mass' height above the
facet is the tangent of the angle the object can be tilted before it tips over: a box on its
large face has a wide margin, a bottle on its cap a narrow one, a cylinder's tessellated side
the half-width of one strip (it rolls, as a real one does until friction stops it).

Every stable facet counts, upside down included: a bowl rests on its base and on its rim,
a mug on its base, its rim (the hull's top disc) and its side. Physics
(:mod:`recon_cli.backends.sim.turnover`) then confirms that the object settles where it was put.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: [rad] hull triangles whose normals differ by less than this are one facet
COPLANAR = math.radians(1.0)
#: [m] a facet is stable when the centre of mass projects at least this far inside it
MIN_MARGIN = 0.5e-3


@dataclass(frozen=True)
class Rest:
    """A stable resting face of an object's convex hull, in the object frame."""

    down: np.ndarray  # (3,) unit outward normal of the facet: points down (-z world) while the object rests on it
    area: float  # of the facet [m^2]
    height: float  # of the centre of mass above the facet's plane [m]
    margin: float  # distance from the centre of mass' projection to the facet's nearest edge [m]

    @property
    def tipping_deg(self) -> float:
        """The tilt [deg] about the nearest edge that tips the object off this face."""
        return math.degrees(math.atan2(self.margin, self.height))

    def to_dict(self) -> dict:
        return {"down_object": [float(v) for v in self.down], "area_cm2": self.area * 1e4,
                "com_height_mm": self.height * 1e3, "margin_mm": self.margin * 1e3,
                "tipping_deg": self.tipping_deg}


def resting_faces(vertices: np.ndarray, com: np.ndarray, min_margin: float = MIN_MARGIN) -> list[Rest]:
    """The stable resting faces (module docstring) of the convex hull of ``vertices`` (N, 3)
    with the centre of mass ``com`` (3,), object frame, most stable (largest tipping angle)
    first."""
    from scipy.spatial import ConvexHull

    hull = ConvexHull(np.asarray(vertices, dtype=float))
    normals = hull.equations[:, :3]
    unused = np.ones(len(normals), dtype=bool)
    rests = []
    for i in range(len(normals)):
        if not unused[i]:
            continue
        same = unused & (normals @ normals[i] >= math.cos(COPLANAR))
        unused &= ~same
        n = normals[same].mean(axis=0)
        n /= np.linalg.norm(n)
        points = hull.points[np.unique(hull.simplices[same])]
        rest = _rest_on(points, n, float(np.max(points @ n)), np.asarray(com, dtype=float))
        if rest is not None and rest.margin >= min_margin:
            rests.append(rest)
    return sorted(rests, key=lambda r: -r.tipping_deg)


def _rest_on(points: np.ndarray, n: np.ndarray, plane: float, com: np.ndarray) -> Rest | None:
    """The facet of ``points`` on the plane ``x . n = plane`` as a rest, or None when the
    centre of mass does not project inside it (margin <= 0) or it has no area."""
    from scipy.spatial import ConvexHull, QhullError

    u = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    flat = np.column_stack([points @ u, points @ v])
    if len(flat) < 3:
        return None
    try:
        polygon = ConvexHull(flat)
    except QhullError:  # a degenerate (collinear) facet
        return None
    p = np.array([com @ u, com @ v])
    # equations: a . x + b <= 0 inside, |a| = 1: the distance inside is -(a . p + b)
    margin = float(np.min(-(polygon.equations[:, :2] @ p + polygon.equations[:, 2])))
    if margin <= 0.0:
        return None
    return Rest(n, float(polygon.volume), float(plane - com @ n), margin)


def tilt_deg(a: np.ndarray, b: np.ndarray) -> float:
    """Angle [deg] between two unit vectors."""
    return math.degrees(math.acos(float(np.clip(np.dot(a, b), -1.0, 1.0))))
