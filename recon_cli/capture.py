"""``recon capture``: move the simulated robot through views and take one scan at each.

Views that cannot be reached (IK or planning fails) are reported and skipped; scans already
written stay. ``cover_board`` lists views (1-based) at which a plain sheet lies over the
ChArUco board, so registration must fall back to kinematics there.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from recon_cli.acquisition import Acquisition, MoveReport, view_record
from recon_cli.errors import ReconError
from recon_cli.geometry.view import View
from recon_cli.objects import SceneObject, load_object
from recon_cli.outputs import atomic_write
from recon_cli.planning.planner import PlanOptions, seed_ompl
from recon_cli.reconstruction.scan_store import Scan, ScanStore
from recon_cli.robot.cell import Cell
from recon_cli.robot.description import CellConfig
from recon_cli.robot.poses import named_configuration


@dataclass(frozen=True)
class CaptureOptions:
    views: tuple[View, ...]
    out: Path
    object_name: str = "drill"
    object_scale: float = 1.0
    cell: CellConfig = field(default_factory=CellConfig)
    seed: int = 0
    noise: bool = True
    resolution: float = 1.0  # image size relative to the sensor's
    box_margin: float = 0.01  # [m] object bounding box margin (before the safety distance)
    plan: PlanOptions = field(default_factory=PlanOptions)
    cover_board: frozenset[int] = frozenset()  # 1-based views with the board covered


@dataclass(frozen=True)
class ViewFailure:
    view: int  # 1-based
    message: str


@dataclass(frozen=True)
class CaptureResult:
    folder: Path
    scans: list[Scan]
    moves: list[MoveReport]
    failures: list[ViewFailure]
    capture_seconds: list[float]
    total_seconds: float
    scene_object: SceneObject

    @property
    def points(self) -> list[int]:
        return [int(np.count_nonzero(s.depth > 0)) for s in self.scans]


def write_ground_truth_mesh(folder: Path, obj: SceneObject) -> Path:
    """The object's exact mesh in the world frame, beside (not inside) the scan data."""
    import open3d as o3d

    gt = folder / "ground_truth"
    gt.mkdir(exist_ok=True)
    path = gt / f"{obj.name}.ply"
    return atomic_write(path, lambda tmp: o3d.io.write_triangle_mesh(str(tmp), obj.mesh_world(), write_ascii=False))


def run_capture(opt: CaptureOptions, progress: Callable[[str, int, int], None] | None = None
                ) -> CaptureResult:
    from recon_cli.backends.sim.station import SimStation
    from recon_cli.perception.sensor import motioncam_3d_m

    t0 = time.perf_counter()
    n = len(opt.views)
    step = (lambda k: progress("capture", k, n)) if progress else (lambda k: None)
    rng = np.random.default_rng(opt.seed)
    seed_ompl(opt.seed)
    obj = load_object(opt.object_name, opt.object_scale)
    box = obj.bounding_box(opt.box_margin)
    cell = Cell(opt.cell, object_box=box)
    start = named_configuration(opt.cell.kind, "home", cell.joint_names)
    sensor = motioncam_3d_m()
    store = ScanStore.create(opt.out, {
        "backend": "sim",
        "cell": {"kind": opt.cell.kind.value, "safety_distance": opt.cell.safety_distance,
                 "table_lift": opt.cell.table_lift},
        "sensor": sensor.name, "noise": opt.noise, "seed": opt.seed,
        "object": {"name": obj.name, "description": obj.description, "world_T_object": obj.world_T_object},
        "object_box": {"frame": "world", "center": list(box.center), "size": list(box.size)},
        "crop_box": dict(zip(("center", "size"), obj.crop_box(opt.box_margin), strict=True), frame="world"),
        "world_T_marker": cell.world_T_marker,
    })
    write_ground_truth_mesh(opt.out, obj)
    scans, moves, failures, capture_seconds = [], [], [], []
    with SimStation(cell, obj, start, rng, noise=opt.noise, resolution=opt.resolution) as station:
        acq = Acquisition(cell, station.robot, station.camera, store, rng, opt.plan,
                          depth_scale=sensor.depth_scale, ground_truth=station.ground_truth)
        for k, view in enumerate(opt.views, start=1):
            try:
                T = cell.view_pose(view)
                move = acq.move_to_pose(T, what=f"view {k}")
            except ReconError as exc:  # unreachable or unplannable view: report, go on
                failures.append(ViewFailure(k, str(exc)))
                step(k)
                continue
            station.cover_board(k in opt.cover_board)
            t_cap = time.perf_counter()
            scans.append(acq.scan(view_record(view, T), move))
            capture_seconds.append(time.perf_counter() - t_cap)
            moves.append(move)
            step(k)
    return CaptureResult(opt.out, scans, moves, failures, capture_seconds, time.perf_counter() - t0, obj)
