"""The ADS robot adapter end to end through pyads against pyads' own test server on
loopback, with a stand-in PLC program that tracks the setpoints (tests/backends/plc_standin.py).
ADS talks TCP port 48898, so one stand-in runs at a time.

Times: the stand-in's clock is robot time (it advances ``speedup`` times the PLC cycle per
cycle); the fault tests run it at speedup 1, so robot time is wall time unless the machine
starves the stand-in's thread, which only makes robot time shorter. Bounds on when the axes
stopped are stated in robot time."""

from __future__ import annotations

import os
import signal
import threading
import time
from dataclasses import replace

import numpy as np
import pytest

pytest.importorskip("pyads", reason="the ADS adapter needs pyads (pip install 'recon-scan[ads]')")

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
    assert stand_in.crash is None, stand_in.crash


@pytest.fixture()
def slow_plc(cell, start):
    """The stand-in in real time (speedup 1): a 1.8 s trajectory takes 1.8 s."""
    stand_in = PLCStandIn(len(cell.joint_names), start, speedup=1.0).start()
    yield stand_in
    stand_in.close()
    assert stand_in.crash is None, stand_in.crash


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
    with pytest.raises(InputError, match=r"speed_override = 2 is outside \(0, 1\]"):
        AdsConfig.from_mapping({"speed_override": 2.0})
    cfg = AdsConfig.from_mapping({"symbols": {"prefix": "GVL.cell", "stop": "GVL.estop_soft"}})
    assert cfg.symbols["state"] == "GVL.cell.state" and cfg.symbols["stop"] == "GVL.estop_soft"


# --------------------------------------------------------------------- the heartbeat
# A config for the fault tests: a short watchdog and a short request timeout, so that faults
# show within a second; poll is at most watchdog / 5.
QUICK = AdsConfig(poll=0.01, timeout=0.2, watchdog=0.3, time_margin=5.0, settle_timeout=0.5)
CYCLE = 0.002  # [s] the stand-in's PLC cycle


def test_heartbeat_runs_from_connect_to_close(cell, start, slow_plc):
    """Between connecting and the first job (planning, a camera set-up) the heartbeat goes on,
    so the PLC's watchdog does not stop the first motion at setpoint 0; closing ends it after
    the stop is written."""
    robot = _robot(cell, QUICK)
    try:
        time.sleep(3 * QUICK.watchdog)
        assert slow_plc.beats >= 3 * QUICK.watchdog / QUICK.poll / 3  # about one beat per poll
        report = robot.execute(_trajectory(cell, start, scale=0.5))
    finally:
        robot.close()
    assert report.settled and slow_plc.event("stopped by watchdog") is None
    time.sleep(5 * CYCLE)  # the stand-in's next cycles see the last beat
    beats = slow_plc.beats
    time.sleep(5 * QUICK.poll)
    assert slow_plc.beats == beats and slow_plc.get("stop", "B")[0] == 1  # closed: stop written, no more beats
    assert not robot._heart.is_alive()


def test_heartbeat_stall_stops_the_axes(cell, start, slow_plc):
    """When recon's heartbeat stalls mid-motion, the PLC's watchdog stops the axes within
    `watchdog` (plus a poll and two PLC cycles) of the last beat, and recon reports it."""
    robot = _robot(cell, QUICK)

    def stall():
        robot._beat_once = lambda: None  # the heartbeat thread hangs
        slow_plc.mark("stall")

    traj = _trajectory(cell, start)
    threading.Timer(0.5, stall).start()
    with robot, pytest.raises(RobotFault, match="the PLC stopped the motion at setpoint") as info:
        robot.execute(traj)
    assert info.value.kind == "plc_fault" and info.value.stopped
    assert "the robot was stopped (confirmed by the PLC after" in info.value.one_line()
    stalled, _ = slow_plc.event("stall")
    stopped, _ = slow_plc.event("stopped by watchdog")
    assert stopped - stalled <= QUICK.watchdog + QUICK.poll + 2 * CYCLE
    assert slow_plc.last_motion() <= stopped


