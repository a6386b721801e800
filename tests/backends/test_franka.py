"""The Franka adapter end to end through pylibfranka (the real client library) against
franka-sim on 127.0.0.1 (a MuJoCo server speaking libfranka's robot protocol, checking the
FCI's motion limits), fed the FR3 cell's own description: a planned trajectory executes and
the measured joints match the plan; a trajectory over a limit is refused with nothing sent;
a control error, connection loss (the stand-in killed mid-motion) and Ctrl-C stop the motion;
`recon station check`, `recon run --station` and `recon autoscan --station` with scans,
registration and mesh; faults mid-run keep the completed scans."""

from __future__ import annotations

import dataclasses
import json
import os
import signal
import threading
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pylibfranka", reason="the Franka adapter needs pylibfranka (pip install 'recon-scan[franka]')")

from recon_cli.backends.hardware.franka import FrankaRobot  # noqa: E402
from recon_cli.backends.hardware.franka_config import FrankaConfig  # noqa: E402
from recon_cli.backends.sim.franka_standin import (  # noqa: E402
    FrankaStandin,
    _port_open,
    standin_venv,
    start_standin,
)
from recon_cli.cli import main  # noqa: E402
from recon_cli.errors import InputError, RobotFault  # noqa: E402
from recon_cli.paths import CELLS_DIR, ROBOT_DIR  # noqa: E402
from recon_cli.planning.trajectory import Trajectory, parameterize  # noqa: E402
from recon_cli.robot.cell import Cell  # noqa: E402
from recon_cli.robot.description import CellConfig, CellName  # noqa: E402

if standin_venv() is None:
    pytest.skip("franka-sim's environment is not built (bash install.sh --franka-sim)", allow_module_level=True)

CONFIG = FrankaConfig(ip="127.0.0.1", realtime="ignore")
HOME = np.radians([0.0, -10.0, 0.0, -130.0, 0.0, 110.0, 0.0])


@pytest.fixture(scope="module")
def fr3() -> Cell:
    return Cell(CellConfig(kind=CellName.parse("fr3")))


@pytest.fixture()
def standin(fr3):
    """franka-sim for one test; after it, also when it failed, the stand-in's processes are
    gone and its port refuses connections (stop() waits for both, a ReconError otherwise)."""
    s = start_standin(fr3.config)
    try:
        yield s
    finally:
        print(f"franka-sim's log (the end):\n{s.log_tail(60)}")  # captured: shown when the test failed
        s.stop()
    assert not s.alive() and not _port_open(s.host, s.port), "franka-sim outlived its test"


def moves(s: FrankaStandin) -> int:
    """Motions the stand-in has started (its log's lines)."""
    return s.log_path.read_text(errors="replace").count("Motion started with ID")


def _plan(cell: Cell, start: np.ndarray, goal: np.ndarray, scale: float = 0.3) -> Trajectory:
    lim = cell.kin.limits
    return parameterize(np.array([start, goal]), lim.velocity, lim.acceleration, scale, scale)


def _when(condition, action, timeout: float = 120.0) -> threading.Thread:
    def watch():
        deadline = time.monotonic() + timeout
        while not condition():
            if time.monotonic() > deadline:
                return
            time.sleep(0.005)
        action()

    thread = threading.Thread(target=watch, daemon=True)
    thread.start()
    return thread


def interrupted_operator(monkeypatch) -> list[str]:
    """The operator answers the prompt with Ctrl-C; the prompts asked."""
    asked: list[str] = []

    def operator(prompt: str = "") -> str:
        asked.append(prompt)
        raise KeyboardInterrupt

    monkeypatch.setattr("builtins.input", operator)
    return asked


# --------------------------------------------------------------------- the adapter
def test_planned_trajectory_executes_and_measured_joints_match(fr3, standin):
    robot = FrankaRobot(CONFIG, fr3.joint_names, fr3.kin.limits)
    start = robot.measured_joints()
    assert np.allclose(start, HOME, atol=3e-3)  # the stand-in starts at the cell's home
    goal = HOME + np.radians([25.0, 8.0, -15.0, 12.0, 30.0, -15.0, 45.0])
    traj = _plan(fr3, start, goal)
    report = robot.execute(traj)
    q = robot.measured_joints()
    assert report.settled and np.all(report.final_error <= CONFIG.settle_tolerance)
    assert np.abs(q - goal).max() <= CONFIG.settle_tolerance
    assert np.all(report.max_tracking_error < 0.02)
    assert report.duration == pytest.approx(traj.duration, abs=0.02)
    assert moves(standin) == 1 and robot.errors() == []
    robot.close()


