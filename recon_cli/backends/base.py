"""The backend interfaces: the only things that differ between simulation and hardware.

A ``RobotBackend`` executes a time-parameterized, already checked trajectory and reports
the measured joints; a ``CameraBackend`` captures colour + depth with its intrinsics; a
``Station`` holds both for one session (``recon_cli.session.open_station`` opens it).
Everything above (planning, scripts, view planning, registration) uses only these.
"""

from __future__ import annotations

from dataclasses import dataclass
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
    """

    duration: float
    settle_time: float
    max_tracking_error: np.ndarray
    final_error: np.ndarray
    settled: bool


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


@runtime_checkable
class CameraBackend(Protocol):
    def capture(self) -> RGBDFrame:
        """Colour and depth images of the current view."""


@runtime_checkable
class Station(Protocol):
    """A cell's robot and camera, opened together (usable as a context manager).

    backend: "sim" or "hardware"; ground_truth(): what only a simulation knows (true camera
    pose, object pose), stored apart from the scan data for evaluation, or None on
    hardware; close(): stop the robot first, then release the devices (idempotent).
    """

    backend: str
    robot: RobotBackend
    camera: CameraBackend

    def ground_truth(self) -> dict | None:
        """Ground truth of the current state (simulation), or None."""

    def close(self) -> None:
        """Stop the robot, then release robot and camera."""

    def __enter__(self) -> Station:
        ...

    def __exit__(self, *exc) -> None:
        ...
