"""STL checks before Open3D (assimp) loads a file: a binary STL's triangle count matches
its size, an ASCII STL's size and facets are within the limits."""

from __future__ import annotations

import re
import struct
from pathlib import Path

from .limits import CHUNK, MAX_STL_TEXT_BYTES, MAX_STL_TRIANGLES
from .refused import _BINARY_PLY, _Refused


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
        while block := f.read(CHUNK):
            data = tail + block
            total += data.count(needle)
            tail = data[-(len(needle) - 1):] if len(needle) > 1 else b""  # shorter than the needle
    return total
