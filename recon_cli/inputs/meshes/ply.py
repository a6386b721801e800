"""PLY checks before Open3D loads a file: the header's counts within the limits and
consistent with the file size, faces that are triangles with indices inside the vertex
list, and for binary files every record read in chunks (finite values, coordinates,
extent, total area)."""

from __future__ import annotations

import contextlib
import mmap
import re
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from . import limits
from .geometry import _area, _Scan
from .limits import LIMITS, MAX_HEADER_BYTES
from .ply_header import _INDEX_LISTS, PlyElement, PlyHeader, PlyProperty, ply_header
from .refused import _BINARY_PLY, _count, _Refused


@contextlib.contextmanager
def _mapped(path: Path) -> Iterator[mmap.mmap]:
    with open(path, "rb") as f, mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as mm:
        yield mm


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
    if vertex is None or any(p is None or p.is_list for p in (vertex.property(a) for a in "xyz")):
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
    floats = {noun: any(_checked(vertex, a).type[0] == "f" for a in axes) for noun, axes in groups.items()}
    exact32 = all(_checked(vertex, a).type in ("f4", "i1", "u1", "i2", "u2") for a in "xyz")
    points = np.empty((vertex.count, 3), np.float32 if exact32 else np.float64) if face is not None else None
    block = max(1, limits.SCAN_BYTES // offset)
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


def _checked(element: PlyElement, name: str) -> PlyProperty:
    """A property of ``element`` that :func:`_ply_guard` found there."""
    found = element.property(name)
    if found is None:
        raise _Refused(f"has no property '{name}' in its element '{element.name}'")
    return found


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
        if p.count_type is None:  # not a list
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
        block = max(1, limits.SCAN_BYTES // offset)  # faces read at a time
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
        layout = _ply_face_layout(f, header, face, start)
        if isinstance(layout, str):  # _ply_binary_faces refused such faces before
            raise _Refused(layout)
        fields, offset = layout
        record = _ply_face_record(header, fields, offset)
        f.seek(start)
        block = max(1, min(limits.SCAN_BYTES // offset, 1_000_000))
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


def _ply_ascii_faces(mm: mmap.mmap, header: PlyHeader, before: tuple[PlyElement, ...], face: PlyElement) -> str | None:
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
