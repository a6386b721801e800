"""The expanded URDF of a cell: required parts (a child element or an attribute that the
cell's xacro always writes; a missing one is a broken robot description, an internal error,
named by tag and attribute), and :func:`check_structure`, the check of a user's robot
description that runs before pinocchio, the collision model or MuJoCo see the text."""

from __future__ import annotations

import functools
import math

from lxml import etree

from recon_cli.errors import InputError
from recon_cli.expansion.annotate import parser


def child(element: etree._Element, path: str) -> etree._Element:
    """The first element at ``path`` under ``element``."""
    found = element.find(path)
    if found is None:
        raise ValueError(f"URDF <{element.tag!s} name={element.get('name')!r}> has no <{path}>")
    return found


def attribute(element: etree._Element, name: str) -> str:
    """The value of attribute ``name`` of ``element``."""
    value = element.get(name)
    if value is None:
        raise ValueError(f"URDF <{element.tag!s}> has no attribute {name!r}")
    return value


# ----------------------------------------------------------------------------- structure
#: most links a robot description may have (the shipped cells have at most 19; the collision
#: model checks shape pairs, which grow with the square of the links)
MAX_LINKS = 500
#: most joints between the root link and the deepest link (the shipped cells: at most 13)
MAX_DEPTH = 100
#: largest absolute length in a description [m]: origins and shape sizes
MAX_LENGTH_M = 1000.0
#: joint types of URDF
JOINT_TYPES = ("revolute", "continuous", "prismatic", "fixed", "floating", "planar")
_HINT = "fix the robot description"


def check_structure(urdf: str, description: object) -> None:
    """Refuse a robot description that breaks the URDF model before pinocchio, the collision
    model or MuJoCo parse it, as one line naming the description (``description``: its file;
    with the line of the element when the text is the file as written, a ``.urdf``) and the
    link or joint: unique link and joint names, joints naming existing links, one root link,
    no cycles, at most :data:`MAX_LINKS` links and :data:`MAX_DEPTH` links deep; finite
    origins, axes, masses, inertias, shape sizes and limits (lengths within
    :data:`MAX_LENGTH_M`); a lower position limit below the upper one; velocity and effort
    limits above zero where given; the elements URDF requires (a revolute or prismatic
    joint's ``<limit>`` with ``velocity`` and ``effort``; a mass and six inertia values)."""
    _check_structure(urdf, str(description))


class _Where:
    def __init__(self, description: str) -> None:
        self.file = description
        self.lines = description.lower().endswith(".urdf")  # the text is the file as written

    def __call__(self, element: etree._Element, what: str, hint: str = _HINT) -> InputError:
        line = f":{element.sourceline}" if self.lines and element.sourceline else ""
        return InputError(f"{self.file}{line}: {what}", hint=hint)


