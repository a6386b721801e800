"""Cell files: one robot cell described in one YAML file (``format: 1``).

A cell file names the robot description (a URDF or xacro file, relative to the cell file,
with its xacro arguments and the arguments that take recon's settings), the planning joints
in joint-vector order and which of them are linear axes, the robot's base link, the flange,
the camera's optical frame and sensor file, the table's top shape, the ChArUco board, where
objects stand, the collision model's declared exclusions, the joint limits (URDF values,
overridable; accelerations, which URDF cannot hold), the named poses and the default
safety distance. The shipped cells are ``cells/NAME.yaml``; a user's cell is any such file.

A file is read by the one YAML reader and checked against schemas/cell.schema.json; what
needs the URDF (joints, links and shapes that must exist in it) is checked by
:func:`check_against_urdf` once the description is expanded. Every refusal is one line
naming ``file:line``.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
from lxml import etree

from recon_cli.errors import InputError, ScriptError, UnknownNameError
from recon_cli.expansion.readable import cell_rule, readable
from recon_cli.geometry.transforms import pose_from_xyz_rpy
from recon_cli.inputs.files import version_stamp
from recon_cli.inputs.schema import check
from recon_cli.inputs.yamlfile import line_of, read_yaml
from recon_cli.paths import CELLS_DIR
from recon_cli.robot.urdf import attribute, child

CELL_FORMAT = 1
#: the cell used when none is named
DEFAULT_CELL = "gantry"
#: other names of shipped cells
ALIASES = {"9dof": "gantry", "7dof": "ceiling"}
_PATH_HINT = ("paths in a cell file are relative to the cell file's folder (or to recon's robot/ folder) and stay "
              "inside them")


def shipped_cells() -> tuple[str, ...]:
    """Names of the shipped cells (cells/NAME.yaml), the default first."""
    names = sorted(p.stem for p in CELLS_DIR.glob("*.yaml"))
    return tuple(sorted(names, key=lambda n: n != DEFAULT_CELL))


@dataclass(frozen=True)
class DescriptionSettings:
    """The xacro arguments that take recon's settings (None: the description takes none).

    safety_distance: the inflation of every collision shape [m]; table_lift: [m];
    base_position: (x, y) of the robot base in the world [m]; base_pose: (xyz, rpy) of the
    base link in its URDF parent; camera_pose: (xyz, rpy) of the optical frame in its URDF parent
    """

    safety_distance: str | None = None
    table_lift: str | None = None
    base_position: tuple[str, str] | None = None
    base_pose: tuple[str, str] | None = None
    camera_pose: tuple[str, str] | None = None


@dataclass(frozen=True)
class JointLimit:
    """Limits of one joint as a cell file gives them (revolute in deg, prismatic in m); None:
    the URDF's value."""

    name: str
    type: str | None = None
    lower: float | None = None
    upper: float | None = None
    velocity: float | None = None
    acceleration: float | None = None
    effort: float | None = None
    jerk: float | None = None


@dataclass(frozen=True)
class LimitTable:
    """The limits section of a cell file (or the limits file it names)."""

    joints: tuple[JointLimit, ...]
    soft_margin_revolute_deg: float | None = None
    soft_margin_prismatic_m: float | None = None
    where: str = ""

    def get(self, joint: str) -> JointLimit | None:
        return next((j for j in self.joints if j.name == joint), None)


@dataclass(frozen=True)
class AllowedPair:
    """Two links never checked against each other, and why."""

    links: tuple[str, str]
    why: str