def test_connecting_and_moving_leave_the_callers_scheduling_as_it_was(fr3, standin):
    """libfranka's Robot constructor moves its calling thread to real-time FIFO 99 (where the
    system permits it, also with realtime: ignore) and leaves it there: recon's thread would
    then render, plan and register at FIFO 99, starving the machine, and pass the policy on
    to every thread and process it starts. Only the 1 kHz loop runs real-time."""
    before = (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority)
    robot = FrankaRobot(CONFIG, fr3.joint_names, fr3.kin.limits)
    assert (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority) == before
    # another thread of the process: real-time below the loop while it runs (it may hold the
    # interpreter lock the loop needs), as before afterwards
    seen: set[int] = set()
    done = threading.Event()

    def watch() -> None:
        while not done.is_set():
            seen.add(os.sched_getscheduler(0))
            time.sleep(0.002)
        seen.add(-1)
        seen.add(os.sched_getscheduler(0) + 100)  # after the motion

    watcher = threading.Thread(target=watch, daemon=True)
    watcher.start()
    start = robot.measured_joints()
    robot.execute(_plan(fr3, start, start + np.radians([5.0, 0, 0, 0, 0, 0, 5.0])))
    assert (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority) == before
    done.set()
    watcher.join()
    if before[0] == os.SCHED_OTHER and os.sched_get_priority_max(os.SCHED_FIFO) > 0:
        assert os.SCHED_RR in seen or os.SCHED_OTHER in seen  # RR where the system permits it
    assert os.SCHED_OTHER + 100 in seen, seen  # restored after the motion
    robot.close()


def test_the_standins_arm_at_rest_stays_where_it_stands(fr3, standin):
    """The stand-in's position servo is stable on the cell's arm (its damping bounded by the
    arm's inertia, servo_damping_bound): at rest no joint moves by 10 µrad in a second. (With
    franka-sim's own wrist gains the wrist rang at its torque limit and drifted 2 mrad.)"""
    robot = FrankaRobot(CONFIG, fr3.joint_names, fr3.kin.limits)
    first = robot.measured_joints()
    worst = 0.0
    for _ in range(20):
        time.sleep(0.05)
        worst = max(worst, float(np.abs(robot.measured_joints() - first).max()))
    assert worst < 1e-5
    robot.close()


def test_fast_moves_end_at_the_goal_not_where_the_arm_lagged(fr3, standin):
    """Faster moves (0.6 of the velocity and acceleration limits; the wrist lags its command by
    up to about the settle tolerance at the end of the stream) end at the goal: the motion is
    finished only once the arm has settled there (the controller holds whatever pose the arm
    has when a motion finishes). (At the full scales a lost cycle has no margin left: the
    controller answers with a reflex.)"""
    robot = FrankaRobot(CONFIG, fr3.joint_names, fr3.kin.limits)
    lim = fr3.kin.limits
    for k, delta in enumerate(([0, 0, 0, 0, 40.0, -30.0, 80.0], [10.0, 5.0, -10.0, 8.0, -40.0, 30.0, -80.0])):
        start = robot.measured_joints()
        goal = HOME + np.radians(delta)
        traj = parameterize(np.array([start, goal]), lim.velocity, lim.acceleration, 0.6, 0.6)
        report = robot.execute(traj)
        assert report.settled and np.all(report.final_error <= CONFIG.settle_tolerance)
        time.sleep(0.3)
        q = robot.measured_joints()
        assert np.abs(q - goal).max() <= CONFIG.settle_tolerance, k
    robot.close()


def test_over_velocity_limit_is_refused_with_nothing_sent(fr3, standin):
    robot = FrankaRobot(CONFIG, fr3.joint_names, fr3.kin.limits)
    start = robot.measured_joints()
    traj = _plan(fr3, start, start + np.radians([90.0, 0, 0, 0, 0, 0, 0]), 1.0)
    fast = Trajectory(traj.times / 1.5, traj.q, traj.qd * 1.5, traj.qdd * 2.25)  # 1.5 x the velocity limit
    with pytest.raises(RobotFault) as info:
        robot.execute(fast)
    assert info.value.kind == "limit" and info.value.joint == "fr3_joint1" and not info.value.stopped
    assert "beyond its limit 2.62 rad/s; nothing was sent" in info.value.message
    time.sleep(0.2)
    assert moves(standin) == 0 and np.allclose(robot.measured_joints(), start, atol=1e-3)
    robot.close()


