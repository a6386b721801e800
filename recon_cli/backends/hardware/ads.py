"""The robot over Beckhoff TwinCAT ADS (thesis chapter 5: the real cell is driven by
TwinCAT; recon sends commands over ADS from the reconstruction computer).

recon sends only trajectories its planner has checked, sampled at a fixed period, and
checks them again before sending: every setpoint finite and within the joint limits, every
step within the velocity limits (times the speed override). The PLC program is the cell's
own (the thesis does not publish it); what recon needs from it is the symbol contract below,
whose names are configuration (``robot.ads.symbols`` of the station file). Units: recon's
(rad, m) times ``scale`` per joint, in the PLC's axis order ``axes``.

    chunk        ARRAY[0..chunk_points-1, 0..n-1] OF LREAL   setpoint rows being downloaded
    chunk_offset DINT    index of the chunk's first row in the trajectory buffer
    chunk_count  DINT    valid rows in the chunk
    chunk_seq    UDINT   recon increments it after writing a chunk ...
    chunk_ack    UDINT   ... the PLC copies the chunk into its buffer and echoes the number
    count        DINT    setpoints in the trajectory
    period       LREAL   [s] between setpoints (the PLC interpolates linearly)
    job          UDINT   recon increments it to run the downloaded trajectory ...
    job_ack      UDINT   ... the PLC echoes it when it has started that trajectory; state and
                         index belong to the current trajectory only once job_ack = job
    stop         BOOL    TRUE: decelerate and hold, and leave state 1; recon sets it on every
                         fault, on Ctrl-C/SIGTERM and on close
    heartbeat    UDINT   recon increments it every ``poll`` from connect to close; the PLC
                         stops the axes when it stalls for longer than ``watchdog``
    watchdog     LREAL   [s] (written at connect)
    state        INT     0 idle, 1 moving, 2 done, 3 stopped, 4 fault
    index        DINT    setpoint being executed
    measured     ARRAY[0..n-1] OF LREAL   measured axis positions
    error        BOOL    PLC fault flag
    error_id     UDINT   the fault's code (TwinCAT NC/ADS codes are printed as text)

The heartbeat runs in a background thread from connect to close; during a motion it beats
only while the polling loop is alive, so the PLC's watchdog also catches a stalled recon.
Every access to the connection holds one lock (pyads does not document a ``Connection`` as
safe to share between threads).

Faults stop the robot and raise :class:`~recon_cli.errors.RobotFault`: connection loss, the
PLC's fault flag, a motion the PLC stops or ends early, no completion within the time
bound, a tracking error over its bound, a measurement or status that is not a number or out
of range, a robot that does not settle. Stopping means: pause the heartbeat, write ``stop``
(reconnecting when the connection is gone) until the PLC confirms it (``stop`` reads back
TRUE and ``state`` is 0, 2, 3 or 4) or ``watchdog`` seconds have passed; the fault's message says
which of the two happened. Ctrl-C and SIGTERM during a motion stop the robot the same way
before they propagate.
"""

from __future__ import annotations

import contextlib
import ctypes
import threading
import time
from dataclasses import dataclass

import numpy as np

from recon_cli import install_hint
from recon_cli.backends.base import ExecutionReport
from recon_cli.backends.hardware.ads_config import (  # noqa: F401 (the config is part of the adapter's API)
    PAIRS,
    POLLS_PER_WATCHDOG,
    RANGES,
    SETTLE_HOLD,
    SETTLE_POLLS,
    SETTLE_SPREAD,
    SYMBOL_KEYS,
    AdsConfig,
    Range,
    default_symbols,
    range_rows,
)
from recon_cli.errors import HardwareUnavailable, InputError, RobotFault
from recon_cli.inputs.images import native_output_captured
from recon_cli.planning.trajectory import Trajectory
from recon_cli.robot.limits import JointLimits

STATE_IDLE, STATE_MOVING, STATE_DONE, STATE_STOPPED, STATE_FAULT = 0, 1, 2, 3, 4
STATE_STARTING = -1  # recon's own: the PLC has not yet acknowledged the trajectory
STATE_NAMES = {-1: "starting", 0: "idle", 1: "moving", 2: "done", 3: "stopped", 4: "fault"}

def ads_error_text(exc: Exception) -> str:
    """The readable text of a pyads ADSError (or any error of the connection)."""
    code = getattr(exc, "err_code", None)
    if code is None:
        return str(exc) or type(exc).__name__
    return f"ADS error {code}: {error_id_text(code)}"


