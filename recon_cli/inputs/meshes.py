"""Mesh and point cloud reads (object meshes, reference meshes, reconstructions) with the
declared sizes checked before Open3D loads anything and the geometry checked after.

Before loading: the file is a regular file of at most :data:`MAX_MESH_FILE_BYTES`, of a
format recon reads (meshes: PLY, OBJ, STL; clouds: PLY, PCD). A PLY or PCD header is
parsed strictly: vertex and face counts at most :data:`MAX_VERTICES` /
:data:`MAX_TRIANGLES` and consistent with the file size (a header claiming 10^11 vertices
in a small file is refused before Open3D reserves memory for them), and for a mesh every
face of a PLY is checked to be a triangle (Open3D's polygon splitting reads vertices
without bounds checks); a PCD declares all three normal fields or none (Open3D writes
the ones it finds into an array it did not size for them otherwise). A binary STL's
triangle count must match its size; an OBJ's vertex and face lines are counted, its
faces must be triangles (Open3D drops the others silently), and its material library
(``mtllib``, which would make Open3D open further files and decode their textures) is
left out.

After loading: no NaN or infinite coordinates, normals or colours; coordinates within
:data:`MAX_COORDINATE_M` and an extent of at most :data:`MAX_EXTENT_M` (after the caller's
scale); triangle indices inside the vertex list; a mesh has triangles of non-zero total
area. Open3D's own messages are silenced; every refusal is one
:class:`~recon_cli.errors.FileError` line.
"""

from __future__ import annotations

import contextlib
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
"""Most vertices of a mesh or points of a cloud (a full-resolution 2064 x 1544 scan has
3.2 million; recon's fused clouds have a few hundred thousand)."""

MAX_TRIANGLES = 10_000_000
"""Most triangles (faces) of a mesh (recon's Poisson meshes have 1-2 million; YCB meshes
tens of thousands)."""

MAX_EXTENT_M = 100.0
"""Largest extent of a mesh or cloud along any axis, in metres after scaling."""

MAX_COORDINATE_M = 1000.0
"""Largest absolute coordinate, in metres after scaling."""

MAX_HEADER_BYTES = 64 * 1024
"""Longest PLY or PCD header."""

MESH_SUFFIXES = (".ply", ".obj", ".stl")
CLOUD_SUFFIXES = (".ply", ".pcd")

_CHUNK = 4 * 2**20
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


def _ply_guard(path: Path, size: int, mesh: bool) -> None:
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
    if vertex.count > MAX_VERTICES:
        raise _Refused(f"declares {vertex.count} vertices, more than the {MAX_VERTICES} recon reads")
    for element in header.elements:
        limit = MAX_VERTICES if element is vertex else MAX_TRIANGLES
        if element.count > limit:
            raise _Refused(f"declares {element.count} '{element.name}' elements, more than the {limit} recon reads")
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
        return
    if any(p.name in _INDEX_LISTS and not p.is_list for p in face.properties):
        raise _Refused("declares its face vertex indices as a single value, not a list")
    before = header.elements[:header.elements.index(face)]
    listed = [e.name for e in before if any(p.is_list for p in e.properties)]
    if listed:
        raise _Refused(f"has list properties in the element '{listed[0]}' before its faces, which recon does not read")
    if header.format == "ascii":
        with _mapped(path) as mm:
            problem = _ply_ascii_faces(mm, header, before, face)
    else:
        problem = _ply_binary_faces(path, size, header, before, face)
    if problem:
        raise _Refused(problem)


