"""A cell's robot description expanded into URDF text, and ``CellConfig``: which cell (a
shipped cell's name or a cell file) with recon's settings of it.

The cell file (:mod:`recon_cli.robot.cell_file`) names the description (a URDF or xacro
file), its xacro arguments and the arguments that take the settings (safety distance, table
lift, base and camera poses). The one description feeds every consumer: pinocchio
(kinematics, dynamics), the collision model and the MuJoCo scene. A xacro description is
expanded in the sandbox that expands scripts (:mod:`recon_cli.expansion`): a cell file is
a user's file, and nothing in it or its description may run code or read beyond the cell
file's folder and robot/. Expansion is cached per process, keyed by the arguments and the
content of the description's files.
"""

from __future__ import annotations

import functools
import hashlib
import math
import tempfile
from collections.abc import Iterable
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path
from typing import Any

import numpy as np
from lxml import etree

from recon_cli.errors import InputError, ScriptError, UnknownNameError
from recon_cli.expansion.annotate import SRC_ATTR, Annotated, expansion_error, parser
from recon_cli.expansion.expressions import Limits
from recon_cli.expansion.readable import cell_rule
from recon_cli.expansion.sandbox import sandboxed
from recon_cli.geometry.transforms import invert
from recon_cli.inputs.files import file_errors, read_limited
from recon_cli.robot.capsule_fit import FittedCapsule, MeshFit, fit_mesh_collisions
from recon_cli.robot.cell_file import (
    ALIASES,
    DEFAULT_CELL,
    CellFile,
    camera_parent,
    check_against_urdf,
    load_cell,
    parent_T_child,
    resolve,
    shipped_cells,
)
from recon_cli.robot.inflate import inflate_primitives
from recon_cli.robot.urdf import check_structure


class CellKind(StrEnum):
    """The names of the thesis' two shipped cells (cells/gantry.yaml, cells/ceiling.yaml)."""

    GANTRY = "gantry"  #: 9 DoF: two linear axes + iiwa (Figures 1.1, 2.7)
    CEILING = "ceiling"  #: 7 DoF: iiwa fixed under the roof (section 5.1)


class CellName(str):
    """Which cell: the name of a shipped cell (cells/NAME.yaml) or the path of a cell file."""

    __slots__ = ()

    @property
    def value(self) -> str:
        return str(self)

    @property
    def shipped(self) -> bool:
        return str(self) in shipped_cells()

    @property
    def path(self) -> Path:
        """The cell file."""
        return resolve(str(self))

    @classmethod
    def parse(cls, text: str) -> CellName:
        """A shipped cell's name (or alias, any case) or a cell file's path (made absolute);
        anything else is refused naming the shipped cells."""
        key = str(text).strip()
        low = ALIASES.get(key.lower(), key.lower())
        if low in shipped_cells():
            return cls(low)
        path = Path(key).expanduser()
        if path.suffix.lower() in (".yaml", ".yml"):
            return cls(str(path.resolve()))
        raise UnknownNameError("cell", str(text), [*shipped_cells(), "a cell FILE.yaml"])


