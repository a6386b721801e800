"""Resuming a setpoint stream after controller cycles the client did not answer.

A controller with a fixed command rate (Franka's FCI at 1 kHz) judges each command by its
backward finite differences against the commands it applied before. A cycle the client does
not answer in time is extrapolated by the controller at constant acceleration, and the
controller reports the reference it applied in every state (Franka: ``q_d``, ``dq_d``,
``ddq_d``). Jumping back onto the planned stream after such a gap makes a jerk as large as
the stream's own jerk times ``(n + 1)^3 / 6`` after ``n`` lost cycles, which is over the
limit after a few milliseconds of silence.

So a client resumes from the controller's reference instead:

* :func:`match_history` finds the command the reported reference continues and how many
  cycles lie between the controller's last applied command and the cycle about to be
  answered: normally one, more when a controller (or a simulator of one) threw its
  extrapolation away for a command that arrived late. It walks the reported reference back
  along its constant-acceleration chain and matches it against the commands the client sent:
  the newest command it matches (an older one can match too where the arm was nearly at
  rest, in a motion's first cycles), at the step where the commands before it lie on the
  chain too (near rest the chain turns around and passes near the same command again).
* :class:`Resumption` makes the first command continue that reference with a zero third
  difference over those cycles, then blends from the extrapolated motion back onto the
  planned stream with a quintic (value, velocity and acceleration of the offset matched at
  the start, all three zero at the end), the shortest blend whose own velocity,
  acceleration and jerk fit into what the stream leaves of the limits.

Everything is in discrete time, as the controller differences it: the first command's
differences over the gap are the reference's own, and the blend is fitted through the last
three samples of the reference, so its finite differences are those of a smooth polynomial.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from recon_cli.backends.hardware.setpoint_stream import SetpointStream
from recon_cli.robot.limits import JointLimits

#: blend lengths tried, shortest first [cycles]
BLEND_CYCLES = (6, 8, 12, 16, 24, 32, 48, 64, 96, 128, 192, 256)
#: share of each limit the stream and a blend together may use
LIMIT_SHARE = 0.9
#: the most recent commands sent that a reported reference is matched against
RECENT = 8
#: the oldest reference a match is looked for [cycles] (the controller stops a motion after 20 lost)
MAX_AGE = 32
#: a reported reference matches a sent command within one unit in the last place of a 32-bit
#: float at the joint's value (Franka's state may carry ``q_d`` as 32-bit floats: half a unit
#: of rounding) plus this, for the chain's own arithmetic on rounded ``dq_d``/``ddq_d`` [rad]
MATCH_FLOOR = 1e-8
#: the commands before a matched one that are checked against the chain too: a chain that
#: passes through a command and its predecessors, a cycle apart each, is the controller's
#: history; one that only passes near a command (a constant-acceleration chain turns around
#: near rest and comes back) is not
PREDECESSORS = 2


@dataclass(frozen=True)
class Reference:
    """The controller's applied reference of one state: joints, velocity and acceleration
    (the backward differences it judges the next command against)."""

    q: npt.NDArray[np.float64]
    dq: npt.NDArray[np.float64]
    ddq: npt.NDArray[np.float64]

    def problem(self, joints: int = 7) -> str | None:
        """What makes this reference unusable for a resumption (a wrong size or a value that
        is not finite), as text naming the field and the joint; None when it is usable."""
        if (self.q.shape == self.dq.shape == self.ddq.shape == (joints,)
                and np.isfinite(self.q).all() and np.isfinite(self.dq).all() and np.isfinite(self.ddq).all()):
            return None
        for name, value in (("q_d", self.q), ("dq_d", self.dq), ("ddq_d", self.ddq)):
            if value.shape != (joints,):
                return f"its reference {name} has {value.size} values, not {joints}"
            bad = np.flatnonzero(~np.isfinite(value))
            if bad.size:
                return f"its reference {name} of joint {int(bad[0]) + 1} is {value[bad[0]]}"
        return None


@dataclass(frozen=True)
class HistoryMatch:
    """Which command the controller's reported reference continues: ``age``, the cycles
    between the controller's last applied command and the cycle about to be answered, and
    ``command_cycle``, the cycle the matched command answered (None: it matches no command
    sent, and ``age`` is 1)."""

    age: int
    command_cycle: int | None


def match_tolerance(q: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Per joint: how close a reference's chain must come to a sent command to match it [rad]."""
    spacing: npt.NDArray[np.float64] = np.spacing(np.abs(q).astype(np.float32)).astype(float) + MATCH_FLOOR
    return spacing


