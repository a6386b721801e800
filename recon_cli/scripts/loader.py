"""Loading an automation script: safe parse, xacro expansion, XSD validation, typed commands.

1. The file is parsed by lxml with entities, DTDs and network access off; a DOCTYPE is
   refused (scripts need none; it is where entity bombs and external entities live).
2. ``xacro:include`` files must be plain relative paths found beside the script or in
   scripts_xml/ (no substitutions, nothing outside those folders); they get the same checks.
3. Every element is tagged with its file and line, xacro expands macros and properties
   (its expression evaluator refuses names like ``__import__``), and the tags are taken off
   again before validation, so each error names the line the user wrote (for elements made
   by a macro: the line in the macro's body).
4. The root picks the dialect: ``<recon>`` (schemas/recon_script.xsd) or the thesis system's
   ``<script>`` (schemas/thesis_script.xsd); the XSD validates, and the elements become
   typed commands (``commands``).
"""

from __future__ import annotations

import math
import shutil
import tempfile
from pathlib import Path

import numpy as np
from lxml import etree

from recon_cli.errors import FileError, LimitError, ScriptError
from recon_cli.geometry.view import Frame, View
from recon_cli.paths import SCHEMA_DIR, SCRIPTS_DIR
from recon_cli.scripts import commands as C
from recon_cli.scripts.sandbox import LIMITS, PI_TARGET, SandboxError, sandboxed

XACRO_NS = "http://www.ros.org/wiki/xacro"
SRC_ATTR = "recon_source"
DIALECTS = {"recon": "recon_script.xsd", "script": "thesis_script.xsd"}
MAX_BYTES = LIMITS.max_file_bytes


def _parser() -> etree.XMLParser:
    return etree.XMLParser(resolve_entities=False, no_network=True, load_dtd=False, dtd_validation=False,
                           huge_tree=False, remove_blank_text=False)


def _parse_file(path: Path) -> etree._ElementTree:
    if not path.is_file():
        raise FileError(f"script {path} does not exist", hint="check the path")
    if path.stat().st_size > MAX_BYTES:
        raise ScriptError(f"{path}: {path.stat().st_size} bytes is too large for a script",
                          hint=f"scripts are limited to {MAX_BYTES // 1_000_000} MB")
    try:
        tree = etree.parse(str(path), _parser())
    except etree.XMLSyntaxError as exc:
        line, col = exc.position if exc.position else (0, 0)
        raise ScriptError(f"{path}:{line}:{col}: not well-formed XML ({exc.msg})",
                          hint="fix the XML syntax") from None
    if tree.docinfo.doctype or tree.docinfo.internalDTD is not None:
        raise ScriptError(f"{path}:1: DOCTYPE declarations are not allowed in scripts",
                          hint="remove the <!DOCTYPE ...> (and any entities); use xacro properties instead")
    return tree


def _resolve_include(name: str, here: Path, where: str) -> Path:
    if not name or any(ch in name for ch in "$(){}") or Path(name).is_absolute():
        raise ScriptError(f"{where}: xacro:include filename {name!r} must be a plain relative path",
                          hint="include files beside the script or in scripts_xml/, e.g. macros.xml")
    for base in (here, SCRIPTS_DIR):
        candidate = (base / name).resolve()
        if candidate.is_file() and (candidate.is_relative_to(here.resolve())
                                    or candidate.is_relative_to(SCRIPTS_DIR.resolve())):
            return candidate
    raise ScriptError(f"{where}: included file {name!r} not found beside the script or in scripts_xml/",
                      hint="check the filename")


# xacro directives; every other xacro:NAME element is a macro call
_DIRECTIVES = {"macro", "property", "include", "arg", "if", "unless", "insert_block", "element", "attribute"}


