"""The one YAML reader: every YAML file recon reads (station, camera, realism, batch,
calibration, cell and the shipped robot/ files) goes through :func:`read_yaml`.

A YAML file is refused, with one line naming ``file:line``, before anything is built from it
when it

* is larger than its kind's size limit (checked before it is read);
* uses an alias (``*name``) or a merge key (``<<``): aliases let a few kB expand to
  gigabytes ("billion laughs"), and no recon file needs them;
* carries a tag (``!!python/object``, ``!custom``, even ``!!str``): recon's files hold plain
  values only;
* nests deeper than :attr:`YamlLimits.max_depth`, holds more than :attr:`YamlLimits.max_nodes`
  values, a text longer than :attr:`YamlLimits.max_text` or an integer longer than
  :attr:`YamlLimits.max_int_digits` digits;
* holds a key twice in one mapping (YAML would silently keep the last), or a key that is
  not a name or a number;
* holds a non-finite number anywhere (``.nan``, ``.inf``, ``1e999``): no recon setting
  takes one, and NaN passes every comparison-based range check; the refusal names the key
  path (``hand_eye[0][3]``);
* is, or lies behind, a link leading out of the folder it belongs to, when the caller names
  that folder (``root``): refused before it is read.

No refusal quotes what was read: it names the file, the line, the key path (a key is shown
when it is a plain name, :func:`shown_key`) and what was expected, never a value, a tag, an
anchor or a piece of the text (a file linked to a system file must not be shown in a log).

What it returns are plain dicts and lists (:class:`Map`, :class:`Seq`) that also know the line
of every key and item, so that later checks (the schemas of :mod:`.schema`) name
``file:line`` too.
"""

from __future__ import annotations

import errno
import math
import re
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from recon_cli.errors import FileError, InputError
from recon_cli.inputs import files


@dataclass(frozen=True)
class YamlLimits:
    """What one YAML file may hold (docs/inputs.md has the table)."""

    max_bytes: int = 1_000_000  # station, camera, realism, batch and cell files are a few kB
    max_depth: int = 32  # nested mappings and lists
    max_nodes: int = 200_000  # scalars, mappings and lists together
    max_text: int = 10_000  # characters of one text value or key
    max_int_digits: int = 30  # digits of one integer (2^64 has 20)


LIMITS = YamlLimits()


class Map(dict):
    """A YAML mapping; ``lines[key]`` is the 1-based line of the key, ``line`` the mapping's."""

    lines: dict
    line: int = 0


class Seq(list):
    """A YAML sequence; ``lines[i]`` is the 1-based line of item i, ``line`` the sequence's."""

    lines: list
    line: int = 0


#: a key shown in messages: a plain name of at most 64 characters (other keys are "a key")
_PLAIN_KEY = re.compile(r"[A-Za-z_][A-Za-z0-9_-]{0,63}")


def shown_key(key: Any) -> str | None:
    """``key`` as it may appear in a message (a plain name, or a number of a mapping with
    number keys), else None: a key that is not a name is not echoed."""
    if isinstance(key, bool):
        return None
    if isinstance(key, int):
        return str(key)
    if isinstance(key, str) and _PLAIN_KEY.fullmatch(key):
        return key
    return None


def unknown_key_text(where: str, key: Any) -> str:
    """``where.key is not a known key``, the key shown only when it is a plain name."""
    name = shown_key(key)
    if name is not None:
        return f"{where}.{name} is not a known key"
    return f"{where} has a key that is not a known key (nor a plain name)"


def key_path(path) -> str:
    """``a.b[2].c`` of a path of keys and list indices (a key that is not a plain name is
    written ``<key>``)."""
    out = ""
    for part in path:
        if isinstance(part, int) and not isinstance(part, bool):
            out += f"[{part}]"
        else:
            name = shown_key(part) or "<key>"
            out += f".{name}" if out else name
    return out


