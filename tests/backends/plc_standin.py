"""A stand-in for the cell's PLC program on pyads' own ADS test server (loopback): the recon
symbol contract of recon_cli/backends/hardware/ads.py and a simulated drive that tracks the
setpoints with a first-order lag. Faults are injected by the tests.

Known quirks of pyads' test server, handled here: ``start()`` returns before the server
listens (we wait until a TCP connect succeeds), unknown symbols time out instead of
answering an ADS error (every symbol of the contract is created up front), and requests
larger than the server's receive buffer break (the contract downloads setpoints in chunks).
"""

from __future__ import annotations

import socket
import struct
import threading
import time
from dataclasses import dataclass

import numpy as np
from pyads import constants
from pyads.testserver import AdsTestServer, AdvancedHandler, PLCVariable

PREFIX = "MAIN.recon"
NC_FOLLOWING_ERROR = 0x4550  # TwinCAT NC: position lag monitoring (following error)


class _CycleHandler(AdvancedHandler):
    """Answers ADS requests between PLC cycles, as a real PLC does: a sum read sees the
    values of one cycle."""

    def __init__(self, lock: threading.Lock) -> None:
        super().__init__()
        self.lock = lock

    def handle_request(self, request):
        with self.lock:
            return super().handle_request(request)


@dataclass
class Faults:
    """Injected faults, as fractions of the trajectory (None: off)."""

    fault_at: float | None = None  # the PLC raises its error flag ...
    error_id: int = NC_FOLLOWING_ERROR  # ... with this error id
    freeze_at: float | None = None  # the drive stops moving, the PLC stays "moving"
    drift_at: float | None = None  # the drive stops following (tracking error grows)
    settle_offset: float | None = None  # at the goal the last axis holds this far off (it never settles)
    # at the goal the last axis swings around it: (amplitude, period in robot time [s]); it passes
    # through the goal twice a period and never comes to rest
    oscillate: tuple[float, float] | None = None
    ignore_chunks: bool = False
    motion: int | None = None  # only during this motion (1-based); None: every motion
    # garbage: from this fraction of a motion on (0: from the start, also at rest) the PLC publishes
    garbage_at: float | None = None
    measured_value: float | None = None  # ... this value as measured[measured_axis]
    measured_axis: int = 0
    state_value: int | None = None  # ... this state while it moves
    index_value: int | None = None  # ... this setpoint index while it moves