def _annotate(path: Path, out_dir: Path, copies: dict[Path, Path], display: dict[Path, str]) -> Path:
    """Copy ``path`` into out_dir with every element tagged file:line, every macro call
    preceded by a ``<?recon-src file:line?>`` instruction, and includes resolved to their
    tagged copies. Returns the copy's path."""
    path = path.resolve()
    if path in copies:
        return copies[path]
    if len(copies) >= LIMITS.max_files:
        raise SandboxError(f"{display.get(path, path.name)}: the script includes more than the limit of "
                           f"{LIMITS.max_files} files", hint="merge macro files")
    tree = _parse_file(path)
    target = out_dir / f"{len(copies):03d}_{path.name}"
    copies[path] = target
    label = display.setdefault(path, path.name)
    for el in tree.getroot().iter():
        if not isinstance(el.tag, str):
            continue
        if el.tag == f"{{{XACRO_NS}}}include":
            where = f"{label}:{el.sourceline}"
            included = _resolve_include(el.get("filename", ""), path.parent, where)
            display.setdefault(included, included.name)
            el.set("filename", str(_annotate(included, out_dir, copies, display)))
        elif not el.tag.startswith(f"{{{XACRO_NS}}}"):
            el.set(SRC_ATTR, f"{label}:{el.sourceline}")
        elif etree.QName(el).localname not in _DIRECTIVES and el.getparent() is not None:
            el.addprevious(etree.ProcessingInstruction(PI_TARGET, f"{label}:{el.sourceline}"))
    tree.write(str(target), xml_declaration=True, encoding="utf-8")
    return target


def expand(path: Path) -> tuple[etree._Element, dict[etree._Element, C.Source], str]:
    """Parse, check and xacro-expand a script in the sandbox: (root, element -> source,
    expanded XML)."""
    import xacro

    path = Path(path)
    tmp = Path(tempfile.mkdtemp(prefix="recon-script-"))
    try:
        main = _annotate(path, tmp, {}, {path.resolve(): path.name})
        roots = (path.resolve().parent, SCRIPTS_DIR.resolve())
        frames = None
        try:
            with sandboxed(roots[0], roots) as frames:
                doc = xacro.process_file(str(main))
                text = doc.toxml()
        except Exception as exc:  # xacro reports macro/property errors as exceptions
            raise _expansion_error(path, exc, frames, tmp) from None
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    root = etree.fromstring(text.encode(), _parser())
    for pi in root.xpath("//processing-instruction()"):
        if pi.getparent() is not None:
            pi.getparent().remove(pi)
    tagged = {}
    for el in root.iter():
        if isinstance(el.tag, str) and el.get(SRC_ATTR):
            file, _, line = el.get(SRC_ATTR).rpartition(":")
            tagged[el] = C.Source(file, int(line))
            del el.attrib[SRC_ATTR]
    etree.cleanup_namespaces(root)
    expanded = etree.tostring(root, pretty_print=True, encoding="unicode")
    # re-parse so that line numbers (of validation errors) refer to the expanded text
    clean = etree.fromstring(expanded.encode(), _parser())
    old = [e for e in root.iter() if isinstance(e.tag, str)]
    new = [e for e in clean.iter() if isinstance(e.tag, str)]
    sources = {n: tagged[o] for o, n in zip(old, new, strict=True) if o in tagged}
    return clean, sources, expanded


def _expansion_error(path: Path, exc: BaseException, frames, tmp: Path) -> ScriptError:
    """One line for an error of the expansion: where (the element or macro call being
    expanded, and the macro calls that led there) and what."""
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
    else:
        what = " ".join(str(exc).split()) or type(exc).__name__
        for copy in tmp.iterdir():
            what = what.replace(str(copy), copy.name[4:])
        what, hint = f"xacro: {what}", "fix the macro call or property"
    stack = (frames.failure or frames.stack) if frames is not None else []
    where = stack[-1][1] if stack else path.name
    calls = [src for kind, src in stack if kind == "macro" and src != where]
    if calls:
        what += " (in macro called at " + ", called at ".join(reversed(calls)) + ")"
    if limit is not None:
        return LimitError(f"{where}: {what}", hint=hint, limit=limit.limit, bound=limit.bound)
    return ScriptError(f"{where}: {what}", hint=hint, source=where)


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
        raise ScriptError(f"{path}:{root.sourceline}: unknown root element <{root.tag}>",
                          hint="a script starts with <recon name=...> or the thesis system's <script name=...>")
    schema = etree.XMLSchema(etree.parse(str(SCHEMA_DIR / DIALECTS[localname])))
    if not schema.validate(root):
        err = schema.error_log[0]
        src = _source_at(root, err.line, sources) or C.Source(path.name, err.line)
        message = err.message.replace("{http://www.ros.org/wiki/xacro}", "xacro:")
        raise ScriptError(f"{src}: {message}", hint=f"see schemas/{DIALECTS[localname]}")
    build = _build_recon if dialect == "recon" else _build_thesis
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
        name, on_failure, optimize = root.get("name"), root.get("on_failure", "skip"), _bool(root.get("optimize"))
    else:
        name, on_failure, optimize = root.get("name"), "skip", _bool(root.get("optimization"))
    return C.Script(str(path), name, dialect, on_failure, optimize, tuple(cmds), expanded)


