"""The station file: which robot and camera adapters a cell uses, and how to reach them.

A YAML file (documented with a complete example in docs/hardware.md)::

    format: 1
    name: thesis cell
    cell: {kind: gantry, safety_distance: 0.03, table_lift: 0.0}   # the description to plan with
    hand_eye:                       # flange_T_camera, 4 rows (default: the description's)
      - [0.0085, -0.0118, -0.9999, -0.0289]
      - ...
    joint_offsets: [0, 0, 0, 0, 0, 0, 0.5, -0.43, 0]   # the joints' zero offsets, [deg] or [mm] (optional)
    robot:
      adapter: ads                  # ads | sim
      ads: {ams_net_id: 5.80.201.232.1.1, ip: 192.168.0.10, port: 851, ...}
    camera:
      adapter: genicam              # genicam | realsense | replay | sim
      genicam: {serial: PhoXi-1234, ...}

Every key is checked when the file is read: an unknown key, a wrong type or a missing
section is one line naming ``FILE: key``, never quoting the file's text. A station file that
is a link leading out of its folder is refused before it is read, and so is a cell file it
names that does not lie in that folder (links resolved). The adapters (their names, what they are, how
their sections are read) are the registry of recon_cli/backends/adapters.py.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from recon_cli.backends.adapters import (
    CAMERA_ADAPTERS,
    ROBOT_ADAPTERS,
    CameraConfig,
    RobotConfig,
    station_capabilities,
)
from recon_cli.backends.base import Capabilities
from recon_cli.errors import FileError, InputError, UnknownNameError
from recon_cli.inputs import files
from recon_cli.inputs.schema import check
from recon_cli.inputs.yamlfile import line_of, read_yaml, unknown_key_text
from recon_cli.robot.cell_file import load_cell
from recon_cli.robot.description import CellConfig, CellName

STATION_FORMAT = 1
TOP_KEYS = ("format", "name", "cell", "hand_eye", "joint_offsets", "robot", "camera")


@dataclass(frozen=True)
class StationFile:
    """A read station file: its cell, and the adapter (registry name) and typed section of
    the robot and of the camera."""

    path: Path
    name: str
    cell: CellConfig
    robot_adapter: str
    robot: RobotConfig
    camera_adapter: str
    camera: CameraConfig
    raw: dict = field(default_factory=dict, repr=False)
    #: the robot's joint zero offsets as the file gives them ([deg] of a revolute joint, [mm] of
    #: a prismatic one), in the cell's joint order: the joints the robot reports plus these are
    #: its true joints (recon_cli.backends.joint_offsets); None: none
    joint_offsets: tuple[float, ...] | None = None

    @property
    def capabilities(self) -> Capabilities:
        """What the station of this file can do (simulated only when both adapters are)."""
        return station_capabilities(ROBOT_ADAPTERS[self.robot_adapter], CAMERA_ADAPTERS[self.camera_adapter])


def _known_keys(d: Any, where: str, known: tuple[str, ...]) -> None:
    if not isinstance(d, dict):
        raise InputError(f"{where} is not a mapping", hint="write 'key: value' lines under it")
    for key in d:
        if key not in known:
            raise InputError(unknown_key_text(where, key), hint=f"known keys: {', '.join(known)}")


def load_station(path: Path) -> StationFile:
    """Read and check a station file (the one YAML reader, then schemas/station.schema.json,
    then the adapters' own checks)."""

    path = Path(path)
    data = read_yaml(path, "station file", hint="see docs/hardware.md for an example", root=path.parent)
    w = str(path)
    check(data, "station", w)
    cell_map = data.get("cell", {}) or {}
    _known_keys(cell_map, f"{w}: cell", ("kind", "safety_distance", "table_lift", "ceiling_xy"))
    hand_eye = data.get("hand_eye")
    flat = None
    if hand_eye is not None:
        try:
            rows = [[float(v) for v in row] for row in hand_eye]
        except (TypeError, ValueError):
            rows = []
        if len(rows) != 4 or any(len(r) != 4 for r in rows):
            raise InputError(f"{w}: hand_eye is not 4 rows of 4 numbers", hint="flange_T_camera, row by row [m]")
        flat = tuple(v for r in rows for v in r)
    kind = str(cell_map.get("kind", "gantry"))
    if Path(kind).suffix.lower() in (".yaml", ".yml"):  # a cell file, relative to the station file
        named = path.parent / Path(kind).expanduser()
        if files.link_out_of(named, path.parent) is not None:  # before it is read
            line = line_of(cell_map, "kind") or line_of(data, "cell")
            raise FileError(f"{w}:{line}: cell.kind names a file outside the station file's folder "
                            f"{path.parent.absolute()} (or a link leading out of it); not read",
                            hint="keep the cell file in the station file's folder (docs/hardware.md)")
        kind = str(named)
        load_cell(kind)  # its mistakes are lines of that file
    try:
        cell = CellConfig(kind=CellName.parse(kind),
                          safety_distance=(float(cell_map["safety_distance"]) if "safety_distance" in cell_map
                                           else None),  # type: ignore[arg-type]  # None: the cell file's
                          table_lift=float(cell_map.get("table_lift", 0.0)),
                          ceiling_xy=tuple(cell_map.get("ceiling_xy", (0.0, 0.0))), flange_T_camera=flat)
    except (TypeError, ValueError):  # (the schema has checked the types; Python's text would quote the value)
        raise InputError(f"{w}: cell holds a value that is not a number where one is expected",
                         hint="see docs/hardware.md") from None
    except UnknownNameError as exc:  # the name is not repeated: it is the file's text
        line = line_of(cell_map, "kind") or line_of(data, "cell")
        raise InputError(f"{w}:{line}: cell.kind is not a shipped cell nor a cell FILE.yaml" if line else
                         f"{w}: cell.kind is not a shipped cell nor a cell FILE.yaml", hint=exc.hint) from None
    except InputError as exc:
        key = "hand_eye" if "hand-eye" in exc.message else "cell"
        line = line_of(data, key)
        raise InputError(f"{w}:{line}: {exc.message}" if line else f"{w}: {exc.message}", hint=exc.hint) from None

    robot_adapter, robot = _part(data, "robot", ROBOT_ADAPTERS, w,
                                 "robot: {adapter: ads, ads: {...}} or {adapter: sim}")
    camera_adapter, camera = _part(data, "camera", CAMERA_ADAPTERS, w, "camera: {adapter: genicam, genicam: {...}}")
    offsets = None
    if data.get("joint_offsets") is not None:  # (the schema has checked the numbers and their range)
        line = line_of(data, "joint_offsets")
        at = f"{w}:{line}" if line else w
        if ROBOT_ADAPTERS[robot_adapter].simulated:
            raise InputError(f"{at}: joint_offsets correct the joints a real robot reports; the {robot_adapter} "
                             "robot adapter is a simulation and reports its true joints",
                             hint="remove joint_offsets, or use it with the real robot's adapter")
        offsets = tuple(float(v) for v in data["joint_offsets"])
        joints = cell.cell_file.planning_joints
        if len(offsets) != len(joints):
            raise InputError(f"{at}: joint_offsets has {len(offsets)} numbers; the cell has {len(joints)} joints "
                             f"({', '.join(joints)})", hint="one offset per joint, in the cell's joint order")
    return StationFile(path, str(data.get("name", path.stem)), cell, robot_adapter, robot, camera_adapter, camera,
                       data, offsets)


def _part(data: dict, part: str, registry: dict, w: str, example: str):
    """The adapter name and typed config of the ``robot`` or ``camera`` section."""

    mapping = data.get(part)
    if mapping is None:
        raise InputError(f"{w}: no {part} section", hint=example)
    _known_keys(mapping, f"{w}: {part}", ("adapter", *registry))
    name = str(mapping.get("adapter", ""))
    if name not in registry:  # (the schema refuses it first; the name is the file's text, not repeated)
        raise InputError(f"{w}: {part}.adapter is not one of {', '.join(registry)}",
                         hint=f"choose one of: {', '.join(registry)}")
    line = line_of(mapping, name) or line_of(data, part)
    where = f"{w}:{line}: {part}.{name}" if line else f"{w}: {part}.{name}"
    return name, registry[name].read(mapping.get(name) or {}, where)
