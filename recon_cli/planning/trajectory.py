"""Time-parameterized joint trajectories and their checks.

A ``Trajectory`` holds samples of q(t), qd(t), qdd(t) on a time grid and a continuous
evaluator. ``straight_line`` time-parameterizes the straight joint-space segment between
two configurations with toppra under the joint velocity and acceleration limits (scaled).
``check_trajectory`` verifies limits and collisions at a resolution where no robot point
moves more than ``max_step`` between checked samples.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from recon_cli.errors import ReconError


@dataclass(frozen=True)
class Trajectory:
    """times: (K,) [s] from 0; q, qd, qdd: (K, n). ``sample(t)`` interpolates continuously."""

    times: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    evaluate: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]] | None = None

    @property
    def duration(self) -> float:
        return float(self.times[-1])

    @property
    def start(self) -> np.ndarray:
        return self.q[0]

    @property
    def goal(self) -> np.ndarray:
        return self.q[-1]

    def sample(self, t: np.ndarray | float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """q, qd, qdd at times t (clamped to [0, duration]); shapes (len(t), n)."""
        t = np.clip(np.atleast_1d(np.asarray(t, dtype=float)), 0.0, self.duration)
        if self.evaluate is not None:
            return self.evaluate(t)
        q = np.stack([np.interp(t, self.times, self.q[:, j]) for j in range(self.q.shape[1])], 1)
        qd = np.stack([np.interp(t, self.times, self.qd[:, j]) for j in range(self.q.shape[1])], 1)
        qdd = np.stack([np.interp(t, self.times, self.qdd[:, j]) for j in range(self.q.shape[1])], 1)
        return q, qd, qdd


class TrajectoryError(ReconError):
    """A trajectory that may not be executed (limits or collisions)."""


def parameterize(path: np.ndarray, velocity: np.ndarray, acceleration: np.ndarray,
                 velocity_scale: float = 1.0, acceleration_scale: float = 1.0,
                 grid_points: int = 200) -> Trajectory:
    """Time-optimal rest-to-rest trajectory along a piecewise-linear joint path (K, n).

    toppra on a path that interpolates the waypoints linearly in a normalized path
    parameter; velocity and acceleration limits are scaled like MoveIt's scaling factors.
    """
    import toppra as ta
    import toppra.algorithm as algo
    import toppra.constraint as constraint

    path = np.asarray(path, dtype=float)
    seg = np.linalg.norm(np.diff(path, axis=0), axis=1)
    keep = np.concatenate([[True], seg > 1e-12])
    path = path[keep]
    n = path.shape[1]
    if len(path) == 1:
        z = np.zeros((1, n))
        return Trajectory(np.zeros(1), path.copy(), z, z.copy())
    if len(path) == 2:  # a straight segment: collinear, evenly spaced knots make the spline exact
        path = np.linspace(path[0], path[1], 5)
        geom = ta.SplineInterpolator(np.linspace(0.0, 1.0, 5), path, bc_type="natural")
    else:
        s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(path, axis=0), axis=1))])
        geom = ta.SplineInterpolator(s / s[-1], path, bc_type="clamped")
    vlim = np.stack([-velocity * velocity_scale, velocity * velocity_scale], axis=1)
    alim = np.stack([-acceleration * acceleration_scale, acceleration * acceleration_scale], axis=1)
    pc_vel = constraint.JointVelocityConstraint(vlim)
    pc_acc = constraint.JointAccelerationConstraint(
        alim, discretization_scheme=constraint.DiscretizationType.Interpolation)
    gridpoints = np.linspace(0.0, 1.0, grid_points)
    instance = algo.TOPPRA([pc_vel, pc_acc], geom, gridpoints=gridpoints,
                           parametrizer="ParametrizeConstAccel")
    jt = instance.compute_trajectory(0.0, 0.0)
    if jt is None:
        raise TrajectoryError("time parameterization failed for a path of "
                              f"{len(path)} waypoints", hint="re-plan the motion")
    times = np.linspace(0.0, jt.duration, max(2, int(np.ceil(jt.duration / 0.01)) + 1))

    def evaluate(t: np.ndarray):
        return jt(t), jt(t, 1), jt(t, 2)

    q, qd, qdd = evaluate(times)
    q[0], q[-1] = path[0], path[-1]
    return Trajectory(times, q, qd, qdd, evaluate)


def straight_line(q0: np.ndarray, q1: np.ndarray, velocity: np.ndarray,
                  acceleration: np.ndarray, velocity_scale: float = 1.0,
                  acceleration_scale: float = 1.0) -> Trajectory:
    """Time-optimal rest-to-rest motion along the straight joint-space segment q0 -> q1."""
    return parameterize(np.stack([q0, q1]), velocity, acceleration, velocity_scale,
                        acceleration_scale)