@dataclass(frozen=True)
class CellConfig:
    """Which cell, and recon's settings of it.

    kind: the cell: a shipped cell's name or a cell file's path (:class:`CellName`)
    safety_distance: inflation of every collision shape [m] (thesis 2.2.4); None: the cell file's
    table_lift: extension of the telescoping table [m]
    ceiling_xy: base position of the robot in the world [m] (cells whose description takes it)
    flange_T_camera: hand-eye transform, the camera's optical frame in the flange frame,
        16 numbers row by row [m]; None: the calibration in the description
    mount_T_base: the robot base link in its mount (its URDF parent: gantry carriage or
        ceiling plate), 16 numbers row by row [m]; None: the nominal mount of the description
        (a realism profile gives the simulated robot another one: base pose error)
    """

    kind: CellName = CellName(DEFAULT_CELL)
    safety_distance: float = None  # type: ignore[assignment]  # None: the cell file's (a float after init)
    table_lift: float = 0.0
    ceiling_xy: tuple[float, float] = (0.0, 0.0)
    flange_T_camera: tuple[float, ...] | None = None
    mount_T_base: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.kind, CellName):
            object.__setattr__(self, "kind", CellName.parse(self.kind))
        if self.safety_distance is None:
            object.__setattr__(self, "safety_distance", self.cell_file.safety_distance)
        if self.mount_T_base is not None:
            object.__setattr__(self, "mount_T_base", _rigid(self.mount_T_base, "the robot base pose mount_T_base"))
        if self.flange_T_camera is not None:
            object.__setattr__(self, "flange_T_camera",
                               _rigid(self.flange_T_camera, "the hand-eye transform flange_T_camera"))
        if not (math.isfinite(self.safety_distance) and 0.0 <= self.safety_distance <= 0.2):
            raise InputError(
                f"safety distance {self.safety_distance} m is outside 0 ... 0.2 m",
                hint="give it in metres, e.g. 0.03",
            )
        if not (math.isfinite(self.table_lift) and 0.0 <= self.table_lift <= 0.65):
            raise InputError(
                f"table lift {self.table_lift} m is outside the table's 0 ... 0.65 m",
                hint="give it in metres",
            )

    @property
    def cell_file(self) -> CellFile:
        """The checked cell file (read once per process and file version)."""
        return load_cell(str(self.kind))

    @property
    def name(self) -> str:
        """The cell's name (its cell file's ``name``)."""
        return self.cell_file.name

    def xacro_args(self) -> dict[str, str]:
        cell = self.cell_file
        s = cell.settings
        args = dict(cell.arguments)
        if s.safety_distance:
            args[s.safety_distance] = repr(float(self.safety_distance))
        self._setting(s.table_lift, "table lift", self.table_lift != 0.0)
        if s.table_lift:
            args[s.table_lift] = repr(float(self.table_lift))
        self._setting(s.base_position, "base position (ceiling_xy)", tuple(self.ceiling_xy) != (0.0, 0.0))
        if s.base_position:
            args[s.base_position[0]] = repr(float(self.ceiling_xy[0]))
            args[s.base_position[1]] = repr(float(self.ceiling_xy[1]))
        self._setting(s.base_pose, "base pose (mount_T_base)", self.mount_T_base is not None)
        if s.base_pose and self.mount_T_base is not None:
            args.update(zip(s.base_pose, _xyz_rpy(np.array(self.mount_T_base).reshape(4, 4)), strict=True))
        self._setting(s.camera_pose, "camera pose (flange_T_camera)", self.flange_T_camera is not None)
        if s.camera_pose and self.flange_T_camera is not None:
            mount_T_camera = invert(_flange_T_mount(cell)) @ np.array(self.flange_T_camera).reshape(4, 4)
            args.update(zip(s.camera_pose, _xyz_rpy(mount_T_camera), strict=True))
        return args

    def _setting(self, argument: object, what: str, given: bool) -> None:
        if given and not argument:
            raise InputError(f"the {self.name} cell's description takes no {what}",
                             hint=f"leave it out, or name its xacro argument in {self.cell_file.path}: "
                                  "description.settings")


def _xyz_rpy(T: np.ndarray) -> tuple[str, str]:
    """URDF origin text (xyz, rpy: fixed axes x, y, z) of a rigid transform."""
    from scipy.spatial.transform import Rotation

    rpy = Rotation.from_matrix(T[:3, :3]).as_euler("xyz")
    return (" ".join(repr(float(v)) for v in T[:3, 3]), " ".join(repr(float(v)) for v in rpy))


@functools.lru_cache(maxsize=16)
def _flange_T_mount(cell: CellFile) -> np.ndarray:
    """The camera frame's URDF parent in the flange frame (from the description as written)."""
    urdf = _expand_file(cell, tuple(sorted(cell.arguments)))
    check_structure(urdf, cell.description)
    return parent_T_child(urdf, cell.flange_link, camera_parent(urdf, cell.camera_frame))


#: largest |R^T R - I| entry a given rotation may have: 5 decimals written by hand are
#: off by about 1e-5; the rotation used is then the nearest true one
RIGID_TOLERANCE = 1e-4
#: below this the rotation is taken as written (calibration output, 9 decimals)
_EXACT = 1e-9


