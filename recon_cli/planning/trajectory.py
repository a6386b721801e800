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
from typing import TypeAlias

import numpy as np
import numpy.typing as npt

from recon_cli.errors import TrajectoryError

#: q, qd, qdd at some instants, each (K, n)
Samples: TypeAlias = tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64]]


@dataclass(frozen=True)
class Trajectory:
    """times: (K,) [s] from 0; q, qd, qdd: (K, n). ``sample(t)`` interpolates continuously."""

    times: npt.NDArray[np.float64]
    q: npt.NDArray[np.float64]
    qd: npt.NDArray[np.float64]
    qdd: npt.NDArray[np.float64]
    evaluate: Callable[[npt.NDArray[np.float64]], Samples] | None = None

    @property
    def duration(self) -> float:
        return float(self.times[-1])

    @property
    def start(self) -> npt.NDArray[np.float64]:
        q: npt.NDArray[np.float64] = self.q[0]
        return q

    @property
    def goal(self) -> npt.NDArray[np.float64]:
        q: npt.NDArray[np.float64] = self.q[-1]
        return q

    def sample(self, t: npt.ArrayLike) -> Samples:
        """q, qd, qdd at times t (clamped to [0, duration]); shapes (len(t), n)."""
        ts = np.clip(np.atleast_1d(np.asarray(t, dtype=float)), 0.0, self.duration)
        if self.evaluate is not None:
            return self.evaluate(ts)
        q = np.stack([np.interp(ts, self.times, self.q[:, j]) for j in range(self.q.shape[1])], 1)
        qd = np.stack([np.interp(ts, self.times, self.qd[:, j]) for j in range(self.q.shape[1])], 1)
        qdd = np.stack([np.interp(ts, self.times, self.qdd[:, j]) for j in range(self.q.shape[1])], 1)
        return q, qd, qdd


#: toppra enforces the limits at its grid points only; between them a curved path can
#: exceed them slightly, so it plans against limits shrunk by this factor
LIMIT_MARGIN = 0.98


def parameterize(path: npt.NDArray[np.float64], velocity: npt.NDArray[np.float64],
                 acceleration: npt.NDArray[np.float64], velocity_scale: float = 1.0, acceleration_scale: float = 1.0,
                 grid_points: int = 400) -> Trajectory:
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
    v = velocity * velocity_scale * LIMIT_MARGIN
    a = acceleration * acceleration_scale * LIMIT_MARGIN
    vlim = np.stack([-v, v], axis=1)
    alim = np.stack([-a, a], axis=1)
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

    def evaluate(t: npt.NDArray[np.float64]) -> Samples:
        return jt(t), jt(t, 1), jt(t, 2)

    q, qd, qdd = evaluate(times)
    q[0], q[-1] = path[0], path[-1]
    return Trajectory(times, q, qd, qdd, evaluate)


def concatenate(parts: list[Trajectory]) -> Trajectory:
    """Trajectories one after the other (each must start where the previous one ends)."""
    parts = [p for p in parts if p.duration > 0] or parts[:1]
    offsets = np.cumsum([0.0] + [p.duration for p in parts[:-1]])
    times = np.concatenate([p.times[(1 if k else 0):] + off
                            for k, (p, off) in enumerate(zip(parts, offsets, strict=True))])
    q = np.concatenate([p.q[(1 if k else 0):] for k, p in enumerate(parts)])
    qd = np.concatenate([p.qd[(1 if k else 0):] for k, p in enumerate(parts)])
    qdd = np.concatenate([p.qdd[(1 if k else 0):] for k, p in enumerate(parts)])
    ends = offsets + np.array([p.duration for p in parts])

    def evaluate(t: npt.NDArray[np.float64]) -> Samples:
        idx = np.clip(np.searchsorted(ends, t, side="left"), 0, len(parts) - 1)
        out = [np.empty((len(t), q.shape[1])) for _ in range(3)]
        for k in np.unique(idx):
            m = idx == k
            for o, v in zip(out, parts[k].sample(t[m] - offsets[k]), strict=True):
                o[m] = v
        return out[0], out[1], out[2]

    return Trajectory(times, q, qd, qdd, evaluate)


def reverse(traj: Trajectory) -> Trajectory:
    """The same motion backwards in time (goal to start): positions mirrored in time,
    velocities negated, accelerations unchanged. Limits and the checked course are the
    same, so a planned edge serves both directions."""
    T = traj.duration

    def evaluate(t: npt.NDArray[np.float64]) -> Samples:
        q, qd, qdd = traj.sample(T - np.asarray(t, dtype=float))
        return q, -qd, qdd

    times = traj.times[-1] - traj.times[::-1]
    return Trajectory(times, traj.q[::-1].copy(), -traj.qd[::-1], traj.qdd[::-1].copy(), evaluate)


def stop_and_go(path: npt.NDArray[np.float64], velocity: npt.NDArray[np.float64],
                acceleration: npt.NDArray[np.float64], velocity_scale: float = 1.0,
                acceleration_scale: float = 1.0) -> Trajectory:
    """Rest-to-rest motion along each straight segment of a path: the executed course is
    exactly the piecewise-linear path the planner checked (slower than a smooth one)."""
    return concatenate([straight_line(a, b, velocity, acceleration, velocity_scale, acceleration_scale)
                        for a, b in zip(path[:-1], path[1:], strict=True)])


def straight_line(q0: npt.NDArray[np.float64], q1: npt.NDArray[np.float64], velocity: npt.NDArray[np.float64],
                  acceleration: npt.NDArray[np.float64], velocity_scale: float = 1.0,
                  acceleration_scale: float = 1.0) -> Trajectory:
    """Time-optimal rest-to-rest motion along the straight joint-space segment q0 -> q1."""
    return parameterize(np.stack([q0, q1]), velocity, acceleration, velocity_scale,
                        acceleration_scale)