@dataclass(frozen=True)
class CellFile:
    """A checked cell file. Paths are absolute; ``lines`` holds the line of each key path
    (``flange``, ``joints.planning[3]``, ...) for later messages."""

    path: Path
    name: str
    description: Path
    arguments: tuple[tuple[str, str], ...]
    settings: DescriptionSettings
    planning_joints: tuple[str, ...]
    linear_joints: tuple[str, ...]
    base_link: str
    flange_link: str
    camera_frame: str
    sensor_file: Path
    table_shape: str
    board_frame: str
    board_file: Path
    object_position: tuple[float, float, float]
    drives_file: Path | None
    limits: LimitTable
    safety_distance: float
    poses: tuple[tuple[str, tuple[float, ...]], ...]
    allowed_links: tuple[AllowedPair, ...]
    allowed_shapes: tuple[tuple[str, str], ...]
    #: named poses tried as IK seeds before random ones (posture preferences, e.g. elbow up)
    ik_seeds: tuple[str, ...] = ()
    #: configurations of the IK's seed library (0: none)
    ik_library: int = 0
    #: every file the cell file names (description, sensor, board, drives, limits, collision)
    sources: tuple[Path, ...] = ()
    lines: tuple[tuple[str, str], ...] = field(default=(), compare=False, repr=False)

    def where(self, key: str) -> str:
        """``file:line`` of a key path (the file alone when its line is unknown)."""
        return dict(self.lines).get(key, str(self.path))

    def pose(self, name: str, joint_names: tuple[str, ...]) -> npt.NDArray[np.float64]:
        """A named configuration in SI units (linear axes in m, the others converted from deg)."""
        table = dict(self.poses)
        if name not in table:
            raise UnknownNameError(f"configuration of the {self.name} cell", name, list(table))
        return np.array([float(v) if j in self.linear_joints else math.radians(float(v))
                         for j, v in zip(joint_names, table[name], strict=True)])


# ----------------------------------------------------------------------------- reading
def resolve(name_or_path: str) -> Path:
    """The cell file of a shipped cell's name (or alias), or a path as given."""
    key = str(name_or_path).strip()
    low = ALIASES.get(key.lower(), key.lower())
    if low in shipped_cells():
        return CELLS_DIR / f"{low}.yaml"
    return Path(key).expanduser()


def load_cell(name_or_path: str) -> CellFile:
    """The checked cell file of a shipped cell's name or of a path."""
    path = resolve(name_or_path)
    if path.suffix.lower() not in (".yaml", ".yml") and not path.exists():
        raise UnknownNameError("cell", str(name_or_path), [*shipped_cells(), "a cell FILE.yaml"])
    return _load(path.resolve())


@functools.lru_cache(maxsize=32)
def _load_cached(path: Path, stamp: tuple[int, int]) -> CellFile:
    return _parse(path)


def _load(path: Path) -> CellFile:
    return _load_cached(path, version_stamp(path))