def _source_at(root, line: int, sources) -> C.Source | None:
    for el in root.iter():
        if isinstance(el.tag, str) and el.sourceline == line and el in sources:
            return sources[el]
    return None


# --------------------------------------------------------------------- element -> command
def _bool(text: str | None, default: bool = False) -> bool:
    return default if text is None else text.strip() in ("true", "1")


def _vec(text: str | None) -> tuple[float, ...] | None:
    return None if text is None else tuple(float(v) for v in text.split())


def _angle(value: str | None, unit: str, default: float = 0.0) -> float:
    v = default if value is None else float(value)
    return math.radians(v) if unit == "deg" else v


def _finite(values, src: C.Source, what: str) -> None:
    if not all(math.isfinite(v) for v in values):
        raise ScriptError(f"{src}: {what} has a non-finite number", hint="use finite numbers")


# largest magnitudes of written angles (degrees; the same in radians for radian fields):
# a polar angle beyond half a turn, or an azimuth/roll beyond two turns, is a unit mistake
ANGLE_BOUNDS_DEG = {"theta": 180.0, "phi": 720.0, "alpha": 720.0, "phi_start": 720.0, "phi_step": 360.0}


def check_angles(src: C.Source, tag: str, unit: str, values: dict[str, str | float | None]) -> None:
    """Refuse written angles that cannot be meant in ``unit`` (e.g. degrees in a radians field)."""
    for name, raw in values.items():
        if raw is None:
            continue
        v = float(raw)
        bound = ANGLE_BOUNDS_DEG[name]
        if unit == "rad":
            bound = math.radians(bound)
        if not math.isfinite(v) or abs(v) > bound + 1e-9:
            if unit == "rad":
                hint = (f"this field takes radians; if you meant {v:g} degrees write {math.radians(v):.4f}"
                        + (' or unit="deg"' if tag != "coordinates" else ""))
                text = f"{name} {v:g} rad is beyond +-{bound:.4f} rad (+-{ANGLE_BOUNDS_DEG[name]:g} deg)"
            else:
                hint = "write the angle in degrees within the bound"
                text = f"{name} {v:g} deg is beyond +-{bound:g} deg"
            raise ScriptError(f"{src}: <{tag}> {text}", hint=hint)


def _view(el, src: C.Source, theta: float, phi: float) -> View:
    unit = el.get("unit", "deg")
    focus = _vec(el.get("focus"))
    radius = float(el.get("radius"))
    check_angles(src, el.tag, unit, {"alpha": el.get("alpha")})
    alpha = _angle(el.get("alpha"), unit)
    _finite((*focus, radius, theta, phi, alpha), src, f"<{el.tag}>")
    return View(focus, radius, theta, phi, alpha, Frame(el.get("frame", "world")))


def relative_output(name: str, src: C.Source, what: str) -> str:
    """An output path of a script: relative, and inside the output folder."""
    p = Path(name)
    depth = 0
    for part in p.parts:
        depth += -1 if part == ".." else (0 if part == "." else 1)
        if depth < 0:
            break
    if p.is_absolute() or depth < 0 or name.startswith("~"):
        raise ScriptError(f"{src}: {what} {name!r} is outside the output folder",
                          hint="scripts write only into the output folder (--out); give a relative path "
                               "such as drill.ply")
    return name


