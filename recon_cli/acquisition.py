"""Moving the camera and taking scans: planning + execution + capture + scan store.

``Acquisition`` works on any backend pair (simulation or hardware): it plans a checked
trajectory to a camera goal, lets the robot backend execute it, waits for the settled
robot, captures an RGB-D frame and writes the scan atomically with everything the
registration needs (measured joints, forward-kinematics camera pose, planned view).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from recon_cli.backends.base import CameraBackend, ExecutionReport, RobotBackend
from recon_cli.errors import PlanningError, RobotFault
from recon_cli.geometry.transforms import pose_error
from recon_cli.geometry.view import View
from recon_cli.planning.planner import MotionPlanner, PlanOptions, PlanResult
from recon_cli.reconstruction.scan_store import Scan, ScanStore, stored_depth
from recon_cli.robot.cell import Cell


@dataclass(frozen=True)
class MoveReport:
    plan: PlanResult
    execution: ExecutionReport
    camera_position_error: float  # [m] FK(measured) vs FK(goal), due to tracking
    camera_rotation_error: float  # [rad]

    def to_dict(self) -> dict:
        return {
            "planner": self.plan.planner,
            "plan_time_s": self.plan.plan_time,
            "simplify_time_s": self.plan.simplify_time,
            "planning_total_s": self.plan.total_time,
            "path_waypoints": None if self.plan.path is None else len(self.plan.path),
            "trajectory_duration_s": self.execution.duration,
            "settle_time_s": self.execution.settle_time,
            "settled": self.execution.settled,
            "lost_cycles": self.execution.lost_cycles,
            "max_tracking_error": self.execution.max_tracking_error,
            "final_joint_error": self.execution.final_error,
            "camera_position_error_m": self.camera_position_error,
            "camera_rotation_error_rad": self.camera_rotation_error,
        }


def view_record(view: View | None, world_T_camera: np.ndarray) -> dict:
    rec: dict = {"world_T_camera_goal": world_T_camera}
    if view is not None:
        rec.update(focus=list(view.focus), radius=view.radius, theta=view.theta, phi=view.phi,
                   alpha=view.alpha, frame=view.frame.value, angle_unit="rad")
    return rec


class Acquisition:
    def __init__(self, cell: Cell, robot: RobotBackend, camera: CameraBackend, store: ScanStore,
                 rng: np.random.Generator, plan_options: PlanOptions = PlanOptions(),  # noqa: B008
                 depth_scale: float = 20000.0,
                 ground_truth: Callable[[], dict | None] | None = None,
                 on_scan: Callable[[Scan], None] | None = None) -> None:
        self.cell = cell
        self.robot = robot
        self.camera = camera
        self.store = store
        self.rng = rng
        self.planner = MotionPlanner(cell, plan_options)
        self.depth_scale = depth_scale
        self.ground_truth = ground_truth
        self.on_scan = on_scan  # told of every scan once it is written (recordings)
        self._writer: ThreadPoolExecutor | None = None  # writes a scan while its caller goes on
        self._writing: Future[Path] | None = None  # the scan being written

    def move_to_pose(self, world_T_camera: np.ndarray, what: str = "view") -> MoveReport:
        q0 = self.robot.measured_joints()
        return self._execute(self.planner.plan_to_pose(q0, world_T_camera, self.rng, what=what), what)

    def move_to_joints(self, goals: np.ndarray | list[np.ndarray], what: str = "view") -> MoveReport:
        """Plan to a joint goal (n,) or to whichever of several is reached first, execute it
        and wait for the settled robot."""
        q0 = self.robot.measured_joints()
        return self._execute(self.planner.plan_to_joints(q0, goals, seed=int(self.rng.integers(1 << 30))), what)

    def _execute(self, plan: PlanResult, what: str) -> MoveReport:
        trajectory = plan.trajectory  # a solved plan has one
        if not plan.ok or trajectory is None:
            raise PlanningError(f"cannot move to the {what}: {plan.status.value} ({plan.message})",
                                hint="try another view, a longer planning time or another planner", status=plan.status)
        execution = self.robot.execute(trajectory)
        if not execution.settled:
            raise self._not_settled(execution, what)
        q = self.robot.measured_joints()
        dp, dr = pose_error(self.cell.kin.world_T_camera(q), self.cell.kin.world_T_camera(trajectory.goal))
        return MoveReport(plan, execution, dp, dr)

    def _not_settled(self, execution: ExecutionReport, what: str) -> RobotFault:
        """A robot that has not settled at the goal is not scanned: stop it and say how far
        off each joint is (the largest three)."""
        stopped = bool(self.robot.stop())
        err = np.asarray(execution.final_error, dtype=float)
        worst = np.argsort(-err)[:3]
        names = self.cell.joint_names
        prismatic = self.cell.kin.limits.prismatic
        errors = ", ".join(f"{names[j]} {err[j]:.3g} {'m' if prismatic[j] else 'rad'}" for j in worst)
        return RobotFault(f"the robot did not settle after the move to the {what} within its settling time "
                          f"(final error {errors}); no scan was taken",
                          kind="settle", joint=names[int(worst[0])], value=float(err[worst[0]]), stopped=stopped,
                          hint="check the drives and the settling tolerance; completed scans are kept")

    def scan(self, planned: dict, move: MoveReport | None = None, name: str | None = None, *,
             written: bool = True) -> Scan:
        """Capture a frame at the settled robot and write it as the next scan (``name``, when
        given, is stored in scan.json); the scan returned holds the depth as stored.

        ``written=False``: the scan is written beside the caller (PNG encoding lets go of the
        interpreter lock), which must call :meth:`settle` before it reads the store and
        before its command ends; a failed write is raised there. The scan's ``path`` is its
        folder-to-be."""
        self.settle()
        t0 = time.time()
        frame = self.camera.capture()
        t1 = time.time()
        q = self.robot.measured_joints()
        scan = Scan(
            index=self.store.next_index(),
            color=frame.color,
            depth=frame.depth,
            intrinsics=frame.intrinsics,
            joints=dict(zip(self.cell.joint_names, q.tolist(), strict=True)),
            world_T_camera_fk=self.cell.kin.world_T_camera(q),
            meta={
                **({"name": name} if name else {}),
                "planned_view": planned,
                "move": None if move is None else move.to_dict(),
                "timestamps": {"capture_start": t0, "capture_end": t1, "backend_time": frame.timestamp},
                "capture_seconds": t1 - t0,
            },
            ground_truth=self.ground_truth() if self.ground_truth else None,
            distortion=frame.distortion,
        )
        if self._writer is None:
            self._writer = ThreadPoolExecutor(max_workers=1, thread_name_prefix="scan-writer")
        self._writing = self._writer.submit(self.store.write, scan, self.depth_scale)
        # from here on the scan is what its readers get: the depth as stored
        scan = replace(scan, depth=stored_depth(scan.depth, self.depth_scale), path=self.store.folder(scan.index))
        if written or self.on_scan is not None:
            self.settle()
        if self.on_scan is not None:
            self.on_scan(scan)
        return scan

    def settle(self) -> None:
        """Wait until the scan being written is in the store (its FileError raised here)."""
        writing, self._writing = self._writing, None
        if writing is not None:
            writing.result()
