"""The PLY header, parsed as strictly as Open3D's reader (rply) needs it to agree on where
the body starts."""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from .limits import MAX_HEADER_BYTES

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
