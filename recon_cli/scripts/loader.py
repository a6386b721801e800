"""Loading an automation script: safe parse, xacro expansion, XSD validation, typed commands.

1. The file is parsed by lxml with entities, DTDs and network access off; a DOCTYPE is
   refused (scripts need none; it is where entity bombs and external entities live).
2. ``xacro:include`` files must be plain relative paths found beside the including file or
   in scripts_xml/, inside the script's folder or scripts_xml/ (no substitutions; the rule of
   ``readable.readable``); they get the same checks.
3. Every element is tagged with its file and line, xacro expands macros and properties
   (its expression evaluator refuses names like ``__import__``), and the tags are taken off
   again before validation, so each error names the line the user wrote (for elements made
   by a macro: the line in the macro's body).
4. The root picks the dialect: ``<recon>`` (schemas/recon_script.xsd) or the thesis system's
   ``<script>`` (schemas/thesis_script.xsd); the XSD validates, and the elements become
   typed commands (``commands``).
"""

from __future__ import annotations

import re
import shutil
import tempfile
from pathlib import Path

from lxml import etree

from recon_cli.errors import FileError, ScriptError
from recon_cli.expansion.annotate import SRC_ATTR, Annotated, expansion_error, parser, untag
from recon_cli.expansion.readable import script_rule
from recon_cli.expansion.sandbox import LIMITS, sandboxed
from recon_cli.paths import SCHEMA_DIR, SCRIPTS_DIR
from recon_cli.scripts import commands as C
from recon_cli.scripts.build import as_bool, build_recon, build_thesis

DIALECTS = {"recon": "recon_script.xsd", "script": "thesis_script.xsd"}
MAX_BYTES = LIMITS.max_file_bytes


def _parser() -> etree.XMLParser:
    return parser()


def expand(path: Path) -> tuple[etree._Element, dict[etree._Element, C.Source], str]:
    """Parse, check and xacro-expand a script in the sandbox: (root, element -> source,
    expanded XML)."""
    import xacro

    path = Path(path)
    tmp = Path(tempfile.mkdtemp(prefix="recon-script-"))
    try:
        files = Annotated(tmp, script_rule(path.resolve().parent), "script", MAX_BYTES)
        files.display[path.resolve()] = path.name
        if not path.is_file():
            raise FileError(f"script {path} does not exist", hint="check the path")
        main = files.add(path)
        frames = None
        try:
            with sandboxed(files.rule, includes=files.includes) as frames:
                doc = xacro.process_file(str(main))
                text = doc.toxml()
        except Exception as exc:  # xacro reports macro/property errors as exceptions
            raise expansion_error(path.name, exc, frames, files) from None
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    try:
        root = etree.fromstring(text.encode(), _parser())
    except etree.XMLSyntaxError as exc:  # xacro:element, xacro:attribute and expressions can make anything
        raise _not_xml(path, doc, exc) from None
    tagged = {}
    for el, tagged_at in untag(root).items():
        file, _, line = tagged_at.rpartition(":")
        tagged[el] = C.Source(file, int(line))
    expanded = etree.tostring(root, pretty_print=True, encoding="unicode")
    # re-parse so that line numbers (of validation errors) refer to the expanded text
    clean = etree.fromstring(expanded.encode(), _parser())
    old = [e for e in root.iter() if isinstance(e.tag, str)]
    new = [e for e in clean.iter() if isinstance(e.tag, str)]
    sources = {n: tagged[o] for o, n in zip(old, new, strict=True) if o in tagged}
    return clean, sources, expanded


_NOT_XML_CHAR = re.compile("[^\t\n\r\x20-\ud7ff\ue000-\ufffd\U00010000-\U0010ffff]")
_MAX_NAME = 50_000  # libxml2's longest name


def _name_problem(kind: str, name: str, prefixes: frozenset[str]) -> str | None:
    """Why ``name`` is no XML element or attribute name (a QName whose prefix is declared
    in ``prefixes``), or None; ``kind``: "element name" or "attribute name"."""
    if len(name) > _MAX_NAME:
        return f"an {kind} of {len(name)} characters, more than the {_MAX_NAME} an XML parser reads"
    parts = name.split(":")
    shown = f"{name[:40]!r}{'...' if len(name) > 40 else ''}"
    if len(parts) > 2 or not all(_ncname(part) for part in parts):
        return f"an invalid {kind} {shown}"
    if len(parts) == 2 and parts[0] not in prefixes:
        return f"an {kind} {shown} whose prefix '{parts[0]}' is not declared"
    return None