def test_control_error_stops_with_its_flags_and_recovery_only_when_asked(fr3, standin):
    """A careless cell file (acceleration and jerk limits far above the FR3's) lets a
    trajectory through recon's check; the controller aborts it with its reflex, recon reports
    the error flags, and the error stays until recover() is asked for."""
    careless = dataclasses.replace(fr3.kin.limits, acceleration=fr3.kin.limits.acceleration * 30,
                                   jerk=fr3.kin.limits.jerk * 30)
    robot = FrankaRobot(CONFIG, fr3.joint_names, careless)
    start = robot.measured_joints()
    # 30 rad/s^2: three times the FR3's acceleration limit, a tenth of the careless one
    traj = parameterize(np.array([start, start + np.radians([30.0, 0, 0, 0, 0, 0, 0])]), careless.velocity,
                        careless.acceleration, 1.0, 0.1)
    with pytest.raises(RobotFault) as info:
        robot.execute(traj)
    e = info.value
    assert e.kind == "control" and e.stopped
    assert e.message.startswith("the Franka controller aborted the motion: Move command aborted")
    assert "recon station recover" in (e.hint or "")
    flags = robot.errors()  # not cleared by itself
    assert len(flags) == 1 and flags[0] in e.message
    assert flags[0] in ("joint_motion_generator_velocity_discontinuity",  # acceleration over the limit
                        "joint_motion_generator_acceleration_discontinuity")  # jerk over the limit
    assert robot.recover() == flags and robot.errors() == []
    robot.close()


def test_connection_loss_mid_motion_is_a_fault_within_two_seconds(fr3, standin):
    robot = FrankaRobot(CONFIG, fr3.joint_names, fr3.kin.limits)
    start = robot.measured_joints()
    traj = _plan(fr3, start, HOME + np.radians([40.0, 0, 0, 0, 0, 0, 0]), 0.15)
    _when(lambda: moves(standin) == 1, lambda: (time.sleep(0.3), standin.kill()))
    t0 = time.monotonic()
    with pytest.raises(RobotFault) as info:
        robot.execute(traj)
    assert time.monotonic() - t0 < traj.duration
    e = info.value
    assert e.kind == "connection" and not e.stopped
    assert e.message.startswith("lost the connection to the Franka controller at 127.0.0.1 in a motion")
    robot.close()


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_signal_mid_motion_stops_the_robot_first(fr3, standin, signum):
    from recon_cli.interrupts import stop_signals

    robot = FrankaRobot(CONFIG, fr3.joint_names, fr3.kin.limits)
    start = robot.measured_joints()
    goal = HOME + np.radians([40.0, 0, 0, 0, 0, 0, 0])
    traj = _plan(fr3, start, goal, 0.15)
    _when(lambda: moves(standin) == 1, lambda: (time.sleep(0.5), os.kill(os.getpid(), signum)))
    with stop_signals(), pytest.raises(KeyboardInterrupt):
        robot.execute(traj)
    assert "Handling StopMove command" in standin.log_path.read_text()
    a = robot.measured_joints()
    time.sleep(0.3)
    b = robot.measured_joints()
    assert np.abs(a - b).max() < 2e-3  # at rest ...
    assert np.abs(b - goal).max() > 0.1  # ... short of the goal
    robot.close()


def test_unreachable_controller_and_config_mistakes_are_one_line(fr3):
    with pytest.raises(RobotFault) as info:
        FrankaRobot(FrankaConfig(ip="127.0.0.9", realtime="ignore"), fr3.joint_names, fr3.kin.limits)
    assert info.value.kind == "connection" and not info.value.stopped
    assert info.value.message.startswith("cannot reach the Franka controller at 127.0.0.9")
    with pytest.raises(InputError, match="robot.franka.tracking_bound"):
        FrankaConfig.from_mapping({"ip": "127.0.0.1", "tracking_bound": 5.0})
    with pytest.raises(InputError, match="robot.franka has no ip"):
        FrankaConfig.from_mapping({})
    with pytest.raises(InputError, match="robot.franka.realtime"):
        FrankaConfig.from_mapping({"ip": "127.0.0.1", "realtime": "off"})
    with pytest.raises(InputError, match="robot.franka.lost_cycles"):
        FrankaConfig.from_mapping({"ip": "127.0.0.1", "lost_cycles": 9})  # the check stays at the limit