def _ply_binary_faces(path: Path, size: int, header: PlyHeader, before: list[PlyElement],
                      face: PlyElement) -> str | None:
    """Why the faces are not all triangles (other lists of one constant length), or None."""
    e = header.format
    start = header.body + sum(el.count * el.min_bytes(e) for el in before)
    offset, fields = 0, []
    with open(path, "rb") as f:
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
        if start + face.count * offset > size:
            return (f"ends inside its faces: {face.count} faces of {offset} bytes do not fit after the other elements "
                    "(truncated, or faces that are not all triangles)")
        for p, _, _, n in fields:
            if p.name in _INDEX_LISTS and n != 3:
                return (f"has a face of {_count(n, 'vertex', 'vertices')} (face 0); recon reads triangle meshes only "
                        "(triangulate it)")
        record = np.dtype({"names": [f"c{i}" for i in range(len(fields))], "formats": [f[2] for f in fields],
                           "offsets": [f[1] for f in fields], "itemsize": offset})
        block = max(1, 32 * 2**20 // offset)  # faces read at a time
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
    return None


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
        if declared > MAX_TRIANGLES:
            raise _Refused(f"declares {declared} triangles, more than the {MAX_TRIANGLES} recon reads")
        return
    text = head.lstrip()
    if text.startswith(b"solid") and not re.search(rb"[\x00\x80-\xff]", head):
        facets = _count_in(path, b"facet")
        if facets > 2 * MAX_TRIANGLES:  # "facet" starts and ends every triangle
            raise _Refused(f"holds {facets // 2} ASCII facets, more than the {MAX_TRIANGLES} triangles recon reads")
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


# --------------------------------------------------------------------- OBJ
_OBJ_TOKEN = rb"[^ \t\r\n]+"
_OBJ_POLYGON = re.compile(rb"\nf[ \t]+" + rb"[ \t]+".join([_OBJ_TOKEN] * 3) + rb"[ \t]+[^ \t\r\n#]")
_OBJ_INDENT = re.compile(rb"\n[ \t]+")
_OBJ_MTLLIB = re.compile(rb"mtllib[^\r\n]*")


def _obj_chunks(path: Path) -> Iterator[bytes]:
    """The file in chunks of at most _CHUNK bytes that end at line ends."""
    with open(path, "rb") as f:
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
                    raise _Refused(f"has a line longer than {_CHUNK // 2**20} MiB: it is not an OBJ file recon reads")
                rest = data
                continue
            yield data[:cut + 1]
            rest = data[cut + 1:]


def _obj_guard(path: Path) -> Path | None:
    """Count the vertex and face lines (faces must be triangles: Open3D drops the others
    silently); a copy without the material library lines when there are any (returned;
    the caller removes it), else None."""
    vertices = faces = polygons = 0
    materials = False
    for chunk in _obj_chunks(path):
        if b"\x00" in chunk:
            raise _Refused("holds NUL bytes: it is not a text OBJ file")
        lines = b"\n" + chunk.replace(b"\r", b"\n")  # every line after a "\n", whatever the line ends
        if b"\n " in lines or b"\n\t" in lines:
            lines = _OBJ_INDENT.sub(b"\n", lines)
        vertices += lines.count(b"\nv ") + lines.count(b"\nv\t")
        faces += lines.count(b"\nf ") + lines.count(b"\nf\t")
        polygons += _OBJ_POLYGON.search(lines) is not None
        materials = materials or b"mtllib" in lines
        if vertices > MAX_VERTICES:
            raise _Refused(f"has more than {MAX_VERTICES} vertex lines, more than recon reads")
        if faces > MAX_TRIANGLES:
            raise _Refused(f"has more than {MAX_TRIANGLES} face lines, more than recon reads")
    if polygons:
        raise _Refused("has faces of more than three vertices, which Open3D would leave out; recon reads "
                       "triangle meshes only (triangulate it)")
    if not materials:
        return None
    fd, name = tempfile.mkstemp(suffix=".obj", prefix="recon-mesh-")
    try:
        with os.fdopen(fd, "wb") as out:
            for chunk in _obj_chunks(path):
                out.write(_OBJ_MTLLIB.sub(b"", chunk))
    except BaseException:
        os.unlink(name)
        raise
    return Path(name)


# --------------------------------------------------------------------- PCD
_PCD_ORDER = ("VERSION", "FIELDS", "SIZE", "TYPE", "COUNT", "WIDTH", "HEIGHT", "VIEWPOINT", "POINTS", "DATA")


def _pcd_guard(path: Path, size: int) -> None:
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
    if points > MAX_VERTICES:
        raise _Refused(f"declares {points} points, more than the {MAX_VERTICES} recon reads")
    data = seen["DATA"]
    if len(data) != 1 or data[0] not in ("ascii", "binary", "binary_compressed"):
        raise _Refused("has a DATA line other than 'DATA ascii', 'DATA binary' or 'DATA binary_compressed'")
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
        if uncompressed > MAX_MESH_FILE_BYTES:
            raise _Refused(f"would decompress to {uncompressed / 2**20:.0f} MiB, more than the "
                           f"{MAX_MESH_FILE_BYTES / 2**20:.0f} MiB recon reads")
        need = 8 + compressed
        if compressed == 0:
            raise _Refused("declares 0 bytes of compressed data")
    if need > body:
        raise _Refused(f"declares {points} points, which need at least {need} bytes, but it has {body} after its "
                       "header (truncated, or the header is wrong)")


# --------------------------------------------------------------------- loading and checks
@contextlib.contextmanager
def _open3d_quiet():
    """Open3D with its logging at errors only (which it raises) and the process's stdout
    and stderr captured (rply prints its read errors there directly)."""
    import open3d as o3d

    from recon_cli.inputs.images import native_output_captured

    with native_output_captured((1, 2), opencv=False), \
            o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error):
        yield o3d


def _fmt_point(p: np.ndarray) -> str:
    return "(" + ", ".join(f"{v:.6g}" for v in p) + ")"


def _check_arrays(named: dict[str, np.ndarray]) -> None:
    """Every row finite; ``named``: singular noun -> (N, 3) array."""
    plural = {"vertex": "vertices", "point": "points", "normal": "normals", "colour": "colours"}
    for noun, a in named.items():
        if a.size and not np.isfinite(a).all():
            rows = np.flatnonzero(~np.isfinite(a).all(axis=1))
            raise _Refused(f"has {len(rows)} {noun if len(rows) == 1 else plural[noun]} with NaN or infinite values "
                           f"({noun} {int(rows[0])}: {_fmt_point(a[rows[0]])})")


