"""A station of a robot adapter and a camera adapter, opened from a station file.

The adapters are the registry's (recon_cli/backends/adapters.py): robots ``ads`` (TwinCAT
over ADS) or ``sim`` (the MuJoCo robot); cameras ``genicam``, ``realsense``, ``replay`` or
``sim`` (the simulated sensor rendered at the robot's measured joints, a stand-in camera
for wiring a real robot). The station's capabilities are composed from what the two
adapters declare: a station of ``sim`` parts only is a simulation (backend ``sim``, with
ground truth). Closing stops the robot first, then releases the camera.

``check_station`` is ``recon station check``: connect, read the joints, grab one frame,
move nothing. ``preflight`` is the same check before a session on the station moves
anything, refusing with one line when it fails.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from recon_cli.backends.adapters import CAMERA_ADAPTERS, ROBOT_ADAPTERS, CameraPart, RobotPart, Surroundings
from recon_cli.backends.base import Backend, Capabilities, Station
from recon_cli.backends.hardware.franka import FrankaRobot
from recon_cli.backends.joint_offsets import OffsetRobot
from recon_cli.backends.sim.rendered import RenderedCamera
from recon_cli.backends.sim.robot import SimRobot
from recon_cli.backends.sim.station import simulation_truth
from recon_cli.backends.station_file import StationFile
from recon_cli.errors import ReconError, RobotFault
from recon_cli.objects import SceneObject
from recon_cli.robot.cell import Cell
from recon_cli.robot.poses import named_configuration


class AdapterStation(Station):
    """Station of a station file (see recon_cli/backends/base.py for the interface)."""

    def __init__(self, station: StationFile, cell: Cell, scene_object: SceneObject | None, start: np.ndarray,
                 rng: np.random.Generator) -> None:
        self.station_file = station
        self.cell = cell
        self.scene_object = scene_object
        self.capabilities: Capabilities = station.capabilities
        self._open_robot: RobotPart | None = None  # the parts close() has to release
        self._open_camera: CameraPart | None = None
        around = Surroundings(cell, scene_object, start, rng)
        try:
            self.robot: RobotPart = ROBOT_ADAPTERS[station.robot_adapter].open(station.robot, around)
            self._open_robot = self.robot
            if station.joint_offsets is not None:  # [deg] and [mm] as the file gives them
                given = np.asarray(station.joint_offsets, dtype=float)
                self.robot = OffsetRobot(self.robot, np.where(cell.kin.limits.prismatic, given / 1000.0,
                                                              np.radians(given)))
            self.camera: CameraPart = CAMERA_ADAPTERS[station.camera_adapter].open(station.camera, around, self.robot)
            self._open_camera = self.camera
        except BaseException:
            self.close()
            raise

    def ground_truth(self) -> dict | None:
        """The simulated parts' truth (a station of simulated parts only), else None: a real
        cell does not know it."""
        if not self.capabilities.ground_truth:
            return None
        robot, camera = self.robot, self.camera
        # the parts of the sim adapters, the only simulated ones
        assert isinstance(robot, SimRobot) and isinstance(camera, RenderedCamera)
        return simulation_truth(robot, camera.world_T_camera_truth(), self.scene_object)

    def cover_board(self, covered: bool) -> None:
        if not self.capabilities.cover_board:
            super().cover_board(covered)
        camera = self.camera
        assert isinstance(camera, RenderedCamera)  # the sim adapter's, the only one that covers the board
        camera.cover_board(covered)

    def close(self) -> None:
        """Stop the robot, then release robot and camera (idempotent)."""
        robot, camera = self._open_robot, self._open_camera
        self._open_robot = self._open_camera = None
        try:
            if robot is not None:
                robot.close()
        finally:
            if camera is not None:
                camera.close()


# --------------------------------------------------------------------- recon station check
@dataclass(frozen=True)
class StationCheck:
    """What ``recon station check`` found: the joint state and one frame."""

    name: str
    robot_adapter: str
    camera_adapter: str
    backend: Backend  # sim: every part is simulated
    joints: dict[str, float]  # [rad or m]
    prismatic: dict[str, bool]  # True: the joint is linear (m)
    within_limits: bool
    outside_limits: tuple[str, ...]  # the joints outside their soft limits
    width: int
    height: int
    intrinsics: dict[str, float]
    valid_depth: float  # share of pixels with a depth
    depth_range: tuple[float, float] | None  # [m] of the valid pixels
    seconds: float

    def problem(self) -> str | None:
        """Why a run must not start on this station (None: it may)."""
        if not self.within_limits:
            return f"the measured joints {', '.join(self.outside_limits)} are outside their soft limits"
        if self.depth_range is None:
            return "the camera's frame has no depth"
        return None


def check_station(station: StationFile, seed: int) -> StationCheck:
    """Connect to the robot and the camera of a station file, read the joint state and grab
    one frame; nothing moves. ``seed``: of a rendered camera's noise. A robot that cannot be
    reached (nothing moved, nothing was running) is a one-line ReconError, as a wrong address
    in the file is."""
    t0 = time.perf_counter()
    cell = Cell(station.cell)

    start = named_configuration(station.cell.kind, "home", cell.joint_names)
    try:
        with AdapterStation(station, cell, None, start, np.random.default_rng(seed)) as st:
            q = st.robot.measured_joints()
            frame = st.camera.capture()
    except RobotFault as exc:
        if exc.kind != "connection" or exc.stopped:
            raise
        raise ReconError(exc.message, hint=exc.hint) from None
    depth = np.asarray(frame.depth)
    valid = depth > 0
    k = frame.intrinsics
    return StationCheck(
        station.name, station.robot_adapter, station.camera_adapter, station.capabilities.backend,
        dict(zip(cell.joint_names, map(float, q), strict=True)),
        dict(zip(cell.joint_names, map(bool, cell.kin.limits.prismatic), strict=True)),
        bool(cell.kin.limits.within_soft(q, 1e-6)),
        tuple(n for n, m in zip(cell.joint_names, cell.kin.limits.margin_to_soft(q), strict=True) if m < -1e-6),
        int(depth.shape[1]), int(depth.shape[0]),
        {"fx": k.fx, "fy": k.fy, "cx": k.cx, "cy": k.cy}, float(valid.mean()) if depth.size else 0.0,
        (float(depth[valid].min()), float(depth[valid].max())) if valid.any() else None, time.perf_counter() - t0)


def recover_robot(station: StationFile) -> list[str]:
    """Clear the error state of the station's robot (libfranka's automatic error recovery),
    only when the user asks for it; the errors it cleared. A robot adapter without an error
    recovery over its protocol is one line."""
    cell = Cell(station.cell)
    start = named_configuration(station.cell.kind, "home", cell.joint_names)
    around = Surroundings(cell, None, start, np.random.default_rng(0))
    adapter = ROBOT_ADAPTERS[station.robot_adapter]
    if station.robot_adapter != "franka":
        raise ReconError(f"the {adapter.name} robot adapter has no error recovery over its protocol",
                         hint="clear the fault where the controller shows it (the PLC, the simulation)")
    try:
        robot = adapter.open(station.robot, around)
    except RobotFault as exc:
        if exc.kind != "control":
            raise
        # in reflex mode: open the connection without the refusal to recover from it
        robot = FrankaRobot(station.robot, cell.joint_names, cell.kin.limits, refuse_reflex=False)  # type: ignore[arg-type]
    try:
        return robot.recover()  # type: ignore[attr-defined]
    finally:
        robot.close()


def refuse_unready(station: StationFile, result: StationCheck) -> None:
    """One line when a run must not start on the station (``StationCheck.problem``)."""
    problem = result.problem()
    if problem is not None:
        raise ReconError(f"station {station.path}: {problem}; nothing was moved",
                         hint=f"recon station check {station.path} shows the joints and the frame")


def preflight(station: StationFile, seed: int) -> StationCheck:
    """``check_station`` before a session on the station moves anything (its own connection,
    closed again: a replayed recording still starts at its first frame); a station that
    fails it is refused with one line. ``seed``: the run's."""
    result = check_station(station, seed)
    refuse_unready(station, result)
    return result
