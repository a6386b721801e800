"""The one JSON reader: every JSON file of a scan store, a recording or a run folder that
recon reads back goes through :func:`load_json`, which refuses, before anything is built
from the file, one that

* is not a regular file (a FIFO, a device, a folder: nothing is opened that could block) or
  is larger than its limit (checked before it is read);
* given the folder it belongs to (a run folder, a scan store), is or lies behind a link
  leading out of that folder (checked before anything else);
* is not UTF-8 or not JSON;
* nests lists and objects deeper than :data:`MAX_DEPTH` levels (checked before it is
  parsed: Python's parser recurses once per level);
* holds ``NaN``, ``Infinity`` or a number too large for a float (``1e999``): Python's JSON
  parser accepts them, and NaN passes every comparison-based range check;
* holds an integer of more than :data:`MAX_INT_DIGITS` digits, a key twice in one object
  (JSON parsers keep the last silently) or text that is not Unicode (a lone surrogate).

Every refusal is one :class:`~recon_cli.errors.MetadataError` naming the file (and the line
where there is one), so that a reader can skip a bad scan with its reason.
"""

from __future__ import annotations

import json
import math
import re
import stat
from pathlib import Path
from typing import Any

import numpy as np

from recon_cli.errors import MetadataError
from recon_cli.inputs import files

#: bytes of a scan store's own small files: scan.json, session.json, ground_truth.json, a
#: recording's intrinsics.json (recon writes a few kB)
MAX_METADATA_BYTES = 1_000_000
#: bytes of any other JSON file recon reads back (its reports, read for a report page)
MAX_JSON_BYTES = 16 * 2**20
#: nesting of lists and objects (recon's files nest 6 levels)
MAX_DEPTH = 32
#: digits of one integer (2^64 has 20)
MAX_INT_DIGITS = 30
_WRONG_FILE = "check that it is the right file"


class _Refused(Exception):
    """A value the JSON reader does not take: ``message``, and a pattern that finds it in
    the text (for the line)."""

    def __init__(self, message: str, pattern: str | None = None, hint: str | None = None) -> None:
        self.message, self.pattern, self.hint = message, pattern, hint
        super().__init__(message)