def test_stalled_polling_loop_stops_the_heartbeat(cell, start, slow_plc):
    """During a motion the heartbeat beats only while the polling loop is alive: a polling
    loop that hangs lets the PLC's watchdog stop the axes."""
    robot = _robot(cell, QUICK)
    status, calls = robot._status, []

    def hanging_status():
        calls.append(1)
        if len(calls) == 20:
            slow_plc.mark("hang")
            time.sleep(4 * QUICK.watchdog)
        return status()

    robot._status = hanging_status
    traj = _trajectory(cell, start)
    with robot, pytest.raises(RobotFault, match="the PLC stopped the motion") as info:
        robot.execute(traj)
    assert info.value.kind == "plc_fault"
    hang, _ = slow_plc.event("hang")
    stopped, _ = slow_plc.event("stopped by watchdog")
    assert stopped - hang <= QUICK.watchdog / 2 + QUICK.poll + QUICK.watchdog + 2 * CYCLE


# --------------------------------------------------------------------- connection loss
def test_connection_loss_for_good(cell, start, slow_plc):
    """The network goes away mid-motion and stays away: recon cannot stop the robot, says so,
    and the PLC's watchdog stops the axes within `watchdog` (+ a poll, two cycles) of the loss."""
    traj = _trajectory(cell, start)
    threading.Timer(0.5, slow_plc.drop_connection).start()
    t0 = time.monotonic()
    with _robot(cell, QUICK) as robot, pytest.raises(RobotFault) as info:
        robot.execute(traj)
    raised = time.monotonic()
    text = info.value.one_line()
    assert info.value.kind == "connection" and not info.value.stopped and "\n" not in text
    assert text.startswith("lost the connection to the PLC (")
    assert (f"the stop could not be confirmed within {QUICK.watchdog:g} s; the PLC watchdog stops the axes after "
            f"{QUICK.watchdog:g} s without a heartbeat") in text
    assert "the robot was stopped" not in text
    dropped, dropped_at = slow_plc.event("dropped")
    stopped, _ = slow_plc.event("stopped by watchdog")
    assert slow_plc.event("done") is None  # stopped mid-motion, not at the end
    assert slow_plc.last_motion() - dropped <= QUICK.watchdog + QUICK.poll + 2 * CYCLE
    # recon gave up after one failing request and `watchdog` seconds of trying
    assert raised - dropped_at <= QUICK.timeout + QUICK.watchdog + 0.5 and raised - t0 < 1.8


def test_connection_loss_then_back_is_stopped_and_confirmed(cell, start, slow_plc):
    """The network goes away for 0.15 s: recon reconnects, writes stop and reports the PLC's
    confirmation; the axes stop well before the PLC's watchdog would have stopped them."""
    config = replace(QUICK, watchdog=1.0)

    def glitch():
        slow_plc.drop_connection()
        time.sleep(0.15)
        slow_plc.restore_connection()

    traj = _trajectory(cell, start, scale=0.05)
    threading.Timer(0.5, glitch).start()
    with _robot(cell, config) as robot, pytest.raises(RobotFault) as info:
        robot.execute(traj)
    text = info.value.one_line()
    assert info.value.kind == "connection" and info.value.stopped
    assert "the robot was stopped (confirmed by the PLC after " in text and "could not be confirmed" not in text
    seconds = float(text.split("confirmed by the PLC after ")[1].split(" s)")[0])
    assert 0 < seconds < config.watchdog
    dropped, _ = slow_plc.event("dropped")
    stopped, _ = slow_plc.event("stopped by stop")
    assert slow_plc.event("stopped by watchdog") is None and slow_plc.event("done") is None
    # the loss is seen after one request timeout, the stop follows the reconnection
    assert slow_plc.last_motion() - dropped <= QUICK.timeout + 0.15 + 0.25 < config.watchdog
    assert slow_plc.last_motion() <= stopped


