"""The ADS robot adapter end to end through pyads against pyads' own test server on
loopback, with a stand-in PLC program that tracks the setpoints (tests/backends/plc_standin.py).
ADS talks TCP port 48898, so one stand-in runs at a time."""

from __future__ import annotations

import threading
from dataclasses import replace

import numpy as np
import pytest

pytest.importorskip("pyads", reason="the ADS adapter needs pyads (pip install recon-cli[ads])")

from recon_cli.backends.hardware.ads import AdsConfig, AdsRobot  # noqa: E402
from recon_cli.errors import InputError, RobotFault  # noqa: E402
from recon_cli.planning.trajectory import Trajectory, parameterize  # noqa: E402
from recon_cli.robot.cell import Cell  # noqa: E402
from recon_cli.robot.description import CellConfig  # noqa: E402
from recon_cli.robot.poses import named_configuration  # noqa: E402

from .plc_standin import NC_FOLLOWING_ERROR, PLCStandIn  # noqa: E402

FAST = AdsConfig(poll=0.005, timeout=1.0, watchdog=1.0, time_margin=1.0, settle_timeout=2.0)


@pytest.fixture(scope="module")
def cell():
    return Cell(CellConfig())


@pytest.fixture()
def start(cell):
    return named_configuration(cell.config.kind, "home", cell.joint_names)


@pytest.fixture()
def plc(cell, start):
    stand_in = PLCStandIn(len(cell.joint_names), start, speedup=10.0).start()
    yield stand_in
    stand_in.close()


def _trajectory(cell, start, scale=0.15) -> Trajectory:
    goal = start.copy()
    goal[:3] += (0.10, -0.08, 0.05)  # linear axes [m]
    goal[3:] += 0.25  # arm joints [rad]
    lim = cell.kin.limits
    return parameterize(np.stack([start, goal]), lim.velocity, lim.acceleration, scale, 0.3)


def _robot(cell, config=FAST) -> AdsRobot:
    return AdsRobot(config, cell.joint_names, cell.kin.limits)


def test_trajectory_executes_and_joints_match(cell, start, plc):
    traj = _trajectory(cell, start)
    robot = _robot(cell)
    try:
        assert np.allclose(robot.measured_joints(), start)
        report = robot.execute(traj)
        q_sent, period = robot.setpoints(traj)
    finally:
        robot.close()
    assert report.settled and plc.started == 1
    assert np.all(report.final_error <= np.where(cell.kin.limits.prismatic, 5e-5, 2e-4))
    assert np.allclose(plc.measured, traj.goal, atol=2e-4)
    # the PLC received exactly the checked setpoints
    assert np.allclose(plc.buffer[:len(q_sent)], q_sent)
    # the measured joints followed the planned trajectory all the way
    t = np.array([row[0] for row in plc.log])
    measured = np.array([row[2] for row in plc.log])
    planned = traj.sample(t)[0]
    tracking = np.abs(measured - planned).max(axis=0)
    assert np.all(tracking < np.where(cell.kin.limits.prismatic, 0.005, 0.02))
    assert np.all(report.max_tracking_error >= 0) and report.duration == pytest.approx(traj.duration, abs=period)
    assert plc.get("stop", "B")[0] == 1  # closing stops the robot


def test_connection_loss_mid_trajectory(cell, start, plc):
    threading.Timer(0.15, plc.drop_connection).start()
    with _robot(cell) as robot, pytest.raises(RobotFault) as info:
        robot.execute(_trajectory(cell, start))
    assert info.value.kind == "connection" and "lost the connection to the PLC" in info.value.one_line()
    assert "\n" not in info.value.one_line()


def test_plc_fault_flag_stops(cell, start, plc):
    plc.faults.fault_at = 0.3
    with _robot(cell) as robot, pytest.raises(RobotFault, match=rf"fault {NC_FOLLOWING_ERROR} \(") as info:
        robot.execute(_trajectory(cell, start))
    assert info.value.kind == "plc_fault" and info.value.code == NC_FOLLOWING_ERROR and info.value.stopped
    assert plc.get("stop", "B")[0] == 1  # recon commanded the stop


