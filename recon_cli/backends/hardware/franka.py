"""A Franka robot (FR3, Panda) over libfranka's own protocol, through pylibfranka.

recon streams the checked trajectory as joint positions at the controller's 1 kHz
(:mod:`recon_cli.backends.hardware.setpoint_stream`: smoothed to the jerk limit, every
finite difference within the cell's velocity, acceleration and jerk limits, refused before
anything is sent otherwise), in libfranka's ``readOnce``/``writeOnce`` loop with the joint
impedance controller, keeps commanding the goal until the robot has settled there, only then
finishes the motion, and reports the measured joints.

Faults stop the robot and raise :class:`~recon_cli.errors.RobotFault`, completed scans stay:
a control error or reflex of the controller (its error flags as text: the controller has
stopped the robot itself), connection loss (the controller stops a robot whose commands
stop: communication constraints), a tracking error over its bound, no completion in time,
a robot that does not settle, measured joints that are not numbers or outside the limits.
Ctrl-C and SIGTERM in a motion stop the robot before they propagate. The controller's error
state is cleared only when the user asks (``recon station recover``): a robot found in
reflex mode is refused with its errors.
"""

from __future__ import annotations

import collections
import contextlib
import gc
import os
import sys
import threading
import time
from collections.abc import Iterator
from typing import Any

import numpy as np

from recon_cli import install_hint
from recon_cli.backends.base import ExecutionReport
from recon_cli.backends.hardware.franka_config import REST_SPREAD, SETTLE_STATES, FrankaConfig
from recon_cli.backends.hardware.resume import RECENT, Reference, Resumption, applied_as, match_history
from recon_cli.backends.hardware.setpoint_stream import SetpointStream, jerk_share_for, setpoint_stream
from recon_cli.errors import HardwareUnavailable, InputError, RobotFault
from recon_cli.planning.trajectory import Trajectory
from recon_cli.robot.limits import JointLimits

#: the FCI's command rate
PERIOD = 0.001
#: longest hold of the interpreter lock by another thread during the 1 kHz loop [s]
SWITCH_INTERVAL = 0.0002
#: controller cycles of the loop's recent history a control fault reports lost cycles from
RECENT_CYCLES = 200
#: the blend of a resumption whose command is on its way (made once the command is out): no
#: offsets yet, and not the end of the motion
_BLEND_PENDING = np.zeros((0, 7))
#: a state not answered within this of reading it is left to the controller's extrapolation [s]
LATE_ANSWER = 0.0008
#: a read that returned within this had its state waiting: published before the read began [s]
WAITED = 0.0001
#: consecutive states after a gap left unanswered so that the next is answered at the start of its cycle:
#: one. Every state left unanswered is another cycle the controller extrapolates, and a controller
#: that applied a late command differences the resumed one over the whole gap since (franka-sim
#: does): its velocity is then the gap's mean, and the next command's acceleration is off by
#: half the gap times the motion's own: a discontinuity reflex in a fast motion when the gap is
#: several cycles long
MAX_SKIPS = 1
#: a state read this much later after its controller time than the quickest of the last
#: STAMP_WINDOW reads (since the last gap, or the last state the controller published late)
#: was waiting: its read was delayed (the thread descheduled, or another thread holding the
#: interpreter lock when the state arrived) [s]
STALE = 0.0004
STAMP_WINDOW = 32
#: how long a stop may take to bring the joints to rest before it counts as unconfirmed
STOP_BOUND = 2.0


#: real-time priorities while the 1 kHz loop runs: the loop's thread (FIFO) and the process's
#: other threads (round-robin, below a controller stand-in's 40 and above every normal process)
LOOP_PRIORITY = 80
OTHERS_PRIORITY = 30
_NORMAL = tuple(getattr(os, name) for name in ("SCHED_OTHER", "SCHED_BATCH", "SCHED_IDLE") if hasattr(os, name))


