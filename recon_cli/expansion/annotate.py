"""A user's xacro file and the files it includes, checked and tagged before xacro sees them.

1. Each file is read through the size guard and parsed by lxml with entities, DTDs and
   network access off; a DOCTYPE is refused (neither scripts nor robot descriptions need
   one; it is where entity bombs and external entities live).
2. ``xacro:include`` names a plain relative path (no substitutions), resolved by the read
   rule (:mod:`.readable`) beside the including file; the included file gets the same checks.
3. Every element is tagged with its file and line (attribute :data:`SRC_ATTR`) and every
   macro call is preceded by a ``<?recon-src file:line?>`` instruction, so that an error of
   the expansion names the line the user wrote; the tagged copies go to a scratch folder,
   includes pointing at the copies (the only files the sandboxed xacro may include).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from lxml import etree

from recon_cli.errors import FileError, LimitError, ScriptError
from recon_cli.expansion.expressions import LIMITS, SandboxError
from recon_cli.expansion.readable import ReadRule, readable
from recon_cli.expansion.sandbox import PI_TARGET
from recon_cli.inputs.files import file_errors, read_limited

XACRO_NS = "http://www.ros.org/wiki/xacro"
SRC_ATTR = "recon_source"

# xacro directives; every other xacro:NAME element is a macro call
_DIRECTIVES = {"macro", "property", "include", "arg", "if", "unless", "insert_block", "element", "attribute"}


def parser() -> etree.XMLParser:
    """lxml's parser with entities, DTDs, network access and huge trees off."""
    return etree.XMLParser(resolve_entities=False, no_network=True, load_dtd=False, dtd_validation=False,
                           huge_tree=False, remove_blank_text=False)


def parse_file(path: Path, what: str, max_bytes: int, shown: str | None = None) -> etree._ElementTree:
    """A user's XML file through the size guard and the safe parser (``what``: "script",
    "robot description"; ``shown``: its name in messages)."""
    label = shown or str(path)
    refuse = file_errors(Path(label), f"the {what}", f"give a {what} file",
                         lambda size: (f"too large: {size:,} bytes, more than a {what} may hold ({max_bytes:,})",
                                       f"{what}s are limited to {max_bytes // 1_000_000} MB"))
    data = read_limited(path, max_bytes, refuse, empty=False)
    try:
        tree = etree.ElementTree(etree.fromstring(data, parser()))
    except etree.XMLSyntaxError as exc:
        line, col = exc.position if exc.position else (0, 0)
        raise ScriptError(f"{label}:{line}:{col}: not well-formed XML ({exc.msg})",
                          hint="fix the XML syntax") from None
    if tree.docinfo.doctype or tree.docinfo.internalDTD is not None:
        raise ScriptError(f"{label}:1: DOCTYPE declarations are not allowed in a {what}",
                          hint="remove the <!DOCTYPE ...> (and any entities); use xacro properties instead")
    return tree