class PLCStandIn:
    def __init__(self, n: int, start: np.ndarray, port: int = 48898, chunk_points: int = 40, max_points: int = 20000,
                 speedup: float = 10.0, tau: float = 0.02) -> None:
        self.n, self.chunk_points, self.speedup, self.tau = n, chunk_points, speedup, tau
        self.lock = threading.Lock()
        self.handler = _CycleHandler(self.lock)
        self.faults = Faults()
        self.buffer = np.zeros((max_points, n))
        self.measured = np.asarray(start, dtype=float).copy()
        self.clock = 0.0  # [s] robot time: advances speedup x the cycle every PLC cycle
        self.log: list[tuple[float, int, np.ndarray, float]] = []  # (trajectory time, index, measured, clock) moving
        self.events: list[tuple[float, float, str]] = []  # (clock, time.monotonic(), what)
        self.received: list[np.ndarray] = []  # the setpoints of every started motion (PLC units and axis order)
        self.beats = 0  # heartbeat changes seen
        self.started = 0  # motions started
        self.crash: str | None = None
        self._garbage = False
        self._done_clock = 0.0  # robot time at which the last motion reached its end
        L, S16, D, U, B = constants.ADST_REAL64, constants.ADST_INT16, constants.ADST_INT32, constants.ADST_UINT32, \
            constants.ADST_BIT
        spec = {"chunk": (bytes(8 * chunk_points * n), L), "chunk_offset": (0, D), "chunk_count": (0, D),
                "chunk_seq": (0, U), "chunk_ack": (0, U), "count": (0, D), "period": (0.01, L), "job": (0, U),
                "job_ack": (0, U), "stop": (0, B), "heartbeat": (0, U), "watchdog": (0.5, L), "state": (0, S16),
                "index": (-1, D),
                "measured": (struct.pack(f"<{n}d", *self.measured), L), "error": (0, B), "error_id": (0, U)}
        for key, (value, ads_type) in spec.items():
            if ads_type == B:
                value = bytes([value])
            self.handler.add_variable(PLCVariable(f"{PREFIX}.{key}", value, ads_type, "T"))
        deadline = time.monotonic() + 15.0
        while True:  # the previous stand-in's sockets may hold the port for a moment
            try:
                self.server = AdsTestServer(handler=self.handler, logging=False, ip_address="127.0.0.1", port=port)
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.1)
        self.port = port
        self._run = threading.Event()
        self._thread = threading.Thread(target=self._loop, daemon=True)

    # ------------------------------------------------------------------ variables
    def _var(self, key):
        return self.handler.get_variable_by_name(f"{PREFIX}.{key}")

    def get(self, key: str, fmt: str):
        return struct.unpack("<" + fmt, self._var(key).value[: struct.calcsize("<" + fmt)])

    def set(self, key: str, fmt: str, *values) -> None:
        self._var(key).value = struct.pack("<" + fmt, *values)

    # ------------------------------------------------------------------ life
    def start(self) -> PLCStandIn:
        self.server.start()
        deadline = time.monotonic() + 10.0
        while True:  # start() returns before the server listens
            try:
                socket.create_connection(("127.0.0.1", self.port), timeout=0.2).close()
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.02)
        self._run.set()
        self._thread.start()
        return self

    def close(self) -> None:
        self._run.clear()
        self._thread.join(timeout=2.0)
        self.server.stop()

    def mark(self, what: str) -> None:
        """Record an event at the current robot time."""
        with self.lock:
            self.events.append((self.clock, time.monotonic(), what))

    def event(self, what: str) -> tuple[float, float] | None:
        """(clock, monotonic time) of the first event ``what``, or None."""
        return next(((c, w) for c, w, e in self.events if e == what), None)

    def drop_connection(self) -> None:
        """The network goes away: the server closes its sockets and stops listening."""
        self.mark("dropped")
        self.server.stop()

    def restore_connection(self) -> None:
        """The network comes back: a server on the same port answers again."""
        deadline = time.monotonic() + 10.0
        while True:
            try:
                self.server = AdsTestServer(handler=self.handler, logging=False, ip_address="127.0.0.1", port=self.port)
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.02)
        self.server.start()
        while True:
            try:
                socket.create_connection(("127.0.0.1", self.port), timeout=0.2).close()
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.01)
        self.mark("restored")

    def last_motion(self) -> float | None:
        """Robot time (clock) of the last cycle in which the axes moved, or None."""
        return self.log[-1][3] if self.log else None

    # ------------------------------------------------------------------ the PLC cycle
    def _loop(self) -> None:
        cycle = 0.002
        state, t, beat, beat_time = 0, 0.0, 0, time.monotonic()
        frozen_q, hold = None, self.measured.copy()
        while self._run.is_set():
            time.sleep(cycle)
            with self.lock:
                try:
                    state, t, beat, beat_time, frozen_q, hold = self._cycle(cycle, state, t, beat, beat_time,
                                                                            frozen_q, hold)
                except Exception:  # a bug of the stand-in must not look like a PLC that does nothing
                    import traceback

                    self.crash = traceback.format_exc()
                    raise

    def _cycle(self, cycle, state, t, beat, beat_time, frozen_q, hold):
        now = time.monotonic()
        self.clock += cycle * self.speedup
        seq, = self.get("chunk_seq", "I")
        ack, = self.get("chunk_ack", "I")
        if seq != ack and not self.faults.ignore_chunks:
            offset, = self.get("chunk_offset", "i")
            count, = self.get("chunk_count", "i")
            rows = np.array(self.get("chunk", f"{self.chunk_points * self.n}d")).reshape(self.chunk_points, self.n)
            self.buffer[offset:offset + count] = rows[:count]
            self.set("chunk_ack", "I", seq)
        job, = self.get("job", "I")
        job_ack, = self.get("job_ack", "I")
        stop = self.get("stop", "B")[0]
        hb, = self.get("heartbeat", "I")
        if hb != beat:
            beat, beat_time = hb, now
            self.beats += 1
        watchdog, = self.get("watchdog", "d")
        count, = self.get("count", "i")
        period, = self.get("period", "d")
        f = self.faults
        if job != job_ack and count > 0 and not stop and state in (0, 2, 3):
            state, t, frozen_q = 1, 0.0, None
            self.started += 1
            self.log.clear()
            self.received.append(self.buffer[:count].copy())
            self.events.append((self.clock, now, f"started {self.started}"))
            self.set("index", "i", 0)
            self.set("job_ack", "I", job)
        if f.motion is not None and f.motion != self.started:
            f = Faults()
        frac = 0.0
        if state == 1:
            duration = (count - 1) * period
            frac = t / duration if duration > 0 else 1.0
            if stop:
                state = 3
                self.events.append((self.clock, now, "stopped by stop"))
            elif now - beat_time > watchdog:
                state = 3  # heartbeat lost: the axes stop
                self.events.append((self.clock, now, "stopped by watchdog"))
            else:
                if f.fault_at is not None and frac >= f.fault_at:
                    self.set("error", "B", 1)
                    self.set("error_id", "I", f.error_id)
                    state = 4
                    self.events.append((self.clock, now, "fault"))
                elif f.freeze_at is not None and frac >= f.freeze_at:
                    pass  # stuck: neither time nor the axes move on
                else:
                    t += cycle * self.speedup
                    k = min(int(t / period), count - 1)
                    s = min(t / period, count - 1)
                    lo = int(np.floor(s))
                    hi = min(lo + 1, count - 1)
                    q_d = self.buffer[lo] + (s - lo) * (self.buffer[hi] - self.buffer[lo])
                    if f.drift_at is not None and frac >= f.drift_at:
                        frozen_q = self.measured.copy() if frozen_q is None else frozen_q
                        q_d = frozen_q
                    alpha = 1.0 - np.exp(-cycle * self.speedup / self.tau)
                    self.measured = self.measured + alpha * (q_d - self.measured)
                    self.set("index", "i", k)
                    self.log.append((t, k, self.measured.copy(), self.clock))
                    if t >= duration:
                        state, hold = 2, self.buffer[count - 1].copy()
                        self._done_clock = self.clock
                        if f.settle_offset is not None:
                            hold[-1] += f.settle_offset
                        self.events.append((self.clock, now, "done"))
        elif state == 2:  # hold the goal: the axes converge
            alpha = 1.0 - np.exp(-cycle * self.speedup / self.tau)
            self.measured = self.measured + alpha * (hold - self.measured)
            if f.oscillate is not None:
                amplitude, period = f.oscillate
                self.measured[-1] = hold[-1] + amplitude * np.sin(2 * np.pi * (self.clock - self._done_clock) / period)
        if f.garbage_at is not None and (f.garbage_at == 0 or (state == 1 and frac >= f.garbage_at)):
            self._garbage = True
        published_state, measured = state, self.measured.copy()
        if self._garbage and f.garbage_at is not None:
            if f.measured_value is not None:
                measured[f.measured_axis] = f.measured_value
            if state == 1 and f.state_value is not None:
                published_state = f.state_value
            if state == 1 and f.index_value is not None:
                self.set("index", "i", f.index_value)
        self.set("state", "h", published_state)
        self.set("measured", f"{self.n}d", *measured)
        return state, t, beat, beat_time, frozen_q, hold