def match_history(ref: Reference, sent: npt.NDArray[np.float64], sent_cycles: npt.NDArray[np.int64], cycle: int,
                  dt: float) -> HistoryMatch:
    """The command the controller's reference ``ref`` continues and how old its history is at
    ``cycle`` (the cycle of the state that reported ``ref``, which the next command answers):
    age 1 when the reference is a command the client sent, or its extrapolation, as old as the
    gap since. ``sent`` (R, n) and ``sent_cycles`` (R,): the commands sent and the cycles they
    answered."""
    if len(sent) == 0:
        return HistoryMatch(1, None)
    if len(sent) > RECENT:
        recent = np.argsort(sent_cycles)[-RECENT:]
        sent, sent_cycles = sent[recent], sent_cycles[recent]
    back = min(max(cycle - int(sent_cycles.min()), 0), MAX_AGE + RECENT)
    # the reference walked back along its constant-acceleration chain: chain[j] is the value
    # j cycles before (semi-implicit Euler backwards: x_j-1 = x_j - v_j dt, v_j-1 = v_j - a dt,
    # summed: x_j = x_0 - j dt v_0 + j (j - 1) / 2 dt^2 a)
    steps_back, triangle = _chain_steps(back + PREDECESSORS)
    chain = ref.q - steps_back * (ref.dq * dt) + triangle * (ref.ddq * (dt * dt))
    close: npt.NDArray[np.bool_] = np.all(np.abs(chain[:, None, :] - sent[None, :, :]) <= match_tolerance(ref.q),
                                          axis=2)  # (J, R)
    # a match at chain step j with command r: the controller applied r, then extrapolated j cycles
    valid: npt.NDArray[np.bool_] = close[:back + 1] & (sent_cycles[None, :] + steps_back[:back + 1] < cycle)
    matched: list[bool] = np.any(valid, axis=0).tolist()
    if not any(matched):
        return HistoryMatch(1, None)
    # the newest command matched is the last one applied: an older one can match too where the
    # arm was nearly at rest (the motion's first cycles), at a place the chain only passes near
    cycles = sent_cycles.tolist()
    r = -max((c, -i) for i, (c, m) in enumerate(zip(cycles, matched, strict=True)) if m)[1]
    steps = np.flatnonzero(valid[:, r])
    # of its matches, those whose predecessors lie on the chain too, a cycle further back each;
    # of those the youngest: at rest every step matches, and a longer age would invent a step
    support = np.zeros(len(steps), dtype=int)
    column = {c: i for i, c in reversed(list(enumerate(cycles)))}  # a cycle's first column
    for k in range(1, PREDECESSORS + 1):
        before = column.get(cycles[r] - k)
        if before is not None:
            support += close[steps + k, before]
    step = int(steps[support == support.max()].max())
    return HistoryMatch(max(1, cycle - cycles[r] - step), cycles[r])


@functools.cache
def _chain_steps(last: int) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """(last + 1, 1) columns j and j (j - 1) / 2 for j = 0 .. last (the chain's coefficients)."""
    j = np.arange(last + 1, dtype=float)[:, None]
    return j, j * (j - 1.0) / 2.0


def applied_as(ref: Reference, q: npt.NDArray[np.float64], dq: npt.NDArray[np.float64],
               dt: float) -> tuple[bool, bool]:
    """Whether the controller's reported reference is the command ``q``, and whether its
    velocity is the ``dq`` the command's backward difference gives (each within the 32-bit
    rounding of the reported values and of the position the difference was taken from)."""
    tolerance = match_tolerance(q)
    same_q = bool(np.all(np.abs(ref.q - q) <= tolerance))
    same_dq = bool(np.all(np.abs(ref.dq - dq) <= np.spacing(np.abs(dq).astype(np.float32)) + tolerance / dt))
    return same_q, same_dq


def continues(ref: Reference, q: npt.NDArray[np.float64], dq: npt.NDArray[np.float64], dt: float) -> bool:
    """Whether the controller's reported reference is the command ``q`` applied on time, with
    the velocity ``dq`` its backward difference gives (:func:`applied_as`). It is not when the
    command came too late for the state (the controller extrapolated instead) or when the
    controller applied a late command over another interval (franka-sim does): the next
    command then answers from the reference, not from the stream."""
    same_q, same_dq = applied_as(ref, q, dq, dt)
    return same_q and same_dq


def torn(ref: Reference, q: npt.NDArray[np.float64], dq: npt.NDArray[np.float64], dt: float) -> bool:
    """Whether the reported reference is the command ``q`` but not the velocity ``dq`` its
    difference gives (:func:`applied_as`), when the state before it reported the command
    answered before ``q``: nothing a controller applied on time or extrapolated has that
    velocity. A state written while it was read gives it (franka-sim publishes ``q_d`` and then
    ``dq_d`` from another thread: read in between, the new position with the previous cycle's
    velocity); answered from, the command's jerk is the acceleration over one cycle."""
    same_q, same_dq = applied_as(ref, q, dq, dt)
    return same_q and not same_dq