# --------------------------------------------------------------------- Ctrl-C and SIGTERM
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_signal_mid_motion_stops_first(cell, start, slow_plc, signum):
    """Ctrl-C (SIGINT) and SIGTERM in the polling loop: the stop reaches the PLC before the
    interruption leaves execute(), and the axes stop within 0.1 s of the signal."""
    from recon_cli.interrupts import stop_signals

    def interrupt():
        slow_plc.mark("signal")
        os.kill(os.getpid(), signum)

    traj = _trajectory(cell, start)
    robot = _robot(cell, QUICK)
    try:
        threading.Timer(0.6, interrupt).start()
        with stop_signals(), pytest.raises(KeyboardInterrupt):
            robot.execute(traj)
        # before close(): the stop was written by execute() itself
        assert slow_plc.get("stop", "B")[0] == 1 and slow_plc.event("stopped by stop") is not None
        sent, _ = slow_plc.event("signal")
        assert 0 <= slow_plc.last_motion() - sent <= 0.1
        assert slow_plc.event("done") is None
    finally:
        robot.close()


# --------------------------------------------------------------------- what the PLC receives
def test_plc_receives_scaled_setpoints_in_its_axis_order(cell, start):
    """mm and degrees in a shuffled axis order: the setpoints the stand-in received are the
    planned ones, axis by axis times the scale; the measured values come back in recon's units."""
    names = cell.joint_names
    axes = (names[3], names[0], *names[4:], names[2], names[1])
    scale = tuple(1000.0 if cell.kin.limits.prismatic[names.index(a)] else 180.0 / np.pi for a in axes)
    config = replace(FAST, axes=axes, scale=scale)
    order = [names.index(a) for a in axes]
    start_plc = start[order] * np.array(scale)
    stand_in = PLCStandIn(len(names), start_plc, speedup=10.0).start()
    traj = _trajectory(cell, start)
    try:
        with _robot(cell, config) as robot:
            assert np.allclose(robot.measured_joints(), start)
            robot.execute(traj)
            q, _ = robot.setpoints(traj)
            assert np.allclose(robot.measured_joints(), traj.goal, atol=2e-4)
    finally:
        stand_in.close()
    assert stand_in.crash is None
    (received,) = stand_in.received
    expected = np.stack([q[:, names.index(a)] * s for a, s in zip(axes, scale, strict=True)], axis=1)
    assert received.shape == expected.shape and np.allclose(received, expected, rtol=0, atol=1e-9)
    assert np.allclose(received[-1], traj.goal[order] * np.array(scale))


# --------------------------------------------------------------------- NaN and garbage from the PLC
@pytest.mark.parametrize("value, message", [
    (float("nan"), r"measured position of arm_joint_2 \(axis 3\) as nan, not a finite number"),
    (float("inf"), r"measured position of arm_joint_2 \(axis 3\) as inf, not a finite number"),
    (1e6, r"measured position of arm_joint_2 is 1e\+06 rad, outside its limits"),
    (-2.3, r"measured position of arm_joint_2 is -2.3 rad, outside its limits \[-2.0944, 2.0944\] rad widened"),
])
def test_garbage_measurement_at_rest_stops(cell, start, plc, value, message):
    plc.faults.garbage_at, plc.faults.measured_axis, plc.faults.measured_value = 0.0, 3, value
    time.sleep(0.02)  # a PLC cycle publishes it
    with _robot(cell) as robot:
        with pytest.raises(RobotFault, match=message) as info:
            robot.measured_joints()
        assert info.value.kind == "measurement" and info.value.joint == "arm_joint_2" and info.value.stopped
        assert plc.get("stop", "B")[0] == 1
        with pytest.raises(RobotFault, match=message):  # nothing is sent from a pose that is not known
            robot.execute(_trajectory(cell, start))
    assert plc.started == 0


