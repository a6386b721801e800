"""One acquisition session for every workflow: object, cell, station, scan store.

Capture, autoscan, script runs and the benchmarks open their session here and nowhere
else::

    with open_session(SessionSpec(out, config, mode=Mode.CAPTURE)) as s:
        move = s.acquisition.move_to_pose(T)      # plan -> check -> execute -> settle
        s.acquisition.scan(view_record(view, T))  # capture -> write the scan (atomic)

:func:`open_session` loads the object, builds the cell with the object's box as collision
object, opens the station (the simulation, or the adapters of a station file after the
check of ``recon station check`` has passed), creates the scan store with a typed
:class:`SessionInfo` (``session.json``, versioned) and writes the effective configuration
(``config.yaml``) beside it. What the session writes besides the scans (the backend, the
object's exact mesh, the realism record) follows the station's capabilities.
``plan_only=True`` (dry runs) stops after the cell: nothing is written, nothing moves.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from recon_cli.acquisition import Acquisition
from recon_cli.backends.base import Backend, Capabilities, Station  # noqa: F401 (Backend re-exported)
from recon_cli.backends.hardware.station import AdapterStation, preflight
from recon_cli.backends.sim.station import SimStation
from recon_cli.backends.station_file import load_station
from recon_cli.cell_check import check_layout
from recon_cli.config import DEFAULTS, Config, write_config
from recon_cli.console import write_json
from recon_cli.errors import FileError, HardwareUnavailable, InputError
from recon_cli.objects import SceneObject, load_object, ycb_path
from recon_cli.outputs import atomic_write
from recon_cli.perception.charuco import cell_board
from recon_cli.perception.sensor import cell_sensor
from recon_cli.planning.planner import seed_ompl
from recon_cli.reconstruction.metadata import SESSION_FORMAT, BoxInfo, SessionInfo  # noqa: F401 (re-exported)
from recon_cli.reconstruction.scan_store import ScanStore
from recon_cli.recording.station import RecordedStation
from recon_cli.robot.cell import Cell
from recon_cli.robot.collision import ObjectBox
from recon_cli.robot.poses import named_configuration

if TYPE_CHECKING:
    from recon_cli.backends.station_file import StationFile
    from recon_cli.recording.recorder import Recorder


class Mode(StrEnum):
    """What produced a session's scans."""

    CAPTURE = "capture"
    AUTOSCAN = "autoscan"
    SCRIPT = "script"
    BENCHMARK = "benchmark"
    CALIBRATION = "calibration"  # board views without an object (recon calibrate)


def resolve_object_name(name: str) -> str:
    """"auto": the YCB drill of the thesis where the shared data is present, else the
    built-in bottle; any other name as given."""
    if name != "auto":
        return name

    return "drill" if ycb_path("drill").exists() else "bottle"


# --------------------------------------------------------------------- the session
@dataclass(frozen=True)
class SessionSpec:
    """Everything a workflow says about its session; the rest comes from ``config``."""

    out: Path  # the scan store folder
    config: Config = DEFAULTS
    mode: Mode = Mode.CAPTURE
    backend: Backend = Backend.SIM  # HARDWARE needs a station file; with one, its capabilities decide
    box: tuple[tuple[float, float, float], tuple[float, float, float]] | None = None  # centre, size [m] (world)
    script: str | None = None  # the script of a script run
    append: bool = False  # add to the scan store in ``out`` (same cell, object and backend)
    run_folder: Path | None = None  # where config.yaml goes (default: ``out``)
    run: dict = field(default_factory=dict)  # what else config.yaml records (command, options)
    station: Path | None = None  # a station file: the robot and camera adapters (and the cell) to use
    board_only: bool = False  # nothing on the table but the ChArUco board (calibration views)
    recorder: Recorder | None = None  # the cell, every motion and every scan go into it
    station_checked: bool = False  # the station file passed its check already (recon run checks it first)
    scene_object: SceneObject | None = None  # the object as it lies (turned over); default: the config's, standing


