"""Reading text formats (OBJ, ASCII PCD) in chunks of whole lines, and the number syntax
their values must have."""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path

from .limits import CHUNK
from .refused import _Refused

_NUMBER = rb"[+-]?+(?:\d++(?:\.\d*+)?+|\.\d++)(?:[eE][+-]?+\d++)?+|[+-]?+(?i:nan|inf(?:inity)?+)"
"""A decimal number as strtod reads it whole (NaN and infinity too: the checks after
loading name them); not hexadecimal, not with a decimal comma or another suffix."""


def _line_chunks(path: Path, kind: str, start: int = 0) -> Iterator[bytes]:
    """The file from ``start`` in chunks of at most CHUNK bytes that end at line ends."""
    with open(path, "rb") as f:
        f.seek(start)
        rest = b""
        while True:
            block = f.read(CHUNK - len(rest))
            if not block:
                if rest:
                    yield rest
                return
            data = rest + block
            cut = max(data.rfind(b"\n"), data.rfind(b"\r"))
            if cut < 0:
                if len(data) >= CHUNK:
                    raise _Refused(f"has a line longer than {CHUNK // 2**20} MiB: it is not {kind} file recon reads")
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
