"""read_mesh and read_cloud: the file checked, the format's checks before loading, Open3D's
load, the geometry checks after."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from recon_cli.errors import FileError
from recon_cli.inputs import files

from .geometry import _check_area, _check_arrays, _check_geometry, _Scan, _total_area
from .limits import CLOUD_SUFFIXES, MAX_MESH_FILE_BYTES, MAX_TRIANGLES, MAX_VERTICES, MESH_SUFFIXES
from .load import _open3d_quiet, _read_failure
from .obj import _obj_guard
from .pcd import _pcd_guard
from .ply import _ply_guard
from .refused import _UNITS, _count, _Refused, _Units
from .stl import _stl_guard


def _check_file(path: Path, what: str, hint: str) -> int:
    refuse = files.file_errors(path, what, hint, lambda size: (
        f"{size / 2**20:.1f} MiB, more than the {MAX_MESH_FILE_BYTES / 2**20:.0f} MiB recon reads",
        "simplify or downsample it"))
    return files.checked_size(path, MAX_MESH_FILE_BYTES, refuse, empty=False)


def check_mesh_file(path: Path | str, what: str = "mesh", hint: str | None = None) -> int:
    """The size of a mesh or cloud file, from its stat before a byte is read: a regular file
    of at most :data:`MAX_MESH_FILE_BYTES` (one FileError line otherwise). :func:`read_mesh`
    and :func:`read_cloud` start with it; a caller that looks at a file before reading it
    (a cache key, a digest) calls it first."""
    return _check_file(Path(path), what, hint or "check the file with a mesh viewer")


def _refusal(path: Path, what: str, exc: _Refused | str, hint: str, units: str = _UNITS) -> FileError:
    return FileError(f"{path}: {what} {exc}", hint=units if isinstance(exc, _Units) else hint)


def read_mesh(path: Path | str, what: str = "mesh", *, scale: float = 1.0, triangles: bool = True,
              hint: str | None = None, units_hint: str | None = None):
    """An Open3D TriangleMesh of an OBJ, PLY or STL file, guarded (see the module
    docstring). ``scale`` is the caller's unit factor (extent limits are checked after
    it); ``triangles=False`` accepts a file without triangles (its vertices only);
    ``units_hint`` replaces the hint when the coordinates look like another unit."""
    path = Path(path)
    fix = hint or "check the file with a mesh viewer"
    units = units_hint or _UNITS
    size = _check_file(path, what, fix)
    suffix = path.suffix.lower()
    if suffix not in MESH_SUFFIXES:
        raise FileError(f"{path}: {what} has the type '{path.suffix}', recon reads OBJ, PLY and STL meshes",
                        hint="convert it to PLY, OBJ or STL")
    copy = None
    try:
        try:
            if suffix == ".ply":
                _ply_guard(path, size, mesh=True, scan=_Scan("vertex", scale), triangles=triangles)
            elif suffix == ".stl":
                _stl_guard(path, size)
            else:
                copy = _obj_guard(path)
        except _Refused as exc:
            raise _refusal(path, what, exc, fix, units) from None
        with _open3d_quiet() as (o3d, log):
            try:
                mesh = o3d.io.read_triangle_mesh(str(copy or path), enable_post_processing=False)
            except RuntimeError as exc:
                raise _refusal(path, what, f"cannot be read ({str(exc).strip().splitlines()[-1][:160]})", fix) from None
    finally:
        if copy is not None:
            copy.unlink(missing_ok=True)
    failure = _read_failure(log)
    if failure:
        raise _refusal(path, what, f"cannot be read ({failure})", fix)
    vertices = np.asarray(mesh.vertices)
    tris = np.asarray(mesh.triangles)
    try:
        if not len(vertices) and not len(tris):
            raise _Refused("has no triangles (unreadable or empty)" if triangles else "has no vertices (unreadable "
                           "or empty)")
        arrays = {"vertex": vertices}
        if mesh.has_vertex_normals():
            arrays["normal"] = np.asarray(mesh.vertex_normals)
        if mesh.has_vertex_colors():
            arrays["colour"] = np.asarray(mesh.vertex_colors)
        _check_arrays(arrays)
        lo, hi = (vertices.min(axis=0), vertices.max(axis=0)) if len(vertices) else (np.zeros(3), np.zeros(3))
        _check_geometry(lo, hi, scale)
        if len(vertices) > MAX_VERTICES:
            raise _Refused(f"has {len(vertices)} vertices, more than the {MAX_VERTICES} recon reads")
        if len(tris) > MAX_TRIANGLES:
            raise _Refused(f"has {len(tris)} triangles, more than the {MAX_TRIANGLES} recon reads")
        if not len(tris):
            if triangles:
                raise _Refused(f"has no triangles ({_count(len(vertices), 'vertex', 'vertices')} only)")
            return mesh
        low, high = int(tris.min()), int(tris.max())
        if low < 0 or high >= len(vertices):
            raise _Refused(f"has triangles with vertex index {low if low < 0 else high}, outside 0 to "
                           f"{len(vertices) - 1}")
        _check_area(_total_area(vertices, tris), lo, hi, len(tris))
    except _Refused as exc:
        raise _refusal(path, what, exc, fix, units) from None
    return mesh


def read_cloud(path: Path | str, what: str = "point cloud", *, points: bool = True, hint: str | None = None):
    """An Open3D PointCloud of a PLY or PCD file, guarded (see the module docstring);
    ``points=False`` accepts an empty cloud."""
    path = Path(path)
    fix = hint or "check the file with a point cloud viewer"
    size = _check_file(path, what, fix)
    suffix = path.suffix.lower()
    if suffix not in CLOUD_SUFFIXES:
        raise FileError(f"{path}: {what} has the type '{path.suffix}', recon reads PLY and PCD point clouds",
                        hint="convert it to PLY or PCD")
    try:
        if suffix == ".ply":
            _ply_guard(path, size, mesh=False, scan=_Scan("point"))
        else:
            _pcd_guard(path, size, scan=_Scan("point"))
    except _Refused as exc:
        raise _refusal(path, what, exc, fix) from None
    with _open3d_quiet() as (o3d, log):
        try:
            cloud = o3d.io.read_point_cloud(str(path), remove_nan_points=False, remove_infinite_points=False)
        except RuntimeError as exc:
            raise _refusal(path, what, f"cannot be read ({str(exc).strip().splitlines()[-1][:160]})", fix) from None
    failure = _read_failure(log)
    if failure:
        raise _refusal(path, what, f"cannot be read ({failure})", fix)
    pts = np.asarray(cloud.points)
    try:
        if not len(pts):
            if points:
                raise _Refused("holds no points (unreadable or empty)")
            return cloud
        arrays = {"point": pts}
        if cloud.has_normals():
            arrays["normal"] = np.asarray(cloud.normals)
        if cloud.has_colors():
            arrays["colour"] = np.asarray(cloud.colors)
        _check_arrays(arrays)
        _check_geometry(pts.min(axis=0), pts.max(axis=0), 1.0)
        if len(pts) > MAX_VERTICES:
            raise _Refused(f"has {len(pts)} points, more than the {MAX_VERTICES} recon reads")
    except _Refused as exc:
        raise _refusal(path, what, exc, fix) from None
    return cloud