class _Lines:
    """Key paths → ``file:line`` of one document."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.rows: dict[str, str] = {}
        self.read: list[Path] = []  # the section files read beside the document

    def at(self, container: Any, key: Any, name: str) -> str:
        line = line_of(container, key)
        where = f"{self.path}:{line}" if line else str(self.path)
        self.rows[name] = where
        return where


def _file(lines: _Lines, container: Any, key: str, name: str, what: str) -> Path:
    """A file the cell file names: a relative path beside the cell file (or in recon's robot/
    folder) that stays inside those folders (:func:`~recon_cli.expansion.readable.cell_rule`),
    checked before anything is read."""
    where = lines.at(container, key, name)
    given = str(container[key])
    try:
        return readable(given, cell_rule(lines.path), None, f"the {what}")
    except ScriptError as exc:
        if "does not exist" in exc.message:
            raise InputError(f"{where}: {name}: the {what} {given} does not exist", hint=_PATH_HINT) from None
        raise InputError(f"{where}: {name}: {exc.message}", hint=exc.hint) from None


def _numbers(values: Any) -> tuple[float, ...]:
    return tuple(float(v) for v in values)


def _parse(path: Path) -> CellFile:
    doc = read_yaml(path, "cell file", hint=f"name a shipped cell ({', '.join(shipped_cells())}) or a cell FILE.yaml")
    check(doc, "cell", path)
    lines = _Lines(path)
    desc = doc["description"]
    description = _file(lines, desc, "file", "description.file", "robot description")
    if description.suffix.lower() not in (".urdf", ".xacro"):
        raise InputError(f"{lines.rows['description.file']}: description.file {description.name} is neither a "
                         ".urdf nor a .xacro file", hint="give the robot's URDF or xacro file")
    arguments = tuple((str(k), _argument(v)) for k, v in desc.get("arguments", {}).items())
    s = desc.get("settings", {})
    settings = DescriptionSettings(
        s.get("safety_distance"), s.get("table_lift"),
        *(tuple(s[k]) if k in s else None for k in ("base_position", "base_pose", "camera_pose")))
    if description.suffix.lower() == ".urdf" and (arguments or s):
        lines.at(desc, "arguments" if arguments else "settings", "description")
        raise InputError(f"{lines.rows['description']}: a URDF file takes no xacro arguments or settings",
                         hint="remove description.arguments and description.settings, or give a xacro file")

    joints = doc["joints"]
    planning = tuple(joints["planning"])
    for i, j in enumerate(planning):
        lines.at(joints["planning"], i, f"joints.planning[{i}]")
        if j in planning[:i]:
            raise InputError(f"{lines.rows[f'joints.planning[{i}]']}: joints.planning names {j} twice",
                             hint="list every planning joint once, in joint-vector order")
    linear = tuple(joints.get("linear", ()))
    for i, j in enumerate(linear):
        where = lines.at(joints["linear"], i, f"joints.linear[{i}]")
        if j not in planning:
            raise InputError(f"{where}: linear joint {j} is not a planning joint",
                             hint=f"the planning joints: {', '.join(planning)}")

    for key in ("base", "flange"):
        lines.at(doc, key, key)
    lines.at(doc["camera"], "frame", "camera.frame")
    lines.at(doc["table"], "shape", "table.shape")
    lines.at(doc["board"], "frame", "board.frame")
    sensor = _file(lines, doc["camera"], "sensor", "camera.sensor", "camera file")
    board = _file(lines, doc["board"], "spec", "board.spec", "board file")
    drives = _file(lines, doc, "drives", "drives", "drives file") if "drives" in doc else None

    limits = _limits(doc, lines)
    allowed, shapes = _collision(doc, lines)

    poses = []
    for name, values in doc["poses"].items():
        where = lines.at(doc["poses"], name, f"poses.{name}")
        if len(values) != len(planning):
            raise InputError(f"{where}: pose {name} has {len(values)} values, the cell has {len(planning)} "
                             "planning joints", hint=f"give one value per joint: {', '.join(planning)}")
        poses.append((str(name), _numbers(values)))

    seeds = tuple(str(s) for s in (doc.get("ik") or {}).get("seeds", ()))
    for i, name in enumerate(seeds):
        where = lines.at(doc["ik"]["seeds"], i, f"ik.seeds[{i}]")
        if name not in dict(poses):
            raise InputError(f"{where}: IK seed {name} is not a pose of the cell",
                             hint=f"name one of poses: {', '.join(dict(poses))}")
    lines.at(doc, "safety_distance", "safety_distance")
    if "library" in (doc.get("ik") or {}):
        lines.at(doc["ik"], "library", "ik.library")
    return CellFile(
        path=path, name=str(doc["name"]), description=description, arguments=arguments, settings=settings,
        planning_joints=planning, linear_joints=linear, base_link=str(doc["base"]), flange_link=str(doc["flange"]),
        camera_frame=str(doc["camera"]["frame"]), sensor_file=sensor, table_shape=str(doc["table"]["shape"]),
        board_frame=str(doc["board"]["frame"]), board_file=board,
        object_position=tuple(_numbers(doc["objects"]["position"])),  # type: ignore[arg-type]
        drives_file=drives, limits=limits, safety_distance=float(doc["safety_distance"]), poses=tuple(poses),
        allowed_links=allowed, allowed_shapes=shapes, ik_seeds=seeds,
        ik_library=int((doc.get("ik") or {}).get("library", 0)),
        sources=tuple(dict.fromkeys(p for p in (description, sensor, board, drives, *lines.read) if p is not None)),
        lines=tuple(lines.rows.items()))


def _argument(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)
    return str(value)


def _inline_or_file(doc: Any, lines: _Lines, key: str) -> tuple[Any, _Lines]:
    """The section ``key`` as written in the cell file, or read (and checked) from the file
    it names; with the lines of where it stands."""
    section = doc[key]
    if not isinstance(section, str):
        return section, lines
    source = _file(lines, doc, key, key, f"{key} file")
    lines.read.append(source)
    section = read_yaml(source, f"{key} file")
    check(section, "cell", source, part=key)
    return section, _Lines(source)


def _limits(doc: Any, lines: _Lines) -> LimitTable:
    where = lines.at(doc, "limits", "limits")
    section, owner = _inline_or_file(doc, lines, "limits")
    rows = []
    for name, entry in section["joints"].items():
        at = owner.at(section["joints"], name, f"limits.joints.{name}")
        lines.rows.setdefault(f"limits.joints.{name}", at)
        rows.append(JointLimit(str(name), entry.get("type"), *(entry.get(k) for k in
                                                                ("lower", "upper", "velocity", "acceleration",
                                                                 "effort", "jerk"))))
    return LimitTable(tuple(rows), section.get("soft_margin_revolute_deg"), section.get("soft_margin_prismatic_m"),
                      where)


def _collision(doc: Any, lines: _Lines) -> tuple[tuple[AllowedPair, ...], tuple[tuple[str, str], ...]]:
    lines.at(doc, "collision", "collision")
    section, owner = _inline_or_file(doc, lines, "collision")
    allowed = []
    for i, entry in enumerate(section.get("allowed", [])):
        lines.rows[f"collision.allowed[{i}]"] = owner.at(section["allowed"], i, f"collision.allowed[{i}]")
        allowed.append(AllowedPair((str(entry["links"][0]), str(entry["links"][1])), str(entry["why"])))
    shapes = []
    for i, pair in enumerate(section.get("shapes", [])):
        lines.rows[f"collision.shapes[{i}]"] = owner.at(section["shapes"], i, f"collision.shapes[{i}]")
        shapes.append((str(pair[0]), str(pair[1])))
    return tuple(allowed), tuple(shapes)


# ----------------------------------------------------------------------------- against the URDF
#: what a cell's description holds besides the arm
WHOLE_CELL = "arm, camera, table, board"
#: the cell file's keys that name a part of the cell outside a vendor's arm description
_CELL_PARTS = ("camera.frame", "board.frame")
WRAPPER_HINT = ("a vendor's arm URDF or xacro holds the arm alone: write a wrapper xacro that includes it and adds "
                "the world, the table, the camera on the flange and the board (docs/cells.md, \"A wrapper around "
                "a vendor's arm\")")


def check_against_urdf(cell: CellFile, urdf: str) -> None:
    """Refuse a cell file whose names do not fit its expanded description (one line, file:line)."""
    _check(cell, urdf)


@functools.lru_cache(maxsize=32)
def _check(cell: CellFile, urdf: str) -> None:
    root = etree.fromstring(urdf.encode())
    desc = cell.description.name
    links = [str(link.get("name")) for link in root.iterfind("link")]
    joints = {str(j.get("name")): j for j in root.iterfind("joint")}
    movable = [n for n, j in joints.items() if j.get("type") not in ("fixed", "floating", "planar")]

    for i, name in enumerate(cell.planning_joints):
        if name not in joints:
            raise InputError(f"{cell.where(f'joints.planning[{i}]')}: planning joint {name} is not a joint of {desc}",
                             hint=f"its movable joints: {', '.join(movable)}")
        if name not in movable:
            raise InputError(f"{cell.where(f'joints.planning[{i}]')}: planning joint {name} is a "
                             f"{joints[name].get('type')} joint of {desc}",
                             hint=f"its movable joints: {', '.join(movable)}")
    order = _tree_order(root, movable)
    if list(cell.planning_joints) != order:
        raise InputError(f"{cell.where('joints.planning[0]')}: joints.planning is not the movable joints of {desc} "
                         "in tree order", hint=f"list them as {', '.join(order)}")
    for i, name in enumerate(cell.planning_joints):
        prismatic = joints[name].get("type") == "prismatic"
        if prismatic != (name in cell.linear_joints):
            raise InputError(f"{cell.where(f'joints.planning[{i}]')}: joint {name} is {joints[name].get('type')} "
                             f"in {desc} but {'' if name in cell.linear_joints else 'not '}in joints.linear",
                             hint="joints.linear lists exactly the prismatic planning joints")
    for joint in cell.planning_joints:
        entry = cell.limits.get(joint)
        if entry is None or entry.acceleration is None:
            raise InputError(f"{cell.limits.where}: the limits lack the acceleration of planning joint {joint}",
                             hint="give limits.joints.NAME.acceleration of every planning joint "
                                  "(deg/s^2, m/s^2 for linear axes; URDF holds no acceleration limits)")

    for key, name in (("base", cell.base_link), ("flange", cell.flange_link), ("camera.frame", cell.camera_frame),
                      ("board.frame", cell.board_frame)):
        if name not in links:
            whole = (f"; the description must hold the whole cell ({WHOLE_CELL})"
                     if key in _CELL_PARTS and arm_alone(urdf, cell.base_link) else "")
            raise InputError(f"{cell.where(key)}: {key} {name} is not a link of {desc}{whole}",
                             hint=(f"{WRAPPER_HINT}; " if whole else "") + f"its links: {', '.join(links)}")
    mount = rigid_mount(urdf, cell.flange_link, cell.camera_frame)
    if isinstance(mount, str) and mount.startswith("joint "):
        raise InputError(f"{cell.where('camera.frame')}: the camera frame {cell.camera_frame} is not fixed to "
                         f"the flange {cell.flange_link}: {mount} moves between them",
                         hint="name the link the camera is mounted on as the flange (the camera frame must ride "
                              "rigidly on it: fixed joints only between them)")
    if mount is None:
        raise InputError(f"{cell.where('camera.frame')}: the camera frame {cell.camera_frame} does not hang on "
                         f"the flange {cell.flange_link}", hint="name the flange link the camera is mounted on")
    for i, pair in enumerate(cell.allowed_links):
        for link in pair.links:
            if link not in links:
                raise InputError(f"{cell.where(f'collision.allowed[{i}]')}: {link} is not a link of {desc}",
                                 hint=f"its links: {', '.join(links)}")
    shapes = {f"{link.get('name')}/{c.get('name')}" for link in root.iterfind("link")
              for c in link.findall("collision")}
    if not any(s.endswith(f"/{cell.table_shape}") for s in shapes):
        alone = arm_alone(urdf, cell.base_link)
        raise InputError(f"{cell.where('table.shape')}: {desc} has no collision shape {cell.table_shape}"
                         + (f"; the description must hold the whole cell ({WHOLE_CELL})" if alone else ""),
                         hint="name the <collision name=...> of the table top" + (f"; {WRAPPER_HINT}" if alone else ""))
    for i, shape_pair in enumerate(cell.allowed_shapes):
        for label in shape_pair:
            if label not in shapes:
                raise InputError(f"{cell.where(f'collision.shapes[{i}]')}: {label} is not a collision shape "
                                 f"(link/name) of {desc}", hint="name shapes as LINK/COLLISION_NAME")


def _parents(root: Any) -> dict[str, tuple[str, Any]]:
    """child link → (parent link, joint element)."""
    return {j.find("child").get("link"): (j.find("parent").get("link"), j) for j in root.iterfind("joint")}


def descendant_links(urdf: str, link: str, fixed_only: bool = False) -> tuple[str, ...]:
    """The links below ``link`` in the description's tree (``link`` excluded); ``fixed_only``:
    only those reached through fixed joints (what rides rigidly on it)."""
    children: dict[str, list[str]] = {}
    for j in etree.fromstring(urdf.encode()).iterfind("joint"):
        if not fixed_only or j.get("type") == "fixed":
            children.setdefault(attribute(child(j, "parent"), "link"), []).append(attribute(child(j, "child"), "link"))
    out: list[str] = []
    todo = list(children.get(link, []))
    while todo:
        name = todo.pop()
        out.append(name)
        todo += children.get(name, [])
    return tuple(out)


def _tree_order(root: Any, movable: list[str]) -> list[str]:
    """The movable joints depth first from the root link, in document order (pinocchio's order)."""
    children: dict[str, list[Any]] = {}
    for j in root.iterfind("joint"):
        children.setdefault(j.find("parent").get("link"), []).append(j)
    child_links = {j.find("child").get("link") for j in root.iterfind("joint")}
    roots = [link.get("name") for link in root.iterfind("link") if link.get("name") not in child_links]
    out: list[str] = []

    def walk(link: str) -> None:
        for j in children.get(link, []):
            if j.get("name") in movable:
                out.append(j.get("name"))
            walk(j.find("child").get("link"))

    for r in roots:
        walk(r)
    return out


def _rigid_path(up: dict[str, tuple[str, Any]], a: str, b: str) -> tuple[str | None, list[Any], list[Any]]:
    """(lowest common ancestor of links ``a`` and ``b``, the joints from it down to ``a``, those
    down to ``b``, each list nearest the ancestor last); (None, [], []) for links in two trees."""
    chain_a, link = [a], a
    while link in up and len(chain_a) <= len(up):
        link = up[link][0]
        chain_a.append(link)
    depth = {name: i for i, name in enumerate(chain_a)}
    joints_b: list[Any] = []
    link = b
    while link not in depth:
        if link not in up or len(joints_b) > len(up):
            return None, [], []
        link, joint = up[link]
        joints_b.append(joint)
    joints_a, name = [], a
    while name != link:
        name, joint = up[name]
        joints_a.append(joint)
    return link, joints_a, joints_b


def arm_alone(urdf: str, base: str) -> bool:
    """Does the description hold an arm alone (as a vendor ships it): every link the base link,
    above it or below it, nothing beside it (no table top or board on a branch of their own)?"""
    up = _parents(etree.fromstring(urdf.encode()))
    line, link = {base, *descendant_links(urdf, base)}, base
    while link in up and len(line) <= len(up) + 1:
        link = up[link][0]
        line.add(link)
    return all(str(link.get("name")) in line for link in etree.fromstring(urdf.encode()).iterfind("link"))


def rigid_mount(urdf: str, a: str, b: str) -> str | None:
    """Where links ``a`` and ``b`` meet when they are parts of one rigid body: their lowest
    common ancestor (``a`` itself when ``b`` hangs below it, ``b`` when ``a`` does) if only
    fixed joints lie between them; ``"joint NAME"`` naming the first movable joint between them
    otherwise; None for links in two separate trees."""
    lca, joints_a, joints_b = _rigid_path(_parents(etree.fromstring(urdf.encode())), a, b)
    if lca is None:
        return None
    moving = [j for j in (*reversed(joints_a), *reversed(joints_b)) if j.get("type") != "fixed"]
    return f"joint {moving[0].get('name')}" if moving else lca


def rigid_ancestors(urdf: str, link: str) -> tuple[str, ...]:
    """The links above ``link`` reached through fixed joints only, nearest first: the links of
    its rigid body it hangs on."""
    up = _parents(etree.fromstring(urdf.encode()))
    out: list[str] = []
    while link in up and up[link][1].get("type") == "fixed" and len(out) < len(up):
        link = up[link][0]
        out.append(link)
    return tuple(out)


def _origin(joint: Any) -> npt.NDArray[np.float64]:
    origin = joint.find("origin")
    xyz = [float(v) for v in (origin.get("xyz", "0 0 0") if origin is not None else "0 0 0").split()]
    rpy = [float(v) for v in (origin.get("rpy", "0 0 0") if origin is not None else "0 0 0").split()]
    return pose_from_xyz_rpy(xyz, rpy)


def parent_T_child(urdf: str, parent: str, child: str) -> npt.NDArray[np.float64]:
    """The fixed transform between two links of one rigid body (fixed joints only between them,
    in either direction or through a common ancestor): ``child``'s frame in ``parent``'s."""
    lca, to_parent, to_child = _rigid_path(_parents(etree.fromstring(urdf.encode())), parent, child)
    if lca is None:
        raise InputError(f"{child} does not hang on {parent}")
    for joint in (*to_parent, *to_child):
        if joint.get("type") != "fixed":
            raise InputError(f"{child} moves relative to {parent} (joint {joint.get('name')})",
                             hint="mount the camera rigidly on the flange")
    lca_T = {}
    for name, joints in (("parent", to_parent), ("child", to_child)):
        T = np.eye(4)
        for joint in reversed(joints):
            T = T @ _origin(joint)
        lca_T[name] = T
    return np.linalg.inv(lca_T["parent"]) @ lca_T["child"]


def camera_parent(urdf: str, frame: str) -> str:
    """The URDF parent link of the camera's optical frame."""
    root = etree.fromstring(urdf.encode())
    return str(_parents(root)[frame][0])
