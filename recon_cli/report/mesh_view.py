"""Grey-shaded pictures of a mesh from a few directions, and whether a picture shows anything.

The mesh is ray-cast on the CPU with Open3D's ``RaycastingScene`` (Embree): one ray per
sub-pixel (2 x 2 per pixel, averaged), the hit triangle's vertex normals interpolated and
lit by a light beside the camera. No graphics context is needed, so this works the same on a
headless server, in CI and on a desktop, and cannot take a run down with a failing graphics
driver (Open3D's OffscreenRenderer does run headless with a software Vulkan device, but it
starts its Filament engine for seconds, prints the engine's log, and crashes where EGL is
missing). Each view looks from one of the :data:`MESH_VIEWS` directions at the mesh, framed so
that it just fills the image.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from recon_cli.errors import FileError
from recon_cli.inputs.meshes import read_mesh
from recon_cli.report.options import MESH_VIEWS

BACKGROUND = 255  # white
SUPERSAMPLE = 2  # rays per pixel along each axis
FOV_DEG = 30.0  # vertical field of view
ROWS_PER_BATCH = 400_000  # rays cast at once


@dataclass(frozen=True)
class ImageStats:
    """Pixel statistics of a grey image on a white background."""

    std: float  # standard deviation of the grey values (0...255)
    foreground: float  # share of pixels that differ from the background

    def blank(self, min_std: float = 5.0, min_foreground: float = 0.01) -> bool:
        return self.std < min_std or self.foreground < min_foreground


@dataclass(frozen=True)
class MeshView:
    name: str  # front, side, top, oblique
    path: Path  # the PNG
    azimuth_deg: float
    elevation_deg: float
    stats: ImageStats


def image_stats(image: np.ndarray, background: int = BACKGROUND, tolerance: int = 8) -> ImageStats:
    """``image``: (H, W) or (H, W, C) uint8."""
    grey = np.asarray(image, dtype=float)
    if grey.ndim == 3:
        grey = grey.mean(axis=2)
    return ImageStats(float(grey.std()), float(np.mean(np.abs(grey - background) > tolerance)))


def _look_at(eye: np.ndarray, center: np.ndarray, up: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    forward = center - eye
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, up)
    right /= np.linalg.norm(right)
    return forward, right, np.cross(right, forward)


def shade(mesh, eye: np.ndarray, center: np.ndarray, up: np.ndarray, width: int, height: int,
          scene=None) -> np.ndarray:
    """A (height, width) uint8 grey picture of an Open3D TriangleMesh (legacy) seen from
    ``eye`` looking at ``center``."""
    import open3d as o3d

    if scene is None:
        scene = o3d.t.geometry.RaycastingScene()
        scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(mesh))
    eye = np.asarray(eye, float)
    forward, right, cam_up = _look_at(eye, np.asarray(center, float), np.asarray(up, float))
    light = -forward + 0.5 * cam_up - 0.35 * right  # beside the camera, above and to the left
    light /= np.linalg.norm(light)
    w, h = width * SUPERSAMPLE, height * SUPERSAMPLE
    f = 0.5 * h / np.tan(np.radians(FOV_DEG) / 2)  # pinhole with FOV_DEG vertically
    u = (np.arange(w) + 0.5 - w / 2) / f
    triangles = np.asarray(mesh.triangles)
    vertex_normals = np.asarray(mesh.vertex_normals) if mesh.has_vertex_normals() else None
    grey = np.empty((h, w))
    rows = max(SUPERSAMPLE, (ROWS_PER_BATCH // w) // SUPERSAMPLE * SUPERSAMPLE)
    for top in range(0, h, rows):  # in blocks of rows: memory stays bounded at any size
        v = (np.arange(top, min(h, top + rows)) + 0.5 - h / 2) / f
        uu, vv = np.meshgrid(u, v)
        dirs = forward + uu[..., None] * right - vv[..., None] * cam_up
        dirs /= np.linalg.norm(dirs, axis=2, keepdims=True)
        rays = np.concatenate([np.broadcast_to(eye, dirs.shape), dirs], axis=2).astype(np.float32)
        hit = scene.cast_rays(o3d.core.Tensor.from_numpy(rays))
        found = np.isfinite(hit["t_hit"].numpy())
        normals = hit["primitive_normals"].numpy().astype(float)
        if vertex_normals is not None:  # smooth: the vertex normals interpolated at the hit
            tri = triangles[np.where(found, hit["primitive_ids"].numpy().astype(np.int64), 0)]
            bary = hit["primitive_uvs"].numpy().astype(float)
            a, b = bary[..., :1], bary[..., 1:2]
            smooth = (1 - a - b) * vertex_normals[tri[..., 0]] + a * vertex_normals[tri[..., 1]] \
                + b * vertex_normals[tri[..., 2]]
            length = np.linalg.norm(smooth, axis=2, keepdims=True)
            normals = np.where(length > 1e-9, smooth / np.maximum(length, 1e-9), normals)
        facing = np.einsum("hwk,hwk->hw", normals, dirs)
        normals = np.where(facing[..., None] > 0, -normals, normals)  # both sides lit alike
        diffuse = np.clip(normals @ light, 0.0, 1.0)
        grey[top: top + len(v)] = np.where(found, 35.0 + 195.0 * (0.18 + 0.82 * diffuse), float(BACKGROUND))
    image = grey.reshape(height, SUPERSAMPLE, width, SUPERSAMPLE).mean(axis=(1, 3))
    return np.clip(np.round(image), 0, 255).astype(np.uint8)


def framed_view(vertices: np.ndarray, azimuth_deg: float, elevation_deg: float, aspect: float,
                margin: float = 1.08) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Camera position, the point it looks at and its up vector for a view from the
    direction (azimuth, elevation) in which the vertices just fill the image (``aspect``:
    width / height)."""
    az, el = np.radians(azimuth_deg), np.radians(elevation_deg)
    direction = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])  # toward the camera
    up = np.array([0.0, 0.0, 1.0]) if abs(elevation_deg) < 80 else \
        -np.sign(elevation_deg) * np.array([np.cos(az), np.sin(az), 0.0])
    forward, right, cam_up = _look_at(direction, np.zeros(3), up)
    x, y, z = vertices @ right, vertices @ cam_up, vertices @ forward
    center = (x.max() + x.min()) / 2 * right + (y.max() + y.min()) / 2 * cam_up + (z.max() + z.min()) / 2 * forward
    x, y, z = x - center @ right, y - center @ cam_up, z - center @ forward
    tan_v = np.tan(np.radians(FOV_DEG) / 2)
    tan_h = tan_v * aspect
    # a vertex at depth distance + z is inside the image when |x| <= tan_h (distance + z), ...
    needed = max(float(np.max(np.abs(x) / tan_h - z)), float(np.max(np.abs(y) / tan_v - z)), 1e-6)
    distance = max(needed * margin, 1e-3 - float(z.min()))  # never inside the mesh
    return center - distance * forward, center, cam_up


