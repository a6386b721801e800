"""The metadata of a scan store, read back and checked: ``session.json`` as a typed
:class:`SessionInfo`, ``scan.json`` against its schema.

Both files are versioned (``format``) and described by JSON Schemas in ``schemas/``
(``session.schema.json``, ``scan.schema.json``) that give every number its range; every
violation is one :class:`~recon_cli.errors.MetadataError` naming the file and the line
(broken JSON) or the key (a missing key, a value of the wrong type or out of range), so a
reader can skip a bad scan with its reason instead of stopping.

Every JSON file of a scan store or a recording is read by :func:`load_json`, which refuses,
before anything is built from the file, one that

* is not a regular file (a FIFO, a device, a folder: nothing is opened that could block) or
  is larger than its limit (checked before it is read);
* is not UTF-8 or not JSON;
* nests lists and objects deeper than :data:`MAX_DEPTH` levels (checked before it is
  parsed: Python's parser recurses once per level);
* holds ``NaN``, ``Infinity`` or a number too large for a float (``1e999``): Python's JSON
  parser accepts them, and NaN passes every comparison-based range check;
* holds an integer of more than :data:`MAX_INT_DIGITS` digits, a key twice in one object
  (JSON parsers keep the last silently) or text that is not Unicode (a lone surrogate).

A pose (``world_T_camera_fk``, ``marker_T_camera``, ``world_T_marker``, ...) must also be a
rigid transform: a rotation and a translation, last row 0 0 0 1.
"""

from __future__ import annotations

import functools
import json
import math
import re
import stat
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from recon_cli.errors import MetadataError
from recon_cli.inputs import files

SESSION_FORMAT = 1
SCAN_FORMAT = 1

#: bytes of a scan store's own small files: scan.json, session.json, ground_truth.json, a
#: recording's intrinsics.json (recon writes a few kB)
MAX_METADATA_BYTES = 1_000_000
#: bytes of any other JSON file recon reads back (its reports, read for a report page)
MAX_JSON_BYTES = 16 * 2**20
#: nesting of lists and objects (recon's files nest 6 levels)
MAX_DEPTH = 32
#: digits of one integer (2^64 has 20)
MAX_INT_DIGITS = 30
#: how far a pose's rotation part may be from a rotation (entries of R^T R - I)
RIGID_TOLERANCE = 1e-3
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


def read_bytes(path: Path, what: str, max_bytes: int = MAX_METADATA_BYTES) -> bytes:
    """The bytes of a regular file of at most ``max_bytes`` bytes, or a MetadataError. The
    file's kind and size are checked before it is opened, and it is opened without
    blocking (a FIFO put in its place meanwhile is refused, not waited on)."""
    path = Path(path)

    def refuse(r: files.Refusal) -> MetadataError:
        if r.reason == files.MISSING or isinstance(r.error, FileNotFoundError):
            return MetadataError(f"{path}: {what} is missing", path=str(path))
        if r.reason == files.UNREADABLE:
            return MetadataError(f"{path}: {what} cannot be read ({r.error.strerror or r.error})", path=str(path))
        if r.reason == files.NOT_REGULAR:
            return MetadataError(f"{path}: {what} is not a regular file ({_kind(r.mode)})", path=str(path),
                                 hint="replace it with a regular file, or remove it")
        if r.reason == files.TOO_LARGE:
            return MetadataError(f"{path}: {what} has {r.size:,} bytes, more than the {max_bytes:,} recon reads",
                                 path=str(path), hint=_WRONG_FILE)
        return MetadataError(f"{path}: {what} grew past {max_bytes:,} bytes while it was read", path=str(path),
                             hint=_WRONG_FILE)

    return files.read_limited(path, max_bytes, refuse)


def load_json(path: Path, what: str, max_bytes: int = MAX_JSON_BYTES) -> Any:
    """The content of a JSON file (see the module docstring for what is refused), or a
    MetadataError with file:line:column where there is a line."""
    path = Path(path)
    data = read_bytes(path, what, max_bytes)
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


def _object(pairs: list) -> dict:
    out = dict(pairs)
    if len(out) != len(pairs):
        seen: set = set()
        key = next(k for k, _ in pairs if k in seen or seen.add(k))
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


@functools.cache
def _validator(name: str):
    import jsonschema

    from recon_cli.paths import SCHEMA_DIR

    schema = json.loads((SCHEMA_DIR / name).read_text())
    cls = jsonschema.validators.validator_for(schema)
    cls.check_schema(schema)
    return cls(schema)


def check(data: Any, schema: str, path: Path, what: str, hint: str | None = None) -> None:
    """Raise a MetadataError naming the key of the first (most relevant) schema violation."""
    import jsonschema

    if not isinstance(data, dict):
        kind = {list: "a list", str: "a string", int: "a number", float: "a number", bool: "a boolean",
                type(None): "null"}.get(type(data), type(data).__name__)
        raise MetadataError(f"{path}: {what} holds {kind}, not a JSON object", path=str(path),
                            hint=hint or f"see schemas/{schema} for what {what} holds")
    fmt = data.get("format")
    newest = _validator(schema).schema["properties"]["format"]["maximum"]
    if isinstance(fmt, int) and not isinstance(fmt, bool) and fmt > newest:
        raise MetadataError(f"{path}: {what} has format {fmt}, this recon reads format {newest} and older",
                            path=str(path), where="format", hint="update recon to read this scan store")
    error = jsonschema.exceptions.best_match(_validator(schema).iter_errors(data))
    if error is None:
        return
    where = "".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in error.absolute_path).lstrip(".")
    message = error.message if len(error.message) <= 160 else error.message[:157] + "..."
    raise MetadataError(f"{path}: {what} " + (f"key '{where}': " if where else "") + message,
                        path=str(path), where=where or None,
                        hint=hint or f"see schemas/{schema} for what {what} holds")