def _kind(mode: int) -> str:
    for test, name in ((stat.S_ISDIR, "a folder"), (stat.S_ISFIFO, "a FIFO"), (stat.S_ISSOCK, "a socket"),
                       (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device")):
        if test(mode):
            return name
    return "a special file"


def read_bytes(path: Path, what: str, max_bytes: int = MAX_METADATA_BYTES, root: Path | None = None) -> bytes:
    """The bytes of a regular file of at most ``max_bytes`` bytes, or a MetadataError. The
    file's kind and size are checked before it is opened, and it is opened without
    blocking (a FIFO put in its place meanwhile is refused, not waited on). ``root``: the
    folder the file belongs to (a run folder, a scan store); a file that is, or lies behind,
    a link leading out of it is refused before anything else."""
    path = Path(path)

    def refuse(r: files.Refusal) -> MetadataError:
        if r.reason == files.OUTSIDE:
            return MetadataError(files.outside_text(r, what), path=str(path), hint=files.OUTSIDE_HINT)
        if r.reason == files.MISSING or isinstance(r.error, FileNotFoundError):
            return MetadataError(f"{path}: {what} is missing", path=str(path))
        if r.reason == files.UNREADABLE and r.error is not None:
            return MetadataError(f"{path}: {what} cannot be read ({r.error.strerror or r.error})", path=str(path))
        if r.reason == files.NOT_REGULAR:
            return MetadataError(f"{path}: {what} is not a regular file ({_kind(r.mode)})", path=str(path),
                                 hint="replace it with a regular file, or remove it")
        if r.reason == files.TOO_LARGE:
            return MetadataError(f"{path}: {what} has {r.size:,} bytes, more than the {max_bytes:,} recon reads",
                                 path=str(path), hint=_WRONG_FILE)
        return MetadataError(f"{path}: {what} grew past {max_bytes:,} bytes while it was read", path=str(path),
                             hint=_WRONG_FILE)

    return files.read_limited(path, max_bytes, refuse, root=root)


def load_json(path: Path, what: str, max_bytes: int = MAX_JSON_BYTES, root: Path | None = None) -> Any:
    """The content of a JSON file (see the module docstring for what is refused), or a
    MetadataError with file:line:column where there is a line. ``root``: the folder the file
    belongs to (see :func:`read_bytes`)."""
    path = Path(path)
    data = read_bytes(path, what, max_bytes, root)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise MetadataError(f"{path}: {what} cannot be read (not UTF-8 text: byte {exc.start})", path=str(path),
                            hint="save it as UTF-8 text") from None
    return parse_json(text, path, what)


#: a JSON string, or an unterminated one up to the end of its line: a match from every quote
#: succeeds, without backtracking, so removing the strings takes one pass over the text
_STRING = re.compile(r'"(?:[^"\\\n]|\\.)*+(?:"|\\?$)', re.MULTILINE)


def _line(bare: str, pattern: str | None) -> int | None:
    """The 1-based line of the first match of ``pattern`` in ``bare`` (strings removed)."""
    if pattern is None:
        return None
    m = re.search(pattern, bare)
    return None if m is None else bare.count("\n", 0, m.start()) + 1


def _depth_check(bare: str, path: Path, what: str) -> None:
    """Refuse nesting deeper than MAX_DEPTH before the (recursive) parser sees it."""
    b = np.frombuffer(bare.encode("utf-8", "surrogatepass"), np.uint8)
    step = ((b == ord("[")) | (b == ord("{"))).astype(np.int32) - ((b == ord("]")) | (b == ord("}")))
    if not len(step):
        return
    depth = np.cumsum(step)
    if depth.max() > MAX_DEPTH:
        at = int(np.argmax(depth > MAX_DEPTH))
        line = int(np.count_nonzero(b[:at] == ord("\n"))) + 1
        raise MetadataError(f"{path}:{line}: {what} nests lists and objects more than {MAX_DEPTH} levels deep",
                            path=str(path), where=f"line {line}", hint=_WRONG_FILE)


def _constant(name: str):
    raise _Refused(f"holds {name}, which is not a finite number", rf"(?<![\w.]){name}\b",
                   "NaN and Infinity are not JSON numbers; write a finite number")


def _int(token: str) -> int:
    digits = len(token.lstrip("-"))
    if digits > MAX_INT_DIGITS:
        raise _Refused(f"holds an integer of {digits:,} digits, more than {MAX_INT_DIGITS}",
                       rf"\d{{{MAX_INT_DIGITS + 1}}}", _WRONG_FILE)
    return int(token)


def _float(token: str) -> float:
    x = float(token)
    if not math.isfinite(x):
        shown = token if len(token) <= 24 else token[:21] + "..."
        raise _Refused(f"holds {shown}, which is too large for a number", re.escape(token[:200]),
                       "write a finite number")
    return x


def _object(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out = dict(pairs)
    if len(out) != len(pairs):
        seen: set[str] = set()
        for key, _ in pairs:
            if key in seen:
                break
            seen.add(key)
        shown = key if len(key) <= 40 else key[:37] + "..."
        raise _Refused(f"has the key {shown!r} twice in one object", None,
                       "JSON readers would keep the last one silently; remove one")
    return out


def _text_check(doc: Any, path: Path, what: str) -> None:
    """Refuse text that is not Unicode (a lone surrogate, e.g. "\\ud800")."""
    stack = [doc]
    while stack:
        node = stack.pop()
        if isinstance(node, dict):
            stack.extend(node.keys())
            stack.extend(node.values())
        elif isinstance(node, list):
            stack.extend(node)
        elif isinstance(node, str):
            try:
                node.encode("utf-8")
            except UnicodeEncodeError:
                code = next(ord(c) for c in node if 0xD800 <= ord(c) <= 0xDFFF)
                raise MetadataError(f"{path}: {what} holds text that is not Unicode (a lone surrogate "
                                    f"\\u{code:04x})", path=str(path),
                                    hint=_WRONG_FILE) from None


def parse_json(text: str, path: Path, what: str) -> Any:
    """The document of a JSON text read from ``path`` (see the module docstring)."""
    path = Path(path)
    bare = _STRING.sub('""', text)  # strings cannot hold line breaks: lines stay where they are
    _depth_check(bare, path, what)
    try:
        doc = json.loads(text, parse_constant=_constant, parse_int=_int, parse_float=_float,
                         object_pairs_hook=_object)
    except _Refused as exc:
        line = _line(bare, exc.pattern)
        at = f"{path}:{line}" if line else f"{path}"
        raise MetadataError(f"{at}: {what} {exc.message}", path=str(path),
                            where=f"line {line}" if line else None,
                            hint=exc.hint) from None
    except json.JSONDecodeError as exc:
        raise MetadataError(f"{path}:{exc.lineno}:{exc.colno}: {what} is broken JSON ({exc.msg})",
                            path=str(path), where=f"line {exc.lineno}") from None
    except RecursionError:  # below MAX_DEPTH only where the interpreter's own stack is nearly used up
        raise MetadataError(f"{path}: {what} nests too deeply", path=str(path),
                            hint=_WRONG_FILE) from None
    _text_check(doc, path, what)
    return doc
