"""Simulation benchmark (``recon bench sim``): the camera sees the board, captures are fast,
execution is precise.

1. The 24 views of eq. 4.1 around the object (f = (0, 0, 0.78) m, r = 0.6 m): the robot is
   put at an IK solution of each view, the camera renders colour and depth at full
   resolution with noise, OpenCV looks for the ChArUco board in the colour image (no
   ground-truth shortcut) and, when found, estimates its pose, compared with the truth.
2. One planned move from the cell's home to the first view, executed by the computed-torque
   controller: tracking error, settling time, camera pose error due to tracking.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from recon_cli.backends.sim.station import SimStation
from recon_cli.config import DEFAULTS, SceneConfig, SensorConfig
from recon_cli.geometry.transforms import invert, pose_error
from recon_cli.lazy import lazy_module
from recon_cli.perception.charuco import detect, estimate_pose, thesis_board
from recon_cli.planning.planner import MotionPlanner, PlanOptions
from recon_cli.robot.ik import IKOptions
from recon_cli.session import Mode, SessionSpec, open_session
from recon_cli.thesis import eq_4_1_views

cv2 = lazy_module("cv2")


@dataclass(frozen=True)
class ViewRow:
    view: int
    corners: int
    markers: int
    found: bool
    translation_error_mm: float | None
    rotation_error_deg: float | None
    reprojection_px: float | None
    capture_s: float
    points: int


@dataclass(frozen=True)
class SimBenchResult:
    object_name: str
    rows: list[ViewRow]
    move: dict

    @property
    def found(self) -> int:
        return sum(r.found for r in self.rows)


def run_sim_bench(out: Path, object_name: str = "drill", seed: int = 0,
                  progress: Callable[[str, int, int], None] | None = None) -> SimBenchResult:
    rng = np.random.default_rng(seed)
    spec = thesis_board()
    rows: list[ViewRow] = []
    thumbs = []
    config = DEFAULTS.replace(scene=SceneConfig(object_name), sensor=SensorConfig(noise=True), seed=seed)
    with open_session(SessionSpec(out / "scans", config, Mode.BENCHMARK, run={"command": "bench sim"}), rng) as s:
        station, cell, obj, home = s.station, s.cell, s.scene_object, s.start
        assert isinstance(station, SimStation) and obj is not None  # an open simulation session of an object
        views = eq_4_1_views()
        for i, view in enumerate(views, start=1):
            ik = cell.solve_view(view, rng, options=IKOptions(max_solutions=1))
            station.robot.reset(ik.solutions[0].q)
            t0 = time.perf_counter()
            frame = station.camera.capture()
            dt = time.perf_counter() - t0
            det = detect(frame.color, spec)
            pose = estimate_pose(det, spec, frame.intrinsics)
            truth = invert(station.camera.world_T_camera_truth()) @ cell.world_T_marker
            if pose is not None:
                e_t, e_r = pose_error(pose.camera_T_marker, truth)
                rows.append(ViewRow(i, det.n_corners, det.marker_count, True, e_t * 1e3,
                                    float(np.degrees(e_r)), pose.reprojection_rms, dt,
                                    int(np.count_nonzero(frame.depth))))
            else:
                rows.append(ViewRow(i, det.n_corners, det.marker_count, False, None, None, None, dt,
                                    int(np.count_nonzero(frame.depth))))
            thumbs.append(_thumbnail(frame.color, det, i))
            if progress:
                progress("24 views", i, len(views))
        # one planned, executed move: home -> first view
        station.robot.reset(home)
        planner = MotionPlanner(cell, PlanOptions())
        plan = planner.plan_to_pose(home, cell.view_pose(views[0]), rng)
        move: dict = {"plan_status": plan.status.value, "plan_total_s": plan.total_time}
        trajectory = plan.trajectory if plan.ok else None
        if trajectory is not None:
            report = station.robot.execute(trajectory)
            q = station.robot.measured_joints()
            dp, dr = pose_error(cell.kin.world_T_camera(q), cell.kin.world_T_camera(trajectory.goal))
            move.update(trajectory_s=trajectory.duration, settled=report.settled,
                        settle_s=report.settle_time,
                        max_tracking_error=float(np.max(report.max_tracking_error)),
                        max_tracking_error_joint=cell.joint_names[int(np.argmax(report.max_tracking_error))],
                        camera_position_error_mm=dp * 1e3, camera_rotation_error_deg=float(np.degrees(dr)))
        if progress:
            progress("move", 1, 1)
    sheet = np.vstack([np.hstack(thumbs[r * 6:(r + 1) * 6]) for r in range(4)])
    cv2.imwrite(str(out / "eq_4_1_views.png"), cv2.cvtColor(sheet, cv2.COLOR_RGB2BGR))
    return SimBenchResult(obj.name, rows, move)


def _thumbnail(color: np.ndarray, det, index: int) -> np.ndarray:
    img = color.copy()
    for (u, v) in det.corners:
        cv2.circle(img, (int(round(u)), int(round(v))), 6, (255, 40, 40), -1)
    small = cv2.resize(img, (320, 240), interpolation=cv2.INTER_AREA)
    cv2.putText(small, f"{index}: {det.n_corners} corners", (6, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.55,
                (255, 255, 255), 2, cv2.LINE_AA)
    return small