class _Bad:
    """A scalar the loader could not accept (a non-finite number, a number it cannot read),
    left in the document so that the refusal can name its key path."""

    __slots__ = ("line", "problem", "hint")

    def __init__(self, line: int, problem: str, hint: str) -> None:
        self.line, self.problem, self.hint = line, problem, hint


def _first_bad(doc: Any, path: list) -> tuple[_Bad, list] | None:
    """The first :class:`_Bad` of ``doc`` in document order, with its key path."""
    if isinstance(doc, _Bad):
        return doc, path
    if isinstance(doc, dict):
        items: Iterable[tuple[Any, Any]] = doc.items()
    elif isinstance(doc, list):
        items = enumerate(doc)
    else:
        return None
    for key, value in items:
        found = _first_bad(value, [*path, key])
        if found is not None:
            return found
    return None


#: quoted parts of a parser's problem that are YAML syntax, not the file's text
_SYNTAX = re.compile(r"<[a-z ]+>|[-,\[\]{}:?|>!&*#%@`'\"]")


def _problem_text(problem: str) -> str:
    """A parser's problem without what it quotes of the file (``found character '\\t'``
    becomes ``found character``; quoted syntax characters such as ``','`` stay)."""
    def keep(m: re.Match) -> str:
        inner = m.group(0)[1:-1]
        return m.group(0) if _SYNTAX.fullmatch(inner) else ""
    text = re.sub(r"'(?:[^'\\]|\\.)*'|\"(?:[^\"\\]|\\.)*\"", keep, problem)
    text = re.sub(r"\s+", " ", text).strip(" ,;")
    return text if re.fullmatch(r"[A-Za-z0-9 ,;<>'\-:\[\]{}?|!&*#%@`]*", text) else "a syntax error"


class _Refused(Exception):
    """A refusal found while parsing; carries the 1-based line."""

    def __init__(self, line: int, message: str, hint: str | None = None) -> None:
        super().__init__(message)
        self.line = line
        self.message = message
        self.hint = hint


def _scan_events(text: str, limits: YamlLimits, loader) -> None:
    """Walk the event stream (no values are built): aliases, tags, depth and size."""

    depth = nodes = 0
    for event in yaml.parse(text, Loader=loader):
        line = event.start_mark.line + 1 if event.start_mark is not None else 0
        if isinstance(event, yaml.AliasEvent):
            raise _Refused(line, "an alias (*name) is not accepted",
                           "write the value out where it is needed (recon's files take no aliases or anchors)")
        if isinstance(event, yaml.NodeEvent):
            nodes += 1
            if nodes > limits.max_nodes:
                raise _Refused(line, f"more than {limits.max_nodes:,} values", "this is not a recon input file")
            tag = getattr(event, "tag", None)
            if tag is not None and tag != "!":
                raise _Refused(line, "a tag (!name or !!type) is not accepted",
                               "remove the tag: recon's files hold plain values")
            if isinstance(event, yaml.ScalarEvent) and len(event.value) > limits.max_text:
                raise _Refused(line, f"a value of {len(event.value):,} characters (at most {limits.max_text:,})",
                               "this is not a recon input file")
        if isinstance(event, yaml.CollectionStartEvent):
            depth += 1
            if depth > limits.max_depth:
                raise _Refused(line, f"nested more than {limits.max_depth} levels deep",
                               "this is not a recon input file")
        elif isinstance(event, yaml.CollectionEndEvent):
            depth -= 1


_FLOAT_1_2 = re.compile(r"^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9_]+)[eE][-+]?[0-9]+$")