def render_mesh(mesh_path: Path, out_dir: Path, views: tuple[str, ...] = tuple(MESH_VIEWS),
                width: int = 480, *, seed: int) -> tuple[MeshView, ...]:
    """``mesh_<view>.png`` in ``out_dir`` for each view; a FileError when the file holds no
    triangles. ``seed``: of the vertex subset that frames a large mesh (the run's seed)."""
    import cv2
    import open3d as o3d


    if not Path(mesh_path).is_file():
        raise FileError(f"{mesh_path} holds no triangles (there is no such file)",
                        hint="rebuild the mesh (recon register)")
    mesh = read_mesh(mesh_path, "mesh", hint="rebuild the mesh (recon register)")
    if not mesh.has_vertex_normals():
        mesh.compute_vertex_normals()
    vertices = np.asarray(mesh.vertices)
    if len(vertices) > 50_000:  # the framing needs the outline only
        vertices = vertices[np.random.default_rng(seed).choice(len(vertices), 50_000, replace=False)]
    height = max(1, round(width * 3 / 4))
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(mesh))
    out_dir.mkdir(parents=True, exist_ok=True)
    out = []
    for name in views:
        azimuth, elevation = MESH_VIEWS[name]
        eye, center, up = framed_view(vertices, azimuth, elevation, width / height)
        image = shade(mesh, eye, center, up, width, height, scene)
        path = out_dir / f"mesh_{name}.png"
        if not cv2.imwrite(str(path), image):
            raise FileError(f"cannot write {path}", hint="check free space and permissions of the run folder")
        out.append(MeshView(name, path, azimuth, elevation, image_stats(image)))
    return tuple(out)