def _quintic(cycles: int) -> npt.NDArray[np.float64]:
    """(cycles, 3): the blend's samples at 1..cycles as a linear map of its values at -2, -1, 0,
    for the quintic through those three that ends at zero with zero slope and curvature."""
    s0 = np.array([-2.0, -1.0, 0.0]) / cycles
    powers = np.arange(6)
    a = np.vstack([s0[:, None] ** powers,
                   np.ones(6),
                   powers.astype(float),
                   (powers * (powers - 1)).astype(float)])
    inverse = np.linalg.inv(a)[:, :3]
    s = np.arange(1, cycles + 1, dtype=float) / cycles
    out: npt.NDArray[np.float64] = (s[:, None] ** powers) @ inverse
    return out


@dataclass(frozen=True)
class _Blends:
    """Every blend of BLEND_CYCLES: its samples, and the first, second and third differences
    of [reference's last three samples, blend] of all blends stacked in one table (``table``,
    (3, rows): a blend's rows together from ``starts``; ``orders`` the difference order of
    each row), checked against the limits in one product (rows along the last axis: the
    largest over the joints is then an elementwise maximum, not a reduction over 7 values)."""

    samples: list[npt.NDArray[np.float64]]
    table: npt.NDArray[np.float64]
    orders: npt.NDArray[np.int64]
    starts: npt.NDArray[np.int64]


@functools.cache
def _blends() -> _Blends:
    samples = [_quintic(k) for k in BLEND_CYCLES]
    rows: list[npt.NDArray[np.float64]] = []
    orders: list[npt.NDArray[np.int64]] = []
    starts: list[int] = []
    for q in samples:
        series = np.vstack([np.eye(3), q])  # (cycles + 3, 3)
        starts.append(sum(len(r) for r in rows))
        for order in (1, 2, 3):
            rows.append(np.diff(series, order, axis=0))
            orders.append(np.full(len(rows[-1]), order - 1))
    return _Blends(samples, np.ascontiguousarray(np.vstack(rows).T), np.concatenate(orders), np.array(starts))


class Resumption:
    """Resumes ``stream`` after lost cycles within ``limits`` (see the module)."""

    def __init__(self, stream: SetpointStream, limits: JointLimits) -> None:
        self.q = stream.q
        self.dt = stream.dt
        _blends()  # made now, not in the 1 kHz loop (its first making takes milliseconds)
        jerk = limits.jerk if limits.jerk is not None else np.full(limits.n, np.inf)
        floor = 1.0 - LIMIT_SHARE
        # what the stream leaves of each limit (at least a tenth of it), per finite difference order
        budgets = np.array([np.maximum(LIMIT_SHARE * np.asarray(limit, dtype=float) - peak, floor * limit)
                            * self.dt ** order
                            for order, limit, peak in ((1, limits.velocity, stream.peak_velocity),
                                                       (2, limits.acceleration, stream.peak_acceleration),
                                                       (3, jerk, stream.peak_jerk))])
        # per joint and row of the blend table, the reciprocal of what the row's order may use
        self._scale = np.ascontiguousarray((1.0 / budgets[_blends().orders]).T)

    def planned(self, index: int) -> npt.NDArray[np.float64]:
        """The stream's setpoint at ``index`` (its start before it, its goal after it)."""
        return self.q[min(max(index, 0), len(self.q) - 1)]

    def command(self, ref: Reference, age: int) -> npt.NDArray[np.float64]:
        """The command that continues ``ref``, which the controller reported as applied ``age``
        cycles before the cycle it answers: over those cycles its first difference is the
        reference's velocity carried on at its acceleration, its second the reference's own."""
        velocity = ref.dq + ref.ddq * (age * self.dt)
        command: npt.NDArray[np.float64] = ref.q + velocity * (age * self.dt)
        return command

    def blend(self, ref: Reference, age: int, index: int) -> npt.NDArray[np.float64]:
        """The offsets (K, n) to add to the setpoints ``index + 1 ... index + K`` after
        :meth:`command` answered setpoint ``index``: the shortest blend back onto the stream
        that fits into what the stream leaves of the limits (computed after the command went
        out: it is needed from the next cycle on)."""
        dt = self.dt
        velocity = ref.dq + ref.ddq * (age * dt)
        command = ref.q + velocity * (age * dt)
        # the command's last three samples as 1 ms steps with the same differences
        before = command - velocity * dt
        history = np.vstack([before - (velocity - ref.ddq * dt) * dt, before, command])
        offsets = history - self.q[np.clip(np.arange(index - 2, index + 1), 0, len(self.q) - 1)]
        blends = _blends()
        use = np.abs(offsets.T @ blends.table)  # (n, rows)
        use *= self._scale
        use = np.maximum.reduceat(use.max(axis=0), blends.starts)  # per blend, the largest share of a limit
        fits = use <= 1.0
        chosen = int(np.argmax(fits)) if fits.any() else len(BLEND_CYCLES) - 1
        offsets_blend: npt.NDArray[np.float64] = blends.samples[chosen] @ offsets
        return offsets_blend

    def resume(self, ref: Reference, age: int, index: int) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """:meth:`command` and :meth:`blend` together."""
        return self.command(ref, age), self.blend(ref, age, index)