def _threads() -> set[int]:
    """The native ids of this process's threads."""
    try:
        return {int(t) for t in os.listdir("/proc/self/task")}
    except OSError:
        return set()


@contextlib.contextmanager
def realtime_priority() -> Iterator[bool]:
    """Run the calling thread under the real-time FIFO scheduler meanwhile, as libfranka does
    for its own control loop on a real-time kernel, and the process's other threads under
    round-robin below it (yields False where the system does not permit it: then the loop
    runs at normal priority and missed cycles are more likely).

    The loop needs Python's interpreter lock for every cycle. Another thread of the process
    (a progress bar's refresh, a recording, a test's watcher) that holds the lock when a
    normal process preempts it would keep the loop waiting for as long as that process runs:
    at a real-time priority of its own it is not preempted by normal processes and hands the
    lock over within the switch interval. Every thread's policy is restored afterwards; a
    thread started meanwhile is given the caller's former policy."""
    if not hasattr(os, "sched_setscheduler"):
        yield False
        return
    me = threading.get_native_id()
    try:
        policy, param = os.sched_getscheduler(0), os.sched_getparam(0)
        top = os.sched_get_priority_max(os.SCHED_FIFO)
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(min(LOOP_PRIORITY, top)))
    except OSError:
        yield False
        return
    before = _threads()
    saved: dict[int, tuple[int, os.sched_param]] = {}
    for tid in before - {me}:
        with contextlib.suppress(OSError):
            other = os.sched_getscheduler(tid)
            if other in _NORMAL:
                saved[tid] = (other, os.sched_getparam(tid))
                os.sched_setscheduler(tid, os.SCHED_RR, os.sched_param(min(OTHERS_PRIORITY, top)))
    try:
        yield True
    finally:
        with contextlib.suppress(OSError):
            os.sched_setscheduler(0, policy, param)
        for tid, (other, other_param) in saved.items():
            with contextlib.suppress(OSError):  # (a thread that ended meanwhile)
                os.sched_setscheduler(tid, other, other_param)
        for tid in _threads() - before:  # started meanwhile: they inherited a real-time policy
            with contextlib.suppress(OSError):
                if os.sched_getscheduler(tid) not in _NORMAL:
                    os.sched_setscheduler(tid, policy, param)


@contextlib.contextmanager
def scheduling_kept() -> Iterator[None]:
    """The calling thread's scheduling policy and priority as they were before, afterwards.

    libfranka's ``Robot`` constructor moves the thread that calls it to the real-time FIFO
    scheduler at the highest priority, where the system permits it, and leaves it there, for
    ``RealtimeConfig.kIgnore`` too. recon's thread then renders, plans and registers: at FIFO
    99 it starves every other process of its core, and every thread and process it starts
    inherits the policy. Only the 1 kHz loop runs real-time (:func:`realtime_priority`)."""
    if not hasattr(os, "sched_getscheduler"):
        yield
        return
    policy, param = os.sched_getscheduler(0), os.sched_getparam(0)
    try:
        yield
    finally:
        if (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority) != (policy, param.sched_priority):
            with contextlib.suppress(OSError):
                os.sched_setscheduler(0, policy, param)


def _spread(window: list[np.ndarray]) -> float:
    """Largest range of any joint over consecutive states [rad]."""
    w = np.asarray(window)
    return float(np.max(w.max(axis=0) - w.min(axis=0)))


def _pylibfranka():
    try:
        import pylibfranka
    except ImportError:
        raise HardwareUnavailable("the Franka robot adapter needs pylibfranka, which is not installed",
                                  hint=install_hint("franka")) from None
    return pylibfranka


def error_names(errors) -> list[str]:
    """The flags set in a libfranka ``Errors`` (e.g. ``joint_motion_generator_velocity_discontinuity``)."""
    if errors is None:
        return []
    return [name for name in dir(errors) if not name.startswith("_") and getattr(errors, name, False) is True]


