"""Checks that every trajectory passes before a backend may execute it.

Collision checking samples the trajectory so densely that no point of the robot moves more
than ``max_step`` (5 mm by default) between two checked samples. The bound on a point's
displacement for a joint step dq is sum_j |dq_j| * r_j, with r_j the largest distance from
joint j's axis to any point of the robot beyond it (1 for prismatic joints), computed once
from the kinematic chain and the collision shapes (a triangle-inequality bound, so the
sampling is conservative).
"""

from __future__ import annotations

import functools
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


def _shape_reach(shape) -> float:
    """Largest distance of a shape's points from its own origin [m]."""
    d = shape.dims
    if shape.kind == "box":
        return float(np.linalg.norm(np.asarray(d) / 2.0))
    if shape.kind in ("capsule", "cylinder"):
        return float(d[1] / 2.0 + d[0])
    return float(d[0])


@functools.lru_cache(maxsize=8)
def _lever_arms(cell_key: int, cell: Cell) -> np.ndarray:
    model = cell.kin.model
    # distance from each joint's origin to the farthest point of each body beyond it, along
    # the chain: sum of joint-origin offsets + shape reach (triangle inequality)
    reach_body = np.zeros(model.njoints)
    for s in cell.collision.robot_shapes:
        reach_body[s.joint] = max(reach_body[s.joint],
                                  np.linalg.norm(s.joint_T_shape[:3, 3]) + _shape_reach(s))
    lever = np.zeros(model.nq)
    for j in range(1, model.njoints):
        best = 0.0
        for k in range(j, model.njoints):
            # chain from joint j to joint k: sum of the placements in between
            dist, i = 0.0, k
            while i != j and i > 0:
                dist += float(np.linalg.norm(model.jointPlacements[i].translation))
                i = model.parents[i]
            if i == j:
                best = max(best, dist + reach_body[k])
        idx = model.joints[j].idx_q
        is_prismatic = "P" in model.joints[j].shortname()
        lever[idx] = 1.0 if is_prismatic else best
    return lever


def lever_arms(cell: Cell) -> np.ndarray:
    """r_j of the module docstring, shape (n,) [m per rad, or 1 for prismatic joints]."""
    return _lever_arms(id(cell), cell)


def point_step_bound(cell: Cell, dq: np.ndarray) -> np.ndarray:
    """Upper bound on any robot point's displacement [m] for joint steps dq (..., n)."""
    return np.abs(dq) @ lever_arms(cell)


def check_trajectory(traj: Trajectory, cell: Cell, velocity_scale: float = 1.0,
                     acceleration_scale: float = 1.0, max_step: float = 0.005) -> TrajectoryCheck:
    lim = cell.limits
    # time grid fine enough for the displacement bound (refined until it holds)
    n = max(2, len(traj.times))
    while True:
        t = np.linspace(0.0, traj.duration, n)
        q, qd, qdd = traj.sample(t)
        step = float(np.max(point_step_bound(cell, np.diff(q, axis=0)))) if n > 1 else 0.0
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
    for k in range(len(t)):
        report = cell.collision.check(q[k])
        if report.colliding:
            collision, when = report.pairs, float(t[k])
            break
    return TrajectoryCheck(len(t), step, vr, ar, within, collision, when)

