"""The station file sections of the simulated adapters (``robot.sim``, ``camera.sim``)."""

from __future__ import annotations

from dataclasses import dataclass

from recon_cli.backends.hardware.camera_config import check_keys
from recon_cli.config import DEFAULTS, RESOLUTION_RANGE
from recon_cli.errors import InputError


@dataclass(frozen=True)
class SimRobotConfig:
    """``robot.sim``: the MuJoCo robot of the cell, at rest at its home configuration (no keys)."""

    @classmethod
    def from_mapping(cls, d: dict, where: str = "robot.sim") -> SimRobotConfig:
        check_keys(d, where, cls)
        return cls()


@dataclass(frozen=True)
class SimCameraConfig:
    """``camera.sim``: the simulated sensor rendered at the robot's measured joints (a camera
    stand-in for wiring and testing a real robot adapter)."""

    noise: bool = DEFAULTS.sensor.noise
    resolution: float = DEFAULTS.sensor.resolution

    @classmethod
    def from_mapping(cls, d: dict, where: str = "camera.sim") -> SimCameraConfig:
        d = check_keys(d, where, cls)
        cfg = cls(bool(d.get("noise", cls.noise)), float(d.get("resolution", cls.resolution)))
        lo, hi = RESOLUTION_RANGE
        if not lo <= cfg.resolution <= hi:
            raise InputError(f"{where}.resolution = {cfg.resolution} is outside {lo:g} ... {hi:g}", hint="e.g. 0.5")
        return cfg