def _build_recon(el, src: C.Source) -> list[C.Command]:
    tag, a = el.tag, el.attrib
    if tag == "cell":
        return [C.SetCell(src, a.get("kind", "gantry"), float(a.get("safety_distance", 0.03)),
                          a.get("backend", "sim"), float(a.get("resolution", 1.0)), _bool(a.get("noise"), True))]
    if tag == "object":
        return [C.SetObject(src, a["name"], float(a.get("scale", 1.0)))]
    if tag == "box":
        center, size = _vec(a.get("center")), _vec(a.get("size"))
        if (center is None) != (size is None):
            raise ScriptError(f"{src}: <box> needs both center and size, or neither (box around the object)",
                              hint='e.g. <box center="0 0 0.83" size="0.3 0.3 0.3"/>')
        if size is not None and min(size) <= 0:
            raise ScriptError(f"{src}: <box> sizes must be positive", hint="give edge lengths in metres")
        return [C.SetBox(src, center, size, a.get("frame", "world"), float(a.get("margin", 0.01)))]
    if tag == "planner":
        from recon_cli.planning.planner import PLANNERS

        name = a.get("name", "RRTConnect")
        if name not in PLANNERS:
            raise ScriptError(f"{src}: unknown planner {name!r}", hint="one of " + ", ".join(PLANNERS))
        return [C.SetPlanner(src, name, float(a.get("time", 5.0)), float(a.get("velocity_scale", 0.15)),
                             float(a.get("acceleration_scale", 0.3)))]
    if tag == "home":
        return [C.MoveHome(src)]
    if tag == "move":
        unit = a.get("unit", "deg")
        check_angles(src, tag, unit, {"theta": a["theta"], "phi": a["phi"]})
        return [C.MoveView(src, _view(el, src, _angle(a["theta"], unit), _angle(a["phi"], unit)))]
    if tag == "pose":
        q = _vec(a["orientation"])
        if np.linalg.norm(q) < 1e-9:
            raise ScriptError(f"{src}: <pose> orientation quaternion is zero", hint="give x y z w of a rotation")
        return [C.MovePose(src, _vec(a["position"]), tuple(np.asarray(q) / np.linalg.norm(q)), a.get("frame", "world"))]
    if tag == "joints":
        unit = a.get("unit", "rad")
        values = _vec(a["values"])
        _finite(values, src, "<joints>")
        return [C.MoveJoints(src, tuple(values), unit)]
    if tag == "ring":
        unit = a.get("unit", "deg")
        check_angles(src, tag, unit, {"theta": a["theta"], "phi_start": a.get("phi_start"),
                                      "phi_step": a.get("phi_step")})
        count = int(a["count"])
        if count > LIMITS.max_ring_count:
            raise ScriptError(f"{src}: <ring> count {count} exceeds the limit of {LIMITS.max_ring_count} views",
                              hint="use several rings or fewer views")
        start = float(a.get("phi_start", 0.0))
        full_turn = 360.0 if unit == "deg" else 2 * math.pi
        step = float(a["phi_step"]) if a.get("phi_step") is not None else full_turn / count
        theta = _angle(a["theta"], unit)
        out: list[C.Command] = []
        for k in range(count):
            out.append(C.MoveView(src, _view(el, src, theta, _angle(str(start + k * step), unit))))
            if _bool(a.get("scan"), True):
                out.append(C.Scan(src))
        return out
    if tag == "scan":
        return [C.Scan(src, a.get("name"))]
    if tag == "wait":
        return [C.Wait(src, float(a["seconds"]))]
    if tag == "register":
        return [C.Register(src, _bool(a.get("local"), True), _bool(a.get("board"), True),
                           a.get("loop_closures", "icp"))]
    if tag == "reconstruct":
        return [C.Reconstruct(src, float(a.get("voxel", 0.001)), int(a.get("depth", 9)), float(a.get("trim", 0.02)))]
    if tag == "export":
        if not a.get("cloud") and not a.get("mesh"):
            raise ScriptError(f"{src}: <export> needs cloud=... and/or mesh=...",
                              hint='e.g. <export mesh="drill.ply"/>')
        return [C.Export(src, *(None if a.get(k) is None else relative_output(a[k], src, f"<export {k}>")
                                for k in ("cloud", "mesh")))]
    if tag == "evaluate":
        return [C.Evaluate(src, a.get("reference", "ground_truth"), float(a.get("tolerance", 0.001)),
                           a.get("align", "none"))]
    raise ScriptError(f"{src}: unexpected element <{tag}>", hint="see schemas/recon_script.xsd")