@pytest.mark.parametrize("faults, message", [
    ({"measured_value": float("nan"), "measured_axis": 5}, r"arm_joint_4 \(axis 5\) as nan, not a finite number "
                                                           r"at setpoint \d+ of \d+"),
    ({"measured_value": 1e9, "measured_axis": 0}, r"measured position of base_joint_1 is 1e\+09 m, outside"),
    ({"state_value": 7}, r"the PLC reports state 7, not one of 0 \(idle\)"),
    ({"state_value": -1}, r"the PLC reports state -1, not one of"),
    ({"index_value": 10**6}, r"the PLC reports setpoint 1000000 while moving, outside 0\.\.\d+ of the downloaded"),
    ({"index_value": -5}, r"the PLC reports setpoint -5 while moving"),
])
def test_garbage_status_mid_motion_stops(cell, start, plc, faults, message):
    plc.faults.garbage_at = 0.3
    for key, value in faults.items():
        setattr(plc.faults, key, value)
    with _robot(cell) as robot, pytest.raises(RobotFault, match=message) as info:
        robot.execute(_trajectory(cell, start))
        assert False, "no fault"  # noqa: B011 (a settled report would end here)
    assert info.value.kind == "measurement" and "\n" not in info.value.one_line()
    assert "the robot was stopped (confirmed by the PLC after" in info.value.one_line()
    assert plc.get("stop", "B")[0] == 1 and plc.event("stopped by stop") is not None
    assert plc.event("done") is None


def test_huge_error_id_is_one_line(cell, start, plc):
    plc.faults.fault_at, plc.faults.error_id = 0.3, 0xFFFFFFFF
    with _robot(cell) as robot, pytest.raises(RobotFault) as info:
        robot.execute(_trajectory(cell, start))
    text = info.value.one_line()
    assert info.value.kind == "plc_fault" and info.value.code == 0xFFFFFFFF and info.value.stopped
    assert "fault 4294967295 (0xFFFFFFFF: unknown error code)" in text and "\n" not in text


# --------------------------------------------------------------------- settling
def test_robot_that_never_settles_is_stopped(cell, start, plc):
    """The drive holds the last axis 0.01 rad off the goal (inside the tracking bound, outside
    the settle tolerance): no report comes back, the robot is stopped, the joint is named."""
    plc.faults.settle_offset = 0.01
    config = replace(FAST, settle_timeout=0.3)
    t0 = time.monotonic()
    with _robot(cell, config) as robot, pytest.raises(RobotFault) as info:
        robot.execute(_trajectory(cell, start))
        assert False, "no fault"  # noqa: B011
    text = info.value.one_line()
    assert info.value.kind == "settle" and info.value.joint == "arm_joint_7" and info.value.stopped
    assert info.value.value == pytest.approx(0.01, abs=1e-3) and info.value.bound == 2e-4
    assert "the robot did not settle at the goal within 0.3 s (final error arm_joint_7 0.01 rad (tolerance " \
           "0.0002)); no scan was taken; the robot was stopped (confirmed by the PLC after" in text
    assert plc.get("stop", "B")[0] == 1 and time.monotonic() - t0 < 3.0


def test_drive_that_swings_through_the_goal_is_not_settled(cell, start, plc):
    """At the goal the last axis oscillates around it (amplitude 10 x the tolerance, a 10 s
    period in the stand-in's robot time, about 1 s of wall time): it passes through the
    tolerance for several polls at a time, but it never comes to rest there, so no report comes
    back: a settle fault naming the joint, the robot stopped."""
    plc.faults.oscillate = (0.002, 10.0)
    config = replace(FAST, settle_timeout=1.0)
    with _robot(cell, config) as robot, pytest.raises(RobotFault) as info:
        robot.execute(_trajectory(cell, start))
        assert False, "no fault: an oscillating axis was taken for settled"  # noqa: B011
    text = info.value.one_line()
    assert info.value.kind == "settle" and info.value.joint == "arm_joint_7" and info.value.stopped, text
    assert "the robot did not settle at the goal within 1 s (" in text and "no scan was taken" in text, text
    assert plc.get("stop", "B")[0] == 1
