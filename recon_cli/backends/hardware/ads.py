"""The robot over Beckhoff TwinCAT ADS (thesis chapter 5: the real cell is driven by
TwinCAT; recon sends commands over ADS from the reconstruction computer).

recon sends only trajectories its planner has checked, sampled at a fixed period, and
checks them again before sending: every setpoint within the joint limits, every step
within the velocity limits (times the speed override). The PLC program is the cell's own
(the thesis does not publish it); what recon needs from it is the symbol contract below,
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
    stop         BOOL    TRUE: decelerate and hold; recon sets it on every fault and on close
    heartbeat    UDINT   recon increments it every poll; the PLC stops the axes when it
                         stalls for longer than ``watchdog`` (written at connect)
    watchdog     LREAL   [s]
    state        INT     0 idle, 1 moving, 2 done, 3 stopped, 4 fault
    index        DINT    setpoint being executed
    measured     ARRAY[0..n-1] OF LREAL   measured axis positions
    error        BOOL    PLC fault flag
    error_id     UDINT   the fault's code (TwinCAT NC/ADS codes are printed as text)

Faults stop the robot (``stop`` := TRUE) and raise :class:`~recon_cli.errors.RobotFault`:
connection loss, the PLC's fault flag, no completion within the time bound, a tracking
error over its bound; Ctrl-C during a motion stops the robot before it propagates.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, fields

import numpy as np

from recon_cli.backends.base import ExecutionReport
from recon_cli.errors import HardwareUnavailable, InputError, RobotFault
from recon_cli.planning.trajectory import Trajectory
from recon_cli.robot.limits import JointLimits

STATE_IDLE, STATE_MOVING, STATE_DONE, STATE_STOPPED, STATE_FAULT = 0, 1, 2, 3, 4
STATE_STARTING = -1  # recon's own: the PLC has not yet acknowledged the trajectory
STATE_NAMES = {-1: "starting", 0: "idle", 1: "moving", 2: "done", 3: "stopped", 4: "fault"}

SYMBOL_KEYS = ("chunk", "chunk_offset", "chunk_count", "chunk_seq", "chunk_ack", "count", "period", "job",
               "job_ack", "stop", "heartbeat", "watchdog", "state", "index", "measured", "error", "error_id")


def default_symbols(prefix: str = "MAIN.recon") -> dict[str, str]:
    return {k: f"{prefix}.{k}" for k in SYMBOL_KEYS}


@dataclass(frozen=True)
class AdsConfig:
    """The ``robot.ads`` section of a station file."""

    ams_net_id: str = "127.0.0.1.1.1"  # the PLC's AMS Net ID
    port: int = 851  # TwinCAT 3 PLC runtime 1
    ip: str = "127.0.0.1"  # the PLC's address (a route to it must exist on the PLC side)
    symbols: dict[str, str] = field(default_factory=default_symbols)
    axes: tuple[str, ...] = ()  # recon joint names in the PLC's axis order (default: recon's order)
    scale: tuple[float, ...] = ()  # PLC unit per recon unit, per axis (default 1: rad and m)
    period: float = 0.01  # [s] setpoint period
    chunk_points: int = 40  # setpoint rows per download chunk
    max_points: int = 20000  # size of the PLC's trajectory buffer
    poll: float = 0.02  # [s] status polling and heartbeat period
    watchdog: float = 0.5  # [s] the PLC stops the axes when the heartbeat stalls this long
    timeout: float = 2.0  # [s] for one ADS request and one chunk handshake
    speed_override: float = 1.0  # of the planned speed (<= 1 slows the trajectory down)
    time_margin: float = 5.0  # [s] beyond the (overridden) duration before "timeout"
    tracking_bound: tuple[float, float] = (0.02, 0.005)  # [rad, m] largest |measured - setpoint|
    settle_tolerance: tuple[float, float] = (2e-4, 5e-5)  # [rad, m] at the goal
    settle_timeout: float = 3.0  # [s]
    limit_tolerance: float = 0.02  # relative slack of the velocity re-check (sampling)

    @classmethod
    def from_mapping(cls, d: dict, where: str = "robot.ads") -> AdsConfig:
        if not isinstance(d, dict):
            raise InputError(f"{where} is not a mapping", hint="write key: value lines under it")
        known = {f.name for f in fields(cls)}
        for key in d:
            if key not in known:
                raise InputError(f"{where}.{key} is not a known key",
                                 hint=f"known keys: {', '.join(sorted(known))}")
        kw = dict(d)
        if "symbols" in kw:
            sym = kw["symbols"]
            prefix = sym.get("prefix", "MAIN.recon") if isinstance(sym, dict) else None
            if prefix is None:
                raise InputError(f"{where}.symbols is not a mapping", hint="e.g. prefix: MAIN.recon")
            merged = default_symbols(prefix)
            for key, name in sym.items():
                if key == "prefix":
                    continue
                if key not in SYMBOL_KEYS:
                    raise InputError(f"{where}.symbols.{key} is not a symbol of the contract",
                                     hint=f"symbols: prefix, {', '.join(SYMBOL_KEYS)}")
                merged[key] = str(name)
            kw["symbols"] = merged
        for key in ("axes", "scale", "tracking_bound", "settle_tolerance"):
            if key in kw:
                if not isinstance(kw[key], (list, tuple)):
                    raise InputError(f"{where}.{key} is not a list", hint="write [a, b, ...]")
                kw[key] = tuple(kw[key])
        try:
            cfg = cls(**kw)
            for key in ("period", "poll", "watchdog", "timeout", "speed_override", "settle_timeout"):
                value = float(getattr(cfg, key))
                if not value > 0:
                    raise InputError(f"{where}.{key} = {value} is not positive", hint="give a positive number")
            if cfg.speed_override > 1.0:
                raise InputError(f"{where}.speed_override = {cfg.speed_override} is above 1",
                                 hint="recon never runs faster than planned; use a value in (0, 1]")
        except TypeError as exc:
            raise InputError(f"{where}: {exc}", hint="see docs/hardware.md for the keys") from None
        return cfg


def ads_error_text(exc: Exception) -> str:
    """The readable text of a pyads ADSError (or any error of the connection)."""
    code = getattr(exc, "err_code", None)
    if code is None:
        return str(exc)
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
                                  hint="pip install recon-cli[ads]") from None
    return pyads


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
        if self._scale.shape != (n,) or np.any(self._scale == 0):
            raise InputError(f"robot.ads.scale needs {n} non-zero numbers", hint="1 for rad and m")
        self._seq = 0
        self._beat = 0
        self._pyads = pyads
        self.sym = config.symbols
        self.plc = connection or pyads.Connection(config.ams_net_id, config.port, config.ip)
        self._lreal_n = pyads.PLCTYPE_LREAL * n
        self._chunk_type = pyads.PLCTYPE_LREAL * (config.chunk_points * n)
        try:
            if not self.plc.is_open:
                self.plc.open()
            self.plc.set_timeout(int(config.timeout * 1000))
            self._write("watchdog", float(config.watchdog), pyads.PLCTYPE_LREAL)
            self._seq = int(self._read("chunk_ack", pyads.PLCTYPE_UDINT))
            self._job = int(self._read("job_ack", pyads.PLCTYPE_UDINT))
        except Exception as exc:  # noqa: BLE001 (any failure to reach the PLC)
            self._close_quietly()
            raise RobotFault(f"cannot reach the PLC {config.ams_net_id}:{config.port} at {config.ip} "
                             f"({ads_error_text(exc)})", kind="connection", stopped=False,
                             hint="check the address, the ADS route and that the PLC runs") from None

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

    def _read(self, key: str, plc_type):
        return self.plc.read_by_name(self.sym[key], plc_type)

    def _write(self, key: str, value, plc_type) -> None:
        self.plc.write_by_name(self.sym[key], value, plc_type)

    def _status(self) -> tuple[int, int, np.ndarray, bool, int]:
        """state, index, measured (recon order), error flag, error id, read in one ADS sum
        request (one PLC cycle's values); beats the heartbeat first."""
        pyads = self._pyads
        self._beat = (self._beat + 1) % 2**32
        self._write("heartbeat", self._beat, pyads.PLCTYPE_UDINT)
        names = [self.sym[k] for k in ("state", "index", "measured", "error", "error_id", "job_ack")]
        values = self.plc.read_list_by_name(names, structure_defs=None, cache_symbol_info=True)
        state, index, measured, error, error_id, job_ack = (values[n] for n in names)
        if int(job_ack) != self._job and not error:
            state, index = STATE_STARTING, 0  # the PLC has not taken this trajectory yet
        return (int(state), int(index), self.from_plc(np.asarray(measured, dtype=float)), bool(error),
                int(error_id) if error else 0)

    # ------------------------------------------------------------------ RobotBackend
    def measured_joints(self) -> np.ndarray:
        try:
            return self.from_plc(np.asarray(self._read("measured", self._lreal_n)))
        except Exception as exc:  # noqa: BLE001
            raise self._lost(exc) from None

    def setpoints(self, trajectory: Trajectory) -> tuple[np.ndarray, float]:
        """The trajectory sampled for the PLC (recon order) and its period, checked against
        the joint and velocity limits; raises RobotFault(kind="limit") before anything is sent."""
        cfg = self.config
        duration = trajectory.duration / cfg.speed_override
        period = max(cfg.period, duration / max(cfg.max_points - 1, 1))
        k = max(int(np.ceil(duration / period)), 1)
        t = np.minimum(np.arange(k + 1) * period, duration)
        q = trajectory.sample(t * cfg.speed_override)[0]
        lim = self.limits
        for j, name in enumerate(self.joint_names):
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
        pyads = self._pyads
        q, period = self.setpoints(trajectory)
        try:
            start = self.measured_joints()
            self._check_start(start, q[0])
            self._download(q, period)
            self._write("stop", False, pyads.PLCTYPE_BOOL)
            self._job = (self._job + 1) % 2**32
            self._write("job", self._job, pyads.PLCTYPE_UDINT)
        except RobotFault:
            raise
        except Exception as exc:  # noqa: BLE001
            raise self._lost(exc) from None
        try:
            return self._follow(q, period)
        except BaseException:
            self.stop()
            raise

    def _check_start(self, measured: np.ndarray, first: np.ndarray) -> None:
        tol = np.where(self.limits.prismatic, self.config.tracking_bound[1], self.config.tracking_bound[0])
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
        cfg = self.config
        n_points = len(q)
        duration = (n_points - 1) * period
        bound = np.where(self.limits.prismatic, cfg.tracking_bound[1], cfg.tracking_bound[0])
        settle = np.where(self.limits.prismatic, cfg.settle_tolerance[1], cfg.settle_tolerance[0])
        max_err = np.zeros(len(self.joint_names))
        t0 = time.monotonic()
        t_done = None
        while True:
            try:
                state, index, measured, error, error_id = self._status()
            except Exception as exc:  # noqa: BLE001
                raise self._lost(exc) from None
            now = time.monotonic()
            if error or state == STATE_FAULT:
                stopped = self.stop()
                raise RobotFault(f"the PLC reports fault {error_id} ({error_id_text(error_id)}) at setpoint "
                                 f"{index} of {n_points}; the robot was stopped", kind="plc_fault", code=error_id,
                                 stopped=stopped,
                                 hint="clear the fault on the PLC, then run again; completed scans are kept")
            if state in (STATE_STOPPED, STATE_IDLE):
                raise RobotFault(f"the PLC {'stopped' if state == STATE_STOPPED else 'ended'} the motion at setpoint "
                                 f"{index} of {n_points} without completing it", kind="plc_fault",
                                 stopped=self.stop(),
                                 hint="see the PLC's log (heartbeat watchdog, emergency stop); scans are kept")
            k = int(np.clip(index if state == STATE_MOVING else (n_points - 1 if state == STATE_DONE else 0),
                            0, n_points - 1))
            err = np.abs(measured - q[k])
            max_err = np.maximum(max_err, err) if state in (STATE_MOVING, STATE_DONE) else max_err
            over = err > bound
            if np.any(over) and state in (STATE_MOVING, STATE_DONE):
                j = int(np.argmax(err / bound))
                stopped = self.stop()
                raise RobotFault(f"tracking error of {self.joint_names[j]} is {err[j]:.4f}, above the bound "
                                 f"{bound[j]:.4f}, at setpoint {k} of {n_points}; the robot was stopped",
                                 kind="tracking", joint=self.joint_names[j], value=float(err[j]),
                                 bound=float(bound[j]), stopped=stopped,
                                 hint="check the drives and the load; completed scans are kept")
            if state == STATE_DONE:
                t_done = t_done if t_done is not None else now
                final = np.abs(measured - q[-1])
                if np.all(final <= settle):
                    return ExecutionReport(duration=duration, settle_time=now - t_done, max_tracking_error=max_err,
                                           final_error=final, settled=True)
                if now - t_done > cfg.settle_timeout:
                    return ExecutionReport(duration=duration, settle_time=now - t_done, max_tracking_error=max_err,
                                           final_error=final, settled=False)
            elif now - t0 > duration + cfg.time_margin:
                stopped = self.stop()
                raise RobotFault(f"the motion did not complete within {duration + cfg.time_margin:.1f} s "
                                 f"(PLC state {STATE_NAMES.get(state, state)}, setpoint {index} of {n_points}); "
                                 "the robot was stopped", kind="timeout", stopped=stopped,
                                 hint="check the PLC program and the drives; completed scans are kept")
            time.sleep(cfg.poll)

    # ------------------------------------------------------------------ stopping
    def stop(self) -> bool:
        """Command the robot to stop (decelerate and hold); True when the PLC took it."""
        try:
            self._write("stop", True, self._pyads.PLCTYPE_BOOL)
            return True
        except Exception:  # noqa: BLE001 (the connection may be gone; the PLC watchdog stops then)
            return False

    def _lost(self, exc: Exception) -> RobotFault:
        stopped = self.stop()
        return RobotFault(f"lost the connection to the PLC ({ads_error_text(exc)}); "
                          + ("the robot was stopped" if stopped else
                             f"the stop command did not arrive, the PLC watchdog stops the axes after "
                             f"{self.config.watchdog:g} s"), kind="connection", stopped=stopped,
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
        """Stop the robot, then close the connection (idempotent)."""
        if self.plc is None:
            return
        self.stop()
        self._close_quietly()
        self.plc = None