def check_pose(value: Any, path: Path, what: str, key: str) -> None:
    """Refuse (MetadataError) a 4 x 4 pose (already of finite, bounded numbers) that is not a
    rigid transform: rotation part orthonormal within RIGID_TOLERANCE with determinant +1,
    last row 0 0 0 1."""
    T = np.asarray(value, dtype=float)
    ok = T.shape == (4, 4) and bool(np.all(np.isfinite(T)))
    if ok:
        R = T[:3, :3]
        ok = (bool(np.allclose(T[3], (0.0, 0.0, 0.0, 1.0), rtol=0.0, atol=1e-9))
              and float(np.max(np.abs(R.T @ R - np.eye(3)))) <= RIGID_TOLERANCE and float(np.linalg.det(R)) > 0)
    if not ok:
        raise MetadataError(f"{path}: {what} key '{key}' is not a rigid transform (a rotation and a translation, "
                            "last row 0 0 0 1)", path=str(path), where=key,
                            hint="re-record the scan store, or repair the pose")


# --------------------------------------------------------------------- session.json
@dataclass(frozen=True)
class BoxInfo:
    """An axis-aligned box: centre and edge lengths [m] in ``frame`` (world or marker)."""

    center: tuple[float, float, float]
    size: tuple[float, float, float]
    frame: str = "world"

    def to_dict(self) -> dict:
        return {"frame": self.frame, "center": list(self.center), "size": list(self.size)}

    @classmethod
    def from_dict(cls, d: dict | None) -> BoxInfo | None:
        if d is None:
            return None
        return cls(tuple(map(float, d["center"])), tuple(map(float, d["size"])), d.get("frame", "world"))


def _pose(value) -> np.ndarray | None:
    return None if value is None else np.asarray(value, dtype=float)


@dataclass(frozen=True)
class SessionInfo:
    """What produced a scan store (``session.json``). Written by every acquisition session,
    read back by ``recon register``; a recorded store may leave any of it unknown (None)."""

    backend: str | None = None
    mode: str | None = None
    cell_kind: str | None = None
    safety_distance: float | None = None
    table_lift: float | None = None
    sensor: str | None = None
    noise: bool | None = None
    seed: int | None = None
    object_name: str | None = None
    world_T_object: np.ndarray | None = None
    object_box: BoxInfo | None = None
    crop_box: BoxInfo | None = None
    world_T_marker: np.ndarray | None = None
    script: str | None = None
    realism: dict[str, Any] | None = None  # the simulation's realism profile (name, file, effects on)
    created: float = field(default_factory=time.time)
    format: int = SESSION_FORMAT

    def to_dict(self) -> dict[str, Any]:
        return {
            "format": self.format, "created": self.created, "backend": self.backend, "mode": self.mode,
            "cell": {"kind": self.cell_kind, "safety_distance": self.safety_distance, "table_lift": self.table_lift},
            "sensor": self.sensor, "noise": self.noise, "seed": self.seed, "script": self.script,
            "object": None if self.object_name is None else {"name": self.object_name,
                                                             "world_T_object": self.world_T_object},
            "object_box": None if self.object_box is None else self.object_box.to_dict(),
            "crop_box": None if self.crop_box is None else self.crop_box.to_dict(),
            "world_T_marker": self.world_T_marker,
            **({} if self.realism is None else {"realism": self.realism}),
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> SessionInfo:
        """From a dict that passed ``schemas/session.schema.json``."""
        cell = d.get("cell") or {}
        obj = d.get("object") or {}
        return cls(
            backend=d.get("backend"), mode=d.get("mode"), cell_kind=cell.get("kind"),
            safety_distance=cell.get("safety_distance"), table_lift=cell.get("table_lift"),
            sensor=d.get("sensor"), noise=d.get("noise"), seed=d.get("seed"),
            object_name=obj.get("name"), world_T_object=_pose(obj.get("world_T_object")),
            object_box=BoxInfo.from_dict(d.get("object_box")), crop_box=BoxInfo.from_dict(d.get("crop_box")),
            world_T_marker=_pose(d.get("world_T_marker")), script=d.get("script"), realism=d.get("realism"),
            created=float(d.get("created", 0.0)), format=int(d.get("format", SESSION_FORMAT)))


def read_session(root: Path) -> SessionInfo:
    """``root/session.json`` checked and typed; an empty SessionInfo when there is none."""
    path = Path(root) / "session.json"
    if not path.exists():
        return SessionInfo(created=0.0)
    data = load_json(path, "session.json", MAX_METADATA_BYTES)
    check(data, "session.schema.json", path, "session.json",
          hint="repair or remove session.json (without it, pass the crop box with --box)")
    for key, value in (("world_T_marker", data.get("world_T_marker")),
                       ("object.world_T_object", (data.get("object") or {}).get("world_T_object"))):
        if value is not None:
            check_pose(value, path, "session.json", key)
    return SessionInfo.from_dict(data)


# --------------------------------------------------------------------- scan.json
def read_scan_meta(folder: Path) -> dict[str, Any]:
    """``folder/scan.json`` checked against ``schemas/scan.schema.json``."""
    path = Path(folder) / "scan.json"
    if not path.exists():
        raise MetadataError(f"{folder}: scan folder without scan.json", path=str(path),
                            hint="a scan needs scan.json beside its depth.png")
    data = load_json(path, "scan.json", MAX_METADATA_BYTES)
    check(data, "scan.schema.json", path, "scan.json")
    for key in ("world_T_camera_fk", "marker_T_camera"):
        if data.get(key) is not None:
            check_pose(data[key], path, "scan.json", key)
    return data
