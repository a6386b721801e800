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
"""

from __future__ import annotations

import contextlib
import ctypes
import io
import mmap
import os
import re
import stat
import struct
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from recon_cli.errors import FileError

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

_CHUNK = 4 * 2**20
_BINARY_PLY = f" (convert it to binary PLY, which may hold {MAX_VERTICES} vertices)"
_UNITS = "convert it to metres"


class _Refused(Exception):
    """A file the guard refuses (internal; becomes a FileError naming the file)."""


class _Units(_Refused):
    """Coordinates too large: probably not metres (the caller may know a better hint)."""


# --------------------------------------------------------------------- files
def _check_file(path: Path, what: str, hint: str) -> int:
    try:
        st = path.stat()
    except FileNotFoundError:
        raise FileError(f"{path}: {what} does not exist", hint="check the path") from None
    except OSError as exc:
        raise FileError(f"{path}: {what} cannot be read ({exc.strerror})", hint=hint) from None
    if not stat.S_ISREG(st.st_mode):
        raise FileError(f"{path}: {what} is not a regular file", hint=hint)
    if st.st_size == 0:
        raise FileError(f"{path}: {what} is empty (0 bytes)", hint=hint)
    if st.st_size > MAX_MESH_FILE_BYTES:
        raise FileError(f"{path}: {what} is {st.st_size / 2**20:.1f} MiB, more than the "
                        f"{MAX_MESH_FILE_BYTES / 2**20:.0f} MiB recon reads", hint="simplify or downsample it")
    return st.st_size


@contextlib.contextmanager
def _mapped(path: Path) -> Iterator[mmap.mmap]:
    with open(path, "rb") as f, mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as mm:
        yield mm


def _count(n: int, noun: str, plural: str | None = None) -> str:
    return f"{n} {noun if n == 1 else plural or noun + 's'}"


# --------------------------------------------------------------------- PLY
_PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
              "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
              "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}
_PLY_FORMATS = {"ascii": "ascii", "binary_little_endian": "<", "binary_big_endian": ">"}
_INDEX_LISTS = ("vertex_indices", "vertex_index")


@dataclass(frozen=True)
class PlyProperty:
    name: str
    type: str  # numpy code of a scalar, or of a list's items
    count_type: str | None = None  # numpy code of a list's length, None: scalar

    @property
    def is_list(self) -> bool:
        return self.count_type is not None


@dataclass(frozen=True)
class PlyElement:
    name: str
    count: int
    properties: tuple[PlyProperty, ...]

    def property(self, name: str) -> PlyProperty | None:
        return next((p for p in self.properties if p.name == name), None)

    def min_bytes(self, fmt: str) -> int:
        """The fewest bytes one instance takes (lists empty)."""
        if fmt == "ascii":
            return 2 * len(self.properties)
        return sum(np.dtype(p.count_type or p.type).itemsize for p in self.properties)


@dataclass(frozen=True)
class PlyHeader:
    format: str  # "ascii", "<" or ">"
    elements: tuple[PlyElement, ...]
    body: int  # byte offset of the first element

    def element(self, name: str) -> PlyElement | None:
        return next((e for e in self.elements if e.name == name), None)


def ply_header(data: bytes) -> PlyHeader:
    """Parse a PLY header as strictly as Open3D's reader (rply) needs it to agree on where
    the body starts: ``ply`` and ``end_header`` on lines of their own, one keyword and its
    arguments per line, known types, no duplicate names. ValueError says what is wrong."""
    crlf = data.startswith(b"ply\r\n")
    if not (data.startswith(b"ply\n") or crlf):
        raise ValueError("it does not start with the line 'ply'")
    eol = b"\r\n" if crlf else b"\n"
    end = data.find(eol + b"end_header" + eol)
    if end < 0:
        raise ValueError(f"no line 'end_header' in its first {MAX_HEADER_BYTES // 1024} KiB "
                         "(or the line has trailing characters)")
    text = data[:end]
    if re.search(rb"[^\x20-\x7e\r\n\t]", text) or (not crlf and b"\r" in text):
        raise ValueError("its header holds control or non-ASCII characters")
    lines = text.decode("ascii").split(eol.decode())[1:]
    fmt = None
    elements: list[tuple[str, int, list[PlyProperty]]] = []
    for number, line in enumerate(lines, start=2):
        words = line.split()
        where = f"header line {number}"
        if not words:
            raise ValueError(f"{where} is empty")
        if words[0] in ("comment", "obj_info"):
            if line.strip() == words[0]:  # rply would take the next line as its text
                raise ValueError(f"{where} is a '{words[0]}' without text")
            continue
        if words[0] == "format":
            if fmt is not None or elements or len(words) != 3 or words[1] not in _PLY_FORMATS or words[2] != "1.0":
                raise ValueError(f"{where} is not 'format ascii|binary_little_endian|binary_big_endian 1.0' "
                                 "before the elements")
            fmt = _PLY_FORMATS[words[1]]
        elif words[0] == "element":
            if fmt is None or len(words) != 3 or not re.fullmatch(r"\d{1,15}", words[2]):
                raise ValueError(f"{where} is not 'element NAME COUNT' after the format")
            if any(e[0] == words[1] for e in elements):
                raise ValueError(f"{where} repeats the element '{words[1]}'")
            elements.append((words[1], int(words[2]), []))
        elif words[0] == "property":
            if not elements:
                raise ValueError(f"{where} declares a property before any element")
            props = elements[-1][2]
            if len(words) == 3 and words[1] in _PLY_TYPES:
                prop = PlyProperty(words[2], _PLY_TYPES[words[1]])
            elif len(words) == 5 and words[1] == "list" and words[2] in _PLY_TYPES and words[3] in _PLY_TYPES:
                if _PLY_TYPES[words[2]][0] not in "iu":
                    raise ValueError(f"{where} declares a list whose length is a {words[2]}")
                prop = PlyProperty(words[4], _PLY_TYPES[words[3]], _PLY_TYPES[words[2]])
            else:
                raise ValueError(f"{where} is not 'property TYPE NAME' or 'property list TYPE TYPE NAME' "
                                 "with known types")
            if any(p.name == prop.name for p in props):
                raise ValueError(f"{where} repeats the property '{prop.name}'")
            props.append(prop)
        else:
            raise ValueError(f"{where} starts with '{words[0][:20]}', not a PLY keyword")
    if fmt is None:
        raise ValueError("its header has no format line")
    body = end + 2 * len(eol) + len(b"end_header")
    return PlyHeader(fmt, tuple(PlyElement(n, c, tuple(p)) for n, c, p in elements), body)


def _ply_guard(path: Path, size: int, mesh: bool, scan: _Scan | None = None, triangles: bool = False) -> None:
    """Refuse what Open3D should not load; ``scan`` (binary files) receives the checks of
    the records; ``triangles``: a mesh must have them."""
    with open(path, "rb") as f:
        head = f.read(MAX_HEADER_BYTES)
    if not head.startswith(b"ply"):
        raise _Refused(f"has no {'triangles' if mesh else 'points'} recon can read: it is not a PLY file (its first "
                       "line is not 'ply')")
    try:
        header = ply_header(head)
    except ValueError as exc:
        raise _Refused(f"is not a PLY file recon reads: {exc}") from None
    vertex = header.element("vertex")
    if vertex is None or any(vertex.property(a) is None or vertex.property(a).is_list for a in "xyz"):
        raise _Refused("has no 'vertex' element with x, y and z")
    kind = "ASCII PLY" if header.format == "ascii" else "binary PLY"
    most_vertices, most_faces = LIMITS[kind]
    instead = _BINARY_PLY if kind == "ASCII PLY" else ""
    if vertex.count > most_vertices:
        raise _Refused(f"declares {vertex.count} vertices, more than the {most_vertices} recon reads from {kind}"
                       f"{instead}")
    for element in header.elements:
        limit = most_vertices if element is vertex else most_faces
        if element.count > limit:
            raise _Refused(f"declares {element.count} '{element.name}' elements, more than the {limit} recon reads "
                           f"from {kind}{instead}")
    body = size - header.body
    need = sum(e.count * e.min_bytes(header.format) for e in header.elements)
    if header.format == "ascii":
        need -= 1  # the last value needs no separator after it
    if need > body:
        counts = ", ".join(f"{e.count} {e.name}" for e in header.elements)
        raise _Refused(f"declares {counts}, which need at least {need} bytes, but it has {max(body, 0)} after its "
                       "header (truncated, or the header is wrong)")
    face = header.element("face")
    if not mesh or face is None or face.count == 0 or not any(face.property(n) for n in _INDEX_LISTS):
        face = None
        if mesh and triangles and vertex.count:
            raise _Refused(f"has no triangles ({_count(vertex.count, 'vertex', 'vertices')} only)")
    else:
        if any(p.name in _INDEX_LISTS and not p.is_list for p in face.properties):
            raise _Refused("declares its face vertex indices as a single value, not a list")
        before = header.elements[:header.elements.index(face)]
        listed = [e.name for e in before if any(p.is_list for p in e.properties)]
        if listed:
            raise _Refused(f"has list properties in the element '{listed[0]}' before its faces, which recon does not "
                           "read")
        if header.format == "ascii":
            with _mapped(path) as mm:
                problem = _ply_ascii_faces(mm, header, before, face)
        else:
            problem = _ply_binary_faces(path, size, header, face, vertex.count)
        if problem:
            raise _Refused(problem)
    if scan is not None and header.format != "ascii" and vertex.count:
        _ply_binary_scan(path, header, vertex, face, scan)


_PLY_GROUPS = {"vertex": ("x", "y", "z"), "normal": ("nx", "ny", "nz"), "colour": ("red", "green", "blue")}


def _ply_binary_scan(path: Path, header: PlyHeader, vertex: PlyElement, face: PlyElement | None, scan: _Scan) -> None:
    """Check the vertex records of a binary PLY in chunks (NaN, coordinates, extent), then,
    for a mesh (``face``: its triangles, checked by :func:`_ply_binary_faces`), the total
    area of the triangles."""
    e = header.format
    at = header.elements.index(vertex)
    for element in header.elements[:at + 1]:
        if any(p.is_list for p in element.properties):
            raise _Refused(f"has list properties in the element '{element.name}', before or in its vertices, which "
                           "recon does not read")
    start = header.body + sum(el.count * el.min_bytes(e) for el in header.elements[:at])
    names, formats, offsets, offset = [], [], [], 0
    for p in vertex.properties:
        if any(p.name in group for group in _PLY_GROUPS.values()):
            names.append(p.name)
            formats.append(e + p.type)
            offsets.append(offset)
        offset += np.dtype(p.type).itemsize
    record = np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": offset})
    groups = {noun: [a for a in axes if a in names] for noun, axes in _PLY_GROUPS.items()}
    floats = {noun: any(vertex.property(a).type[0] == "f" for a in axes) for noun, axes in groups.items()}
    exact32 = all(vertex.property(a).type in ("f4", "i1", "u1", "i2", "u2") for a in "xyz")
    points = np.empty((vertex.count, 3), np.float32 if exact32 else np.float64) if face is not None else None
    block = max(1, _SCAN_BYTES // offset)
    with open(path, "rb") as f:
        f.seek(start)
        for first in range(0, vertex.count, block):
            table = np.fromfile(f, record, min(block, vertex.count - first))
            for noun, axes in groups.items():
                if axes and floats[noun] and noun != "vertex":
                    scan.finite(noun, [table[a] for a in axes], first)
            xyz = [table[a].astype(np.float64) for a in "xyz"]
            del table
            scan.coordinates(xyz, first)
            if points is not None:
                for k, c in enumerate(xyz):
                    points[first:first + len(c), k] = c
    scan.check()
    if points is not None and face is not None:
        area = _ply_binary_area(path, header, face, points)
        scan.area(area, face.count)


_SCAN_BYTES = 32 * 2**20


def _ply_face_record(header: PlyHeader, fields: list, size: int) -> np.dtype:
    """The record of one face whose lists have the lengths in ``fields``: the lengths as
    c0, c1, ... and the first vertex index list as "idx"."""
    names, formats, offsets = [], [], []
    for i, (p, offset, count_type, n) in enumerate(fields):
        names.append(f"c{i}")
        formats.append(count_type)
        offsets.append(offset)
        if p.name in _INDEX_LISTS and "idx" not in names:
            names.append("idx")
            formats.append((np.dtype(header.format + p.type), (n,)))
            offsets.append(offset + count_type.itemsize)
    return np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": size})


def _ply_face_layout(f, header: PlyHeader, face: PlyElement, start: int) -> tuple[list, int] | str:
    """(list fields as (property, offset, length type, length in face 0), bytes per face)
    read from the first face, or why not."""
    e = header.format
    offset, fields = 0, []
    for p in face.properties:
        if not p.is_list:
            offset += np.dtype(p.type).itemsize
            continue
        count_type = np.dtype(e + p.count_type)
        f.seek(start + offset)
        raw = f.read(count_type.itemsize)
        if len(raw) < count_type.itemsize:
            return "ends inside its first face (truncated)"
        n = int(np.frombuffer(raw, count_type)[0])
        fields.append((p, offset, count_type, n))
        offset += count_type.itemsize + n * np.dtype(p.type).itemsize
    return fields, offset


def _faces_start(header: PlyHeader, face: PlyElement) -> int:
    before = header.elements[:header.elements.index(face)]
    return header.body + sum(el.count * el.min_bytes(header.format) for el in before)


def _ply_binary_faces(path: Path, size: int, header: PlyHeader, face: PlyElement, vertices: int) -> str | None:
    """Why the faces are not all triangles (other lists of one constant length) with
    vertex indices from 0 to ``vertices`` - 1, or None."""
    start = _faces_start(header, face)
    with open(path, "rb") as f:
        layout = _ply_face_layout(f, header, face, start)
        if isinstance(layout, str):
            return layout
        fields, offset = layout
        if start + face.count * offset > size:
            return (f"ends inside its faces: {face.count} faces of {offset} bytes do not fit after the other elements "
                    "(truncated, or faces that are not all triangles)")
        for p, _, _, n in fields:
            if p.name in _INDEX_LISTS and n != 3:
                return (f"has a face of {_count(n, 'vertex', 'vertices')} (face 0); recon reads triangle meshes only "
                        "(triangulate it)")
        record = _ply_face_record(header, fields, offset)
        block = max(1, _SCAN_BYTES // offset)  # faces read at a time
        lo, hi = 0, -1
        f.seek(start)
        for first in range(0, face.count, block):
            table = np.fromfile(f, record, min(block, face.count - first))
            for i, (p, _, _, n) in enumerate(fields):
                counts = table[f"c{i}"]
                bad = np.flatnonzero(counts != n)
                if bad.size:
                    k = int(bad[0])
                    return (f"has faces of different sizes (face {first + k}: {int(counts[k])} entries in "
                            f"'{p.name}', face 0: {n}); recon reads triangle meshes only (triangulate it)")
            index = table["idx"].astype(np.int32)  # as Open3D stores them
            lo, hi = min(lo, int(index.min())), max(hi, int(index.max()))
    if lo < 0 or hi >= vertices:
        return f"has triangles with vertex index {lo if lo < 0 else hi}, outside 0 to {vertices - 1}"
    return None


def _ply_binary_area(path: Path, header: PlyHeader, face: PlyElement, points: np.ndarray) -> float:
    """The total area of the triangles of a binary PLY whose faces passed
    :func:`_ply_binary_faces`, read in chunks."""
    start = _faces_start(header, face)
    total = 0.0
    with open(path, "rb") as f:
        fields, offset = _ply_face_layout(f, header, face, start)
        record = _ply_face_record(header, fields, offset)
        f.seek(start)
        block = max(1, min(_SCAN_BYTES // offset, 1_000_000))
        for first in range(0, face.count, block):
            total += _area(points, np.fromfile(f, record, min(block, face.count - first))["idx"].astype(np.int64))
    return total


_TOKEN = rb"[\t\n\r ]*+[^\t\n\r ]++"


def _repeat(unit: bytes, n: int) -> re.Pattern:
    return re.compile(b"(?:" + unit + b"){%d}+" % n)


def _ascii_skip(mm: mmap.mmap, at: int, unit: bytes, n: int, block: int = 100_000) -> tuple[int, int]:
    """Match ``unit`` up to ``n`` times from ``at``: (position after the last match, matches)."""
    done = 0
    blocks = _repeat(unit, block)
    while n - done >= block:
        m = blocks.match(mm, at)
        if m is None:
            break
        at, done = m.end(), done + block
    single = re.compile(unit)
    while done < n:
        m = single.match(mm, at)
        if m is None:
            break
        at, done = m.end(), done + 1
    return at, done


def _ply_ascii_faces(mm: mmap.mmap, header: PlyHeader, before: list[PlyElement], face: PlyElement) -> str | None:
    """Walk the values as Open3D's reader does (whitespace-separated, lines do not matter):
    those of the elements before the faces, then each face, whose index list must be '3'
    followed by three values. Why not, or None."""
    if re.search(rb"[\x00\x0b\x0c]", mm):
        return "holds NUL, vertical tab or form feed bytes in its ASCII body"
    if any(p.is_list and p.name not in _INDEX_LISTS for p in face.properties):
        return "has list properties besides the vertex indices in its ASCII faces, which recon does not read"
    skip = sum(el.count * len(el.properties) for el in before)
    at, done = _ascii_skip(mm, header.body, _TOKEN, skip)
    if done < skip:
        return f"ends before the values of its {sum(el.count for el in before)} elements before the faces (truncated)"
    parts = []
    for p in face.properties:
        parts.append(_TOKEN if not p.is_list else rb"[\t\n\r ]*+3(?![^\t\n\r ])(?:" + _TOKEN + rb"){3}+")
    _, k = _ascii_skip(mm, at, b"".join(parts), face.count)
    if k < face.count:
        return (f"has a face that is not a triangle (face {k}: its index list is not '3' and three indices, or the "
                "file ends); recon reads triangle meshes only (triangulate it)")
    return None


# --------------------------------------------------------------------- STL
def _stl_guard(path: Path, size: int) -> None:
    with open(path, "rb") as f:
        head = f.read(4096)
    declared = struct.unpack_from("<I", head, 80)[0] if len(head) >= 84 else None
    if declared is not None and 84 + 50 * declared == size:
        if declared > MAX_STL_TRIANGLES:
            raise _Refused(f"declares {declared} triangles, more than the {MAX_STL_TRIANGLES} recon reads from STL"
                           f"{_BINARY_PLY}")
        return
    text = head.lstrip()
    if text.startswith(b"solid") and not re.search(rb"[\x00\x80-\xff]", head):
        if size > MAX_STL_TEXT_BYTES:
            raise _Refused(f"is an ASCII STL of {size / 2**20:.1f} MiB, more than the "
                           f"{MAX_STL_TEXT_BYTES / 2**20:.0f} MiB recon reads{_BINARY_PLY}")
        facets = _count_in(path, b"facet")
        if facets > 2 * MAX_STL_TRIANGLES:  # "facet" starts and ends every triangle
            raise _Refused(f"holds {facets // 2} ASCII facets, more than the {MAX_STL_TRIANGLES} triangles recon "
                           f"reads from STL{_BINARY_PLY}")
        return
    if declared is None:
        raise _Refused(f"is {size} bytes, too short for an STL file (84 bytes of header at least)")
    raise _Refused(f"is not a valid STL file: as binary STL it declares {declared} triangles, which take "
                   f"84 + 50 x {declared} = {84 + 50 * declared} bytes, but the file has {size} bytes "
                   "(truncated or corrupt), and it is not ASCII STL either")


def _count_in(path: Path, needle: bytes) -> int:
    """Occurrences of ``needle`` in the file, read in chunks."""
    total, tail = 0, b""
    with open(path, "rb") as f:
        while block := f.read(_CHUNK):
            data = tail + block
            total += data.count(needle)
            tail = data[-(len(needle) - 1):] if len(needle) > 1 else b""  # shorter than the needle
    return total


# --------------------------------------------------------------------- text
_NUMBER = rb"[+-]?+(?:\d++(?:\.\d*+)?+|\.\d++)(?:[eE][+-]?+\d++)?+|[+-]?+(?i:nan|inf(?:inity)?+)"
"""A decimal number as strtod reads it whole (NaN and infinity too: the checks after
loading name them); not hexadecimal, not with a decimal comma or another suffix."""


def _line_chunks(path: Path, kind: str, start: int = 0) -> Iterator[bytes]:
    """The file from ``start`` in chunks of at most _CHUNK bytes that end at line ends."""
    with open(path, "rb") as f:
        f.seek(start)
        rest = b""
        while True:
            block = f.read(_CHUNK - len(rest))
            if not block:
                if rest:
                    yield rest
                return
            data = rest + block
            cut = max(data.rfind(b"\n"), data.rfind(b"\r"))
            if cut < 0:
                if len(data) >= _CHUNK:
                    raise _Refused(f"has a line longer than {_CHUNK // 2**20} MiB: it is not {kind} file recon reads")
                rest = data
                continue
            yield data[:cut + 1]
            rest = data[cut + 1:]


def _lines_before(chunk: bytes, at: int) -> int:
    """Line ends in ``chunk`` before ``at`` (LF, CRLF or CR)."""
    return max(chunk.count(b"\n", 0, at), chunk.count(b"\r", 0, at))


def _snippet(line: bytes) -> str:
    text = line.strip()[:40].decode("ascii", "replace")
    return re.sub(r"[^\x20-\x7e]", "?", text) + ("..." if len(line.strip()) > 40 else "")


# --------------------------------------------------------------------- OBJ
_OBJ_TOKEN = rb"[^ \t\r\n]+"
_OBJ_POLYGON = re.compile(rb"\nf[ \t]+" + rb"[ \t]+".join([_OBJ_TOKEN] * 3) + rb"[ \t]+[^ \t\r\n#]")
_OBJ_INDENT = re.compile(rb"\n[ \t]+")
_OBJ_MTLLIB = re.compile(rb"mtllib[^\r\n]*")
_OBJ_BAD_VALUES = re.compile(rb"\n[ \t]*+(v[nt]?+)[ \t](?![ \t]*+(?:(?:" + _NUMBER + rb")(?:[ \t]++(?:" + _NUMBER
                             + rb"))*+)?+[ \t]*+(?:#[^\n]*+)?+\n)")


def _obj_guard(path: Path) -> Path | None:
    """Count the vertex, normal, texture coordinate and face lines (faces must be
    triangles: Open3D drops the others silently) and check that the first three hold
    numbers; a copy without the material library lines when there are any (returned; the
    caller removes it), else None."""
    counts = {b"v": 0, b"vn": 0, b"vt": 0, b"f": 0}
    polygons = line = 0
    materials = False
    for chunk in _line_chunks(path, "an OBJ"):
        if b"\x00" in chunk:
            raise _Refused("holds NUL bytes: it is not a text OBJ file")
        lines = b"\n" + chunk.replace(b"\r", b"\n")  # every line after a "\n", whatever the line ends
        if not lines.endswith(b"\n"):
            lines += b"\n"
        bad = _OBJ_BAD_VALUES.search(lines)
        if bad:
            end = lines.find(b"\n", bad.start() + 1)
            raise _Refused(f"has a '{bad.group(1).decode()}' line whose values are not all numbers (line "
                           f"{line + _lines_before(chunk, bad.start()) + 1}: '{_snippet(lines[bad.start():end])}')")
        line += _lines_before(chunk, len(chunk))
        if b"\n " in lines or b"\n\t" in lines:
            lines = _OBJ_INDENT.sub(b"\n", lines)
        for key in counts:
            counts[key] += lines.count(b"\n" + key + b" ") + lines.count(b"\n" + key + b"\t")
        polygons += _OBJ_POLYGON.search(lines) is not None
        materials = materials or b"mtllib" in lines
        for key, noun in ((b"v", "vertex"), (b"vn", "normal"), (b"vt", "texture coordinate"), (b"f", "face")):
            if counts[key] > MAX_OBJ_LINES:
                raise _Refused(f"has more than {MAX_OBJ_LINES} {noun} lines, more than recon reads from OBJ"
                               f"{_BINARY_PLY}")
    if polygons:
        raise _Refused("has faces of more than three vertices, which Open3D would leave out; recon reads "
                       "triangle meshes only (triangulate it)")
    if not materials:
        return None
    fd, name = tempfile.mkstemp(suffix=".obj", prefix="recon-mesh-")
    try:
        with os.fdopen(fd, "wb") as out:
            for chunk in _line_chunks(path, "an OBJ"):
                out.write(_OBJ_MTLLIB.sub(b"", chunk))
    except BaseException:
        os.unlink(name)
        raise
    return Path(name)


# --------------------------------------------------------------------- PCD
_PCD_ORDER = ("VERSION", "FIELDS", "SIZE", "TYPE", "COUNT", "WIDTH", "HEIGHT", "VIEWPOINT", "POINTS", "DATA")


def _pcd_guard(path: Path, size: int, scan: _Scan | None = None) -> None:
    """Refuse what Open3D should not load; ``scan`` receives the checks of the records of
    binary data."""
    with open(path, "rb") as f:
        head = f.read(MAX_HEADER_BYTES)
    seen: dict[str, list[str]] = {}
    at = 0
    while "DATA" not in seen:
        end = head.find(b"\n", at)
        if end < 0:
            raise _Refused(f"has no DATA line in its first {MAX_HEADER_BYTES // 1024} KiB: not a PCD file recon reads")
        raw = head[at:end + 1]
        at = end + 1
        if len(raw) > 1000 or re.search(rb"[^\x20-\x7e\t\r\n]", raw):
            raise _Refused(f"has a header line that is longer than 1000 bytes or holds control characters "
                           f"(line {len(seen) + 1})")
        words = raw.decode("ascii").split()
        if not words or words[0].startswith("#"):
            continue
        key = words[0]
        if key not in _PCD_ORDER or key in seen:
            raise _Refused(f"has the header line '{key[:20]}', not a PCD keyword in PCD order ({' '.join(_PCD_ORDER)})")
        if any(_PCD_ORDER.index(k) > _PCD_ORDER.index(key) for k in seen):
            raise _Refused(f"has its header line {key} out of PCD order ({' '.join(_PCD_ORDER)})")
        seen[key] = words[1:]
    for key in ("FIELDS", "SIZE", "TYPE", "WIDTH", "HEIGHT", "POINTS"):
        if key not in seen:
            raise _Refused(f"has no {key} line in its header")
    fields = seen["FIELDS"]
    n = len(fields)
    counts = seen.get("COUNT", ["1"] * n)
    if not n or len(seen["SIZE"]) != n or len(seen["TYPE"]) != n or len(counts) != n:
        raise _Refused("has FIELDS, SIZE, TYPE and COUNT lines of different lengths")
    if not all(re.fullmatch(r"[1248]", s) for s in seen["SIZE"]) or any(t not in ("I", "U", "F") for t in seen["TYPE"]):
        raise _Refused("has a SIZE other than 1, 2, 4, 8 or a TYPE other than I, U, F")
    if not all(re.fullmatch(r"[1-9]\d{0,3}", c) for c in counts):
        raise _Refused("has a COUNT outside 1 to 9999")
    sizes, counts_i = [int(s) for s in seen["SIZE"]], [int(c) for c in counts]
    normals = [a in fields for a in ("normal_x", "normal_y", "normal_z")]
    if any(normals) and not all(normals):  # Open3D would write normals it has no room for
        raise _Refused("has some of the fields normal_x, normal_y, normal_z but not all three")
    for axis in "xyz":
        if axis not in fields:
            raise _Refused("has no x, y and z fields")
        k = fields.index(axis)
        if (seen["TYPE"][k], sizes[k]) == ("F", 8) or sizes[k] == 8:
            raise _Refused(f"stores {axis} in 8 bytes, which Open3D's PCD reader reads as 0; store 32-bit floats")
    numbers = []
    for key in ("WIDTH", "HEIGHT", "POINTS"):
        if len(seen[key]) != 1 or not re.fullmatch(r"\d{1,12}", seen[key][0]):
            raise _Refused(f"has a {key} line that is not one whole number")
        numbers.append(int(seen[key][0]))
    width, height, points = numbers
    if points != width * height:
        raise _Refused(f"declares POINTS {points}, but WIDTH x HEIGHT is {width * height}")
    if points == 0:
        raise _Refused("declares 0 points")
    data = seen["DATA"]
    if len(data) != 1 or data[0] not in ("ascii", "binary", "binary_compressed"):
        raise _Refused("has a DATA line other than 'DATA ascii', 'DATA binary' or 'DATA binary_compressed'")
    kind = "binary PCD" if data[0] == "binary" else "ASCII or compressed PCD"
    if points > LIMITS[kind][0]:
        instead = "" if kind == "binary PCD" else f" (convert it to binary PCD, which may hold {MAX_VERTICES} points)"
        raise _Refused(f"declares {points} points, more than the {LIMITS[kind][0]} recon reads from {kind}{instead}")
    point_size = sum(s * c for s, c in zip(sizes, counts_i, strict=True))
    body = size - at
    if data[0] == "ascii":
        need = points * (2 * sum(counts_i)) - 1
    elif data[0] == "binary":
        need = points * point_size
    else:
        if body < 8:
            raise _Refused("ends before its compressed data (truncated)")
        with open(path, "rb") as f:
            f.seek(at)
            compressed, uncompressed = struct.unpack("<II", f.read(8))
        if uncompressed != points * point_size:
            raise _Refused(f"declares {uncompressed} bytes of uncompressed data, but {points} points of {point_size} "
                           f"bytes are {points * point_size}")
        if uncompressed > MAX_PCD_UNCOMPRESSED_BYTES:
            raise _Refused(f"would decompress to {uncompressed / 2**20:.1f} MiB, more than the "
                           f"{MAX_PCD_UNCOMPRESSED_BYTES / 2**20:.0f} MiB recon reads")
        if compressed > MAX_PCD_UNCOMPRESSED_BYTES:
            raise _Refused(f"declares {compressed / 2**20:.0f} MiB of compressed data, more than the "
                           f"{MAX_PCD_UNCOMPRESSED_BYTES / 2**20:.0f} MiB recon reads")
        need = 8 + compressed
        if compressed == 0:
            raise _Refused("declares 0 bytes of compressed data")
    if need > body:
        raise _Refused(f"declares {points} points, which need at least {need} bytes, but it has {body} after its "
                       "header (truncated, or the header is wrong)")
    if data[0] == "ascii":
        _pcd_ascii_values(path, at, head[:at].count(b"\n"), sum(counts_i), points)
    elif data[0] == "binary" and scan is not None:
        layout = [(name, {"F": "f", "I": "i", "U": "u"}[t] + str(n), c)
                  for name, t, n, c in zip(fields, seen["TYPE"], sizes, counts_i, strict=True)]
        _pcd_binary_scan(path, at, layout, points, scan)


def _pcd_ascii_values(path: Path, at: int, header_lines: int, values: int, points: int) -> None:
    """Every data line of an ASCII PCD holds ``values`` numbers or nothing, and there are
    ``points`` lines of numbers at least (Open3D skips a line with fewer values, leaving
    the last points uninitialised, and reads a word that is not a number as 0)."""
    number = b"(?:" + _NUMBER + b")"
    bad_line = re.compile(rb"(?m)^(?![ \t\r]*+(?:" + number + rb"(?:[ \t\r]++" + number + rb"){%d}+[ \t\r]*+)?+$)"
                          % (values - 1))
    blank = re.compile(rb"(?m)^[ \t\r]*+$")
    line = header_lines
    found = 0
    for chunk in _line_chunks(path, "an ASCII PCD", at):
        if not chunk.endswith(b"\n"):
            chunk += b"\n"
        bad = bad_line.search(chunk, 0, len(chunk) - 1)
        if bad:
            end = chunk.find(b"\n", bad.start())
            where = line + chunk.count(b"\n", 0, bad.start()) + 1
            raise _Refused(f"has a data line that is not {_count(values, 'number')} (line "
                           f"{where}: '{_snippet(chunk[bad.start():end])}'; "
                           "the header declares that many values per point)")
        lines = chunk.count(b"\n")
        found += lines - sum(1 for _ in blank.finditer(chunk, 0, len(chunk) - 1))
        line += lines
    if found < points:
        raise _Refused(f"has {_count(found, 'line')} of point values, but POINTS declares {points} (truncated, or the "
                       "header is wrong)")


_PCD_GROUPS = {"point": ("x", "y", "z"), "normal": ("normal_x", "normal_y", "normal_z")}


def _pcd_binary_scan(path: Path, at: int, layout: list[tuple[str, str, int]], points: int, scan: _Scan) -> None:
    """Check the records of binary PCD data in chunks; ``layout``: (field, numpy type,
    count) in the order of the record."""
    names, formats, offsets, offset = [], [], [], 0
    for name, code, count in layout:
        if any(name in axes for axes in _PCD_GROUPS.values()):
            names.append(name)
            formats.append(("<" + code, (count,)) if count > 1 else "<" + code)
            offsets.append(offset)
        offset += np.dtype(code).itemsize * count
    record = np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": offset})
    codes = {name: code for name, code, _ in layout}
    normals = _PCD_GROUPS["normal"]
    check_normals = all(a in codes for a in normals) and any(codes[a][0] == "f" for a in normals)

    def column(table, name):
        values = table[name]
        return (values[:, 0] if values.ndim > 1 else values).astype(np.float64)

    block = max(1, _SCAN_BYTES // offset)
    with open(path, "rb") as f:
        f.seek(at)
        for first in range(0, points, block):
            table = np.fromfile(f, record, min(block, points - first))
            if check_normals:
                scan.finite("normal", [column(table, a) for a in normals], first)
            scan.coordinates([column(table, a) for a in "xyz"], first)
    scan.check()


# --------------------------------------------------------------------- checks
_PLURAL = {"vertex": "vertices", "point": "points", "normal": "normals", "colour": "colours"}


def _fmt_point(p: np.ndarray) -> str:
    return "(" + ", ".join(f"{v:.6g}" for v in p) + ")"


def _not_finite(noun: str, count: int, index: int, row: np.ndarray) -> str:
    return (f"has {count} {noun if count == 1 else _PLURAL[noun]} with NaN or infinite values "
            f"({noun} {index}: {_fmt_point(row)})")


def _check_arrays(named: dict[str, np.ndarray]) -> None:
    """Every row finite; ``named``: singular noun -> (N, 3) array."""
    for noun, a in named.items():
        if a.size and not np.isfinite(a).all():
            rows = np.flatnonzero(~np.isfinite(a).all(axis=1))
            raise _Refused(_not_finite(noun, len(rows), int(rows[0]), a[rows[0]]))


def _check_geometry(lo: np.ndarray, hi: np.ndarray, scale: float) -> None:
    """Coordinates and extent of points whose per-axis minimum and maximum are ``lo``, ``hi``."""
    worst = float(max(np.abs(lo).max(), np.abs(hi).max())) * scale
    if worst > MAX_COORDINATE_M:
        raise _Units(f"has a coordinate of {worst:.4g} m (after scale {scale:g}), outside ±{MAX_COORDINATE_M:g} m "
                     "(is the file in metres?)")
    extent = float((hi - lo).max()) * scale
    if extent > MAX_EXTENT_M:
        raise _Units(f"is {extent:.4g} m across (after scale {scale:g}), more than the {MAX_EXTENT_M:g} m recon reads "
                     "(is the file in metres?)")


def _check_area(area: float, lo: np.ndarray, hi: np.ndarray, triangles: int) -> None:
    extent = float((hi - lo).max())
    if not area > 1e-12 * extent**2:
        raise _Refused(f"is degenerate: the total area of its {_count(triangles, 'triangle')} is {area:.3g} "
                       "(every triangle is a point or a line)")


def _area(points: np.ndarray, index: np.ndarray) -> float:
    a, b, c = (points[index[:, k]].astype(np.float64) for k in range(3))
    return float(np.linalg.norm(np.cross(b - a, c - a), axis=1).sum()) / 2.0


def _total_area(vertices: np.ndarray, triangles: np.ndarray) -> float:
    return sum(_area(vertices, triangles[at:at + 1_000_000]) for at in range(0, len(triangles), 1_000_000))


class _Scan:
    """The checks after loading, run over the records of a file read in chunks before
    loading: NaN or infinite rows, coordinates and extent (after ``scale``), total area.
    ``noun`` names a row of coordinates ("vertex" or "point")."""

    def __init__(self, noun: str, scale: float = 1.0) -> None:
        self.noun = noun
        self.scale = scale
        self.bad: dict[str, list] = {}  # noun -> [rows, first row's index, first row]
        self.lo = np.full(3, np.inf)
        self.hi = np.full(3, -np.inf)

    def finite(self, noun: str, columns: list[np.ndarray], first: int) -> None:
        """Rows ``first``, ``first`` + 1, ... given as one array per axis."""
        ok = np.isfinite(columns[0])
        for c in columns[1:]:
            ok &= np.isfinite(c)
        if not ok.all():
            bad = np.flatnonzero(~ok)
            row = np.array([float(c[bad[0]]) for c in columns])
            entry = self.bad.setdefault(noun, [0, first + int(bad[0]), row])
            entry[0] += len(bad)

    def coordinates(self, xyz: list[np.ndarray], first: int) -> None:
        self.finite(self.noun, xyz, first)
        if len(xyz[0]) and self.noun not in self.bad:
            self.lo = np.minimum(self.lo, [c.min() for c in xyz])
            self.hi = np.maximum(self.hi, [c.max() for c in xyz])

    def check(self) -> None:
        for noun in (self.noun, "normal", "colour"):
            if noun in self.bad:
                raise _Refused(_not_finite(noun, *self.bad[noun]))
        if np.isfinite(self.lo).all():
            _check_geometry(self.lo, self.hi, self.scale)

    def area(self, area: float, triangles: int) -> None:
        _check_area(area, self.lo, self.hi, triangles)


# --------------------------------------------------------------------- loading
_ANSI = re.compile(r"\x1b\[[0-9;]*m")


@contextlib.contextmanager
def _open3d_quiet():
    """Open3D with its logging at warnings (it raises its errors) and its messages captured:
    the process's stdout and stderr (rply prints its read errors there directly) and
    Python's (Open3D's logger prints through Python); yields (open3d, a list that
    receives the captured text afterwards)."""
    import open3d as o3d

    from recon_cli.inputs.images import native_output_captured

    texts: list[str] = []
    python = io.StringIO()
    with native_output_captured((1, 2), opencv=False) as native:
        try:
            with contextlib.redirect_stdout(python), contextlib.redirect_stderr(python), \
                    o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Warning):
                yield o3d, texts
        finally:  # anything still in the C library's buffer of stdout goes to the capture
            ctypes.CDLL(None).fflush(None)
    texts.extend([python.getvalue(), *native])


_FAILURES = ((r"RPly: ([^\n]+)", "rply: {}: a value that is not a number, outside the range of its type, or missing"),
             (r"with ASSIMP: ([^\n]+)", "assimp: {}"), (r"Read \w+ failed: ([^\n]+)", "{}"))


def _read_failure(log: list[str]) -> str | None:
    """Why Open3D's read failed, from what it and its readers printed, or None. A failed
    read still returns geometry: whatever was read, and for a PLY the rest of the arrays
    uninitialised."""
    text = _ANSI.sub("", "".join(log))
    for pattern, form in _FAILURES:
        found = [line.strip().rstrip(".") for line in re.findall(pattern, text)]
        if found and not found[0].startswith("number of vertex <= 0"):  # an empty file: the checks name it
            reason = "; ".join(found[:3])
            if len(reason) > 100:  # assimp quotes the rest of the file, its line ends as "?"
                reason = re.sub(r'"([^"?]{0,40})[^"]*"?', r'"\1..."', reason, count=1)
            return form.format(reason[:160])
    return None


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