@dataclass
class Annotated:
    """The tagged copies of a user's xacro file and its includes."""

    out_dir: Path
    rule: ReadRule
    what: str
    max_bytes: int
    max_files: int = LIMITS.max_files
    full_names: bool = False  # name files in messages by their full path (else by their name)
    copies: dict[Path, Path] = field(default_factory=dict)  # the user's file -> its copy
    display: dict[Path, str] = field(default_factory=dict)  # the user's file -> its name in messages

    @property
    def includes(self) -> frozenset[str]:
        """The copies, as xacro:include names them."""
        return frozenset(str(c) for c in self.copies.values())

    @property
    def originals(self) -> dict[str, Path]:
        """copy -> the user's file."""
        return {str(c): p for p, c in self.copies.items()}

    def shown(self, text: str) -> str:
        """``text`` with the copies' paths replaced by the user's file names."""
        for original, copy in self.copies.items():
            text = text.replace(str(copy), self.display.get(original, original.name))
        return text

    def add(self, path: Path, include: Callable[[str, Path, str], Path] | None = None) -> Path:
        """Check and copy ``path`` (a real path) and, recursively, what it includes; the copy's path.
        ``include(name, here, where)`` resolves an include (default: the read rule)."""
        path = path.resolve()
        if path in self.copies:
            return self.copies[path]
        label = self.display.setdefault(path, self._name(path))
        if len(self.copies) >= self.max_files:
            raise SandboxError(f"{label}: the {self.what} includes more than the limit of {self.max_files} files",
                               hint="merge macro files")
        tree = parse_file(path, self.what, self.max_bytes, label)
        target = self.out_dir / f"{len(self.copies):03d}.xml"
        self.copies[path] = target
        resolve = include or self._include
        for el in tree.getroot().iter():
            if not isinstance(el.tag, str):
                continue
            if el.tag == f"{{{XACRO_NS}}}include":
                where = f"{label}:{el.sourceline}"
                included = resolve(el.get("filename", ""), path.parent, where)
                self.display.setdefault(included, self._name(included))
                el.set("filename", str(self.add(included, include)))
            elif not el.tag.startswith(f"{{{XACRO_NS}}}"):
                el.set(SRC_ATTR, f"{label}:{el.sourceline}")
            elif etree.QName(el).localname not in _DIRECTIVES and el.getparent() is not None:
                # before the comments right above the call, which xacro removes with the call
                first = el
                while isinstance(above := first.getprevious(), etree._Comment) and not (above.tail or "").strip():
                    first = above
                first.addprevious(etree.ProcessingInstruction(PI_TARGET, f"{label}:{el.sourceline}"))
        tree.write(str(target), xml_declaration=True, encoding="utf-8")
        return target

    def _name(self, path: Path) -> str:
        return str(path) if self.full_names else path.name

    def _include(self, name: str, here: Path, where: str) -> Path:
        if not name or any(ch in name for ch in "$(){}"):
            raise ScriptError(f"{where}: xacro:include filename {name!r} must be a plain relative path",
                              hint=f"include files beside the {self.rule.owner} or in {self.rule.shared.name}/ by a "
                                   "relative path, e.g. macros.xacro", source=where)
        return readable(name, self.rule, where, "included file", beside=here)


def untag(root: etree._Element) -> dict[etree._Element, str]:
    """Take the processing instructions and source tags off an expanded tree; element ->
    ``file:line`` of the elements that had one."""
    for pi in root.xpath("//processing-instruction()"):
        if pi.getparent() is not None:
            pi.getparent().remove(pi)
    tagged = {}
    for el in root.iter():
        if isinstance(el.tag, str) and (at := el.get(SRC_ATTR)):
            tagged[el] = at
            del el.attrib[SRC_ATTR]
    etree.cleanup_namespaces(root)
    return tagged


def expansion_error(name: str, exc: BaseException, frames, annotated: Annotated | None) -> ScriptError:
    """One line for an error of the expansion: where (the element or macro call being
    expanded, and the macro calls that led there) and what (``name``: the user's file)."""
    cause: BaseException | None = exc
    seen = set()
    while cause is not None and not isinstance(cause, SandboxError) and id(cause) not in seen:
        seen.add(id(cause))
        cause = getattr(cause, "exc", None) or cause.__cause__ or cause.__context__
    limit = None
    if isinstance(cause, SandboxError):
        what, hint, limit = cause.message, cause.hint, cause
    elif isinstance(exc, RecursionError):
        what, hint = "macros or properties recurse without end", "end the recursion with xacro:if"
    elif isinstance(exc, FileError):
        what, hint = exc.message, exc.hint
    else:
        what = " ".join(str(exc).split()) or type(exc).__name__
        what, hint = f"xacro: {what}", "fix the macro call or property"
    if annotated is not None:
        what = annotated.shown(what)
    stack = (frames.failure or frames.stack) if frames is not None else []
    where = stack[-1][1] if stack else name
    calls = [src for kind, src in stack if kind == "macro" and src != where]
    if calls:
        what += " (in macro called at " + ", called at ".join(reversed(calls)) + ")"
    if limit is not None:
        return LimitError(f"{where}: {what}", hint=hint, limit=limit.limit, bound=limit.bound)
    return ScriptError(f"{where}: {what}", hint=hint, source=where)
