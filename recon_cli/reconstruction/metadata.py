"""The metadata of a scan store, read back and checked: ``session.json`` as a typed
:class:`SessionInfo`, ``scan.json`` against its schema.

Both files are versioned (``format``) and described by JSON Schemas in ``schemas/``
(``session.schema.json``, ``scan.schema.json``) that give every number its range; every
violation is one :class:`~recon_cli.errors.MetadataError` naming the file and the line
(broken JSON) or the key (a missing key, a value of the wrong type or out of range), so a
reader can skip a bad scan with its reason instead of stopping.

Both are read by the one JSON reader (:func:`recon_cli.inputs.jsonfile.load_json`: regular
files of bounded size, bounded nesting, no NaN, long integers or duplicate keys).

A pose (``world_T_camera_fk``, ``marker_T_camera``, ``world_T_marker``, ...) must also be a
rigid transform: a rotation and a translation, last row 0 0 0 1.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from recon_cli.errors import MetadataError
from recon_cli.inputs.jsonfile import (  # noqa: F401 (also read from here)
    _WRONG_FILE,
    MAX_DEPTH,
    MAX_INT_DIGITS,
    MAX_JSON_BYTES,
    MAX_METADATA_BYTES,
    load_json,
    parse_json,
    read_bytes,
)
from recon_cli.inputs.jsonschemas import RIGID_TOLERANCE, check, check_pose  # noqa: F401 (also read from here)

SESSION_FORMAT = 1
SCAN_FORMAT = 1

# --------------------------------------------------------------------- session.json
@dataclass(frozen=True)
class BoxInfo:
    """An axis-aligned box: centre and edge lengths [m] in ``frame`` (world or marker)."""

    center: tuple[float, float, float]
    size: tuple[float, float, float]
    frame: str = "world"

    def to_dict(self) -> dict:
        return {"frame": self.frame, "center": list(self.center), "size": list(self.size)}

    @classmethod
    def from_dict(cls, d: dict | None) -> BoxInfo | None:
        if d is None:
            return None
        cx, cy, cz = (float(v) for v in d["center"])
        sx, sy, sz = (float(v) for v in d["size"])
        return cls((cx, cy, cz), (sx, sy, sz), d.get("frame", "world"))


def _sensor_range(d: dict | None) -> tuple[float, float, float] | None:
    return None if d is None else (float(d["z_min"]), float(d["z_max"]), float(d["max_incidence_deg"]))


def _board(d: dict | None) -> tuple[int, int, float, float, str] | None:
    if d is None:
        return None
    return (int(d["squares_x"]), int(d["squares_y"]), float(d["square_length"]), float(d["marker_length"]),
            str(d["dictionary"]))


def _pose(value) -> np.ndarray | None:
    return None if value is None else np.asarray(value, dtype=float)


@dataclass(frozen=True)
class SessionInfo:
    """What produced a scan store (``session.json``). Written by every acquisition session,
    read back by ``recon register``; a recorded store may leave any of it unknown (None)."""

    backend: str | None = None
    mode: str | None = None
    cell_kind: str | None = None
    safety_distance: float | None = None
    table_lift: float | None = None
    sensor: str | None = None
    #: (z_min [m], z_max [m], max_incidence [deg]) of the sensor
    sensor_range: tuple[float, float, float] | None = None
    #: the cell's ChArUco board: (squares_x, squares_y, square_length [m], marker_length [m], dictionary)
    board: tuple[int, int, float, float, str] | None = None
    noise: bool | None = None
    seed: int | None = None
    object_name: str | None = None
    world_T_object: np.ndarray | None = None
    object_box: BoxInfo | None = None
    crop_box: BoxInfo | None = None
    world_T_marker: np.ndarray | None = None
    script: str | None = None
    realism: dict[str, Any] | None = None  # the simulation's realism profile (name, file, effects on)
    created: float = field(default_factory=time.time)
    format: int = SESSION_FORMAT

    def to_dict(self) -> dict[str, Any]:
        return {
            "format": self.format, "created": self.created, "backend": self.backend, "mode": self.mode,
            "cell": {"kind": self.cell_kind, "safety_distance": self.safety_distance, "table_lift": self.table_lift},
            "sensor": self.sensor,
            **({} if self.sensor_range is None else {"sensor_range": dict(zip(
                ("z_min", "z_max", "max_incidence_deg"), self.sensor_range, strict=True))}),
            **({} if self.board is None else {"board": dict(zip(
                ("squares_x", "squares_y", "square_length", "marker_length", "dictionary"), self.board, strict=True))}),
            "noise": self.noise, "seed": self.seed, "script": self.script,
            "object": None if self.object_name is None else {"name": self.object_name,
                                                             "world_T_object": self.world_T_object},
            "object_box": None if self.object_box is None else self.object_box.to_dict(),
            "crop_box": None if self.crop_box is None else self.crop_box.to_dict(),
            "world_T_marker": self.world_T_marker,
            **({} if self.realism is None else {"realism": self.realism}),
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> SessionInfo:
        """From a dict that passed ``schemas/session.schema.json``."""
        cell = d.get("cell") or {}
        obj = d.get("object") or {}
        return cls(
            backend=d.get("backend"), mode=d.get("mode"), cell_kind=cell.get("kind"),
            safety_distance=cell.get("safety_distance"), table_lift=cell.get("table_lift"),
            sensor=d.get("sensor"), sensor_range=_sensor_range(d.get("sensor_range")), board=_board(d.get("board")),
            noise=d.get("noise"), seed=d.get("seed"),
            object_name=obj.get("name"), world_T_object=_pose(obj.get("world_T_object")),
            object_box=BoxInfo.from_dict(d.get("object_box")), crop_box=BoxInfo.from_dict(d.get("crop_box")),
            world_T_marker=_pose(d.get("world_T_marker")), script=d.get("script"), realism=d.get("realism"),
            created=float(d.get("created", 0.0)), format=int(d.get("format", SESSION_FORMAT)))


def read_session(root: Path) -> SessionInfo:
    """``root/session.json`` checked and typed; an empty SessionInfo when there is none. A
    session.json that is a link leading out of the store is refused before it is read."""
    path = Path(root) / "session.json"
    if not (path.exists() or path.is_symlink()):
        return SessionInfo(created=0.0)
    data = load_json(path, "session.json", MAX_METADATA_BYTES, root=Path(root))
    check(data, "session.schema.json", path, "session.json",
          hint="repair or remove session.json (without it, pass the crop box with --crop-box)")
    for key, value in (("world_T_marker", data.get("world_T_marker")),
                       ("object.world_T_object", (data.get("object") or {}).get("world_T_object"))):
        if value is not None:
            check_pose(value, path, "session.json", key)
    return SessionInfo.from_dict(data)


# --------------------------------------------------------------------- scan.json
def read_scan_meta(folder: Path) -> dict[str, Any]:
    """``folder/scan.json`` checked against ``schemas/scan.schema.json``."""
    path = Path(folder) / "scan.json"
    if not path.exists():
        raise MetadataError(f"{folder}: scan folder without scan.json", path=str(path),
                            hint="a scan needs scan.json beside its depth.png")
    data = load_json(path, "scan.json", MAX_METADATA_BYTES, root=Path(folder).parent)
    check(data, "scan.schema.json", path, "scan.json")
    for key in ("world_T_camera_fk", "marker_T_camera"):
        if data.get(key) is not None:
            check_pose(data[key], path, "scan.json", key)
    return data
