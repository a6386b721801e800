"""A bowl made for the tests: a thin-walled spherical cap, opening up, as a closed mesh file."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np


def bowl_mesh(radius: float = 0.07, wall: float = 0.004, opening_deg: float = 70.0, segments: int = 48,
              rings: int = 16) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (N, 3) [m] and outward triangles (M, 3) of a spherical shell of outer
    ``radius`` and thickness ``wall``, cut at ``opening_deg`` from its lowest point (a cap),
    its lowest point at z = 0: the outer and inner caps joined at the rim."""
    polar = np.radians(np.linspace(0.0, opening_deg, rings + 1))[1:]
    azimuth = np.linspace(0.0, 2.0 * math.pi, segments, endpoint=False)
    vertices = []
    for r in (radius, radius - wall):
        vertices.append((0.0, 0.0, radius - r))
        for t in polar:
            vertices += [(r * math.sin(t) * math.cos(a), r * math.sin(t) * math.sin(a), radius - r * math.cos(t))
                         for a in azimuth]
    per_shell = 1 + rings * segments

    def at(shell: int, ring: int, k: int) -> int:
        return shell * per_shell + 1 + ring * segments + k % segments

    triangles = []
    for shell in (0, 1):
        flip = shell == 1  # the inner cap faces the opening
        faces = [(shell * per_shell, at(shell, 0, k + 1), at(shell, 0, k)) for k in range(segments)]
        for i in range(rings - 1):
            for k in range(segments):
                a, b, c, d = at(shell, i, k), at(shell, i, k + 1), at(shell, i + 1, k + 1), at(shell, i + 1, k)
                faces += [(a, b, c), (a, c, d)]
        triangles += [f[::-1] if flip else f for f in faces]
    for k in range(segments):  # the rim
        a, b = at(0, rings - 1, k), at(0, rings - 1, k + 1)
        c, d = at(1, rings - 1, k + 1), at(1, rings - 1, k)
        triangles += [(a, b, c), (a, c, d)]
    return np.array(vertices), np.array(triangles)


def write_bowl(path: Path, **kwargs) -> Path:
    """The bowl of :func:`bowl_mesh` as a PLY file."""
    import open3d as o3d

    vertices, triangles = bowl_mesh(**kwargs)
    mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(vertices), o3d.utility.Vector3iVector(triangles))
    mesh.compute_vertex_normals()
    o3d.io.write_triangle_mesh(str(path), mesh)
    return path
