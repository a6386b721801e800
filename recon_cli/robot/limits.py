"""Joint limits of a cell, read from the expanded URDF and the cell file's limits.

Position, soft position, velocity and effort limits come from the URDF (``<limit>`` and
``<safety_controller>``) unless the cell file's limits give them (revolute joints in deg,
prismatic in m; a soft margin there puts the soft limits that far inside the hard ones);
acceleration limits and the controller's jerk limits, which URDF cannot hold, come from the
cell file. Units: m, rad, s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from lxml import etree

from recon_cli.errors import InputError
from recon_cli.robot.cell_file import CellFile, LimitTable
from recon_cli.robot.urdf import attribute, child


@dataclass(frozen=True)
class JointLimits:
    """Per-joint limits in joint-vector order. Arrays of shape (n,).

    lower, upper: hard position limits [m or rad]
    soft_lower, soft_upper: planning limits inside the hard ones (10 deg for revolute joints)
    velocity: [m/s or rad/s]; acceleration: [m/s^2 or rad/s^2]; effort: [N or N m]
    prismatic: True for the linear axes
    jerk: [m/s^3 or rad/s^3] the controller's jerk limits where the cell file gives them
        (inf where it does not: the joint's controller has none recon must keep)
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
    jerk: npt.NDArray[np.float64] | None = None

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


#: narrowest soft range of a joint [rad or m]: 0.06 deg, 1 mm (a joint that cannot move that far
#: is a fixed joint; the IK scales its steps by the inverse of the range)
MIN_SOFT_RANGE = 1e-3


def limits_from_urdf(urdf: str, joint_names: tuple[str, ...] | list[str], table: LimitTable,
                     cell: CellFile | None = None) -> JointLimits:
    """Collect the limits of the given (movable) joints from URDF text and a cell's limit table.
    Refused, one line each: a joint that is not revolute or prismatic, a lower limit not below
    the upper one (the URDF's replaced by the table's), a soft range narrower than
    :data:`MIN_SOFT_RANGE` (a soft margin of half the range or more). ``cell``: the cell file
    the table belongs to, for the line of each joint in messages."""
    root = etree.fromstring(urdf.encode())
    rows = []
    for name in joint_names:
        joint = child(root, f"joint[@name='{name}']")
        where = cell.where(f"limits.joints.{name}") if cell is not None else table.where
        description = cell.description if cell is not None else "the robot description"
        if joint.get("type") not in ("revolute", "prismatic"):
            raise InputError(f"{description}: joint {name} is a {joint.get('type')} joint; recon plans revolute and "
                             "prismatic joints with position limits",
                             hint=f"write joint {name} as a revolute joint with <limit lower=... upper=...>")
        limit = child(joint, "limit")
        safety = joint.find("safety_controller")
        prismatic = joint.get("type") == "prismatic"
        given = table.get(name)
        if given is None or given.acceleration is None:
            raise InputError(f"{table.where}: the limits lack the acceleration of joint {name}",
                             hint="give limits.joints.NAME.acceleration of every planning joint")
        k = 1.0 if prismatic else math.pi / 180.0
        margin = table.soft_margin_prismatic_m if prismatic else table.soft_margin_revolute_deg
        # URDF reads a missing lower or upper limit as 0
        lo = given.lower * k if given.lower is not None else float(limit.get("lower", "0"))
        hi = given.upper * k if given.upper is not None else float(limit.get("upper", "0"))
        if margin is not None:
            m = margin if prismatic else margin * math.pi / 180.0
            slo, shi = lo + m, hi - m
        elif safety is not None:
            slo = max(lo, float(safety.get("soft_lower_limit", lo)))
            shi = min(hi, float(safety.get("soft_upper_limit", hi)))
        else:
            slo, shi = lo, hi
        unit = "m" if prismatic else "deg"
        if not lo < hi:
            raise InputError(f"{where if given.lower is not None or given.upper is not None else description}: "
                             f"joint {name}: the lower limit {lo / k:g} {unit} is not below the upper limit "
                             f"{hi / k:g} {unit}", hint=f"give limits.joints.{name}.lower below its upper limit "
                                                       f"({unit})")
        if not shi - slo >= MIN_SOFT_RANGE:
            if margin is not None:
                raise InputError(f"{where}: joint {name}: the soft margin {margin:g} {unit} leaves no range inside its "
                                 f"limits {lo / k:g} ... {hi / k:g} {unit}",
                                 hint=f"make soft_margin_{'prismatic_m' if prismatic else 'revolute_deg'} less than "
                                      f"half of every planning joint's range, or widen joint {name}'s limits")
            raise InputError(f"{description}: joint {name}: its <safety_controller> soft limits leave no range inside "
                             f"its limits {lo / k:g} ... {hi / k:g} {unit}",
                             hint="give soft_lower_limit below soft_upper_limit, both inside the joint's limits")
        velocity = given.velocity * k if given.velocity is not None else float(attribute(limit, "velocity"))
        effort = given.effort if given.effort is not None else float(attribute(limit, "effort"))
        jerk = given.jerk * k if given.jerk is not None else math.inf
        rows.append((lo, hi, slo, shi, velocity, given.acceleration * k, effort, prismatic, jerk))
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
        jerk=np.array(cols[8]),
    )
