"""OBJ checks before Open3D (assimp) loads a file: line counts within the limits, triangle
faces, numeric vertex lines, and a copy without the material library."""

from __future__ import annotations

import os
import re
import tempfile
from pathlib import Path

from .limits import MAX_OBJ_LINES
from .refused import _BINARY_PLY, _Refused
from .text import _NUMBER, _line_chunks, _lines_before, _snippet

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