def test_timeout_stops(cell, start, plc):
    plc.faults.freeze_at = 0.3
    with _robot(cell, replace(FAST, time_margin=0.3)) as robot, \
            pytest.raises(RobotFault, match="did not complete within") as info:
        robot.execute(_trajectory(cell, start))
    assert info.value.kind == "timeout" and info.value.stopped and plc.get("stop", "B")[0] == 1


def test_tracking_error_stops(cell, start, plc):
    plc.faults.drift_at = 0.2
    with _robot(cell) as robot, pytest.raises(RobotFault, match="tracking error of .* above the bound") as info:
        robot.execute(_trajectory(cell, start))
    assert info.value.kind == "tracking" and info.value.value > info.value.bound and info.value.stopped
    assert plc.get("stop", "B")[0] == 1


def test_limit_violations_are_refused_before_sending(cell, start, plc):
    lim = cell.kin.limits
    # a position beyond a hard limit
    goal = start.copy()
    goal[4] = lim.upper[4] + 0.05
    path = np.stack([start, goal])
    beyond = Trajectory(np.array([0.0, 60.0]), path, np.zeros_like(path), np.zeros_like(path))
    # a joint moved at three times its velocity limit
    goal = start.copy()
    goal[5] += 0.5
    path = np.stack([start, goal])
    fast = Trajectory(np.array([0.0, 0.5 / (3.0 * lim.velocity[5])]), path, np.zeros_like(path), np.zeros_like(path))
    with _robot(cell) as robot:
        with pytest.raises(RobotFault, match=r"outside its limits \[.*\]; nothing was sent") as info:
            robot.execute(beyond)
        assert info.value.kind == "limit" and info.value.joint == cell.joint_names[4]
        with pytest.raises(RobotFault, match="above its velocity limit") as info:
            robot.execute(fast)
        assert info.value.kind == "limit" and info.value.joint == cell.joint_names[5]
        assert info.value.value == pytest.approx(3.0 * lim.velocity[5], rel=0.05)
    assert plc.started == 0 and plc.get("count", "i")[0] == 0  # nothing reached the PLC


def test_not_at_start_is_refused(cell, start, plc):
    shifted = start.copy()
    shifted[0] += 0.05
    with _robot(cell) as robot, pytest.raises(RobotFault, match="not at the trajectory's start"):
        robot.execute(_trajectory(cell, shifted))
    assert plc.started == 0


def test_unreachable_plc_is_one_line(cell):
    with pytest.raises(RobotFault, match="cannot reach the PLC") as info:
        AdsRobot(replace(FAST, timeout=0.3), cell.joint_names, cell.kin.limits)
    assert info.value.kind == "connection" and "\n" not in info.value.one_line()


def test_config_errors_name_the_key():
    with pytest.raises(InputError, match=r"robot.ads.bogus is not a known key"):
        AdsConfig.from_mapping({"bogus": 1})
    with pytest.raises(InputError, match=r"robot.ads.symbols.speed is not a symbol"):
        AdsConfig.from_mapping({"symbols": {"speed": "MAIN.x"}})
    with pytest.raises(InputError, match="speed_override = 2.0 is above 1"):
        AdsConfig.from_mapping({"speed_override": 2.0})
    cfg = AdsConfig.from_mapping({"symbols": {"prefix": "GVL.cell", "stop": "GVL.estop_soft"}})
    assert cfg.symbols["state"] == "GVL.cell.state" and cfg.symbols["stop"] == "GVL.estop_soft"


def test_heartbeat_watchdog_stop_is_reported(cell, start, plc):
    """The PLC stops the axes when recon's heartbeat stalls; recon reports it as a fault."""
    import time as _time

    with _robot(cell, replace(FAST, watchdog=0.05, poll=0.2)) as robot, \
            pytest.raises(RobotFault, match="the PLC stopped the motion at setpoint") as info:
        _time.sleep(0.01)
        robot.execute(_trajectory(cell, start))
    assert info.value.kind == "plc_fault"
