"""Checks that every trajectory passes before a backend may execute it.

Collision checking samples the trajectory so densely that no point of the robot moves more
than ``max_step`` (5 mm by default) between two checked samples. The bound on a point's
displacement for a joint step dq is sum_j |dq_j| * r_j, with r_j the largest distance from
joint j's axis to any point of the robot beyond it (1 for prismatic joints); the bound is
taken per collision shape (``CollisionModel.lever``, a triangle-inequality bound along the
chain), so the sampling is conservative.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from recon_cli.planning.trajectory import Trajectory
from recon_cli.robot.cell import Cell


@dataclass(frozen=True)
class TrajectoryCheck:
    """Outcome of checking a trajectory. ``ok`` when every check passed."""

    samples: int
    max_point_step: float  # [m] bound on any robot point's motion between samples
    max_velocity_ratio: float  # max |qd| / limit
    max_acceleration_ratio: float  # max |qdd| / limit
    within_limits: bool
    collision: tuple[tuple[str, str], ...]  # first colliding pair(s), empty when free
    collision_time: float | None

    @property
    def ok(self) -> bool:
        return self.within_limits and not self.collision


def check_trajectory(traj: Trajectory, cell: Cell, velocity_scale: float = 1.0,
                     acceleration_scale: float = 1.0, max_step: float = 0.005) -> TrajectoryCheck:
    lim = cell.limits
    # time grid fine enough for the displacement bound (refined until it holds)
    n = max(2, len(traj.times))
    while True:
        t = np.linspace(0.0, traj.duration, n)
        q, qd, qdd = traj.sample(t)
        step = float(np.max(cell.collision.point_step_bound(np.diff(q, axis=0)))) if n > 1 else 0.0
        if step <= max_step or n > 200_000:
            break
        n = int(np.ceil(n * step / max_step * 1.05)) + 1
    tol = 1e-6
    vr = float(np.max(np.abs(qd) / (lim.velocity * velocity_scale)))
    ar = float(np.max(np.abs(qdd) / (lim.acceleration * acceleration_scale)))
    within = bool(np.all(q >= lim.soft_lower - 1e-9) and np.all(q <= lim.soft_upper + 1e-9)
                  and vr <= 1 + tol and ar <= 1 + tol)
    collision: tuple[tuple[str, str], ...] = ()
    when = None
    k = cell.collision.first_collision(q)
    if k >= 0:
        collision, when = cell.collision.check(q[k]).pairs, float(t[k])
    return TrajectoryCheck(len(t), step, vr, ar, within, collision, when)

