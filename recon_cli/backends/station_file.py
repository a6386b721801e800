"""The station file: which robot and camera adapters a cell uses, and how to reach them.

A YAML file (documented with a complete example in docs/hardware.md)::

    format: 1
    name: thesis cell
    cell: {kind: gantry, safety_distance: 0.03, table_lift: 0.0}   # the description to plan with
    hand_eye:                       # flange_T_camera, 4 rows (default: the description's)
      - [0.0085, -0.0118, -0.9999, -0.0289]
      - ...
    robot:
      adapter: ads                  # ads | sim
      ads: {ams_net_id: 5.80.201.232.1.1, ip: 192.168.0.10, port: 851, ...}
    camera:
      adapter: genicam              # genicam | realsense | replay | sim
      genicam: {serial: PhoXi-1234, ...}

Every key is checked when the file is read: an unknown key, a wrong type or a missing
section is one line naming ``FILE: key``. The adapters' own sections are parsed by their
modules (recon_cli/backends/hardware/).
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from recon_cli.config import DEFAULTS, RESOLUTION_RANGE
from recon_cli.errors import InputError, UnknownNameError
from recon_cli.robot.description import CellConfig, CellKind

STATION_FORMAT = 1
ROBOT_ADAPTERS = ("ads", "sim")
CAMERA_ADAPTERS = ("sim", "genicam", "realsense", "replay")
#: camera adapter -> (module, config class); each module has ``open_camera(config)``
CAMERA_MODULES = {
    "genicam": ("recon_cli.backends.hardware.genicam", "GenICamConfig"),
    "realsense": ("recon_cli.backends.hardware.realsense", "RealSenseConfig"),
    "replay": ("recon_cli.backends.hardware.replay", "ReplayConfig"),
}
TOP_KEYS = ("format", "name", "cell", "hand_eye", "robot", "camera")


@dataclass(frozen=True)
class SimCameraConfig:
    """``camera.sim``: the simulated sensor rendered at the robot's measured joints (a camera
    stand-in for wiring and testing a real robot adapter)."""

    noise: bool = DEFAULTS.sensor.noise
    resolution: float = DEFAULTS.sensor.resolution

    @classmethod
    def from_mapping(cls, d: dict, where: str = "camera.sim") -> SimCameraConfig:
        _known_keys(d, where, ("noise", "resolution"))
        cfg = cls(bool(d.get("noise", cls.noise)), float(d.get("resolution", cls.resolution)))
        lo, hi = RESOLUTION_RANGE
        if not lo <= cfg.resolution <= hi:
            raise InputError(f"{where}.resolution = {cfg.resolution} is outside {lo:g} ... {hi:g}", hint="e.g. 0.5")
        return cfg


@dataclass(frozen=True)
class StationFile:
    path: Path
    name: str
    cell: CellConfig
    robot_adapter: str
    robot: Any  # the adapter's config (AdsConfig) or None for "sim"
    camera_adapter: str
    camera: Any  # the adapter's config
    raw: dict = field(default_factory=dict, repr=False)

    @property
    def hardware(self) -> bool:
        """True when anything but the simulation is involved."""
        return self.robot_adapter != "sim" or self.camera_adapter != "sim"


def _known_keys(d: Any, where: str, known: tuple[str, ...]) -> None:
    if not isinstance(d, dict):
        raise InputError(f"{where} is not a mapping", hint="write 'key: value' lines under it")
    for key in d:
        if key not in known:
            raise InputError(f"{where}.{key} is not a known key", hint=f"known keys: {', '.join(known)}")


def camera_config(adapter: str, mapping: dict, where: str):
    """The typed config of a camera adapter (its module imported lazily)."""
    if adapter == "sim":
        return SimCameraConfig.from_mapping(mapping, where)
    module_name, cls_name = CAMERA_MODULES[adapter]
    module = importlib.import_module(module_name)
    return getattr(module, cls_name).from_mapping(mapping, where)


def load_station(path: Path) -> StationFile:
    """Read and check a station file (the one YAML reader, then schemas/station.schema.json,
    then the adapters' own checks)."""
    from recon_cli.inputs.schema import check
    from recon_cli.inputs.yamlfile import line_of, read_yaml

    path = Path(path)
    data = read_yaml(path, "station file", hint="see docs/hardware.md for an example")
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
    try:
        cell = CellConfig(kind=CellKind.parse(str(cell_map.get("kind", "gantry"))),
                          safety_distance=float(cell_map.get("safety_distance", CellConfig.safety_distance)),
                          table_lift=float(cell_map.get("table_lift", 0.0)),
                          ceiling_xy=tuple(cell_map.get("ceiling_xy", (0.0, 0.0))), flange_T_camera=flat)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{w}: cell: {exc}", hint="see docs/hardware.md") from None
    except InputError as exc:
        key = "hand_eye" if "hand-eye" in exc.message else "cell"
        line = line_of(data, key)
        raise InputError(f"{w}:{line}: {exc.message}" if line else f"{w}: {exc.message}", hint=exc.hint) from None

    robot_map = data.get("robot")
    if robot_map is None:
        raise InputError(f"{w}: no robot section", hint="robot: {adapter: ads, ads: {...}} or {adapter: sim}")
    _known_keys(robot_map, f"{w}: robot", ("adapter", *ROBOT_ADAPTERS))
    robot_adapter = str(robot_map.get("adapter", ""))
    if robot_adapter not in ROBOT_ADAPTERS:
        raise UnknownNameError("robot adapter", robot_adapter, ROBOT_ADAPTERS)
    robot = None
    if robot_adapter == "ads":
        from recon_cli.backends.hardware.ads import AdsConfig

        line = line_of(robot_map, "ads")
        robot = AdsConfig.from_mapping(robot_map.get("ads") or {},
                                       f"{w}:{line}: robot.ads" if line else f"{w}: robot.ads")

    camera_map = data.get("camera")
    if camera_map is None:
        raise InputError(f"{w}: no camera section", hint="camera: {adapter: genicam, genicam: {...}}")
    _known_keys(camera_map, f"{w}: camera", ("adapter", *CAMERA_ADAPTERS))
    camera_adapter = str(camera_map.get("adapter", ""))
    if camera_adapter not in CAMERA_ADAPTERS:
        raise UnknownNameError("camera adapter", camera_adapter, CAMERA_ADAPTERS)
    line = line_of(camera_map, camera_adapter) or line_of(data, "camera")
    camera = camera_config(camera_adapter, camera_map.get(camera_adapter) or {},
                           f"{w}:{line}: camera.{camera_adapter}" if line else f"{w}: camera.{camera_adapter}")
    return StationFile(path, str(data.get("name", path.stem)), cell, robot_adapter, robot, camera_adapter, camera,
                       data)
