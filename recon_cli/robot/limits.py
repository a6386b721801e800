"""Joint limits of a cell, read from the expanded URDF and robot/limits.yaml.

Position, soft position and velocity limits come from the URDF (``<limit>`` and
``<safety_controller>``, written by the xacro from limits.yaml); acceleration limits, which
URDF cannot hold, come from limits.yaml itself. Units: m, rad, s.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from lxml import etree

from recon_cli.inputs.yamlfile import read_yaml
from recon_cli.paths import ROBOT_DIR


@dataclass(frozen=True)
class JointLimits:
    """Per-joint limits in joint-vector order. Arrays of shape (n,).

    lower, upper: hard position limits [m or rad]
    soft_lower, soft_upper: planning limits inside the hard ones (10 deg for revolute joints)
    velocity: [m/s or rad/s]; acceleration: [m/s^2 or rad/s^2]; effort: [N or N m]
    prismatic: True for the linear axes
    """

    names: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    soft_lower: np.ndarray
    soft_upper: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    effort: np.ndarray
    prismatic: np.ndarray

    @property
    def n(self) -> int:
        return len(self.names)

    def within_soft(self, q: np.ndarray, tol: float = 1e-9) -> bool:
        return bool(np.all(q >= self.soft_lower - tol) and np.all(q <= self.soft_upper + tol))

    def margin_to_soft(self, q: np.ndarray) -> np.ndarray:
        """Distance of each joint to its nearer soft limit, shape (n,) (negative: outside)."""
        return np.minimum(q - self.soft_lower, self.soft_upper - q)

    def clip_soft(self, q: np.ndarray) -> np.ndarray:
        return np.clip(q, self.soft_lower, self.soft_upper)

    def sample_soft(self, rng: np.random.Generator) -> np.ndarray:
        return rng.uniform(self.soft_lower, self.soft_upper)


@functools.lru_cache(maxsize=1)
def _limits_yaml() -> dict:
    return read_yaml(ROBOT_DIR / "limits.yaml", "limits file")


def acceleration_limit(joint: str) -> float:
    """Acceleration limit of a joint in SI units [m/s^2 or rad/s^2]."""
    entry = _limits_yaml()["joints"][joint]
    scale = math.pi / 180.0 if entry["type"] == "revolute" else 1.0
    return float(entry["acceleration"]) * scale


def limits_from_urdf(urdf: str, joint_names: tuple[str, ...] | list[str]) -> JointLimits:
    """Collect the limits of the given (movable) joints from URDF text."""
    root = etree.fromstring(urdf.encode())
    rows = []
    for name in joint_names:
        joint = root.find(f"joint[@name='{name}']")
        limit = joint.find("limit")
        safety = joint.find("safety_controller")
        lo, hi = float(limit.get("lower")), float(limit.get("upper"))
        if safety is not None:
            slo = float(safety.get("soft_lower_limit"))
            shi = float(safety.get("soft_upper_limit"))
        else:
            slo, shi = lo, hi
        rows.append((lo, hi, slo, shi, float(limit.get("velocity")), acceleration_limit(name),
                     float(limit.get("effort")), joint.get("type") == "prismatic"))
    cols = list(zip(*rows, strict=True))
    return JointLimits(
        names=tuple(joint_names),
        lower=np.array(cols[0]),
        upper=np.array(cols[1]),
        soft_lower=np.array(cols[2]),
        soft_upper=np.array(cols[3]),
        velocity=np.array(cols[4]),
        acceleration=np.array(cols[5]),
        effort=np.array(cols[6]),
        prismatic=np.array(cols[7], dtype=bool),
    )
