"""The robot and camera adapters a station file may name: one registry entry per ``adapter``.

Each entry declares what its part is (simulated or not, physical or not, whether the board
under it can be covered), reads its section of the station file into a typed frozen config
and opens the part. A driver module is imported only when one of its adapters is read or
opened, so a missing driver library is a one-line hint of that adapter alone.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Generic, Protocol, TypeAlias, TypeVar

import numpy as np

from recon_cli.backends.base import CameraBackend, Capabilities, RobotBackend
from recon_cli.backends.hardware.ads import AdsRobot
from recon_cli.backends.hardware.ads_config import AdsConfig
from recon_cli.backends.hardware.franka import FrankaRobot
from recon_cli.backends.hardware.franka_config import FrankaConfig
from recon_cli.backends.sim.config import SimCameraConfig, SimRobotConfig
from recon_cli.backends.sim.rendered import RenderedCamera
from recon_cli.backends.sim.robot import SimRobot
from recon_cli.backends.sim.scene import build_scene, mujoco

if TYPE_CHECKING:
    from recon_cli.backends.hardware.ads_config import AdsConfig
    from recon_cli.backends.hardware.franka_config import FrankaConfig
    from recon_cli.backends.hardware.genicam import GenICamConfig
    from recon_cli.backends.hardware.realsense import RealSenseConfig
    from recon_cli.backends.hardware.replay import ReplayConfig
    from recon_cli.backends.sim.config import SimCameraConfig, SimRobotConfig
    from recon_cli.objects import SceneObject
    from recon_cli.robot.cell import Cell

#: the typed section of a station file's ``robot:`` / ``camera:`` (one class per adapter)
RobotConfig: TypeAlias = "AdsConfig | FrankaConfig | SimRobotConfig"
CameraConfig: TypeAlias = "SimCameraConfig | GenICamConfig | RealSenseConfig | ReplayConfig"
#: the config class of one robot / camera adapter
RobotConfigT = TypeVar("RobotConfigT", bound=RobotConfig)
CameraConfigT = TypeVar("CameraConfigT", bound=CameraConfig)


class RobotPart(RobotBackend, Protocol):
    def close(self) -> None:
        """Stop the robot, then release it (idempotent)."""


class CameraPart(CameraBackend, Protocol):
    def close(self) -> None:
        """Release the camera (idempotent)."""


@dataclass(frozen=True)
class Surroundings:
    """What an adapter may need to open its part: the cell, the simulated object (None on a
    real cell), where a simulated robot starts (n,) and the session's random generator."""

    cell: Cell
    scene_object: SceneObject | None
    start: np.ndarray
    rng: np.random.Generator


@dataclass(frozen=True)
class RobotAdapter(Generic[RobotConfigT]):
    """simulated: the part is a simulation; physical: it moves in real time (waits are real)."""

    name: str
    simulated: bool
    physical: bool
    read: Callable[[dict, str], RobotConfigT]
    open: Callable[[RobotConfigT, Surroundings], RobotPart]


@dataclass(frozen=True)
class CameraAdapter(Generic[CameraConfigT]):
    """As :class:`RobotAdapter`; cover_board: the part can lay a sheet over the printed board
    it sees (``cover_board(covered)``)."""

    name: str
    simulated: bool
    physical: bool
    read: Callable[[dict, str], CameraConfigT]
    open: Callable[[CameraConfigT, Surroundings, RobotBackend], CameraPart]
    cover_board: bool = False


def station_capabilities(robot: RobotAdapter[Any], camera: CameraAdapter[Any]) -> Capabilities:
    """What a station of these two adapters can do: simulated (and knowing the ground truth)
    when both parts are; real waits when either part is physical."""
    simulated = robot.simulated and camera.simulated
    return Capabilities(simulated=simulated, ground_truth=simulated, cover_board=camera.cover_board,
                        wall_clock=robot.physical or camera.physical)


# --------------------------------------------------------------------- robots
def _read_ads(mapping: dict, where: str) -> AdsConfig:

    return AdsConfig.from_mapping(mapping, where)


def _open_ads(config: AdsConfig, around: Surroundings) -> RobotPart:

    return AdsRobot(config, around.cell.joint_names, around.cell.kin.limits)


def _read_franka(mapping: dict, where: str) -> FrankaConfig:
    return FrankaConfig.from_mapping(mapping, where)


def _open_franka(config: FrankaConfig, around: Surroundings) -> RobotPart:
    return FrankaRobot(config, around.cell.joint_names, around.cell.kin.limits)


def _read_sim_robot(mapping: dict, where: str) -> SimRobotConfig:

    return SimRobotConfig.from_mapping(mapping, where)


def _open_sim_robot(config: SimRobotConfig, around: Surroundings) -> RobotPart:

    scene = build_scene(around.cell.config, around.scene_object)
    robot = SimRobot(scene, mujoco.MjData(scene.model), around.cell.kin)
    robot.reset(np.asarray(around.start, dtype=float))
    return robot


# --------------------------------------------------------------------- cameras
def _read_sim_camera(mapping: dict, where: str) -> SimCameraConfig:

    return SimCameraConfig.from_mapping(mapping, where)


def _open_sim_camera(config: SimCameraConfig, around: Surroundings, robot: RobotBackend) -> CameraPart:

    return RenderedCamera(around.cell, around.scene_object, robot, around.rng, config.noise, config.resolution)


def _driver_camera(module: str, config_class: str) -> tuple[Callable, Callable]:
    """read and open of a camera adapter whose module has ``config_class.from_mapping`` and
    ``open_camera(config)``."""

    def read(mapping: dict, where: str):
        return getattr(importlib.import_module(module), config_class).from_mapping(mapping, where)

    def open_camera(config, around: Surroundings, robot: RobotBackend) -> CameraPart:
        return importlib.import_module(module).open_camera(config)

    return read, open_camera


ROBOT_ADAPTERS: dict[str, RobotAdapter[Any]] = {
    "ads": RobotAdapter("ads", simulated=False, physical=True, read=_read_ads, open=_open_ads),
    "franka": RobotAdapter("franka", simulated=False, physical=True, read=_read_franka, open=_open_franka),
    "sim": RobotAdapter("sim", simulated=True, physical=False, read=_read_sim_robot, open=_open_sim_robot),
}

CAMERA_ADAPTERS: dict[str, CameraAdapter[Any]] = {
    "sim": CameraAdapter("sim", simulated=True, physical=False, read=_read_sim_camera, open=_open_sim_camera,
                         cover_board=True),
    "genicam": CameraAdapter("genicam", False, True,
                             *_driver_camera("recon_cli.backends.hardware.genicam", "GenICamConfig")),
    "realsense": CameraAdapter("realsense", False, True,
                               *_driver_camera("recon_cli.backends.hardware.realsense", "RealSenseConfig")),
    # recorded frames of a real camera: not a simulation (no ground truth), nothing to wait for
    "replay": CameraAdapter("replay", False, False,
                            *_driver_camera("recon_cli.backends.hardware.replay", "ReplayConfig")),
}
