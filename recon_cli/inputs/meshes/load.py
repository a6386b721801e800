"""Open3D loading with its messages captured off the terminal, and the failure its
readers reported."""

from __future__ import annotations

import contextlib
import ctypes
import io
import re
from collections.abc import Iterator
from types import ModuleType

from recon_cli.inputs.images import native_output_captured

_ANSI = re.compile(r"\x1b\[[0-9;]*m")


@contextlib.contextmanager
def _open3d_quiet() -> Iterator[tuple[ModuleType, list[str]]]:
    """Open3D with its logging at warnings (it raises its errors) and its messages captured:
    the process's stdout and stderr (rply prints its read errors there directly) and
    Python's (Open3D's logger prints through Python); yields (open3d, a list that
    receives the captured text afterwards)."""
    import open3d as o3d


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