class Session:
    """An open session: use as a context manager (closing stops the robot and frees the
    station)."""

    def __init__(self, spec: SessionSpec, rng: np.random.Generator, plan_only: bool = False,
                 station_file: StationFile | None = None) -> None:

        cfg = spec.config
        self.spec = spec
        self.rng = rng
        self.station_file = station_file
        self.scene_object = None if spec.board_only else spec.scene_object or load_object(
            resolve_object_name(cfg.scene.object_name), cfg.scene.object_scale, cfg.cell.cell_file.object_position)
        self.object_box = None if spec.board_only else self._object_box()
        self.cell = Cell(cfg.cell, object_box=self.object_box)
        check_layout(self.cell)
        self.start = named_configuration(cfg.cell.kind, "home", self.cell.joint_names)
        self.station: Station | None = None  # these three once the session is open (not with plan_only)
        self.store: ScanStore | None = None
        self.acquisition: Acquisition | None = None
        self.capabilities: Capabilities | None = None  # the station's, once it is open
        self.info: SessionInfo | None = None
        if plan_only:
            return
        try:
            self._open()
        except BaseException:
            self.close()
            raise

    def _object_box(self):

        if self.spec.box is not None:
            return ObjectBox(tuple(self.spec.box[0]), tuple(self.spec.box[1]))
        return self.scene_object.bounding_box(self.spec.config.scene.box_margin)

    def _open(self) -> None:

        spec, cfg = self.spec, self.spec.config
        sensor = cell_sensor(cfg.cell.cell_file)
        box, obj = self.object_box, self.scene_object
        if box is None or obj is None:
            crop = None
        elif spec.box is not None:
            crop = BoxInfo(tuple(box.center), tuple(box.size))
        else:
            c, s = obj.crop_box(cfg.scene.box_margin)
            crop = BoxInfo(c, s)
        self.station = open_station(spec.backend, self.cell, self.scene_object, self.start, self.rng, cfg,
                                    self.station_file)
        caps = self.capabilities = self.station.capabilities
        self.info = SessionInfo(
            backend=caps.backend.value, mode=spec.mode.value, cell_kind=cfg.cell.kind.value,
            safety_distance=cfg.cell.safety_distance, table_lift=cfg.cell.table_lift, sensor=sensor.name,
            sensor_range=(sensor.z_min, sensor.z_max, math.degrees(sensor.max_incidence)),
            board=cell_board(cfg.cell.cell_file).as_tuple(),
            noise=cfg.sensor.noise, seed=cfg.seed, object_name=None if obj is None else obj.name,
            world_T_object=None if obj is None else obj.world_T_object,
            object_box=None if box is None else BoxInfo(tuple(box.center), tuple(box.size)), crop_box=crop,
            world_T_marker=self.cell.world_T_marker, script=spec.script,
            realism=cfg.realism.summary() if caps.realism else None)
        self.store = self._open_store(self.info)
        if spec.recorder is not None:

            self.station = RecordedStation(self.station, spec.recorder)
            spec.recorder.depth_scale = sensor.depth_scale
            spec.recorder.cell(self.cell, self.station.robot.measured_joints(), box,
                               obj.mesh_world() if obj is not None and caps.ground_truth else None)
        write_config(spec.run_folder or spec.out, cfg, mode=spec.mode.value, backend=caps.backend.value,
                     script=spec.script, object=None if obj is None else obj.name,
                     station=None if spec.station is None else str(spec.station), **spec.run)
        if caps.ground_truth and obj is not None:
            write_ground_truth_mesh(spec.out, obj)
        if caps.realism and not cfg.realism.is_ideal:
            write_realism_record(spec.out, self.station.realism_record())
        self.acquisition = Acquisition(self.cell, self.station.robot, self.station.camera, self.store, self.rng,
                                       cfg.planner, depth_scale=sensor.depth_scale,
                                       ground_truth=self.station.ground_truth,
                                       on_scan=None if spec.recorder is None else spec.recorder.scan)

    def _open_store(self, info: SessionInfo) -> ScanStore:

        root = Path(self.spec.out)
        if not (self.spec.append and (root / "session.json").exists()):
            return ScanStore.create(root, info.to_dict())
        store = ScanStore(root)
        old, mine = store.session(), info
        for label, get in (("backend", lambda s: s.backend), ("cell", lambda s: s.cell_kind),
                           ("object", lambda s: s.object_name)):
            if get(mine) != get(old):
                raise FileError(f"--append: the scans in {root} were recorded with {label} {get(old)!r}, this run "
                                f"uses {get(mine)!r}",
                                hint="append only runs of the same cell and object, or choose a new output folder")
        return store

    def close(self) -> None:
        """Stop and release the station (the robot stops first); idempotent."""
        if self.station is not None:
            station, self.station = self.station, None
            station.close()

    def __enter__(self) -> Session:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def open_session(spec: SessionSpec, rng: np.random.Generator | None = None, *, plan_only: bool = False) -> Session:
    """Open the session a workflow asks for (see the module docstring)."""

    cfg = spec.config
    if not (math.isfinite(cfg.scene.object_scale) and cfg.scene.object_scale > 0):
        raise InputError(f"object scale {cfg.scene.object_scale} is not a positive number",
                         hint="e.g. 0.001 for millimetres")
    station_file = None
    if spec.station is not None:


        station_file = load_station(spec.station)
        spec = replace(spec, config=cfg.replace(cell=station_file.cell), backend=station_file.capabilities.backend)
        if not (plan_only or spec.station_checked):  # `recon station check`, before anything moves or is written

            preflight(station_file, spec.config.seed)
    seed_ompl(spec.config.seed)
    return Session(spec, rng if rng is not None else np.random.default_rng(spec.config.seed), plan_only,
                   station_file)


def open_station(backend: Backend, cell, scene_object, start: np.ndarray, rng: np.random.Generator,
                 cfg: Config, station_file: StationFile | None = None) -> Station:
    """The station of a backend: the adapters of a station file, or the MuJoCo simulation."""
    if station_file is not None:

        return AdapterStation(station_file, cell, scene_object, start, rng)
    if backend is Backend.HARDWARE:
        raise HardwareUnavailable(
            "the hardware backend needs a station file (which robot and camera adapters, how to reach them)",
            hint="pass --station cell.yaml (docs/hardware.md has a complete example)")

    return SimStation(cell, scene_object, start, rng, noise=cfg.sensor.noise, resolution=cfg.sensor.resolution,
                      realism=cfg.realism)


def write_realism_record(folder: Path, record: dict) -> Path:
    """What the realism profile drew for a simulated session (encoder offsets, base and
    hand-eye errors, the actual camera) as ``ground_truth/realism.json``, beside the scans
    and never read by any algorithm (evaluation only)."""

    gt = Path(folder) / "ground_truth"
    gt.mkdir(exist_ok=True)
    write_json(gt / "realism.json", record)
    return gt / "realism.json"


def write_ground_truth_mesh(folder: Path, obj) -> Path:
    """The simulated object's exact mesh in the world frame, beside (not inside) the scan
    data (``ground_truth/NAME.ply``; evaluation only)."""
    import open3d as o3d


    gt = Path(folder) / "ground_truth"
    gt.mkdir(exist_ok=True)
    return atomic_write(gt / f"{obj.name}.ply",
                        lambda tmp: o3d.io.write_triangle_mesh(str(tmp), obj.mesh_world(), write_ascii=False))  # type: ignore[arg-type]