def _rigid(values: Iterable[float], what: str) -> tuple[float, ...]:
    """16 numbers of a rigid 4 x 4 transform (row by row), or a one-line InputError. A
    rotation orthonormal within :data:`RIGID_TOLERANCE` is replaced by the nearest rotation
    (polar decomposition), so that a matrix written with 5 decimals is accepted."""

    m = [float(v) for v in values]
    ok = len(m) == 16 and all(math.isfinite(v) for v in m) and m[12:] == [0.0, 0.0, 0.0, 1.0]
    if ok:
        R = np.array([m[0:3], m[4:7], m[8:11]])
        error = float(np.max(np.abs(R.T @ R - np.eye(3))))
        ok = error <= RIGID_TOLERANCE and float(np.linalg.det(R)) > 0  # a mirror is orthonormal too, but no pose
        if ok and error > _EXACT:
            u, _, vt = np.linalg.svd(R)
            R = u @ vt
            for i in range(3):
                m[4 * i: 4 * i + 3] = [float(v) for v in R[i]]
    if not ok:
        raise InputError(f"{what} is not a rigid 4 x 4 transform",
                         hint=f"give 16 numbers row by row with a rotation (orthonormal within {RIGID_TOLERANCE:g}, "
                              "determinant +1) and 0 0 0 1 last")
    return tuple(m)


def expand_urdf(config: CellConfig = CellConfig()) -> str:  # noqa: B008 (frozen)
    """URDF text of the cell for the given settings (its cell file checked against it); collision
    meshes replaced by fitted capsules inflated by the safety distance (:mod:`.capsule_fit`)."""
    cell = config.cell_file
    urdf = _fitted(config).urdf
    check_against_urdf(cell, urdf)
    return urdf


def mesh_capsules(config: CellConfig = CellConfig()) -> tuple[FittedCapsule, ...]:  # noqa: B008 (frozen)
    """The capsules fitted to the description's collision meshes (link frames, before inflation)."""
    return _fitted(config).capsules


def _fitted(config: CellConfig) -> MeshFit:
    # a description that takes no safety distance (a plain URDF, most vendors' xacros) gets its
    # primitives inflated here, and the capsules fitted to its meshes take it too
    cell = config.cell_file
    urdf = _expand_file(cell, tuple(sorted(config.xacro_args().items())))
    check_structure(urdf, cell.description)  # before anything else reads the text
    if not cell.settings.safety_distance:
        urdf = inflate_primitives(urdf, config.safety_distance)
    return fit_mesh_collisions(urdf, cell.description, config.safety_distance, cell_rule(cell.path))


def _expand_file(cell: CellFile, args: tuple[tuple[str, str], ...]) -> str:
    """URDF text of the cell's description for the given xacro arguments: a URDF as written
    (checked XML), a xacro expanded in the sandbox (:func:`expand_xacro`). Cached per process
    by the arguments and the content of every file the description reads."""
    if cell.description.suffix.lower() == ".urdf":
        text = read_description(cell.description)
        key = (str(cell.description), args, hashlib.sha256(text.encode()).hexdigest())
        if key not in _EXPANDED:
            _check_xml(text, str(cell.description))
            _remember(key, text)
        return _EXPANDED[key]
    with tempfile.TemporaryDirectory(prefix="recon-cell-") as tmp:
        files = _annotated(cell, Path(tmp))
        h = hashlib.sha256()
        for original, copy in sorted(files.copies.items()):
            h.update(str(original).encode())
            h.update(copy.read_bytes())
        key = (str(cell.description), args, h.hexdigest())
        if key not in _EXPANDED:
            _remember(key, expand_xacro(cell, files, args))
    return _EXPANDED[key]


_EXPANDED: dict[tuple[str, tuple[tuple[str, str], ...], str], str] = {}


def _remember(key: tuple[str, tuple[tuple[str, str], ...], str], text: str) -> None:
    if len(_EXPANDED) >= 16:
        _EXPANDED.pop(next(iter(_EXPANDED)))
    _EXPANDED[key] = text


#: largest robot description file read (URDF or xacro, each file it includes) [bytes]
MAX_DESCRIPTION_BYTES = 20_000_000
#: xacro files a description may include, at most
MAX_XACRO_FILES = 200
#: bounds of a description's xacro expansion (expressions checked as a script's are)
DESCRIPTION_LIMITS = Limits(percent_format=True, max_text=100_000_000, max_elements=500_000, max_macro_depth=100,
                            max_seconds=20.0,
                            max_file_bytes=MAX_DESCRIPTION_BYTES, max_files=MAX_XACRO_FILES)