def _ncname(part: str) -> bool:
    try:
        etree.Element(part)
    except ValueError:
        return False
    return True


def _not_xml(path: Path, doc, exc: etree.XMLSyntaxError) -> ScriptError:
    """One line for an expansion that is not XML: the first element (in document order)
    with an invalid name, attribute name or character, at the source line of that
    element or of the nearest one above it that the user wrote."""
    hint = ("xacro:element and xacro:attribute need XML names (a letter or '_' first, then letters, digits, '-', "
            "'.', '_'; at most one ':'), and values need characters XML allows")
    stack = [(doc.documentElement, path.name, frozenset({"xml", "xmlns"}))]
    while stack:
        node, where, prefixes = stack.pop()
        own = node.getAttribute(SRC_ATTR)
        where = own or where
        prefixes = prefixes | {name[6:] for name in node.attributes.keys() if name.startswith("xmlns:")}
        what = _name_problem("element name", node.tagName, prefixes)
        if not what:
            for name, value in node.attributes.items():
                if name == SRC_ATTR:
                    continue
                bad = _NOT_XML_CHAR.search(value)
                what = _name_problem("attribute name", name, prefixes) or (bad and (
                    f"the character U+{ord(bad.group()):04X}, which XML does not allow, in the attribute {name!r}"))
                if what:
                    break
        for child in node.childNodes:
            if child.nodeType in (child.TEXT_NODE, child.CDATA_SECTION_NODE) and not what:
                bad = _NOT_XML_CHAR.search(child.data)
                if bad:
                    what = f"the character U+{ord(bad.group()):04X}, which XML does not allow, in a text"
        if what:
            inside = "" if own else " (in an element made inside the element of this line)"
            return ScriptError(f"{where}: the expansion produced {what}{inside}", hint=hint, source=where)
        stack.extend((child, where, prefixes) for child in reversed(node.childNodes)
                     if child.nodeType == child.ELEMENT_NODE)
    return ScriptError(f"{path.name}: the expansion is not XML ({exc.msg})", hint=hint, source=path.name)


def shipped_or_given(path: Path) -> Path:
    """``scripts_xml/NAME`` (or ``NAME``) that is not a file here names a shipped script,
    wherever recon is installed; any other path as given."""
    path = Path(path)
    if not path.exists() and path.parent.name in ("", "scripts_xml") and (SCRIPTS_DIR / path.name).is_file():
        return SCRIPTS_DIR / path.name
    return path


def load_script(path: Path) -> C.Script:
    """Expand, validate and compile a script file into typed commands (``scripts_xml/NAME``
    finds the shipped scripts from any folder)."""
    path = shipped_or_given(path)
    root, sources, expanded = expand(path)
    localname = etree.QName(root).localname
    dialect = {"recon": "recon", "script": "thesis"}.get(localname)
    if dialect is None or etree.QName(root).namespace:
        raise ScriptError(f"{path}:{root.sourceline}: unknown root element <{root.tag!s}>",
                          hint="a script starts with <recon name=...> or the thesis system's <script name=...>")
    schema = etree.XMLSchema(etree.parse(str(SCHEMA_DIR / DIALECTS[localname])))
    if not schema.validate(root):
        err = schema.error_log[0]
        src = _source_at(root, err.line, sources) or C.Source(path.name, err.line)
        message = err.message.replace("{http://www.ros.org/wiki/xacro}", "xacro:")
        raise ScriptError(f"{src}: {message}", hint=f"see schemas/{DIALECTS[localname]}")
    build = build_recon if dialect == "recon" else build_thesis
    cmds: list[C.Command] = []
    for el in root:
        if not isinstance(el.tag, str):
            continue
        src = sources.get(el, C.Source(path.name, el.sourceline or 0))
        cmds.extend(build(el, src))
        if len(cmds) > LIMITS.max_commands:
            raise ScriptError(f"{src}: the script has more than the limit of {LIMITS.max_commands} commands",
                              hint="split it into several scripts")
    if dialect == "recon":
        name, on_failure, optimize = root.get("name", ""), root.get("on_failure", "skip"), as_bool(root.get("optimize"))
    else:
        name, on_failure, optimize = root.get("name", ""), "skip", as_bool(root.get("optimization"))
    return C.Script(str(path), name, dialect, on_failure, optimize, tuple(cmds), expanded)


def _source_at(root, line: int, sources) -> C.Source | None:
    for el in root.iter():
        if isinstance(el.tag, str) and el.sourceline == line and el in sources:
            return sources[el]
    return None
