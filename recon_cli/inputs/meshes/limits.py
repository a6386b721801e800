"""The limits of the mesh and point cloud reader: file size, counts per format, extent and
coordinates, header length, and the chunk sizes files are read in."""

from __future__ import annotations

MAX_MESH_FILE_BYTES = 512 * 2**20
"""Largest mesh or cloud file read: 512 MiB (10 million points with normals and colours
as binary PLY of doubles is 510 MB)."""

MAX_VERTICES = 10_000_000
"""Most vertices of a binary PLY or points of a binary PCD (a full-resolution 2064 x 1544
scan has 3.2 million; recon's fused clouds have a few hundred thousand)."""

MAX_TRIANGLES = 10_000_000
"""Most triangles (faces) of a binary PLY mesh (recon's Poisson meshes have 1-2 million;
YCB meshes tens of thousands)."""

MAX_TEXT_VERTICES = 2_000_000
"""Most vertices of an ASCII PLY and points of an ASCII or compressed PCD: Open3D loads
these before recon can check them, and a file of this size loads within 1 GB."""

MAX_TEXT_TRIANGLES = 2_000_000
"""Most faces of an ASCII PLY."""

MAX_OBJ_LINES = 1_000_000
"""Most vertex, normal, texture coordinate and face lines (each) of an OBJ (Open3D reads
OBJ through assimp, which takes about 0.5 kB for each vertex with its normal, texture
coordinate and face)."""

MAX_STL_TRIANGLES = 500_000
"""Most triangles of an STL file (Open3D reads STL through assimp, which takes about
1 kB per triangle)."""

MAX_STL_TEXT_BYTES = 128 * 2**20
"""Largest ASCII STL file (assimp reads it into memory whole)."""

MAX_PCD_UNCOMPRESSED_BYTES = 128 * 2**20
"""Largest data of a compressed PCD, compressed and uncompressed (Open3D holds both)."""

LIMITS = {"binary PLY": (MAX_VERTICES, MAX_TRIANGLES), "ASCII PLY": (MAX_TEXT_VERTICES, MAX_TEXT_TRIANGLES),
          "binary PCD": (MAX_VERTICES, 0), "ASCII or compressed PCD": (MAX_TEXT_VERTICES, 0),
          "OBJ": (MAX_OBJ_LINES, MAX_OBJ_LINES), "STL": (3 * MAX_STL_TRIANGLES, MAX_STL_TRIANGLES)}
"""Format -> (most vertices or points, most triangles)."""

MAX_EXTENT_M = 100.0
"""Largest extent of a mesh or cloud along any axis, in metres after scaling."""

MAX_COORDINATE_M = 1000.0
"""Largest absolute coordinate, in metres after scaling."""

MAX_HEADER_BYTES = 64 * 1024
"""Longest PLY or PCD header."""

MESH_SUFFIXES = (".ply", ".obj", ".stl")
CLOUD_SUFFIXES = (".ply", ".pcd")

CHUNK = 4 * 2**20
"""Bytes of a text file read at a time (lines are cut at line ends)."""

SCAN_BYTES = 32 * 2**20
"""Bytes of binary records read at a time when a binary PLY or PCD is checked before
loading."""
