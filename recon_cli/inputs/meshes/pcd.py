"""PCD checks before Open3D loads a file: the header strictly, counts within the limits
and consistent with the file size, the values of ASCII data lines, and the records of
binary data read in chunks."""

from __future__ import annotations

import re
import struct
from pathlib import Path

import numpy as np

from . import limits
from .geometry import _Scan
from .limits import LIMITS, MAX_HEADER_BYTES, MAX_PCD_UNCOMPRESSED_BYTES, MAX_VERTICES
from .refused import _count, _Refused
from .text import _NUMBER, _line_chunks, _snippet

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

    block = max(1, limits.SCAN_BYTES // offset)
    with open(path, "rb") as f:
        f.seek(at)
        for first in range(0, points, block):
            table = np.fromfile(f, record, min(block, points - first))
            if check_normals:
                scan.finite("normal", [column(table, a) for a in normals], first)
            scan.coordinates([column(table, a) for a in "xyz"], first)
    scan.check()