def _loader_class(limits: YamlLimits):

    base = getattr(yaml, "CSafeLoader", yaml.SafeLoader)

    class Loader(base):  # type: ignore[misc, valid-type]
        def construct_mapping(self, node, deep=False):  # noqa: D102
            out = Map()
            out.lines = {}
            out.line = node.start_mark.line + 1
            for key_node, value_node in node.value:
                line = key_node.start_mark.line + 1
                if key_node.tag == "tag:yaml.org,2002:merge":
                    raise _Refused(line, "merge key << is not accepted", "write the keys out")
                if not isinstance(key_node, yaml.ScalarNode):
                    raise _Refused(line, "a key must be a name, not a list or a mapping")
                key = self.construct_object(key_node, deep=True)
                if key is None or not isinstance(key, str | int | float | bool):
                    raise _Refused(line, "a key is empty or not a name")
                if key in out:
                    name = shown_key(key)
                    raise _Refused(line, f"{'key ' + name if name else 'a key'} appears twice in one mapping "
                                         f"(also line {out.lines[key]})", "keep one of them")
                out[key] = self.construct_object(value_node, deep=True)
                out.lines[key] = line
            return out

        def construct_sequence(self, node, deep=False):  # noqa: D102
            out = Seq(self.construct_object(child, deep=True) for child in node.value)
            out.lines = [child.start_mark.line + 1 for child in node.value]
            out.line = node.start_mark.line + 1
            return out

        def construct_yaml_int(self, node):  # noqa: D102
            digits = sum(c.isdigit() for c in node.value)
            if digits > limits.max_int_digits:
                raise _Refused(node.start_mark.line + 1, f"an integer of {digits} digits "
                               f"(at most {limits.max_int_digits})", "write a number of sensible size")
            try:
                return super().construct_yaml_int(node)
            except ValueError:
                return _Bad(node.start_mark.line + 1, "is not a number", "write a plain number, e.g. 0.5")

        def construct_yaml_float(self, node):  # noqa: D102
            try:
                value = super().construct_yaml_float(node)
            except ValueError:
                return _Bad(node.start_mark.line + 1, "is not a number", "write a plain number, e.g. 0.5")
            if not math.isfinite(value):  # refused with its key path once the document is built
                return _Bad(node.start_mark.line + 1, f"= {value} is not a finite number",
                            "NaN and infinity are not accepted; write a number")
            return value

        def construct_undefined(self, node):  # noqa: D102
            raise _Refused(node.start_mark.line + 1, "a tag (!name or !!type) is not accepted",
                           "remove the tag: recon's files hold plain values")

    # numbers as YAML 1.2 and every other program read them: 1e-3 is a number, not a text
    Loader.add_implicit_resolver("tag:yaml.org,2002:float", _FLOAT_1_2, list("-+0123456789."))
    Loader.add_constructor("tag:yaml.org,2002:timestamp", Loader.construct_yaml_str)  # dates stay text
    Loader.add_constructor("tag:yaml.org,2002:map", Loader.construct_mapping)
    Loader.add_constructor("tag:yaml.org,2002:seq", Loader.construct_sequence)
    Loader.add_constructor("tag:yaml.org,2002:int", Loader.construct_yaml_int)
    Loader.add_constructor("tag:yaml.org,2002:float", Loader.construct_yaml_float)
    for tag in ("tag:yaml.org,2002:omap", "tag:yaml.org,2002:pairs", "tag:yaml.org,2002:set",
                "tag:yaml.org,2002:binary"):
        Loader.add_constructor(tag, Loader.construct_undefined)
    Loader.add_constructor(None, Loader.construct_undefined)
    return Loader


def parse_yaml(text: str, where: str, limits: YamlLimits = LIMITS):
    """The document of YAML ``text`` (:class:`Map` / :class:`Seq` / a scalar / None);
    ``where`` names it in errors (``where:line: problem``)."""

    if len(text) > limits.max_bytes:
        raise InputError(f"{where}: {len(text):,} characters, more than a recon YAML file may hold "
                         f"({limits.max_bytes:,} bytes)", hint="this is not a recon input file")
    loader = _loader_class(limits)
    try:
        _scan_events(text, limits, loader)
        doc = yaml.load(text, Loader=loader)  # noqa: S506 (a SafeLoader with aliases and tags refused)
        bad = _first_bad(doc, [])
        if bad is not None:
            value, path = bad
            name = key_path(path) or "the file's value"
            raise _Refused(value.line, f"{name} {value.problem}", value.hint)
        return doc
    except _Refused as exc:
        raise InputError(f"{where}:{exc.line}: {exc.message}", hint=exc.hint) from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None) or getattr(exc, "context_mark", None)
        at = f"{where}:{mark.line + 1}" if mark is not None else where
        problem = _problem_text(getattr(exc, "problem", None) or "a syntax error")
        raise InputError(f"{at}: not valid YAML ({problem})", hint="check the indentation and the quotes") from None
    except RecursionError:
        raise InputError(f"{where}: nested too deeply", hint="this is not a recon input file") from None


