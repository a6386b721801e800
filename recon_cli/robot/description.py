"""A cell's robot description expanded into URDF text, and ``CellConfig``: which cell (a
shipped cell's name or a cell file) with recon's settings of it.

The cell file (:mod:`recon_cli.robot.cell_file`) names the description (a URDF or xacro
file), its xacro arguments and the arguments that take the settings (safety distance, table
lift, base and camera poses). The one description feeds every consumer: pinocchio
(kinematics, dynamics), the collision model and the MuJoCo scene. Expansion is cached per
process, keyed by the arguments and the content of the description's files.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import io
import math
import re
from collections.abc import Iterable
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path

import numpy as np
from lxml import etree

from recon_cli.errors import InputError, UnknownNameError
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


def _digest(description: Path) -> str:
    """Content of a URDF file, or of a xacro file and every file it includes or loads (the
    files :func:`guard_xacro` reads)."""
    h = hashlib.sha256()
    if description.suffix.lower() == ".urdf":
        h.update(_read_description(description).encode())
        return h.hexdigest()
    for path, text in sorted(guard_xacro(description).items()):
        h.update(str(path).encode())
        h.update(text.encode())
    return h.hexdigest()


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
    if not cell.settings.safety_distance:
        urdf = inflate_primitives(urdf, config.safety_distance)
    return fit_mesh_collisions(urdf, cell.description, config.safety_distance)


def _expand_file(cell: CellFile, args: tuple[tuple[str, str], ...]) -> str:
    return _expand(str(cell.description), args, _digest(cell.description))


#: largest robot description file read (URDF or xacro) [bytes]
MAX_DESCRIPTION_BYTES = 20_000_000
#: xacro files a description may include, at most
MAX_XACRO_FILES = 200
_EXPRESSION = re.compile(r"\$\{([^}]*)\}|\$\(([^)]*)\)")
_LOAD_YAML = re.compile(r"load_yaml\(\s*[\"']([^\"']+)[\"']")
_INCLUDE = re.compile(r"<xacro:include\b[^>]*\bfilename\s*=\s*[\"']([^\"']+)[\"']")


def _read_description(path: Path) -> str:
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


def guard_xacro(description: Path) -> dict[Path, str]:
    """Refuse a xacro description whose expressions could leave xacro's expression language;
    the text of every file it includes or loads (``xacro.load_yaml``), by path.

    xacro evaluates ``${...}`` with Python's eval over a dictionary of harmless names; a
    dunder attribute (``().__class__...``) walks out of it, and ``$(eval ...)`` is plain
    Python. A description file (and every file it includes) may use neither: one line naming
    the file, line and expression."""
    seen: dict[Path, str] = {}
    todo = [description.resolve()]
    while todo:
        path = todo.pop()
        if path in seen:
            continue
        if len(seen) >= MAX_XACRO_FILES:
            raise InputError(f"{description}: the description includes more than {MAX_XACRO_FILES} files",
                             hint="give the robot's URDF instead")
        text = seen[path] = _read_description(path)
        if path.suffix.lower() in (".yaml", ".yml"):
            continue
        for m in _EXPRESSION.finditer(text):
            expression = m.group(0)
            if "__" in expression or (m.group(2) or "").strip().startswith("eval"):
                line = text.count("\n", 0, m.start()) + 1
                raise InputError(f"{path}:{line}: the xacro expression {expression[:60]!r} is refused (dunder names "
                                 "and $(eval ...) run Python beyond xacro's expression language)",
                                 hint="use plain arithmetic and xacro properties, or give the expanded URDF")
        for m in (*_INCLUDE.finditer(text), *_LOAD_YAML.finditer(text)):
            name = m.group(1)
            if "$" in name:
                continue  # a file named by an expression: xacro resolves it (and refuses what it cannot)
            todo.append((path.parent / name).resolve())
    return seen


@functools.lru_cache(maxsize=16)
def _expand(description: str, args: tuple[tuple[str, str], ...], digest: str) -> str:
    if description.lower().endswith(".urdf"):
        text = _read_description(Path(description))
        try:
            etree.fromstring(text.encode())
        except etree.XMLSyntaxError as exc:
            raise InputError(f"{description}:{exc.lineno or 1}: the robot description is not XML ({exc.msg})",
                             hint="give the robot's URDF file") from None
        return text
    import xacro

    # xacro reports harmless notes on stderr; keep library output quiet
    try:
        with contextlib.redirect_stderr(io.StringIO()):
            doc = xacro.process_file(description, mappings=dict(args))
    except Exception as exc:  # xacro's errors (XML, expressions, missing includes) are the file's mistakes
        reason = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        raise InputError(f"{description}: xacro cannot expand the robot description ({reason})",
                         hint="check the xacro file (run xacro on it to see where), or give the expanded "
                              "URDF") from None
    text = doc.toprettyxml(indent="  ")
    return str(text)
