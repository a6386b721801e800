"""A station of a robot adapter and a camera adapter, opened from a station file.

Robot adapters: ``ads`` (TwinCAT over ADS) or ``sim`` (the MuJoCo robot); camera
adapters: ``genicam``, ``realsense``, ``replay`` or ``sim`` (the simulated sensor rendered
at the robot's measured joints, a stand-in camera for wiring a real robot). Closing stops
the robot first, then releases the camera.
"""

from __future__ import annotations

import importlib

import numpy as np

from recon_cli.backends.station_file import CAMERA_MODULES, StationFile
from recon_cli.objects import SceneObject
from recon_cli.robot.cell import Cell


class RenderedCamera:
    """CameraBackend: the simulated sensor, posed at the joints a robot adapter measures."""

    def __init__(self, cell: Cell, scene_object: SceneObject | None, robot, rng: np.random.Generator,
                 noise: bool, resolution: float) -> None:
        from recon_cli.backends.sim.camera import SimCamera
        from recon_cli.backends.sim.scene import build_scene, mujoco

        self._mujoco = mujoco
        self.robot = robot
        self.scene = build_scene(cell.config, scene_object)
        self.data = mujoco.MjData(self.scene.model)
        self._camera = SimCamera(self.scene, self.data, rng, noise=noise, scale=resolution)
        self.intrinsics = self._camera.intrinsics

    def capture(self):
        self.data.qpos[self.scene.qpos_index] = self.robot.measured_joints()
        self._mujoco.mj_forward(self.scene.model, self.data)
        return self._camera.capture()

    def close(self) -> None:
        self._camera.close()


class HardwareStation:
    """Station of a station file (see recon_cli/backends/base.py for the interface)."""

    backend = "hardware"

    def __init__(self, station: StationFile, cell: Cell, scene_object: SceneObject | None, start: np.ndarray,
                 rng: np.random.Generator) -> None:
        self.station_file = station
        self.cell = cell
        self.robot = self.camera = None
        self._sim = None
        try:
            if station.robot_adapter == "ads":
                from recon_cli.backends.hardware.ads import AdsRobot

                self.robot = AdsRobot(station.robot, cell.joint_names, cell.kin.limits)
            else:
                from recon_cli.backends.sim.station import SimStation

                self._sim = SimStation(cell, scene_object, start, rng, noise=False, resolution=0.05)
                self.robot = self._sim.robot
            if station.camera_adapter == "sim":
                cfg = station.camera
                self.camera = RenderedCamera(cell, scene_object, self.robot, rng, cfg.noise, cfg.resolution)
            else:
                module = importlib.import_module(CAMERA_MODULES[station.camera_adapter][0])
                self.camera = module.open_camera(station.camera)
        except BaseException:
            self.close()
            raise

    def ground_truth(self) -> None:
        return None  # a real cell does not know the truth

    def close(self) -> None:
        """Stop the robot, then release robot and camera (idempotent)."""
        robot, camera, sim = self.robot, self.camera, self._sim
        self.robot = self.camera = self._sim = None
        try:
            if robot is not None and hasattr(robot, "close"):
                robot.close()
        finally:
            if camera is not None and hasattr(camera, "close"):
                camera.close()
            if sim is not None:
                sim.close()

    def __enter__(self) -> HardwareStation:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


# --------------------------------------------------------------------- recon station check
from dataclasses import dataclass  # noqa: E402


@dataclass(frozen=True)
class StationCheck:
    """What ``recon station check`` found: the joint state and one frame."""

    name: str
    robot_adapter: str
    camera_adapter: str
    joints: dict[str, float]  # [rad or m]
    prismatic: dict[str, bool]  # True: the joint is linear (m)
    within_limits: bool
    width: int
    height: int
    intrinsics: dict[str, float]
    valid_depth: float  # share of pixels with a depth
    depth_range: tuple[float, float] | None  # [m] of the valid pixels
    seconds: float


def check_station(station: StationFile, seed: int) -> StationCheck:
    """Connect to the robot and the camera of a station file, read the joint state and grab
    one frame; nothing moves. ``seed``: of a rendered camera's noise."""
    import time

    t0 = time.perf_counter()
    cell = Cell(station.cell)
    from recon_cli.robot.poses import named_configuration

    start = named_configuration(station.cell.kind, "home", cell.joint_names)
    with HardwareStation(station, cell, None, start, np.random.default_rng(seed)) as st:
        q = st.robot.measured_joints()
        frame = st.camera.capture()
    depth = np.asarray(frame.depth)
    valid = depth > 0
    k = frame.intrinsics
    return StationCheck(
        station.name, station.robot_adapter, station.camera_adapter,
        dict(zip(cell.joint_names, map(float, q), strict=True)),
        dict(zip(cell.joint_names, map(bool, cell.kin.limits.prismatic), strict=True)),
        bool(cell.kin.limits.within_soft(q, 1e-6)),
        int(depth.shape[1]), int(depth.shape[0]),
        {"fx": k.fx, "fy": k.fy, "cx": k.cx, "cy": k.cy}, float(valid.mean()) if depth.size else 0.0,
        (float(depth[valid].min()), float(depth[valid].max())) if valid.any() else None, time.perf_counter() - t0)
