"""Mesh and point cloud reads (object meshes, reference meshes, reconstructions) with the
declared sizes checked before Open3D loads anything and the geometry checked after.

Before loading: the file is a regular file of at most :data:`MAX_MESH_FILE_BYTES`, of a
format recon reads (meshes: PLY, OBJ, STL; clouds: PLY, PCD). A PLY or PCD header is
parsed strictly: vertex and face counts within the limits of the format (:data:`LIMITS`)
and consistent with the file size (a header claiming 10^11 vertices in a small file is
refused before Open3D reserves memory for them), and for a mesh every face of a PLY is
checked to be a triangle (Open3D's polygon splitting reads vertices without bounds
checks); a PCD declares all three normal fields or none (Open3D writes the ones it finds
into an array it did not size for them otherwise). A binary STL's triangle count must
match its size; an OBJ's vertex and face lines are counted, its faces must be triangles
(Open3D drops the others silently), its vertex lines must hold numbers, and its material
library (``mtllib``, which would make Open3D open further files and decode their
textures) is left out. An ASCII PCD's data lines must hold one number per value the
header declares (Open3D reads a word that is not a number as 0 and skips a short line,
leaving the last points uninitialised).

Binary PLY and binary PCD files, which may hold :data:`MAX_VERTICES` points, are checked
completely before loading, reading their records in chunks: finite coordinates, normals
and colours, coordinates and extent within the limits, triangle indices inside the
vertex list, a non-zero total area. A file refused is refused in bounded memory; Open3D
loads only files that pass. The other formats are read by Open3D and checked after
loading, so their limits are lower (:data:`LIMITS`): a file of the limit's size loads
within 1 GB.

After loading: Open3D's read reported no failure (rply and assimp print theirs; a PLY
value rply cannot parse leaves the rest of the array uninitialised); no NaN or infinite
coordinates, normals or colours; coordinates within :data:`MAX_COORDINATE_M` and an
extent of at most :data:`MAX_EXTENT_M` (after the caller's scale); triangle indices
inside the vertex list; a mesh has triangles of non-zero total area. Open3D's own
messages are captured off the terminal; every refusal is one
:class:`~recon_cli.errors.FileError` line.

The reader's parts, one module each: :mod:`.limits` (sizes and counts), :mod:`.reader`
(:func:`read_mesh`, :func:`read_cloud`), :mod:`.ply_header` and :mod:`.ply` (PLY header,
chunked checks of binary records, ASCII faces), :mod:`.pcd`, :mod:`.obj`, :mod:`.stl`,
:mod:`.text` (text formats read in chunks of lines), :mod:`.load` (Open3D with its output
captured) and :mod:`.geometry` (the checks of the geometry).
"""

from __future__ import annotations

from .limits import (
    CLOUD_SUFFIXES,
    LIMITS,
    MAX_COORDINATE_M,
    MAX_EXTENT_M,
    MAX_HEADER_BYTES,
    MAX_MESH_FILE_BYTES,
    MAX_OBJ_LINES,
    MAX_PCD_UNCOMPRESSED_BYTES,
    MAX_STL_TEXT_BYTES,
    MAX_STL_TRIANGLES,
    MAX_TEXT_TRIANGLES,
    MAX_TEXT_VERTICES,
    MAX_TRIANGLES,
    MAX_VERTICES,
    MESH_SUFFIXES,
)
from .ply_header import PlyElement, PlyHeader, PlyProperty, ply_header
from .reader import check_mesh_file, read_cloud, read_mesh

__all__ = [
    "CLOUD_SUFFIXES", "LIMITS", "MAX_COORDINATE_M", "MAX_EXTENT_M", "MAX_HEADER_BYTES", "MAX_MESH_FILE_BYTES",
    "MAX_OBJ_LINES", "MAX_PCD_UNCOMPRESSED_BYTES", "MAX_STL_TEXT_BYTES", "MAX_STL_TRIANGLES", "MAX_TEXT_TRIANGLES",
    "MAX_TEXT_VERTICES", "MAX_TRIANGLES", "MAX_VERTICES", "MESH_SUFFIXES", "PlyElement", "PlyHeader", "PlyProperty",
    "check_mesh_file", "ply_header", "read_cloud", "read_mesh",
]