def error_id_text(code: int) -> str:
    try:
        from pyads.errorcodes import ERROR_CODES
        from pyads.errorcodes_nc import NC_ERROR_CODES
    except ImportError:
        return "unknown"
    text = ERROR_CODES.get(code) or NC_ERROR_CODES.get(code) or "unknown error code"
    return text.rstrip(". ")


def _pyads():
    try:
        import pyads
    except ImportError:
        raise HardwareUnavailable("the ADS robot adapter needs pyads, which is not installed",
                                  hint=install_hint("ads")) from None
    return pyads


#: AdsLib's log threshold (``Logger::logLevel``: 0 verbose, 1 info, 2 warning, 3 error)
_ADSLIB_LOG_LEVEL = "_ZN6Logger8logLevelE"
_ADSLIB_SILENT = 4
_ADSLIB_LOG_LOCK = threading.RLock()


@contextlib.contextmanager
def adslib_quiet():
    """Keep AdsLib's own log lines ("Socket(): connect failed", "Unable to create socket", ...,
    written from C++ to stderr) off the terminal while connecting: recon says in one line what
    failed. AdsLib's log threshold is raised above its levels meanwhile; a build without that
    symbol has its stderr (file descriptor 2) captured instead."""
    level = None
    try:
        from pyads import pyads_ex

        level = ctypes.c_size_t.in_dll(pyads_ex._adsDLL, _ADSLIB_LOG_LEVEL)
    except (ImportError, AttributeError, ValueError, OSError):
        level = None
    if level is None:

        with native_output_captured(opencv=False):
            yield
        return
    with _ADSLIB_LOG_LOCK:
        saved = level.value
        level.value = max(saved, _ADSLIB_SILENT)
        try:
            yield
        finally:
            level.value = saved


class _NotConnected(ConnectionError):
    """The connection is closed (pyads answers None instead of raising then)."""


@dataclass(frozen=True)
class StopOutcome:
    """What a stop achieved: confirmed by the PLC (``stop`` reads back TRUE and ``state`` is
    idle, done, stopped or fault) after ``seconds``, or not within ``bound`` seconds."""

    confirmed: bool
    seconds: float
    bound: float