def _nothing_flagged(robot: FrankaRobot, standin: FrankaStandin) -> None:
    """The controller reports no error and franka-sim logged no limit violation; the robot
    is closed."""
    assert robot.errors() == []
    assert "motion limit violated" not in standin.log_path.read_text()
    robot.close()


class _Stalling:
    """pylibfranka's own ActiveControl, with the calling thread put to sleep before chosen
    reads and writes: a loop descheduled for milliseconds, as on a loaded machine without a
    real-time kernel (the controller extrapolates the cycles it does not hear from it)."""

    def __init__(self, control, stalls: dict[int, tuple[str, float]]) -> None:
        self._control, self._stalls, self._reads = control, stalls, 0

    def readOnce(self):  # noqa: N802 (libfranka's name)
        self._reads += 1
        if self._stalls.get(self._reads, ("", 0.0))[0] == "read":
            time.sleep(self._stalls[self._reads][1])
        return self._control.readOnce()

    def writeOnce(self, command):  # noqa: N802
        if self._stalls.get(self._reads, ("", 0.0))[0] == "write":
            time.sleep(self._stalls[self._reads][1])
        return self._control.writeOnce(command)


class _StallingRobot:
    """A pylibfranka Robot whose motions stall (:class:`_Stalling`) as ``plans`` say."""

    def __init__(self, robot, plans) -> None:
        self._robot, self._plans = robot, iter(plans)

    def __getattr__(self, name: str):
        return getattr(self._robot, name)

    def start_joint_position_control(self, mode):
        return _Stalling(self._robot.start_joint_position_control(mode), next(self._plans))


def test_a_loop_that_stalls_for_milliseconds_resumes_within_the_limits(fr3, standin):
    """The loop descheduled for 1.5-8 ms, before a read (it then reads a state several cycles
    on) and between a read and its answer (the answer arrives late, after the controller has
    extrapolated the cycle), three times a motion, at 0.6 of the velocity and acceleration
    limits: every motion completes at its goal, the controller flags nothing, the stalls are
    counted as lost cycles. (Jumping back onto the stream after such a gap was a jerk and
    acceleration reflex in about every second motion.)"""
    rng = np.random.default_rng(7)
    plans = [{int(k): (str(kind), float(ms) / 1000.0)
              for k, kind, ms in zip(rng.choice(np.arange(20, 500), 3, replace=False),
                                     rng.choice(["read", "write"], 3), rng.choice([1.5, 3.0, 5.0, 8.0], 3),
                                     strict=True)}
             for _ in range(6)]
    robot = FrankaRobot(CONFIG, fr3.joint_names, fr3.kin.limits)
    robot.robot = _StallingRobot(robot.robot, plans)
    lim = fr3.kin.limits
    far = HOME + np.radians([25.0, 8.0, -15.0, 12.0, 30.0, -15.0, 45.0])
    for k in range(len(plans)):
        goal = far if k % 2 == 0 else HOME
        traj = parameterize(np.array([robot.measured_joints(), goal]), lim.velocity, lim.acceleration, 0.6, 0.6)
        report = robot.execute(traj)
        assert report.settled and np.all(report.final_error <= CONFIG.settle_tolerance)
        assert np.abs(robot.measured_joints() - goal).max() <= CONFIG.settle_tolerance
        assert report.lost_cycles >= 3
    _nothing_flagged(robot, standin)


def test_the_first_resumption_of_a_process_answers_in_time(fr3, standin):
    """The resumption's blend tables are made before the 1 kHz loop starts: made at the
    first resumption (about 5 ms) they made its answer late, and the controller then saw a
    jerk above its limit (6 of 8 fresh processes with these two stalls early in their
    first motion)."""
    from recon_cli.backends.hardware import resume

    resume._blends.cache_clear()
    robot = FrankaRobot(CONFIG, fr3.joint_names, fr3.kin.limits)
    robot.robot = _StallingRobot(robot.robot, [{7: ("write", 0.0025), 11: ("read", 0.0073)}])
    lim = fr3.kin.limits
    far = HOME + np.radians([25.0, 8.0, -15.0, 12.0, 30.0, -15.0, 45.0])
    traj = parameterize(np.array([robot.measured_joints(), far]), lim.velocity, lim.acceleration, 0.6, 0.6)
    report = robot.execute(traj)
    assert report.settled and report.lost_cycles >= 2
    _nothing_flagged(robot, standin)


