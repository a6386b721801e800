"""A checked trajectory as a stream of joint setpoints at a controller's fixed rate, within
the controller's velocity, acceleration and jerk limits.

toppra times a path under velocity and acceleration limits; its acceleration is piecewise
constant, so the jerk of its samples is unbounded where the acceleration switches. A
controller with a jerk limit (Franka's FCI: 5000 rad/s^3, judged on the finite differences
of consecutive commands at 1 kHz) needs the steps smoothed: the samples are filtered by a
moving average of ``m`` samples (the start and the goal held on either side), which bounds
the jerk by ``2 a_max / (m dt)`` and keeps velocity and acceleration within their peaks. The
filtered stream is the trajectory delayed by ``(m - 1) dt / 2``, off the checked path only
where the acceleration changes, by about ``a dt^2 m^2 / 24``; that deviation is measured and
bounded too.

A cycle the client misses is extrapolated by the controller at constant acceleration; when
the client resumes after ``n`` missed cycles, the controller's third difference jumps by the
stream's jerk times ``(n + 1)^3 / 6``. :func:`jerk_share_for` gives the share of the jerk
limit that keeps such a resumption within the limit (3 missed cycles: 9.4 %).

:func:`setpoint_stream` returns the stream with its measured peaks, or raises
:class:`~recon_cli.errors.RobotFault` (kind ``limit``) naming the joint, the quantity and
both numbers before anything is sent; no value of a station file switches a check off.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from recon_cli.errors import RobotFault
from recon_cli.planning.trajectory import Trajectory
from recon_cli.robot.limits import JointLimits

#: what the finite differences are judged against: the limit itself (the controller's
#: threshold), plus this share for floating-point rounding of the samples
ROUNDING = 1e-9


@dataclass(frozen=True)
class SetpointStream:
    """q: (K, n) setpoints, one every ``dt`` seconds, from the trajectory's start to its goal
    (both held at least once). window: samples of the moving average; deviation: largest
    distance from the checked path (n,); peak_*: largest finite-difference velocity,
    acceleration and jerk per joint (n,)."""

    q: npt.NDArray[np.float64]
    dt: float
    window: int
    deviation: npt.NDArray[np.float64]
    peak_velocity: npt.NDArray[np.float64]
    peak_acceleration: npt.NDArray[np.float64]
    peak_jerk: npt.NDArray[np.float64]

    @property
    def duration(self) -> float:
        return (len(self.q) - 1) * self.dt


def jerk_share_for(lost_cycles: int) -> float:
    """The share of the jerk limit to smooth a stream to, so that resuming after
    ``lost_cycles`` consecutive cycles the controller extrapolated stays within the limit."""
    return min(0.9, 6.0 / (lost_cycles + 1) ** 3)


def smoothing_window(peak_acceleration: npt.NDArray[np.float64], jerk: npt.NDArray[np.float64], dt: float,
                     jerk_share: float) -> int:
    """Samples of the moving average that keep the jerk within ``jerk_share`` of the limit
    (1: no smoothing when no joint has a jerk limit)."""
    finite = np.isfinite(jerk) & (jerk > 0)
    if not np.any(finite):
        return 1
    need = 2.0 * peak_acceleration[finite] / (jerk_share * jerk[finite] * dt)
    return max(1, int(math.ceil(float(np.max(need)) - 1e-9)))


def _moving_average(q: npt.NDArray[np.float64], m: int) -> npt.NDArray[np.float64]:
    if m <= 1:
        return q.copy()
    padded = np.concatenate([np.repeat(q[:1], m - 1, axis=0), q, np.repeat(q[-1:], m - 1, axis=0)])
    c = np.cumsum(np.vstack([np.zeros((1, q.shape[1])), padded]), axis=0)
    out: npt.NDArray[np.float64] = (c[m:] - c[:-m]) / m
    return out


def setpoint_stream(trajectory: Trajectory, limits: JointLimits, joint_names: tuple[str, ...], dt: float = 0.001,
                    jerk_share: float = 0.5, deviation_bound: float = 1e-3,
                    start: npt.NDArray[np.float64] | None = None) -> SetpointStream:
    """The trajectory as setpoints every ``dt`` (smoothed to ``jerk_share`` of the jerk
    limits), checked against the position, velocity, acceleration and jerk limits and the
    deviation bound [rad or m]; RobotFault(kind="limit") before anything is sent.

    ``start``: where the controller's own command stands (Franka's ``q_d``), which differs
    from the measured joints the trajectory starts at by the controller's static error; the
    stream begins there exactly and blends into the trajectory over its whole duration
    (a quintic, zero velocity and acceleration at both ends), so that the first command
    continues the last one."""
    duration = trajectory.duration
    if not np.isfinite(duration) or duration < 0:
        raise RobotFault(f"the trajectory's duration {duration} s is not a finite time; nothing was sent",
                         kind="limit", stopped=False, hint="plan the motion again")
    k = max(int(math.ceil(duration / dt - 1e-9)), 1)
    t = np.minimum(np.arange(k + 1) * dt, duration)
    raw, _, qdd = trajectory.sample(t)
    if not np.all(np.isfinite(raw)):
        j = int(np.flatnonzero(~np.all(np.isfinite(raw), axis=0))[0])
        raise RobotFault(f"a setpoint of {joint_names[j]} is not a finite number; nothing was sent", kind="limit",
                         joint=joint_names[j], stopped=False, hint="plan the motion again")
    units = ["m" if p else "rad" for p in limits.prismatic]
    if len(raw) > 1:  # a trajectory over the velocity limits is named as such (smoothing would not help)
        speed = np.max(np.abs(np.diff(raw, axis=0)), axis=0) / dt
        over = np.flatnonzero(speed > limits.velocity * (1.0 + ROUNDING))
        if over.size:
            j = int(over[np.argmax(speed[over] / limits.velocity[over])])
            raise RobotFault(f"setpoints of {joint_names[j]} reach velocity {speed[j]:.4g} {units[j]}/s, beyond its "
                             f"limit {limits.velocity[j]:.4g} {units[j]}/s; nothing was sent", kind="limit",
                             joint=joint_names[j], value=float(speed[j]), bound=float(limits.velocity[j]),
                             stopped=False, hint="time the trajectory with the cell's velocity limits")
    jerk = limits.jerk if limits.jerk is not None else np.full(limits.n, np.inf)
    # the samples' own accelerations: above toppra's between its grid points where the path bends
    peak_acc = np.max(np.abs(np.diff(raw, 2, axis=0)), axis=0) / dt**2 if len(raw) > 2 else np.zeros(limits.n)
    if np.all(np.isfinite(qdd)):
        peak_acc = np.maximum(peak_acc, np.max(np.abs(qdd), axis=0))
    # the window from the peak accelerations, widened while a sample's bend (a one-sample
    # spike the formula over-weights or a step it under-weights) keeps the jerk above the share
    window = smoothing_window(np.maximum(np.max(np.abs(qdd), axis=0) if np.all(np.isfinite(qdd)) else peak_acc,
                                         1e-12), jerk, dt, jerk_share)
    for _ in range(12):
        q = _moving_average(raw, window)
        peak = np.max(np.abs(np.diff(q, 3, axis=0)), axis=0) / dt**3 if len(q) > 3 else np.zeros(limits.n)
        if np.all(peak <= jerk_share * jerk * (1.0 + ROUNDING)):
            break
        window = int(math.ceil(window * 1.5))
    # the filtered stream follows the path delayed by half the window
    delayed = trajectory.sample(np.clip(np.arange(len(q)) * dt - (window - 1) * dt / 2, 0.0, duration))[0]
    deviation = np.max(np.abs(q - delayed), axis=0)
    if start is not None and len(q) > 1:
        s = np.linspace(0.0, 1.0, len(q))[:, None]
        fade = 1.0 - s**3 * (10.0 - 15.0 * s + 6.0 * s**2)
        q = q + (np.asarray(start, dtype=float) - q[0]) * fade

    def refuse(j: int, what: str, value: float, bound: float, unit: str, hint: str) -> RobotFault:
        return RobotFault(f"setpoints of {joint_names[j]} reach {what} {value:.4g} {unit}, beyond its limit "
                          f"{bound:.4g} {unit}; nothing was sent", kind="limit", joint=joint_names[j],
                          value=float(value), bound=float(bound), stopped=False, hint=hint)

    lo, hi = q.min(axis=0), q.max(axis=0)
    for j in range(limits.n):
        if lo[j] < limits.lower[j] - 1e-9:
            raise refuse(j, "position", lo[j], limits.lower[j], units[j], "plan the motion again; the trajectory "
                         "is not the checked one")
        if hi[j] > limits.upper[j] + 1e-9:
            raise refuse(j, "position", hi[j], limits.upper[j], units[j], "plan the motion again; the trajectory "
                         "is not the checked one")
    velocity = np.max(np.abs(np.diff(q, axis=0)), axis=0) / dt if len(q) > 1 else np.zeros(limits.n)
    acceleration = (np.max(np.abs(np.diff(q, 2, axis=0)), axis=0) / dt**2 if len(q) > 2 else np.zeros(limits.n))
    jerk_peak = np.max(np.abs(np.diff(q, 3, axis=0)), axis=0) / dt**3 if len(q) > 3 else np.zeros(limits.n)
    for name, peak, bound, unit, hint in (
            ("velocity", velocity, limits.velocity, "/s", "time the trajectory with the cell's velocity limits"),
            ("acceleration", acceleration, limits.acceleration, "/s^2",
             "time the trajectory with the cell's acceleration limits"),
            ("jerk", jerk_peak, jerk, "/s^3", "lower the acceleration scale of the motion")):
        over = np.flatnonzero(peak > bound * (1.0 + ROUNDING))
        if over.size:
            j = int(over[np.argmax(peak[over] / bound[over])])
            raise refuse(j, name, peak[j], bound[j], units[j] + unit, hint)
    over = np.flatnonzero(deviation > deviation_bound)
    if over.size:
        j = int(over[np.argmax(deviation[over])])
        raise refuse(j, "a deviation from the checked path of", deviation[j], deviation_bound, units[j],
                     "lower the acceleration scale of the motion")
    return SetpointStream(q, dt, window, deviation, velocity, acceleration, jerk_peak)