class AdsRobot:
    """RobotBackend of a TwinCAT PLC (see the module docstring for the symbol contract)."""

    def __init__(self, config: AdsConfig, joint_names: tuple[str, ...], limits: JointLimits,
                 connection=None) -> None:
        pyads = _pyads()
        self.config = config
        self.joint_names = tuple(joint_names)
        self.limits = limits
        n = len(self.joint_names)
        axes = config.axes or self.joint_names
        unknown = [a for a in axes if a not in self.joint_names]
        if unknown or len(axes) != n or len(set(axes)) != n:
            raise InputError(f"robot.ads.axes {list(axes)} is not an order of the cell's joints",
                             hint=f"list each of {', '.join(self.joint_names)} once")
        self._order = np.array([self.joint_names.index(a) for a in axes])  # PLC axis k = recon joint order[k]
        self._scale = np.asarray(config.scale or (1.0,) * n, dtype=float)
        if self._scale.shape != (n,):
            raise InputError(f"robot.ads.scale has {len(config.scale)} numbers, the cell has {n} joints",
                             hint="one number per axis, in the order of axes (1 for rad and m)")
        prismatic = np.asarray(limits.prismatic, dtype=bool)
        self._units = np.where(prismatic, "m", "rad")
        self._tracking = np.where(prismatic, config.tracking_bound[1], config.tracking_bound[0])
        self._settle = np.where(prismatic, config.settle_tolerance[1], config.settle_tolerance[0])
        # measured positions outside the joint limits widened by the tracking bound are not believed
        self._measured_lo = np.asarray(limits.lower, dtype=float) - self._tracking
        self._measured_hi = np.asarray(limits.upper, dtype=float) + self._tracking
        self._seq = self._job = self._beat = 0
        self._pyads = pyads
        self.sym = config.symbols
        self._lock = threading.RLock()  # every access to self.plc
        self._beating = threading.Event()  # the heartbeat thread writes beats
        self._quit = threading.Event()
        self._supervising = False  # a motion is being polled ...
        self._polled = 0.0  # ... last poll [monotonic s]
        self.beats = 0  # heartbeats written
        self.beat_failures = 0
        self.plc = connection or pyads.Connection(config.ams_net_id, config.port, config.ip)
        self._lreal_n = pyads.PLCTYPE_LREAL * n
        self._chunk_type = pyads.PLCTYPE_LREAL * (config.chunk_points * n)
        try:
            with self._lock, adslib_quiet():
                if not self.plc.is_open:
                    self.plc.open()
                self.plc.set_timeout(int(config.timeout * 1000))
                self._write("watchdog", float(config.watchdog), pyads.PLCTYPE_LREAL)
                self._seq = int(self._read("chunk_ack", pyads.PLCTYPE_UDINT))
                self._job = int(self._read("job_ack", pyads.PLCTYPE_UDINT))
                self._beat = int(self._read("heartbeat", pyads.PLCTYPE_UDINT))
                self._beat_once()
        except Exception as exc:  # noqa: BLE001 (any failure to reach the PLC)
            self._close_quietly()
            raise RobotFault(f"cannot reach the PLC {config.ams_net_id}:{config.port} at {config.ip} "
                             f"({ads_error_text(exc)})", kind="connection", stopped=False,
                             hint="check the address, the ADS route and that the PLC runs") from None
        self._beating.set()
        self._heart = threading.Thread(target=self._beat_loop, name="recon-ads-heartbeat", daemon=True)
        self._heart.start()

    # ------------------------------------------------------------------ units and access
    def to_plc(self, q: np.ndarray) -> np.ndarray:
        """recon joint vector(s) -> PLC axis values."""
        q = np.asarray(q, dtype=float)
        return q[..., self._order] * self._scale

    def from_plc(self, v: np.ndarray) -> np.ndarray:
        v = np.asarray(v, dtype=float) / self._scale
        q = np.empty_like(v)
        q[..., self._order] = v
        return q

    def _connection(self):
        if self.plc is None or not self.plc.is_open:
            raise _NotConnected("the connection is closed")
        return self.plc

    def _read(self, key: str, plc_type):
        with self._lock:
            value = self._connection().read_by_name(self.sym[key], plc_type)
        if value is None:
            raise _NotConnected("the connection is closed")
        return value

    def _write(self, key: str, value, plc_type) -> None:
        with self._lock:
            self._connection().write_by_name(self.sym[key], value, plc_type)

    def _read_list(self, keys: tuple[str, ...]) -> list:
        """Values of several symbols in one ADS sum request (one PLC cycle's values)."""
        names = [self.sym[k] for k in keys]
        with self._lock:
            values = self._connection().read_list_by_name(names, structure_defs=None, cache_symbol_info=True)
        if not isinstance(values, dict) or any(n not in values for n in names):
            raise _NotConnected("the status read returned nothing")
        return [values[n] for n in names]

    def _status(self) -> tuple[int, int, np.ndarray, bool, int, bool]:
        """state, index, measured (raw PLC axis values), error flag, error id and whether the
        PLC has taken the current trajectory, read in one ADS sum request."""
        state, index, measured, error, error_id, job_ack = self._read_list(
            ("state", "index", "measured", "error", "error_id", "job_ack"))
        return (int(state), int(index), np.asarray(measured, dtype=float), bool(error), int(error_id),
                int(job_ack) == self._job)

    # ------------------------------------------------------------------ the heartbeat
    def _beat_once(self) -> None:
        with self._lock:
            self._beat = (self._beat + 1) % 2**32
            self._write("heartbeat", self._beat, self._pyads.PLCTYPE_UDINT)
        self.beats += 1

    def _beat_loop(self) -> None:
        """Beat every ``poll`` while beating is on; during a motion only while the polling loop
        is alive (a stalled recon then lets the PLC's watchdog stop the axes)."""
        cfg = self.config
        while not self._quit.wait(cfg.poll):
            if not self._beating.is_set():
                continue
            if self._supervising and time.monotonic() - self._polled > cfg.watchdog / 2:
                continue
            try:
                self._beat_once()
            except Exception:  # noqa: BLE001 (the connection is gone: the polling loop or the next request says so)
                self.beat_failures += 1

    # ------------------------------------------------------------------ RobotBackend
    def measured_joints(self) -> np.ndarray:
        """The measured joints (recon order and units); a value that is not a number or lies
        outside the joint limits widened by the tracking bound stops the robot and raises
        RobotFault(kind="measurement")."""
        try:
            raw = np.asarray(self._read("measured", self._lreal_n), dtype=float)
        except Exception as exc:  # noqa: BLE001
            raise self._lost(exc) from None
        return self._checked(raw)

    def _checked(self, raw: np.ndarray, at: str = "") -> np.ndarray:
        n = len(self.joint_names)
        if raw.shape != (n,):
            outcome = self._halt()
            raise RobotFault(f"the PLC's {self.sym['measured']} holds {raw.size} values, the cell has {n} joints"
                             f"{at}; {self._stop_text(outcome)}", kind="measurement", stopped=outcome.confirmed,
                             hint="declare it ARRAY[0..n-1] OF LREAL, n the number of axes")
        q = self.from_plc(raw)
        bad = ~np.isfinite(q)
        if np.any(bad):
            j = int(np.flatnonzero(bad)[0])
            k = int(np.flatnonzero(self._order == j)[0])
            outcome = self._halt()
            raise RobotFault(f"the PLC reports the measured position of {self.joint_names[j]} (axis {k}) as "
                             f"{raw[k]}, not a finite number{at}; {self._stop_text(outcome)}", kind="measurement",
                             joint=self.joint_names[j], stopped=outcome.confirmed,
                             hint="check the drive's encoder and the PLC's measured symbol; completed scans are kept")
        out = (q < self._measured_lo) | (q > self._measured_hi)
        if np.any(out):
            j = int(np.flatnonzero(out)[0])
            u = self._units[j]
            outcome = self._halt()
            raise RobotFault(f"the measured position of {self.joint_names[j]} is {q[j]:.4g} {u}, outside its limits "
                             f"[{self.limits.lower[j]:.4f}, {self.limits.upper[j]:.4f}] {u} widened by the tracking "
                             f"bound {self._tracking[j]:g} {u}{at}; {self._stop_text(outcome)}", kind="measurement",
                             joint=self.joint_names[j], value=float(q[j]),
                             bound=float(self._measured_hi[j] if q[j] > self._measured_hi[j] else self._measured_lo[j]),
                             stopped=outcome.confirmed,
                             hint="check robot.ads.axes and scale against the PLC's axes, and the drive's encoder")
        return q

    def setpoints(self, trajectory: Trajectory) -> tuple[np.ndarray, float]:
        """The trajectory sampled for the PLC (recon order) and its period, checked against
        the joint and velocity limits; raises RobotFault(kind="limit") before anything is sent."""
        cfg = self.config
        duration = trajectory.duration / cfg.speed_override
        if not np.isfinite(duration) or duration < 0:
            raise RobotFault(f"the trajectory's duration {trajectory.duration} s is not a finite time; nothing was "
                             "sent", kind="limit", stopped=False, hint="plan the motion again")
        period = max(cfg.period, duration / max(cfg.max_points - 1, 1))
        k = max(int(np.ceil(duration / period)), 1)
        t = np.minimum(np.arange(k + 1) * period, duration)
        q = trajectory.sample(t * cfg.speed_override)[0]
        lim = self.limits
        for j, name in enumerate(self.joint_names):
            if not np.all(np.isfinite(q[:, j])):
                raise RobotFault(f"a setpoint of {name} is not a finite number; nothing was sent", kind="limit",
                                 joint=name, stopped=False, hint="plan the motion again")
            lo, hi = float(q[:, j].min()), float(q[:, j].max())
            if lo < lim.lower[j] - 1e-9 or hi > lim.upper[j] + 1e-9:
                bad, bound = (lo, lim.lower[j]) if lo < lim.lower[j] - 1e-9 else (hi, lim.upper[j])
                raise RobotFault(f"setpoint of {name} at {bad:.4f} is outside its limits "
                                 f"[{lim.lower[j]:.4f}, {lim.upper[j]:.4f}]; nothing was sent", kind="limit",
                                 joint=name, value=bad, bound=float(bound), stopped=False,
                                 hint="plan the motion again; the trajectory is not the checked one")
        if len(q) > 1:
            speed = np.max(np.abs(np.diff(q, axis=0)), axis=0) / period
            bound = lim.velocity * (1.0 + cfg.limit_tolerance)
            over = np.flatnonzero(speed > bound)
            if over.size:
                j = int(over[0])
                raise RobotFault(f"setpoints of {self.joint_names[j]} move at {speed[j]:.4f} per s, above its "
                                 f"velocity limit {lim.velocity[j]:.4f}; nothing was sent", kind="limit",
                                 joint=self.joint_names[j], value=float(speed[j]), bound=float(lim.velocity[j]),
                                 stopped=False, hint="time the trajectory with the velocity limits (toppra)")
        return q, period

    def execute(self, trajectory: Trajectory) -> ExecutionReport:
        """Download and run a trajectory, follow it and wait until the robot has settled at its
        end; every fault, Ctrl-C and SIGTERM stops the robot before the exception leaves."""
        pyads = self._pyads
        q, period = self.setpoints(trajectory)
        start = self.measured_joints()
        self._check_start(start, q[0])
        try:
            self._download(q, period)
            self._beating.set()
            self._write("stop", False, pyads.PLCTYPE_BOOL)
            self._job = (self._job + 1) % 2**32
            self._write("job", self._job, pyads.PLCTYPE_UDINT)
        except RobotFault:
            raise
        except KeyboardInterrupt:
            self._halt()
            raise
        except Exception as exc:  # noqa: BLE001
            raise self._lost(exc) from None
        try:
            return self._follow(q, period)
        except RobotFault:
            raise  # stopped where it was raised
        except BaseException:  # Ctrl-C, SIGTERM (recon_cli.interrupts), a bug
            self._halt()
            raise

    def _check_start(self, measured: np.ndarray, first: np.ndarray) -> None:
        tol = self._tracking
        err = np.abs(measured - first)
        if np.any(err > tol):
            j = int(np.argmax(err / tol))
            raise RobotFault(f"the robot is not at the trajectory's start ({self.joint_names[j]} is "
                             f"{err[j]:.4f} away); nothing was sent", kind="start", joint=self.joint_names[j],
                             value=float(err[j]), bound=float(tol[j]), stopped=False,
                             hint="plan from the measured joints")

    def _download(self, q: np.ndarray, period: float) -> None:
        pyads, cfg = self._pyads, self.config
        rows = self.to_plc(q)
        n = rows.shape[1]
        self._write("count", 0, pyads.PLCTYPE_DINT)
        for offset in range(0, len(rows), cfg.chunk_points):
            chunk = rows[offset:offset + cfg.chunk_points]
            flat = np.zeros(cfg.chunk_points * n)
            flat[:chunk.size] = chunk.ravel()
            self._write("chunk", flat.tolist(), self._chunk_type)
            self._write("chunk_offset", offset, pyads.PLCTYPE_DINT)
            self._write("chunk_count", len(chunk), pyads.PLCTYPE_DINT)
            self._seq = (self._seq + 1) % 2**32
            self._write("chunk_seq", self._seq, pyads.PLCTYPE_UDINT)
            deadline = time.monotonic() + cfg.timeout
            while int(self._read("chunk_ack", pyads.PLCTYPE_UDINT)) != self._seq:
                if time.monotonic() > deadline:
                    raise RobotFault(f"the PLC did not take setpoint chunk {offset // cfg.chunk_points + 1} within "
                                     f"{cfg.timeout:g} s; nothing was started", kind="timeout", stopped=False,
                                     hint="check that the PLC program runs and serves the recon symbols")
                time.sleep(0.002)
        self._write("period", float(period), pyads.PLCTYPE_LREAL)
        self._write("count", len(rows), pyads.PLCTYPE_DINT)

    def _follow(self, q: np.ndarray, period: float) -> ExecutionReport:
        self._supervising, self._polled = True, time.monotonic()
        try:
            return self._poll_until_settled(q, period)
        finally:
            self._supervising = False

    def _fault(self, message: str, **kw) -> RobotFault:
        """Stop the robot, then the fault (``message`` is completed by what the stop achieved)."""
        outcome = self._halt()
        return RobotFault(f"{message}; {self._stop_text(outcome)}", stopped=outcome.confirmed, **kw)

    def _poll_until_settled(self, q: np.ndarray, period: float) -> ExecutionReport:
        cfg = self.config
        n_points = len(q)
        duration = (n_points - 1) * period
        bound, settle = self._tracking, self._settle
        max_err = np.zeros(len(self.joint_names))
        t0 = time.monotonic()
        t_done = None
        streak: list[tuple[float, np.ndarray]] = []  # (time, measured) of consecutive polls within the tolerance
        while True:
            try:
                state, index, raw, error, error_id, taken = self._status()
            except Exception as exc:  # noqa: BLE001
                raise self._lost(exc) from None
            now = self._polled = time.monotonic()
            at = f" at setpoint {index} of {n_points}"
            if error or state == STATE_FAULT:
                raise self._fault(f"the PLC reports fault {error_id} (0x{error_id:X}: {error_id_text(error_id)})"
                                  f"{at}", kind="plc_fault", code=error_id,
                                  hint="clear the fault on the PLC, then run again; completed scans are kept")
            if state not in STATE_NAMES or state == STATE_STARTING:
                raise self._fault(f"the PLC reports state {state}, not one of 0 (idle), 1 (moving), 2 (done), "
                                  f"3 (stopped), 4 (fault)", kind="measurement", value=float(state),
                                  hint=f"check the PLC program's {self.sym['state']}; completed scans are kept")
            if not taken:
                state, index = STATE_STARTING, 0  # the PLC has not taken this trajectory yet
            elif state in (STATE_MOVING, STATE_DONE) and not 0 <= index < n_points:
                raise self._fault(f"the PLC reports setpoint {index} while {STATE_NAMES[state]}, outside "
                                  f"0..{n_points - 1} of the downloaded trajectory", kind="measurement",
                                  value=float(index), bound=float(n_points - 1),
                                  hint=f"check the PLC program's {self.sym['index']}; completed scans are kept")
            measured = self._checked(raw, "" if state == STATE_STARTING else at)
            if state in (STATE_STOPPED, STATE_IDLE):
                raise self._fault(f"the PLC {'stopped' if state == STATE_STOPPED else 'ended'} the motion at setpoint "
                                  f"{index} of {n_points} without completing it", kind="plc_fault",
                                  hint="see the PLC's log (heartbeat watchdog, emergency stop); scans are kept")
            k = int(np.clip(index if state == STATE_MOVING else (n_points - 1 if state == STATE_DONE else 0),
                            0, n_points - 1))
            err = np.abs(measured - q[k])
            if state in (STATE_MOVING, STATE_DONE):
                max_err = np.maximum(max_err, err)
                if np.any(err > bound):
                    j = int(np.argmax(err / bound))
                    raise self._fault(f"tracking error of {self.joint_names[j]} is {err[j]:.4f}, above the bound "
                                      f"{bound[j]:.4f}, at setpoint {k} of {n_points}", kind="tracking",
                                      joint=self.joint_names[j], value=float(err[j]), bound=float(bound[j]),
                                      hint="check the drives and the load; completed scans are kept")
            if state == STATE_DONE:
                t_done = t_done if t_done is not None else now
                final = np.abs(measured - q[-1])
                streak = [*streak, (now, measured)] if np.all(final <= settle) else []
                # at rest: not an axis swinging through the goal on its way elsewhere
                positions = np.array([m for _, m in streak]) if streak else measured[None]
                spread = positions.max(axis=0) - positions.min(axis=0)
                resting = bool(np.all(spread <= SETTLE_SPREAD * settle))
                if len(streak) >= SETTLE_POLLS and now - streak[0][0] >= SETTLE_HOLD and resting:
                    return ExecutionReport(duration=duration, settle_time=now - t_done, max_tracking_error=max_err,
                                           final_error=final, settled=True)
                if not resting:  # moving within the tolerance: the streak starts again from this poll
                    streak = streak[-1:]
                if now - t_done > cfg.settle_timeout and not (streak and resting):  # (resting: let the streak end)
                    raise self._unsettled(final, spread, settle)
            elif now - t0 > duration + cfg.time_margin:
                raise self._fault(f"the motion did not complete within {duration + cfg.time_margin:.1f} s "
                                  f"(PLC state {STATE_NAMES.get(state, state)}, setpoint {index} of {n_points})",
                                  kind="timeout", hint="check the PLC program and the drives; completed scans are kept")
            time.sleep(cfg.poll)

    def _unsettled(self, final: np.ndarray, spread: np.ndarray, settle: np.ndarray) -> RobotFault:
        """The settle fault: the joints outside the tolerance, else those still moving."""
        cfg = self.config
        over = np.flatnonzero(final > settle)
        if over.size:
            j = int(over[np.argmax(final[over] / settle[over])])
            errors = ", ".join(f"{self.joint_names[i]} {final[i]:.3g} {self._units[i]} (tolerance {settle[i]:g})"
                               for i in over)
            what, value = f"final error {errors}", float(final[j])
        else:  # within the tolerance, but moving
            moving = np.flatnonzero(spread > SETTLE_SPREAD * settle)
            j = int(moving[np.argmax(spread[moving] / settle[moving])])
            errors = ", ".join(f"{self.joint_names[i]} moved {spread[i]:.3g} {self._units[i]} "
                               f"(at rest: under {SETTLE_SPREAD * settle[i]:g})" for i in moving)
            what, value = f"still moving: {errors}", float(spread[j])
        return self._fault(f"the robot did not settle at the goal within {cfg.settle_timeout:g} s ({what}); "
                           f"no scan was taken", kind="settle", joint=self.joint_names[j], value=value,
                           bound=float(settle[j]),
                           hint="check the drives' position control or robot.ads.settle_tolerance; "
                                "completed scans are kept")

    # ------------------------------------------------------------------ stopping
    def stop(self) -> bool:
        """Command the robot to stop (decelerate and hold); True when the PLC confirmed it."""
        return self._halt().confirmed

    def _reconnect(self) -> None:
        with self._lock:
            try:
                self.plc.close()
            except Exception:  # noqa: BLE001 (a broken connection may not close cleanly)
                pass
            with adslib_quiet():
                self.plc.open()
                self.plc.set_timeout(int(self.config.timeout * 1000))

    def _halt(self) -> StopOutcome:
        """Write ``stop`` until the PLC confirms it (``stop`` reads back TRUE and ``state`` is
        0, 2, 3 or 4: not moving, and not garbage), reconnecting when the connection is gone, for at most ``watchdog``
        seconds. The heartbeat pauses meanwhile, so that the PLC's watchdog stops the axes
        when recon cannot; it resumes once the stop is confirmed."""
        pyads, cfg = self._pyads, self.config
        self._beating.clear()
        t0 = time.monotonic()
        deadline = t0 + cfg.watchdog
        reconnect = False
        while self.plc is not None:
            try:
                with self._lock:
                    if reconnect:
                        self._reconnect()
                    self._write("stop", True, pyads.PLCTYPE_BOOL)
                    stop, state = self._read_list(("stop", "state"))
                if bool(stop) and int(state) in (STATE_IDLE, STATE_DONE, STATE_STOPPED, STATE_FAULT):
                    self._beating.set()
                    return StopOutcome(True, time.monotonic() - t0, cfg.watchdog)
            except Exception:  # noqa: BLE001 (the connection is gone: reconnect and try again)
                reconnect = True
            left = deadline - time.monotonic()
            if left <= 0:
                break
            time.sleep(min(cfg.poll, left))
        return StopOutcome(False, time.monotonic() - t0, cfg.watchdog)

    def _stop_text(self, outcome: StopOutcome) -> str:
        if outcome.confirmed:
            return f"the robot was stopped (confirmed by the PLC after {outcome.seconds:.2f} s)"
        return (f"the stop could not be confirmed within {outcome.bound:g} s; the PLC watchdog stops the axes "
                f"after {self.config.watchdog:g} s without a heartbeat")

    def _lost(self, exc: Exception) -> RobotFault:
        outcome = self._halt()
        return RobotFault(f"lost the connection to the PLC ({ads_error_text(exc)}); {self._stop_text(outcome)}",
                          kind="connection", stopped=outcome.confirmed,
                          hint="check the network and the PLC; completed scans are kept")

    def _close_quietly(self) -> None:
        try:
            self.plc.close()
        except Exception:  # noqa: BLE001
            pass

    def __enter__(self) -> AdsRobot:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """Write ``stop`` (one attempt), then end the heartbeat and close the connection
        (idempotent)."""
        if self.plc is None:
            return
        try:
            self._write("stop", True, self._pyads.PLCTYPE_BOOL)
        except Exception:  # noqa: BLE001 (the connection is gone; the PLC's watchdog stops the axes)
            pass
        finally:
            self._beating.clear()
            self._quit.set()
            heart = getattr(self, "_heart", None)
            if heart is not None and heart is not threading.current_thread():
                heart.join(timeout=self.config.timeout + self.config.poll + 1.0)
            with self._lock:
                self._close_quietly()
                self.plc = None