def read_description(path: Path) -> str:
    """A description file's text, through the size guard every user file passes."""
    refuse = file_errors(path, "robot description", "give the robot's URDF or xacro file",
                         lambda size: (f"{size:,} bytes, more than {MAX_DESCRIPTION_BYTES:,}",
                                       "give a URDF or xacro file of the robot without embedded data"))
    data = read_limited(path, MAX_DESCRIPTION_BYTES, refuse, empty=False)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        raise InputError(f"{path}: the robot description is not UTF-8 text",
                         hint="give the robot's URDF or xacro file") from None


def _check_xml(text: str, where: str) -> None:
    try:
        root = etree.fromstring(text.encode(), parser())
    except etree.XMLSyntaxError as exc:
        raise InputError(f"{where}:{exc.lineno or 1}: the robot description is not XML ({exc.msg})",
                         hint="give the robot's URDF file") from None
    tree = root.getroottree()
    if tree.docinfo.doctype or tree.docinfo.internalDTD is not None:
        raise InputError(f"{where}:1: DOCTYPE declarations are not allowed in a robot description",
                         hint="remove the <!DOCTYPE ...> (and any entities)")
    for pi in (*root.itersiblings(preceding=True), *root.itersiblings(), *root.iter()):
        if isinstance(pi, etree._ProcessingInstruction):
            raise InputError(f"{where}:{pi.sourceline or 1}: a processing instruction <?{pi.target} ...?> in the "
                             "robot description", hint="remove it: a URDF holds none")


def _annotated(cell: CellFile, tmp: Path) -> Annotated:
    """The description and the files it includes, checked (read rule of the cell file, size,
    safe XML) and copied with their sources tagged."""
    files = Annotated(tmp, cell_rule(cell.path), "robot description", MAX_DESCRIPTION_BYTES,
                      max_files=MAX_XACRO_FILES, full_names=True)
    try:
        files.add(cell.description)
    except ScriptError as exc:
        raise InputError(_reworded(exc.message), hint=exc.hint and _reworded(exc.hint)) from None
    return files


def expand_xacro(cell: CellFile, files: Annotated, args: tuple[tuple[str, str], ...]) -> str:
    """URDF text of a checked xacro description (:func:`_annotated`), expanded by xacro in
    the sandbox that expands scripts: expressions checked and bounded (no dunder names, no
    attributes but namespaces', no ``vars``/``type``/..., ``$(eval ...)`` by the same
    evaluator however it is spelled), ``xacro.load_yaml`` and ``xacro:include`` confined to
    the cell file's folder and robot/, no environment, bounded work."""
    import xacro

    main = files.copies[cell.description.resolve()]
    frames = None
    try:
        with sandboxed(files.rule, DESCRIPTION_LIMITS, includes=files.includes, originals=files.originals) as frames:
            doc = xacro.process_file(str(main), mappings=dict(args))
            _untag(doc)
            text = str(doc.toprettyxml(indent="  "))
    except Exception as exc:  # the description's mistakes and refusals, as one line
        error = expansion_error(str(cell.description), exc, frames, files)
        raise InputError(_reworded(error.message), hint=error.hint and _reworded(error.hint)) from None
    return text.replace(str(main), str(cell.description))


def _untag(node: Any) -> None:
    """Take the source tags of :class:`Annotated` and every processing instruction (a URDF
    holds none; the URDF parsers of pinocchio and MuJoCo refuse some) off an expanded DOM."""
    if node.nodeType == node.ELEMENT_NODE and node.hasAttribute(SRC_ATTR):
        node.removeAttribute(SRC_ATTR)
    for child in list(node.childNodes):
        if child.nodeType == child.PROCESSING_INSTRUCTION_NODE:
            node.removeChild(child)
        elif child.nodeType == child.ELEMENT_NODE:
            if child.hasAttribute(SRC_ATTR):
                child.removeAttribute(SRC_ATTR)
            _untag(child)


def _reworded(text: str) -> str:
    """A message of the expression checks (worded for scripts) for a robot description."""
    for old, new in (("script expressions", "robot description expressions"), ("scripts may", "descriptions may"),
                     ("in scripts", "in robot descriptions"), ("the script", "the description"),
                     ("Scripts", "Robot descriptions"), ("scripts", "robot descriptions")):
        text = text.replace(old, new)
    return text
