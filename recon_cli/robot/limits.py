"""Joint limits of a cell, read from the expanded URDF and robot/limits.yaml.

Position, soft position and velocity limits come from the URDF (``<limit>`` and
``<safety_controller>``, written by the xacro from limits.yaml); acceleration limits, which
URDF cannot hold, come from limits.yaml itself. Units: m, rad, s.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
from lxml import etree

from recon_cli.inputs.yamlfile import read_yaml
from recon_cli.paths import ROBOT_DIR
from recon_cli.robot.urdf import attribute, child


@dataclass(frozen=True)
class JointLimits:
    """Per-joint limits in joint-vector order. Arrays of shape (n,).

    lower, upper: hard position limits [m or rad]
    soft_lower, soft_upper: planning limits inside the hard ones (10 deg for revolute joints)
    velocity: [m/s or rad/s]; acceleration: [m/s^2 or rad/s^2]; effort: [N or N m]
    prismatic: True for the linear axes
    """

    names: tuple[str, ...]
    lower: npt.NDArray[np.float64]
    upper: npt.NDArray[np.float64]
    soft_lower: npt.NDArray[np.float64]
    soft_upper: npt.NDArray[np.float64]
    velocity: npt.NDArray[np.float64]
    acceleration: npt.NDArray[np.float64]
    effort: npt.NDArray[np.float64]
    prismatic: npt.NDArray[np.bool_]

    @property
    def n(self) -> int:
        return len(self.names)

    def within_soft(self, q: npt.NDArray[np.float64], tol: float = 1e-9) -> bool:
        return bool(np.all(q >= self.soft_lower - tol) and np.all(q <= self.soft_upper + tol))

    def margin_to_soft(self, q: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Distance of each joint to its nearer soft limit, shape (n,) (negative: outside)."""
        return np.minimum(q - self.soft_lower, self.soft_upper - q)

    def clip_soft(self, q: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        return np.clip(q, self.soft_lower, self.soft_upper)

    def sample_soft(self, rng: np.random.Generator) -> npt.NDArray[np.float64]:
        return rng.uniform(self.soft_lower, self.soft_upper)


@functools.lru_cache(maxsize=1)
def _limits_yaml() -> dict[str, Any]:
    doc: dict[str, Any] = read_yaml(ROBOT_DIR / "limits.yaml", "limits file")
    return doc


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
        joint = child(root, f"joint[@name='{name}']")
        limit = child(joint, "limit")
        safety = joint.find("safety_controller")
        lo, hi = float(attribute(limit, "lower")), float(attribute(limit, "upper"))
        if safety is not None:
            slo = float(attribute(safety, "soft_lower_limit"))
            shi = float(attribute(safety, "soft_upper_limit"))
        else:
            slo, shi = lo, hi
        rows.append((lo, hi, slo, shi, float(attribute(limit, "velocity")), acceleration_limit(name),
                     float(attribute(limit, "effort")), joint.get("type") == "prismatic"))
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