def read_text(path: Path, what: str, *, hint: str | None = None, limits: YamlLimits = LIMITS,
              root: Path | None = None) -> str:
    """The text of a YAML file, refused when missing, unreadable, not a file or too large
    (its size is checked before it is read); with ``root``, also when it is or lies behind a
    link leading out of that folder (before it is opened)."""
    path = Path(path)

    def refuse(r: files.Refusal) -> FileError:
        if r.reason == files.OUTSIDE:  # the link's name, never where it leads
            folder = Path(r.root or path.parent).absolute()
            if r.link is None or r.link == path:
                return FileError(f"{what} {path} is a link leading out of its folder {folder}; not read",
                                 hint="copy the file into the folder instead of linking it")
            return FileError(f"{what} {path} lies behind the link {r.link}, which leads out of {folder}; not read",
                             hint="copy the file into the folder instead of linking it")
        if r.reason == files.MISSING or (r.reason == files.UNREADABLE and not r.opened and r.error is not None
                                         and r.error.errno in (errno.ENOENT, errno.ENOTDIR, errno.EBADF, errno.ELOOP)):
            return FileError(f"{what} {path} does not exist", hint=hint)
        if r.reason == files.UNREADABLE and r.error is not None:
            return FileError(f"cannot read the {what} {path} ({r.error.strerror or r.error})", hint=hint)
        if r.reason == files.NOT_REGULAR:
            return FileError(f"{what} {path} is not a file", hint=hint)
        if r.reason == files.TOO_LARGE:
            return FileError(f"{what} {path} has {r.size:,} bytes, more than a {what} may hold "
                             f"({limits.max_bytes:,})", hint="this is not a recon input file")
        return FileError(f"{what} {path} is larger than {limits.max_bytes:,} bytes",
                         hint="this is not a recon input file")

    try:
        data = files.read_limited(path, limits.max_bytes, refuse, root=root)
    except ValueError:  # a path that cannot be encoded (a NUL byte)
        raise FileError(f"{what} {path} does not exist", hint=hint) from None
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise FileError(f"{what} {path} is not UTF-8 text (byte {exc.start})",
                        hint="save it as UTF-8 text") from None


def read_yaml(path: Path, what: str = "YAML file", *, hint: str | None = None, limits: YamlLimits = LIMITS,
              root: Path | None = None):
    """The document of a YAML file (see the module docstring for what is refused); ``root``:
    the folder the file belongs to (a link leading out of it is refused before reading)."""
    return parse_yaml(read_text(path, what, hint=hint, limits=limits, root=root), str(path), limits)


def line_of(container, key) -> int | None:
    """The 1-based line of ``container[key]`` when ``container`` was read here, else None."""
    lines = getattr(container, "lines", None)
    if isinstance(lines, dict):
        return lines.get(key)
    if isinstance(lines, list) and isinstance(key, int) and 0 <= key < len(lines):
        return lines[key]
    return getattr(container, "line", None) or None


def plain(doc):
    """``doc`` with plain dicts and lists (for writing it out again with yaml.safe_dump)."""
    if isinstance(doc, dict):
        return {k: plain(v) for k, v in doc.items()}
    if isinstance(doc, list):
        return [plain(v) for v in doc]
    return doc