def _check_geometry(points: np.ndarray, scale: float, noun: str) -> None:
    if not len(points):
        return
    worst = float(np.max(np.abs(points))) * scale
    if worst > MAX_COORDINATE_M:
        raise _Units(f"has a coordinate of {worst:.4g} m (after scale {scale:g}), outside ±{MAX_COORDINATE_M:g} m "
                     "(is the file in metres?)")
    extent = (points.max(axis=0) - points.min(axis=0)) * scale
    if float(extent.max()) > MAX_EXTENT_M:
        raise _Units(f"is {float(extent.max()):.4g} m across (after scale {scale:g}), more than the "
                     f"{MAX_EXTENT_M:g} m recon reads (is the file in metres?)")
    if len(points) > MAX_VERTICES:
        raise _Refused(f"has {len(points)} {noun}, more than the {MAX_VERTICES} recon reads")


def _total_area(vertices: np.ndarray, triangles: np.ndarray) -> float:
    total = 0.0
    for at in range(0, len(triangles), 1_000_000):
        t = triangles[at:at + 1_000_000]
        a, b, c = vertices[t[:, 0]], vertices[t[:, 1]], vertices[t[:, 2]]
        total += float(np.linalg.norm(np.cross(b - a, c - a), axis=1).sum()) / 2.0
    return total


def _refusal(path: Path, what: str, reason: str, hint: str) -> FileError:
    return FileError(f"{path}: {what} {reason}", hint=hint)


def read_mesh(path: Path | str, what: str = "mesh", *, scale: float = 1.0, triangles: bool = True,
              hint: str | None = None, units_hint: str | None = None):
    """An Open3D TriangleMesh of an OBJ, PLY or STL file, guarded (see the module
    docstring). ``scale`` is the caller's unit factor (extent limits are checked after
    it); ``triangles=False`` accepts a file without triangles (its vertices only);
    ``units_hint`` replaces the hint when the coordinates look like another unit."""
    path = Path(path)
    fix = hint or "check the file with a mesh viewer"
    size = _check_file(path, what, fix)
    suffix = path.suffix.lower()
    if suffix not in MESH_SUFFIXES:
        raise FileError(f"{path}: {what} has the type '{path.suffix}', recon reads OBJ, PLY and STL meshes",
                        hint="convert it to PLY, OBJ or STL")
    copy = None
    try:
        try:
            if suffix == ".ply":
                _ply_guard(path, size, mesh=True)
            elif suffix == ".stl":
                _stl_guard(path, size)
            else:
                copy = _obj_guard(path)
        except _Refused as exc:
            raise _refusal(path, what, str(exc), fix) from None
        with _open3d_quiet() as o3d:
            try:
                mesh = o3d.io.read_triangle_mesh(str(copy or path), enable_post_processing=False)
            except RuntimeError as exc:
                raise _refusal(path, what, f"cannot be read ({str(exc).strip().splitlines()[-1][:160]})", fix) from None
    finally:
        if copy is not None:
            copy.unlink(missing_ok=True)
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
        _check_geometry(vertices, scale, "vertices")
        if len(tris) > MAX_TRIANGLES:
            raise _Refused(f"has {len(tris)} triangles, more than the {MAX_TRIANGLES} recon reads")
        if not len(tris):
            if triangles:
                raise _Refused(f"has no triangles ({_count(len(vertices), 'vertex', 'vertices')} only)")
            return mesh
        lo, hi = int(tris.min()), int(tris.max())
        if lo < 0 or hi >= len(vertices):
            raise _Refused(f"has triangles with vertex index {lo if lo < 0 else hi}, outside 0 to {len(vertices) - 1}")
        area = _total_area(vertices, tris)
        extent = float((vertices.max(axis=0) - vertices.min(axis=0)).max())
        if not area > 1e-12 * extent**2:
            raise _Refused(f"is degenerate: the total area of its {_count(len(tris), 'triangle')} is {area:.3g} "
                           "(every triangle is a point or a line)")
    except _Refused as exc:
        units = isinstance(exc, _Units) and (units_hint or _UNITS)
        raise _refusal(path, what, str(exc), units or fix) from None
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
            _ply_guard(path, size, mesh=False)
        else:
            _pcd_guard(path, size)
    except _Refused as exc:
        raise _refusal(path, what, str(exc), fix) from None
    with _open3d_quiet() as o3d:
        try:
            cloud = o3d.io.read_point_cloud(str(path), remove_nan_points=False, remove_infinite_points=False)
        except RuntimeError as exc:
            raise _refusal(path, what, f"cannot be read ({str(exc).strip().splitlines()[-1][:160]})", fix) from None
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
        _check_geometry(pts, 1.0, "points")
    except _Refused as exc:
        raise _refusal(path, what, str(exc), _UNITS if isinstance(exc, _Units) else fix) from None
    return cloud