@functools.lru_cache(maxsize=16)
def _check_structure(urdf: str, description: str) -> None:
    at = _Where(description)
    try:
        root = etree.fromstring(urdf.encode(), parser())
    except etree.XMLSyntaxError as exc:
        raise InputError(f"{description}: the robot description is not XML ({exc.msg})", hint=_HINT) from None
    if root.tag != "robot":
        raise at(root, f"the robot description's root element is <{root.tag!s}>, not <robot>",
                 "give a URDF: one <robot name=...> holding links and joints")
    if not root.get("name"):
        raise at(root, "the <robot> element has no name", 'write <robot name="...">')
    links = root.findall("link")
    joints = root.findall("joint")
    if not links:
        raise at(root, "the robot description has no <link>", "give a URDF with the robot's links and joints")
    if len(links) > MAX_LINKS:
        raise at(links[MAX_LINKS], f"the robot description has {len(links)} links, more than the {MAX_LINKS} "
                 "recon reads", "describe the cell with fewer links (merge links joined by fixed joints)")
    names: dict[str, etree._Element] = {}
    for link in links:
        name = link.get("name")
        if not name:
            raise at(link, "a <link> without a name", 'give every link a name="..."')
        if name in names:
            raise at(link, f"link '{name}' is defined twice", "give every link its own name")
        names[name] = link
    parent_of: dict[str, tuple[str, etree._Element]] = {}  # child link -> (parent link, joint)
    joint_names: set[str] = set()
    for joint in joints:
        name = joint.get("name")
        if not name:
            raise at(joint, "a <joint> without a name", 'give every joint a name="..."')
        if name in joint_names:
            raise at(joint, f"joint '{name}' is defined twice", "give every joint its own name")
        joint_names.add(name)
        kind = joint.get("type")
        if kind not in JOINT_TYPES:
            raise at(joint, f"joint '{name}' has the type '{kind}'", f"give one of: {', '.join(JOINT_TYPES)}")
        ends: list[str] = []
        for end in ("parent", "child"):
            element = joint.find(end)
            target = None if element is None else element.get("link")
            if element is None or not target:
                raise at(joint, f"joint '{name}' has no <{end} link=...>", f"name the joint's {end} link")
            if target not in names:
                raise at(element, f"joint '{name}': its {end} link '{target}' is not a link of the description",
                         "name a <link> of the description or add it")
            ends.append(target)
        parent, child_link = ends
        if parent == child_link:
            raise at(joint, f"joint '{name}' joins link '{parent}' to itself", "a joint joins two links")
        if child_link in parent_of:
            raise at(joint, f"link '{child_link}' is the child of two joints ('{parent_of[child_link][1].get('name')}' "
                     f"and '{name}'): the links do not form a tree", "give every link one parent joint")
        parent_of[child_link] = (parent, joint)
    roots = [n for n in names if n not in parent_of]
    if len(roots) > 1:
        raise at(names[roots[1]], f"the robot description has {len(roots)} root links ('{roots[0]}', '{roots[1]}'"
                 f"{', ...' if len(roots) > 2 else ''}): links without a parent joint",
                 f"join '{roots[1]}' to the tree with a joint (a URDF has one root link)")
    children: dict[str, list[str]] = {}
    for child_link, (parent, _) in parent_of.items():
        children.setdefault(parent, []).append(child_link)
    depth = {roots[0]: 0} if roots else {}  # joints from the root link
    todo = list(depth)
    while todo:
        above = todo.pop()
        for below in children.get(above, ()):
            depth[below] = depth[above] + 1
            if depth[below] > MAX_DEPTH:
                raise at(names[below], f"link '{below}' hangs {depth[below]} joints below the root link, more than "
                         f"the {MAX_DEPTH} recon reads", "describe the cell with a shallower tree of links")
            todo.append(below)
    if len(depth) < len(names):
        # every link has at most one parent: a link not reached from the root lies on a cycle
        # or hangs below one
        on = next(n for n in names if n not in depth)
        seen: list[str] = []
        while on not in seen:
            seen.append(on)
            on = parent_of[on][0]
        cycle = seen[seen.index(on):]
        joint = parent_of[cycle[0]][1]
        raise at(joint, f"the joints form a cycle: {' <- '.join([*cycle, cycle[0]])} (joint '{joint.get('name')}' "
                 "closes it)", "a URDF is a tree: remove the joint that closes the loop")
    for joint in joints:
        _check_joint(joint, at)
    for link in links:
        _check_link(link, at)
    for material in root.findall("material"):
        _numbers(material.find("color"), "rgba", (4,), f"material '{material.get('name')}'", at)


def _numbers(element: etree._Element | None, name: str, count: tuple[int, ...], owner: str, at: _Where,
             *, required: bool = False, bound: float | None = None) -> tuple[float, ...] | None:
    """The numbers of attribute ``name`` of ``element`` (None when the element or the attribute
    is absent and not ``required``), each finite (and within ``bound``)."""
    if element is None:
        return None
    text = element.get(name)
    if text is None:
        if required:
            raise at(element, f"{owner}: <{element.tag!s}> has no {name}", f'write {name}="..." as URDF requires')
        return None
    try:
        values = tuple(float(v) for v in text.split())
    except ValueError:
        values = ()
    plural = " or ".join(str(c) for c in count)
    if len(values) not in count:
        raise at(element, f"{owner}: <{element.tag!s} {name}> is not {plural} number{'s' if count != (1,) else ''}",
                 f"write {name} as URDF does, e.g. xyz=\"0 0 0.1\"")
    if not all(math.isfinite(v) for v in values):
        raise at(element, f"{owner}: <{element.tag!s} {name}> is not finite (NaN or infinite)",
                 f"write {name}=\"...\" as {'a finite number' if count == (1,) else f'{plural} finite numbers'}")
    if bound is not None and any(abs(v) > bound for v in values):
        raise at(element, f"{owner}: <{element.tag!s} {name}> has a value beyond {bound:g} m",
                 "give lengths in metres")
    return values


def _origin(parent: etree._Element, owner: str, at: _Where) -> None:
    origin = parent.find("origin")
    _numbers(origin, "xyz", (3,), owner, at, bound=MAX_LENGTH_M)
    _numbers(origin, "rpy", (3,), owner, at)


