"""What a check inside the reader raises (each becomes one FileError naming the file) and
the wording the checks share."""

from __future__ import annotations

from .limits import MAX_VERTICES

_BINARY_PLY = f" (convert it to binary PLY, which may hold {MAX_VERTICES} vertices)"
_UNITS = "convert it to metres"


class _Refused(Exception):
    """A file the guard refuses (internal; becomes a FileError naming the file)."""


class _Units(_Refused):
    """Coordinates too large: probably not metres (the caller may know a better hint)."""


def _count(n: int, noun: str, plural: str | None = None) -> str:
    return f"{n} {noun if n == 1 else plural or noun + 's'}"