@pytest.mark.parametrize("stalls", [
    {4: ("write", 0.0040), 7: ("write", 0.0009)},
    {3: ("write", 0.0045), 4: ("write", 0.0020), 7: ("read", 0.0012)}], ids=["late-twice", "late-then-read"])
def test_late_answers_in_the_first_cycles_of_a_slow_motion(fr3, standin, stalls):
    """Answers a few milliseconds late in a slow motion's first cycles, where the arm is
    nearly at rest (joint 1 by 40 degrees at 0.15 of the limits): every motion completes and
    franka-sim flags nothing. Two ways this was a jerk reflex: a late answer reached
    franka-sim after it had published the next state, and it applied that answer after the
    loop had answered the state from a reference that did not contain it (the loop now waits
    for a state that continues its last command); and walking a reference back near rest,
    the chain turned around and passed within the match tolerance of the late answer a
    second time, three cycles too old (a match now needs the answer's predecessors on the
    chain too, within a 32-bit float's precision)."""
    robot = FrankaRobot(CONFIG, fr3.joint_names, fr3.kin.limits)
    robot.robot = _StallingRobot(robot.robot, [stalls] * 4)
    lim = fr3.kin.limits
    far = HOME + np.radians([40.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    for k in range(4):
        goal = far if k % 2 == 0 else HOME
        traj = parameterize(np.array([robot.measured_joints(), goal]), lim.velocity, lim.acceleration, 0.15, 0.15)
        report = robot.execute(traj)
        assert report.settled and report.lost_cycles >= 2
    _nothing_flagged(robot, standin)


class _Garbling(_Stalling):
    """As :class:`_Stalling`, and from the stalled read on, every state reports ``dq_d`` of
    the third joint as NaN (a controller's reference gone wrong)."""

    def readOnce(self):  # noqa: N802
        state, period = super().readOnce()
        if self._reads < min(self._stalls):
            return state, period
        return _GarbledState(state), period


class _GarbledState:
    def __init__(self, state) -> None:
        self._state = state

    def __getattr__(self, name: str):
        value = getattr(self._state, name)
        if name == "dq_d":
            value = list(value)
            value[2] = float("nan")
        return value


class _GarblingRobot(_StallingRobot):
    def start_joint_position_control(self, mode):
        return _Garbling(self._robot.start_joint_position_control(mode), next(self._plans))


def test_a_reference_that_is_not_finite_after_a_gap_stops_the_robot_in_one_line(fr3, standin):
    """After missed cycles the loop answers from the controller's reported reference; a
    reference with a NaN in it is a one-line measurement fault that stops the robot, not
    libfranka's ValueError as a traceback."""
    robot = FrankaRobot(CONFIG, fr3.joint_names, fr3.kin.limits)
    robot.robot = _GarblingRobot(robot.robot, [{40: ("read", 0.005)}])
    lim = fr3.kin.limits
    goal = HOME + np.radians([10.0, 0.0, 0.0, 0.0, 0.0, 0.0, 10.0])
    traj = parameterize(np.array([robot.measured_joints(), goal]), lim.velocity, lim.acceleration, 0.3, 0.3)
    with pytest.raises(RobotFault) as info:
        robot.execute(traj)
    fault = info.value
    assert fault.kind == "measurement" and fault.stopped
    assert "\n" not in fault.message
    assert "its reference dq_d of joint 3 is nan" in fault.message
    assert robot.errors() == []
    robot.close()


# --------------------------------------------------------------------- station files and runs
STATION = """\
format: 1
name: FR3 stand-in
cell: {{kind: {cell}}}
robot:
  adapter: franka
  franka: {{ip: 127.0.0.1, realtime: ignore}}
camera:
  adapter: sim
  sim: {{noise: true, resolution: 0.5}}
"""

SCRIPT = """\
<?xml version="1.0"?>
<recon name="FR3 stand-in: three views" on_failure="skip">
  <cell kind="fr3" backend="hardware"/>
  <object name="bottle"/>
  <planner name="RRTConnect" time="5" velocity_scale="{speed1}" acceleration_scale="{accel1}"/>
  <move focus="0.1925 0.1225 0.08" radius="0.22" theta="50" phi="170" frame="marker"/>
  <scan name="a"/>
  <planner name="RRTConnect" time="5" velocity_scale="0.3" acceleration_scale="{accel2}"/>
  <move focus="0.1925 0.1225 0.08" radius="0.22" theta="50" phi="230" frame="marker"/>
  <scan name="b"/>
  <move focus="0.1925 0.1225 0.08" radius="0.22" theta="35" phi="300" frame="marker"/>
  <scan name="c"/>
  <register/>
  <reconstruct voxel="0.002" depth="7"/>
  <export mesh="mesh.ply"/>
</recon>
"""


def _files(tmp_path: Path, cell: str = "fr3", speed1: float = 0.3, accel1: float = 0.3,
           accel2: float = 0.3) -> tuple[Path, Path]:
    (tmp_path / "station.yaml").write_text(STATION.format(cell=cell))
    (tmp_path / "scan.xml").write_text(SCRIPT.format(speed1=speed1, accel1=accel1, accel2=accel2))
    return tmp_path / "station.yaml", tmp_path / "scan.xml"


def _careless_cell(tmp_path: Path) -> str:
    """The FR3 cell with a limits file whose accelerations and jerks are 30 times
    the FR3's: recon's own check passes what the controller refuses."""
    text = (CELLS_DIR / "fr3.yaml").read_text().replace("../robot/", "")  # found in recon's robot/
    limits = (ROBOT_DIR / "fr3" / "limits.yaml").read_text()
    limits = limits.replace("acceleration: 572.9578", "acceleration: 17188.734").replace(
        "jerk: 286478.8976", "jerk: 8594366.93")
    (tmp_path / "careless_limits.yaml").write_text(limits)
    text = text.replace("limits: fr3/limits.yaml", "limits: careless_limits.yaml")
    (tmp_path / "careless_fr3.yaml").write_text(text)
    return "careless_fr3.yaml"


def _scans(out: Path) -> list[str]:
    return [json.loads(s.read_text())["name"] for s in sorted((out / "scans").glob("scan_*/scan.json"))]


def test_station_check_reads_the_joints_and_a_frame(standin, tmp_path, capsys):
    station, _ = _files(tmp_path)
    assert main(["station", "check", str(station)]) == 0
    out = capsys.readouterr().out
    assert "robot franka, camera sim, cell fr3, backend hardware" in out
    assert "fr3_joint4 -130.0" in out and "station ok" in out


def test_joint_offsets_of_a_station_file_make_the_robots_joints_true_joints(fr3, standin, tmp_path, capsys):
    """A station file's joint zero offsets: recon reads the joints franka-sim reports plus the
    offsets and sends a trajectory planned in those joints minus them, so the arm ends where
    the encoders read the goal minus the offsets."""
    from recon_cli.backends.hardware.station import AdapterStation
    from recon_cli.backends.station_file import load_station

    station, _ = _files(tmp_path)
    station.write_text(station.read_text() + "joint_offsets: [0, 0, 0.5, 0, -0.5, 0, 0]\n")
    assert main(["station", "check", str(station)]) == 0
    out = capsys.readouterr().out
    assert "fr3_joint3 0.5" in out and "fr3_joint5 -0.5" in out and "fr3_joint4 -130.0" in out
    offsets = np.radians([0, 0, 0.5, 0, -0.5, 0, 0])
    raw = FrankaRobot(CONFIG, fr3.joint_names, fr3.kin.limits)
    reported = raw.measured_joints()
    raw.close()
    with AdapterStation(load_station(station), fr3, None, HOME, np.random.default_rng(0)) as st:
        start = st.robot.measured_joints()
        assert np.allclose(start, reported + offsets, atol=1e-4)
        goal = start + np.radians([10.0, 0.0, -5.0, 5.0, 10.0, 0.0, 10.0])
        st.robot.execute(_plan(fr3, start, goal))
        assert np.abs(st.robot.measured_joints() - goal).max() <= CONFIG.settle_tolerance
    raw = FrankaRobot(CONFIG, fr3.joint_names, fr3.kin.limits)
    assert np.abs(raw.measured_joints() - (goal - offsets)).max() <= CONFIG.settle_tolerance
    _nothing_flagged(raw, standin)


def test_station_check_of_an_unreachable_franka_is_one_line(tmp_path, capsys):
    station, _ = _files(tmp_path)
    station.write_text(station.read_text().replace("127.0.0.1", "127.0.0.9"))
    assert main(["station", "check", str(station)]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("error: cannot reach the Franka controller at 127.0.0.9")


def test_run_with_station_three_moves_scans_registration_mesh(standin, tmp_path, capsys):
    station, script = _files(tmp_path)
    out = tmp_path / "run"
    code = main(["run", str(script), "--out", str(out), "--station", str(station)])
    text = capsys.readouterr()
    assert code == 0, text.out + text.err + standin.log_tail()
    assert moves(standin) == 3
    assert _scans(out) == ["a", "b", "c"]
    session = json.loads((out / "scans" / "session.json").read_text())
    assert session["backend"] == "hardware" and not (out / "scans" / "ground_truth").exists()
    registration = json.loads((out / "reconstruction" / "report.json").read_text())
    assert registration["scans_registered"] == 3 and registration["scans_skipped"] == 0
    assert (out / "mesh.ply").stat().st_size > 10_000
    report = json.loads((out / "run_report.json").read_text())
    assert report["status"] == "done" and report["backend"] == "hardware"
    # each scan records the joints the controller measured when it was taken
    last = np.array(list(json.loads(sorted((out / "scans").glob("scan_*/scan.json"))[-1].read_text())["joints"]
                         .values()))
    robot = FrankaRobot(CONFIG, Cell(CellConfig(kind=CellName.parse("fr3"))).joint_names,
                        Cell(CellConfig(kind=CellName.parse("fr3"))).kin.limits)
    assert np.abs(robot.measured_joints() - last).max() < 2e-3
    robot.close()
    # the same robot with the replay camera playing the run's scans back
    replay = tmp_path / "replay.yaml"
    replay.write_text(STATION.format(cell="fr3").split("camera:")[0]
                      + f"camera:\n  adapter: replay\n  replay: {{source: {out / 'scans'}}}\n")
    assert main(["station", "check", str(replay)]) == 0
    text = capsys.readouterr().out
    assert "robot franka, camera replay" in text and "frame: 640 x 360 px" in text and "station ok" in text


def test_control_error_mid_run_stops_and_keeps_the_scans(standin, tmp_path, capsys):
    cell = _careless_cell(tmp_path)
    # the first move slow and gentle (within what the FR3 takes), the second at 30 % of the careless accelerations
    station, script = _files(tmp_path, cell=cell, speed1=0.05, accel1=0.01, accel2=0.3)
    out = tmp_path / "run"
    code = main(["run", str(script), "--out", str(out), "--station", str(station)])
    err = capsys.readouterr().err
    assert code == 4 and err.count("\n") == 1 and "Traceback" not in err, err
    assert "the Franka controller aborted the motion" in err and "joint_motion_generator_" in err
    assert _scans(out) == ["a"]
    report = json.loads((out / "run_report.json").read_text())
    assert report["status"] == "aborted" and "aborted the motion" in report["aborted"]
    # recovery when asked (franka-sim forgets a motion's errors when its client reconnects; the
    # adapter test above shows they stay over one connection until recover())
    assert main(["station", "recover", str(station)]) == 0
    assert "the franka robot's errors cleared" in capsys.readouterr().out


def test_standin_killed_mid_run_stops_and_keeps_the_scans(standin, tmp_path, capsys):
    station, script = _files(tmp_path)
    out = tmp_path / "run"
    _when(lambda: moves(standin) == 2, lambda: (time.sleep(0.3), standin.kill()))
    code = main(["run", str(script), "--out", str(out), "--station", str(station)])
    err = capsys.readouterr().err
    assert code == 4 and err.count("\n") == 1 and "Traceback" not in err, err
    assert "lost the connection to the Franka controller at 127.0.0.1 in a motion" in err
    assert _scans(out) == ["a"]
    assert json.loads((out / "run_report.json").read_text())["status"] == "aborted"


def test_autoscan_with_station(standin, tmp_path, capsys):
    station, _ = _files(tmp_path)
    out = tmp_path / "auto"
    code = main(["autoscan", "--station", str(station), "--object", "bottle", "--n", "3", "--no-pictures",
                 "--out", str(out)])
    text = capsys.readouterr()
    assert code == 0, text.out + text.err + standin.log_tail()
    assert moves(standin) == 3 and len(list(out.glob("scan_*/scan.json"))) == 3
    assert (out / "reconstruction" / "mesh.ply").stat().st_size > 10_000
    report = json.loads((out / "autoscan_report.json").read_text())
    assert report["scans"] == 3 and report["error"] is None and report["cell"] == "fr3"


def test_two_sided_autoscan_on_a_real_cell_asks_the_operator_and_ctrl_c_keeps_side_1(standin, tmp_path, capsys,
                                                                                    monkeypatch):
    """On a real cell the robot parks at its home posture and the operator is asked to turn
    the object over; Ctrl-C at that prompt ends the run with exit 130 and keeps side 1."""
    station, _ = _files(tmp_path)
    asked = interrupted_operator(monkeypatch)
    out = tmp_path / "two"
    code = main(["autoscan", "--sides", "2", "--station", str(station), "--object", "bottle", "--n", "3",
                 "--no-pictures", "--out", str(out)])
    text = capsys.readouterr()
    assert code == 130, text.out + text.err + standin.log_tail(60)
    assert len(asked) == 1 and "turn the object over" in text.out and "press Enter" in text.out
    assert "interrupted; kept: side 1 (3 scans" in text.out
    assert len(list((out / "side_1").glob("scan_*/scan.json"))) == 3 and not (out / "side_2").exists()
    assert (out / "side_1" / "reconstruction" / "cloud.ply").exists()  # side 1 registered
    # the robot waited at the cell's home posture
    robot = FrankaRobot(CONFIG, Cell(CellConfig(kind=CellName.parse("fr3"))).joint_names,
                        Cell(CellConfig(kind=CellName.parse("fr3"))).kin.limits)
    assert np.abs(robot.measured_joints() - HOME).max() < 0.01
    robot.close()


TWO_SIDED_SCRIPT = """\
<?xml version="1.0"?>
<recon name="FR3 stand-in: two sides" on_failure="skip">
  <cell kind="fr3" backend="hardware"/>
  <object name="bottle"/>
  <move focus="0.1925 0.1225 0.08" radius="0.22" theta="50" phi="170" frame="marker"/>
  <scan name="a"/>
  <move focus="0.1925 0.1225 0.08" radius="0.22" theta="50" phi="230" frame="marker"/>
  <scan name="b"/>
  <turn_over/>
  <move focus="0.1925 0.1225 0.08" radius="0.22" theta="50" phi="170" frame="marker"/>
  <scan name="c"/>
</recon>
"""


def test_a_script_turn_on_a_real_cell_asks_the_operator_and_ctrl_c_keeps_side_1(standin, tmp_path, capsys,
                                                                                 monkeypatch):
    """A script's <turn_over/> on a real cell parks the robot at its home posture and asks the
    operator; Ctrl-C at that prompt ends the run with exit 130 and keeps side 1's scans."""
    station, _ = _files(tmp_path)
    script = tmp_path / "two.xml"
    script.write_text(TWO_SIDED_SCRIPT)
    asked = interrupted_operator(monkeypatch)
    out = tmp_path / "run"
    code = main(["run", str(script), "--out", str(out), "--station", str(station)])
    text = capsys.readouterr()
    assert code == 130, text.out + text.err + standin.log_tail(60)
    assert len(asked) == 1 and "turn the object over" in text.out and "press Enter" in text.out
    lines = text.err.strip().splitlines()
    assert len(lines) == 1 and "during two.xml:9 (turn the object over" in lines[0], text.err
    assert f"2 completed scan(s) kept in {out / 'side_1' / 'scans'}" in lines[0]
    assert [json.loads(s.read_text())["name"] for s in sorted((out / "side_1" / "scans").glob("scan_*/scan.json"))] \
        == ["a", "b"]
    assert not (out / "side_2").exists() and (out / "side_1" / "reconstruction" / "cloud.ply").exists()
    report = json.loads((out / "run_report.json").read_text())
    assert report["status"] == "interrupted" and report["exit_code"] == 130 and report["scans"] == 2
    assert report["commands"][-1]["status"] == "interrupted" and report["commands"][-1]["source"] == "two.xml:9"
    robot = FrankaRobot(CONFIG, Cell(CellConfig(kind=CellName.parse("fr3"))).joint_names,
                        Cell(CellConfig(kind=CellName.parse("fr3"))).kin.limits)
    assert np.abs(robot.measured_joints() - HOME).max() < 0.01  # it waited at the cell's home posture
    robot.close()