def _quat_matrix(xyzw) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    q = np.asarray(xyzw, dtype=float)
    if np.linalg.norm(q) < 1e-9:
        raise ValueError("zero quaternion")
    return Rotation.from_quat(q / np.linalg.norm(q)).as_matrix()


def _build_thesis(el, src: C.Source) -> list[C.Command]:
    tag, a = el.tag, el.attrib
    if tag == "move":
        ref = a.get("reference", "world")
        if ref not in ("world", "marker"):
            raise ScriptError(f"{src}: move reference {ref!r} is not a frame recon knows",
                              hint="use reference=\"world\" or \"marker\"")
        children = {c.tag: c for c in el if isinstance(c.tag, str)}
        if "position" in children:
            q = _vec(children["orientation"].get("xyzw"))
            if np.linalg.norm(q) < 1e-9:
                raise ScriptError(f"{src}: orientation quaternion is zero", hint="give x y z w of a rotation")
            return [C.MovePose(src, _vec(children["position"].get("xyz")), tuple(np.asarray(q) / np.linalg.norm(q)),
                               ref)]
        sphere, co = children["sphere"], children["coordinates"]
        focus, radius = _vec(sphere.get("xyz")), float(sphere.get("radius"))
        check_angles(src, "coordinates", "rad", {k: co.get(k) for k in ("theta", "phi", "alpha")})
        theta, phi, alpha = float(co.get("theta")), float(co.get("phi")), float(co.get("alpha", 0.0))
        _finite((*focus, radius, theta, phi, alpha), src, "<move>")
        if radius <= 0:
            raise ScriptError(f"{src}: sphere radius must be positive", hint="the camera distance in metres")
        return [C.MoveView(src, View(focus, radius, theta, phi, alpha, Frame(ref)))]
    if tag == "scan":
        return [C.FragmentScan(src, a["name"], a.get("path_color", ""), a.get("path_depth", ""),
                               a.get("path_pose", ""))]
    if tag == "load":
        return [C.LoadFragment(src, a["name"], a.get("type", "rgbd_image"), a.get("path_color", "/"),
                               a.get("path_depth", "/"), a.get("path_point_cloud", "/"))]
    if tag == "register":
        return [C.PairRegister(src, a["source"], a["target"], a.get("method", "point_to_plane_icp"),
                               float(a["threshold"]))]
    if tag == "multiway":
        return [C.Multiway(src, a.get("method", "point_to_plane_icp"), float(a["threshold"]))]
    if tag == "add":
        return [C.AddFragment(src, a["fragment"], a["target"])]
    if tag == "downsample":
        return [C.Downsample(src, a["fragment"], float(a["voxel_size"]))]
    if tag == "transform":
        children = {c.tag: c for c in el if isinstance(c.tag, str)}
        T = np.eye(4)
        try:
            T[:3, :3] = _quat_matrix(_vec(children["rotation"].get("xyzw")))
        except ValueError:
            raise ScriptError(f"{src}: rotation quaternion is zero", hint="give x y z w of a rotation") from None
        T[:3, 3] = _vec(children["translation"].get("xyz"))
        if not _bool(a.get("forward"), True):
            T = np.linalg.inv(T)
        return [C.TransformFragment(src, a["fragment"], tuple(map(tuple, T)))]
    if tag == "export":
        path = a["path"]  # the thesis system wrote absolute paths: recon writes them by file name into --out
        if not Path(path).is_absolute():
            relative_output(path, src, "export")
        return [C.ExportFragment(src, a["fragment"], a.get("type", "mesh"), path)]
    if tag == "wait":
        return [C.Wait(src, float(a["duration"]))]
    if tag == "delete":
        return [C.DeleteFragment(src, a["fragment"])]
    if tag in ("show", "hide"):
        return [C.Display(src, tag, a["fragment"])]
    if tag == "color":
        return [C.Display(src, "color", a["fragment"], _vec(a["rgb"]))]
    raise ScriptError(f"{src}: unexpected element <{tag}>", hint="see schemas/thesis_script.xsd")
