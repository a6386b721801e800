"""The backend interfaces: the only things that differ between simulation and hardware.

A ``RobotBackend`` executes a time-parameterized, already checked trajectory and reports
the measured joints; a ``CameraBackend`` captures colour + depth with its intrinsics; a
``Station`` holds both for one session (``recon_cli.session.open_station`` opens it) and
declares what it can do as :class:`Capabilities`. Everything above (planning, scripts,
view planning, registration) uses only these, and asks a station's capabilities (never
its type or backend name) before it uses what only some stations have.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from enum import StrEnum
from typing import Protocol, runtime_checkable

import numpy as np

from recon_cli.perception.camera_model import Intrinsics
from recon_cli.planning.trajectory import Trajectory


@dataclass(frozen=True)
class ExecutionReport:
    """How a trajectory was executed.

    duration: planned duration [s]; settle_time: time after the end until settled [s]
    max_tracking_error: largest |q - q_d| over the motion, per joint (n,) [rad or m]
    final_error: |q - q_goal| per joint when settled (n,)
    settled: the settling criterion was met before the time-out
    lost_cycles: controller cycles a streamed motion missed (the controller extrapolated them)
    """

    duration: float
    settle_time: float
    max_tracking_error: np.ndarray
    final_error: np.ndarray
    settled: bool
    lost_cycles: int = 0


@dataclass(frozen=True)
class RGBDFrame:
    """One capture. color: (H, W, 3) uint8 RGB; depth: (H, W) float64 [m], 0 = no return;
    distortion: the lens distortion (OpenCV k1, k2, p1, p2, k3) that goes with the
    intrinsics, None for a pinhole camera (or images already undistorted)."""

    color: np.ndarray
    depth: np.ndarray
    intrinsics: Intrinsics
    timestamp: float  # [s] backend clock
    distortion: tuple[float, ...] | None = None


@runtime_checkable
class RobotBackend(Protocol):
    joint_names: tuple[str, ...]

    def measured_joints(self) -> np.ndarray:
        """Measured joint positions (n,) in recon's joint order."""

    def execute(self, trajectory: Trajectory) -> ExecutionReport:
        """Follow a checked trajectory that starts at the current configuration, then wait
        until the robot has settled at its end."""

    def stop(self) -> bool:
        """Command the robot to stop and hold; True when the stop is confirmed."""


@runtime_checkable
class CameraBackend(Protocol):
    def capture(self) -> RGBDFrame:
        """Colour and depth images of the current view."""


class Backend(StrEnum):
    """What a session ran on, as session.json, config.yaml and the run reports write it:
    ``sim`` when every part of the station is simulated, else ``hardware``."""

    SIM = "sim"
    HARDWARE = "hardware"


@dataclass(frozen=True)
class Capabilities:
    """What a station can do, declared by the station (or composed from its adapters).

    simulated: every part is simulated (the session's backend is ``sim``)
    ground_truth: ``ground_truth()`` gives the true camera pose, joints and object; the
        object's exact mesh is written beside the scans
    cover_board: ``cover_board(covered)`` lays a sheet over the printed ChArUco board
    realism: the configuration's realism profile is applied; ``realism_record()`` says what
        it drew
    wall_clock: a physical robot or camera is involved: a wait takes real time
    """

    simulated: bool
    ground_truth: bool = False
    cover_board: bool = False
    realism: bool = False
    wall_clock: bool = False

    @property
    def backend(self) -> Backend:
        return Backend.SIM if self.simulated else Backend.HARDWARE


class Station(ABC):
    """A cell's robot and camera, opened together (usable as a context manager).

    ``capabilities`` says which of the optional methods work; a method the capabilities do
    not declare raises NotImplementedError (asking it is a bug of the caller).
    """

    capabilities: Capabilities
    robot: RobotBackend
    camera: CameraBackend

    @property
    def backend(self) -> Backend:
        return self.capabilities.backend

    def ground_truth(self) -> dict | None:
        """What only a simulation knows (true camera pose, joints, object), stored apart from
        the scan data for evaluation; None without ``capabilities.ground_truth``."""
        return None

    def cover_board(self, covered: bool) -> None:
        """Lay a plain sheet over the printed board (or take it away); ``capabilities.cover_board``."""
        raise NotImplementedError(f"{type(self).__name__} cannot cover the board")

    def realism_record(self) -> dict:
        """What the realism profile drew for this station; ``capabilities.realism``."""
        raise NotImplementedError(f"{type(self).__name__} applies no realism profile")

    @abstractmethod
    def close(self) -> None:
        """Stop the robot, then release robot and camera (idempotent)."""

    def __enter__(self) -> Station:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