def _check_joint(joint: etree._Element, at: _Where) -> None:
    name, kind = joint.get("name"), joint.get("type")
    owner = f"joint '{name}'"
    _origin(joint, owner, at)
    axis = _numbers(joint.find("axis"), "xyz", (3,), owner, at)
    if axis is not None and kind != "fixed" and not any(axis):
        raise at(joint, f"{owner}: the axis is 0 0 0", "give the joint's axis, e.g. xyz=\"0 0 1\"")
    limit = joint.find("limit")
    if limit is None:
        if kind in ("revolute", "prismatic"):
            raise at(joint, f"{owner} is {kind} but has no <limit>",
                     "give <limit lower=... upper=... velocity=... effort=...>, as URDF requires")
    else:
        values = {key: _numbers(limit, key, (1,), owner, at, required=key in ("velocity", "effort"))
                  for key in ("lower", "upper", "velocity", "effort")}
        for key in ("velocity", "effort"):
            v = values[key]
            if v is not None and v[0] <= 0:
                raise at(limit, f"{owner}: the {key} limit {v[0]:g} is not above zero",
                         f"give the joint's {key} limit, a positive number")
        if kind in ("revolute", "prismatic"):
            lower = values["lower"][0] if values["lower"] else 0.0
            upper = values["upper"][0] if values["upper"] else 0.0
            if not lower < upper:
                unit = "m" if kind == "prismatic" else "rad"
                what = "above" if lower > upper else "equal to"
                raise at(limit, f"{owner}: the lower limit {lower:g} {unit} is {what} the upper limit {upper:g} {unit}"
                         f"{' (URDF reads a missing one as 0)' if not (values['lower'] and values['upper']) else ''}",
                         "give lower < upper (a joint that does not move is a fixed joint)")
    safety = joint.find("safety_controller")
    for key in ("soft_lower_limit", "soft_upper_limit", "k_position", "k_velocity"):
        _numbers(safety, key, (1,), owner, at)
    dynamics = joint.find("dynamics")
    for key in ("damping", "friction"):
        _numbers(dynamics, key, (1,), owner, at)
    mimic = joint.find("mimic")
    for key in ("multiplier", "offset"):
        _numbers(mimic, key, (1,), owner, at)


def _check_link(link: etree._Element, at: _Where) -> None:
    owner = f"link '{link.get('name')}'"
    inertial = link.find("inertial")
    if inertial is not None:
        _origin(inertial, owner, at)
        mass = inertial.find("mass")
        if mass is None:
            raise at(inertial, f"{owner}: <inertial> has no <mass>", 'give <mass value="..."/> (kg)')
        m = _numbers(mass, "value", (1,), owner, at, required=True)
        if m is not None and m[0] < 0:
            raise at(mass, f"{owner}: the mass {m[0]:g} kg is negative", "give the link's mass in kg")
        inertia = inertial.find("inertia")
        if inertia is None:
            raise at(inertial, f"{owner}: <inertial> has no <inertia>",
                     "give <inertia ixx=... ixy=... ixz=... iyy=... iyz=... izz=.../> (kg m^2)")
        for key in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz"):
            v = _numbers(inertia, key, (1,), owner, at, required=True)
            if key in ("ixx", "iyy", "izz") and v is not None and v[0] < 0:
                raise at(inertia, f"{owner}: the moment of inertia {key} {v[0]:g} kg m^2 is negative",
                         "give the link's inertia in kg m^2")
    for tag in ("visual", "collision"):
        for element in link.findall(tag):
            _origin(element, owner, at)
            _geometry(element, f"{owner}: <{tag}>", at)
            material = element.find("material")
            if material is not None:
                _numbers(material.find("color"), "rgba", (4,), owner, at)


_SIZES = {"box": (("size", 3),), "cylinder": (("radius", 1), ("length", 1)), "sphere": (("radius", 1),)}


def _geometry(element: etree._Element, owner: str, at: _Where) -> None:
    geometry = element.find("geometry")
    shapes = [] if geometry is None else [g for g in geometry if isinstance(g.tag, str)]
    if len(shapes) != 1:
        raise at(element, f"{owner} has {'no' if not shapes else len(shapes)} shape{'s' if len(shapes) > 1 else ''} "
                 "in its <geometry>", "give one <box>, <cylinder>, <sphere> or <mesh>")
    shape = shapes[0]
    if shape.tag == "mesh":
        _numbers(shape, "scale", (1, 3), owner, at)
        return
    if shape.tag not in _SIZES:
        raise at(shape, f"{owner}: <{shape.tag!s}> is not a URDF shape", "give a <box>, <cylinder>, <sphere> or <mesh>")
    for key, count in _SIZES[shape.tag]:
        values = _numbers(shape, key, (count,), owner, at, required=True, bound=MAX_LENGTH_M)
        if values is not None and any(v < 0 for v in values):
            raise at(shape, f"{owner}: the {shape.tag} {key} is negative", f"give the {shape.tag}'s {key} in metres")