def _library_text(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return text.removeprefix("libfranka: ") or type(exc).__name__


class FrankaRobot:
    """RobotBackend of a Franka arm's controller (FCI) over pylibfranka."""

    def __init__(self, config: FrankaConfig, joint_names: tuple[str, ...], limits: JointLimits,
                 refuse_reflex: bool = True) -> None:
        p = _pylibfranka()
        if len(joint_names) != 7:
            raise InputError(f"the franka adapter drives the 7 joints of a Franka arm; the cell plans "
                             f"{len(joint_names)}", hint="name a cell of a Franka arm (cells/fr3.yaml)")
        self._p = p
        self.config = config
        self.joint_names = tuple(joint_names)
        self.limits = limits
        self.lost_cycles = 0  # controller cycles the 1 kHz loop missed, over all motions
        # per state read: [controller cycles since the last one, of them not answered]
        self._recent: collections.deque[list[int]] = collections.deque(maxlen=RECENT_CYCLES)
        self._measured_lo = np.asarray(limits.lower, dtype=float) - config.tracking_bound
        self._measured_hi = np.asarray(limits.upper, dtype=float) + config.tracking_bound
        realtime = p.RealtimeConfig.kEnforce if config.realtime == "enforce" else p.RealtimeConfig.kIgnore
        self.robot: Any = None  # pylibfranka.Robot; None once closed
        try:
            with scheduling_kept():  # libfranka's constructor puts the calling thread under FIFO 99
                self.robot = p.Robot(config.ip, realtime)
            state = self.robot.read_once()
        except (p.FrankaException, RuntimeError) as exc:
            self.robot = None
            raise RobotFault(f"cannot reach the Franka controller at {config.ip} ({_library_text(exc)})",
                             kind="connection", stopped=False,
                             hint="check the address, the network and that FCI is activated in Desk") from None
        if refuse_reflex and state.robot_mode == p.RobotMode.Reflex:
            names = error_names(state.current_errors) or error_names(state.last_motion_errors)
            self.close()
            raise RobotFault(f"the Franka at {config.ip} is in reflex mode (errors: {', '.join(names) or 'none'}); "
                             "nothing was moved", kind="control", stopped=True,
                             hint="find the cause, then clear it with recon station recover STATION")
        self._checked(np.asarray(state.q, dtype=float))

    # ------------------------------------------------------------------ state
    def _state(self):
        p = self._p
        if self.robot is None:
            raise RobotFault("the connection to the Franka is closed", kind="connection", stopped=False)
        try:
            return self.robot.read_once()
        except (p.FrankaException, RuntimeError) as exc:
            raise self._lost(exc, moving=False) from None

    def _checked(self, q: np.ndarray, at: str = "") -> np.ndarray:
        if q.shape != (7,):
            raise RobotFault(f"the controller reports {q.size} joint positions, a Franka has 7{at}",
                             kind="measurement", stopped=False)
        bad = ~np.isfinite(q) | (q < self._measured_lo) | (q > self._measured_hi)
        if np.any(bad):
            j = int(np.flatnonzero(bad)[0])
            stopped = self._halt()
            raise RobotFault(f"the measured position of {self.joint_names[j]} is {q[j]:.4g} rad, outside its limits "
                             f"[{self.limits.lower[j]:.4f}, {self.limits.upper[j]:.4f}] rad widened by the tracking "
                             f"bound {self.config.tracking_bound:g} rad{at}; {self._stop_text(stopped)}",
                             kind="measurement", joint=self.joint_names[j], value=float(q[j]), stopped=stopped,
                             hint="check that the station's cell is this robot")
        return q

    def measured_joints(self) -> np.ndarray:
        """The measured joints [rad] (checked: finite, within the limits widened by the tracking bound)."""
        return self._checked(np.asarray(self._state().q, dtype=float))

    def errors(self) -> list[str]:
        """The controller's current error flags (empty when none)."""
        return error_names(self._state().current_errors)

    # ------------------------------------------------------------------ RobotBackend
    def stream(self, trajectory: Trajectory, commanded: np.ndarray | None = None) -> SetpointStream:
        """The trajectory as the checked 1 kHz setpoints, beginning at the controller's
        ``commanded`` joints (RobotFault before anything is sent)."""
        return setpoint_stream(trajectory, self.limits, self.joint_names, PERIOD,
                               jerk_share_for(self.config.lost_cycles), self.config.deviation_bound, start=commanded)

    def execute(self, trajectory: Trajectory) -> ExecutionReport:
        """Stream a checked trajectory at 1 kHz, then wait until the robot has settled at its
        goal; every fault, Ctrl-C and SIGTERM stops the robot before the exception leaves."""
        p = self._p
        state = self._state()
        start = self._checked(np.asarray(state.q, dtype=float))
        commanded = self._checked(np.asarray(state.q_d, dtype=float), " (its commanded joints)")
        err = np.maximum(np.abs(start - trajectory.start), np.abs(commanded - trajectory.start))
        if np.any(err > self.config.tracking_bound):
            j = int(np.argmax(err))
            raise RobotFault(f"the robot is not at the trajectory's start ({self.joint_names[j]} is {err[j]:.4f} rad "
                             "away); nothing was sent", kind="start", joint=self.joint_names[j], value=float(err[j]),
                             bound=self.config.tracking_bound, stopped=False, hint="plan from the measured joints")
        stream = self.stream(trajectory, commanded)
        lost = self.lost_cycles
        try:
            max_err, final, settle_time = self._follow(stream)
        except RobotFault:
            raise
        except (p.FrankaException, RuntimeError) as exc:
            raise self._control_fault(exc) from None
        except BaseException:  # Ctrl-C, SIGTERM (recon_cli.interrupts), a bug
            self._halt()
            raise
        return ExecutionReport(duration=stream.duration, settle_time=settle_time, max_tracking_error=max_err,
                               final_error=final, settled=True, lost_cycles=self.lost_cycles - lost)

    def _follow(self, stream: SetpointStream) -> tuple[np.ndarray, np.ndarray, float]:
        """The 1 kHz loop: one setpoint per controller cycle (a cycle the controller reports
        as lost advances the index with it), then the hold at the goal until settled (see
        :meth:`_loop`). Python's cyclic garbage collector is collected before and paused during the loop: a
        full collection in a process holding many objects takes longer than several
        controller cycles (the loop's own objects are freed by reference counting); and another
        Python thread holding the interpreter lock is made to hand it over within
        SWITCH_INTERVAL instead of Python's 5 ms."""
        gc.collect()
        paused = gc.isenabled()
        gc.disable()
        switch = sys.getswitchinterval()
        sys.setswitchinterval(SWITCH_INTERVAL)
        try:
            with realtime_priority():
                return self._loop(stream)
        finally:
            sys.setswitchinterval(switch)
            if paused:
                gc.enable()

    def _loop(self, stream: SetpointStream) -> tuple[np.ndarray, np.ndarray, float]:
        """Stream the setpoints, then keep commanding the goal until the robot has settled
        there (every joint within the settle tolerance on SETTLE_STATES consecutive states and
        moving less than REST_SPREAD among them: positions, not the reported velocities, which
        are noise at rest) and only then finish the motion: a controller takes over the pose
        the robot *has* when the motion finishes, so finishing while the arm still lags its
        command would leave it short of the goal. The largest tracking error per joint, the
        final error and the settle time.

        Lost cycles: a state read after a gap (or one the loop could not answer within
        LATE_ANSWER of reading it, or whose reference is not the command answered before it)
        is not answered; the next one is, at the start of its cycle, from the controller's
        own reference (``q_d``, ``dq_d``, ``ddq_d``) and blended back onto the stream
        (:mod:`~recon_cli.backends.hardware.resume`), instead of a jump back onto the stream
        that the controller would judge as a jerk."""
        p, cfg = self._p, self.config
        q = stream.q
        last = len(q) - 1
        goal = q[last]
        resumption = Resumption(stream, self.limits)
        control = self.robot.start_joint_position_control(p.ControllerMode.JointImpedance)
        index = 0
        sent = q[0]
        max_err = np.zeros(7)
        deadline = time.monotonic() + stream.duration + cfg.time_margin
        arrived = time.monotonic()  # when the last setpoint was first sent
        window: list[np.ndarray] = []
        recent = self._recent
        recent.clear()
        cycle = 0  # the controller's cycle of the state in hand
        # the latest commands sent (a ring: those the reference is matched against) and their cycles
        history = np.zeros((RECENT, 7))
        history_cycles = np.full(RECENT, -(10**9), dtype=np.int64)
        count = reads = 0
        resync = False  # the controller extrapolated: answer from its reference
        skipped = 0
        blend: np.ndarray | None = None  # offsets to the setpoints of the cycles after blend_at
        blend_at = 0
        applied_dq: np.ndarray | None = None  # the last command's velocity as the controller differences it
        delays: collections.deque[float] = collections.deque(maxlen=STAMP_WINDOW)  # read time - state time
        try:
            while True:
                asked_at = time.perf_counter()
                state, period = control.readOnce()
                read_at = time.perf_counter()
                delay = read_at - state.time.to_sec()
                measured = np.asarray(state.q, dtype=float)
                err = np.abs(measured - sent)
                max_err = np.maximum(max_err, err)
                if np.any(~np.isfinite(measured)) or np.any(err > cfg.tracking_bound):
                    control = None
                    raise self._tracking_fault(err, f"at setpoint {index} of {last + 1}")
                now = time.monotonic()
                step = round(period.to_sec() / PERIOD) if reads else 0
                reads += 1
                cycle += step
                if step:
                    recent.append([step, step - 1])
                    self.lost_cycles += step - 1
                if index < last <= index + step:
                    arrived = now
                index = min(index + step, last)
                if step > 1:  # a gap: the states after it are waited for anew
                    resync, skipped = True, 0
                    delays.clear()  # and the controller's schedule may have moved with it
                elif read_at - asked_at > PERIOD + STALE:
                    # the state came late by the controller's own clock (it published late, not
                    # the loop read late): its schedule moved, and states after it are measured
                    # from it
                    delays.clear()
                delays.append(delay)
                ref = Reference(np.asarray(state.q_d, dtype=float), np.asarray(state.dq_d, dtype=float),
                                np.asarray(state.ddq_d, dtype=float))
                same_q, same_dq = applied_as(ref, sent, applied_dq, PERIOD) if applied_dq is not None else (True, True)
                if not resync and same_q and not same_dq and skipped < MAX_SKIPS:
                    # torn (resume.torn): the last command with a velocity it was not applied with, a
                    # state read while it was written; the next one is answered from its reference
                    resync = True
                    skipped += 1
                    self._unanswered()
                    continue
                # a state that does not report the last command as sent came from a controller
                # that did not apply it in time (or applied it late, over another interval)
                resync = resync or not (same_q and same_dq)
                resumed: tuple[Reference, int] | None = None
                if resync:
                    problem = ref.problem()
                    if problem is not None:
                        control = None
                        raise self._reference_fault(problem, f"at setpoint {index} of {last + 1}")
                    # after a gap, answer a state the read waited for (published after the last
                    # command went out, answered at the start of its cycle: not one that waited
                    # for the read) whose reference continues the last command sent: a late
                    # command can reach the controller after it published the next state, and a
                    # simulator applies it then
                    waiting = read_at - asked_at < WAITED or delays[-1] - min(delays) > STALE
                    if skipped < MAX_SKIPS and (step > 1 or waiting):
                        skipped += 1
                        self._unanswered()
                        continue
                    match = match_history(ref, history, history_cycles, cycle, PERIOD)
                    reflects = count > 0 and match.command_cycle == history_cycles[(count - 1) % RECENT]
                    if skipped < MAX_SKIPS and not reflects:
                        skipped += 1
                        self._unanswered()
                        continue
                    # the command now; the blend back onto the stream once it is out (the next
                    # cycle's command is the first to need it)
                    command = resumption.command(ref, match.age)
                    resumed = ref, match.age
                    blend, blend_at = _BLEND_PENDING, cycle
                    resync = False
                    since, interval = ref.q, match.age  # what the controller differences it against
                elif blend is not None and cycle - blend_at <= len(blend):
                    command = q[index] + blend[cycle - blend_at - 1]
                    since, interval = sent, 1
                else:
                    blend = None
                    command = q[index]
                    since, interval = sent, 1
                finished = False
                if index == last:
                    final = np.abs(measured - goal)
                    window = [*window, measured][-SETTLE_STATES:] if np.all(final <= cfg.settle_tolerance) else []
                    finished = blend is None and len(window) == SETTLE_STATES and _spread(window) < REST_SPREAD
                    if not finished and now - arrived > cfg.settle_timeout:
                        control = None
                        raise self._settle_fault(final)
                elif now > deadline:
                    control = None
                    raise self._timeout_fault(stream.duration + cfg.time_margin, f"setpoint {index} of {last + 1}")
                if time.perf_counter() - read_at > LATE_ANSWER and not finished and skipped < MAX_SKIPS:
                    resync = True  # the controller extrapolates this cycle: answering late would contradict it
                    skipped += 1
                    self._unanswered()
                    continue
                skipped = 0
                sent, applied_dq = command, (command - since) / (interval * PERIOD)
                out = p.JointPositions(command.tolist())
                out.motion_finished = finished
                control.writeOnce(out)
                history[count % RECENT] = command
                history_cycles[count % RECENT] = cycle
                count += 1
                if time.perf_counter() - read_at > LATE_ANSWER:
                    resync = True  # it may have come late: the controller extrapolated meanwhile
                if finished:
                    return max_err, final, now - arrived
                if resumed is not None:
                    blend = resumption.blend(resumed[0], resumed[1], index)
        except BaseException:
            # the ActiveControl goes now, while the connection is as the error left it (its
            # destructor cancels an unfinished motion over that connection), not whenever the
            # collector reaches the traceback that holds this frame
            control = None
            raise

    def _unanswered(self) -> None:
        """The state in hand is left to the controller's extrapolation: a lost cycle."""
        self.lost_cycles += 1
        if self._recent:
            self._recent[-1][1] += 1

    # ------------------------------------------------------------------ faults and stopping
    def _tracking_fault(self, err: np.ndarray, where: str) -> RobotFault:
        j = int(np.argmax(np.where(np.isfinite(err), err, np.inf)))
        cfg = self.config
        stopped = self._halt()
        return RobotFault(f"tracking error of {self.joint_names[j]} is {err[j]:.4f} rad, above the bound "
                          f"{cfg.tracking_bound:g} rad, {where}; {self._stop_text(stopped)}", kind="tracking",
                          joint=self.joint_names[j], value=float(err[j]), bound=cfg.tracking_bound, stopped=stopped,
                          hint="check the load and the collision thresholds; completed scans are kept")

    def _reference_fault(self, problem: str, where: str) -> RobotFault:
        stopped = self._halt()
        return RobotFault(f"the Franka controller reported an unusable state after missed cycles ({problem}), "
                          f"{where}; {self._stop_text(stopped)}", kind="measurement", stopped=stopped,
                          hint="check the controller's firmware and the network; completed scans are kept")

    def _settle_fault(self, final: np.ndarray) -> RobotFault:
        j = int(np.argmax(final))
        cfg = self.config
        stopped = self._halt()
        return RobotFault(f"the robot did not settle at the goal within {cfg.settle_timeout:g} s "
                          f"({self.joint_names[j]} is {final[j]:.4g} rad away, tolerance {cfg.settle_tolerance:g} "
                          f"rad); no scan was taken; {self._stop_text(stopped)}", kind="settle",
                          joint=self.joint_names[j], value=float(final[j]), bound=cfg.settle_tolerance,
                          stopped=stopped,
                          hint="check the load and robot.franka.settle_tolerance; completed scans are kept")

    def _timeout_fault(self, allowed: float, where: str) -> RobotFault:
        stopped = self._halt()
        return RobotFault(f"the motion did not complete within {allowed:.1f} s ({where}); "
                          f"{self._stop_text(stopped)}", kind="timeout", stopped=stopped,
                          hint="the control loop fell behind the controller; completed scans are kept")

    def _control_fault(self, exc: BaseException) -> RobotFault:
        """A libfranka exception of a motion: a control error (the controller stopped the
        robot, its flags as text) or a lost connection."""
        p = self._p
        if isinstance(exc, p.NetworkException):
            return self._lost(exc, moving=True)
        names: list[str] = []
        try:
            state = self.robot.read_once()
            names = error_names(state.last_motion_errors) or error_names(state.current_errors)
        except (p.FrankaException, RuntimeError):
            pass
        text = _library_text(exc)
        names = [n for n in names if n not in text]
        flags = f" (errors: {', '.join(names)})" if names else ""
        lost = sum(missed for _, missed in self._recent)
        late = (f"; the control loop missed {lost} of the last {sum(c for c, _ in self._recent)} controller cycles"
                if lost else "")
        stopped = self._halt()
        return RobotFault(f"the Franka controller aborted the motion: {text}{flags}{late}; "
                          f"{self._stop_text(stopped)}", kind="control", stopped=stopped,
                          hint=("the controller extrapolates a missed cycle: run recon on a real-time kernel with "
                                "nothing else on its cores (docs/hardware.md); " if lost else "find the cause, ")
                               + "clear the error with recon station recover STATION; completed scans are kept")

    def _lost(self, exc: BaseException, moving: bool) -> RobotFault:
        what = "in a motion" if moving else "at rest"
        return RobotFault(f"lost the connection to the Franka controller at {self.config.ip} {what} "
                          f"({_library_text(exc)}); the controller stops a robot whose commands stop",
                          kind="connection", stopped=False,
                          hint="check the robot and the network before moving it again; completed scans are kept")

    def stop(self) -> bool:
        """Stop every motion and hold; True when the joints came to rest within STOP_BOUND."""
        return self._halt()

    def _halt(self) -> bool:
        p = self._p
        if self.robot is None:
            return False
        try:
            self.robot.stop()
        except (p.FrankaException, RuntimeError):
            pass
        deadline = time.monotonic() + STOP_BOUND
        window: list[np.ndarray] = []
        while time.monotonic() < deadline:
            try:
                state = self.robot.read_once()
            except (p.FrankaException, RuntimeError):
                return False
            window = [*window, np.asarray(state.q, dtype=float)][-SETTLE_STATES:]
            if len(window) == SETTLE_STATES and _spread(window) < REST_SPREAD:
                return True
        return False

    @staticmethod
    def _stop_text(stopped: bool) -> str:
        return "the robot was stopped" if stopped else \
            f"the stop could not be confirmed within {STOP_BOUND:g} s: check the robot"

    def recover(self) -> list[str]:
        """libfranka's automatic error recovery; the errors it cleared."""
        p = self._p
        names = self.errors()
        try:
            self.robot.automatic_error_recovery()
        except (p.FrankaException, RuntimeError) as exc:
            raise RobotFault(f"the Franka controller refused the error recovery ({_library_text(exc)})",
                             kind="control", stopped=True,
                             hint="release the external activation device or see Desk") from None
        return names

    def close(self) -> None:
        """Release the connection (idempotent); the controller holds the robot."""
        self.robot = None

    def __enter__(self) -> FrankaRobot:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
