"""The 1 kHz setpoint stream of a checked trajectory: smoothed to the controller's jerk limit,
every finite difference within the limits, the start and goal held exactly, refusals named."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from recon_cli.backends.hardware.setpoint_stream import setpoint_stream, smoothing_window
from recon_cli.errors import RobotFault
from recon_cli.planning.trajectory import Trajectory, parameterize
from recon_cli.robot.cell import Cell
from recon_cli.robot.description import CellConfig, CellName

HOME = np.radians([0.0, -10.0, 0.0, -130.0, 0.0, 110.0, 0.0])
GOAL = HOME + np.radians([30.0, 10.0, -20.0, 15.0, 40.0, -20.0, 60.0])


@pytest.fixture(scope="module")
def fr3() -> Cell:
    return Cell(CellConfig(kind=CellName.parse("fr3")))


@pytest.mark.parametrize("scale", [0.15, 0.5, 1.0])
def test_toppra_at_any_scale_streams_within_the_fr3_limits(fr3, scale):
    lim = fr3.kin.limits
    traj = parameterize(np.array([HOME, GOAL]), lim.velocity, lim.acceleration, scale, scale)
    raw_jerk = np.max(np.abs(np.diff(traj.sample(np.arange(0, traj.duration, 1e-3))[0], 3, axis=0))) / 1e-9
    s = setpoint_stream(traj, lim, fr3.joint_names)
    assert np.allclose(s.q[0], HOME, atol=1e-12) and np.allclose(s.q[-1], GOAL, atol=1e-12)
    assert np.all(s.peak_velocity <= lim.velocity) and np.all(s.peak_acceleration <= lim.acceleration * 1.0001)
    # smoothed to half the FR3's 5000 rad/s^3; toppra's own samples are far above it at full scale
    assert np.all(s.peak_jerk <= 0.5 * 5000.0 * 1.0001)
    if scale == 1.0:
        assert raw_jerk > 5000.0 and s.window > 1
    assert np.max(s.deviation) < 1e-4  # off the checked path by less than 0.1 mrad
    assert s.duration == pytest.approx(traj.duration + (s.window - 1) * 1e-3, abs=1.5e-3)


def test_start_blends_from_the_controllers_command(fr3):
    lim = fr3.kin.limits
    traj = parameterize(np.array([HOME, GOAL]), lim.velocity, lim.acceleration, 0.3, 0.3)
    commanded = HOME + 1.5e-3  # the controller's static error at rest
    s = setpoint_stream(traj, lim, fr3.joint_names, start=commanded)
    assert np.allclose(s.q[0], commanded) and np.allclose(s.q[-1], GOAL)
    assert np.all(s.peak_jerk <= 2500.0 * 1.0001) and np.all(s.peak_acceleration <= lim.acceleration)


def test_over_velocity_is_refused_naming_joint_and_numbers(fr3):
    lim = fr3.kin.limits
    traj = parameterize(np.array([HOME, HOME + np.radians([90, 0, 0, 0, 0, 0, 0])]), lim.velocity,
                        lim.acceleration, 1.0, 1.0)
    fast = Trajectory(traj.times / 1.5, traj.q, traj.qd * 1.5, traj.qdd * 2.25)
    with pytest.raises(RobotFault) as info:
        setpoint_stream(fast, lim, fr3.joint_names)
    e = info.value
    assert e.kind == "limit" and e.joint == "fr3_joint1" and not e.stopped
    assert e.message.startswith("setpoints of fr3_joint1 reach velocity 3.85") and "limit 2.62 rad/s" in e.message
    assert "nothing was sent" in e.message


def test_acceleration_and_position_refusals(fr3):
    lim = fr3.kin.limits
    traj = parameterize(np.array([HOME, GOAL]), lim.velocity, lim.acceleration * 3, 1.0, 1.0)
    with pytest.raises(RobotFault, match="reach acceleration .* beyond its limit 10 rad/s\\^2"):
        setpoint_stream(traj, lim, fr3.joint_names)
    outside = HOME.copy()
    outside[3] = lim.upper[3] + 0.01
    traj = parameterize(np.array([HOME, outside]), lim.velocity, lim.acceleration, 0.2, 0.2)
    with pytest.raises(RobotFault, match="fr3_joint4 reach position"):
        setpoint_stream(traj, lim, fr3.joint_names)
    bad = Trajectory(traj.times, np.where(np.arange(len(traj.q))[:, None] == 3, np.nan, traj.q), traj.qd, traj.qdd)
    with pytest.raises(RobotFault, match="not a finite number"):
        setpoint_stream(bad, lim, fr3.joint_names)


def test_a_jerk_that_smoothing_cannot_keep_within_the_deviation_bound_is_refused(fr3):
    lim = dataclasses.replace(fr3.kin.limits, jerk=np.full(7, 20.0))  # a slow controller
    traj = parameterize(np.array([HOME, GOAL]), lim.velocity, lim.acceleration, 1.0, 1.0)
    with pytest.raises(RobotFault, match="deviation from the checked path"):
        setpoint_stream(traj, lim, fr3.joint_names)


def test_no_jerk_limit_means_no_smoothing():
    assert smoothing_window(np.full(3, 10.0), np.full(3, np.inf), 1e-3, 0.5) == 1
    assert smoothing_window(np.full(3, 10.0), np.full(3, 5000.0), 1e-3, 0.5) == 8
