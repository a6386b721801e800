"""Resuming a 1 kHz stream after lost cycles, judged as a Franka controller judges it: the
backward differences of the commands it applied (its own constant-acceleration extrapolation
for the cycles it did not hear from the client), one cycle apart, or over the cycles since its
last applied command when it threw its extrapolation away for a late command."""

from __future__ import annotations

import numpy as np
import pytest

from recon_cli.backends.hardware.resume import HistoryMatch, Reference, Resumption, continues, match_history, torn
from recon_cli.backends.hardware.setpoint_stream import jerk_share_for, setpoint_stream
from recon_cli.planning.trajectory import parameterize
from recon_cli.robot.cell import Cell
from recon_cli.robot.description import CellConfig, CellName

DT = 0.001
HOME = np.radians([0.0, -10.0, 0.0, -130.0, 0.0, 110.0, 0.0])
GOAL = HOME + np.radians([25.0, 8.0, -15.0, 12.0, 30.0, -15.0, 45.0])


@pytest.fixture(scope="module")
def fr3() -> Cell:
    return Cell(CellConfig(kind=CellName.parse("fr3")))


@pytest.fixture(scope="module")
def stream(fr3):
    lim = fr3.kin.limits
    traj = parameterize(np.array([HOME, GOAL]), lim.velocity, lim.acceleration, 0.6, 0.6)
    return setpoint_stream(traj, lim, fr3.joint_names, DT, jerk_share_for(3))


class Controller:
    """The controller's history as the FCI keeps it: value, first and second backward
    difference of the last applied command; a missed cycle extrapolated at constant
    acceleration (semi-implicit, as franka-sim does); what it reports as q_d, dq_d, ddq_d."""

    def __init__(self, q: np.ndarray) -> None:
        self.x, self.v, self.a = q.copy(), np.zeros_like(q), np.zeros_like(q)
        self.peaks = np.zeros((3, q.size))

    def apply(self, q: np.ndarray, cycles: int = 1) -> None:
        v = (q - self.x) / (cycles * DT)
        a = (v - self.v) / (cycles * DT)
        j = (a - self.a) / (cycles * DT)
        self.peaks = np.maximum(self.peaks, np.abs([v, a, j]))
        self.x, self.v, self.a = q.copy(), v, a

    def extrapolate(self) -> None:
        self.v = self.v + self.a * DT
        self.x = self.x + self.v * DT

    def reported(self, float32: bool = True) -> Reference:
        cast = (lambda x: x.astype(np.float32).astype(float)) if float32 else (lambda x: x)
        return Reference(cast(self.x), cast(self.v), cast(self.a))


def _within(peaks: np.ndarray, lim, share: float = 1.0) -> bool:
    return bool(np.all(peaks[0] <= share * lim.velocity) and np.all(peaks[1] <= share * lim.acceleration)
                and np.all(peaks[2] <= share * lim.jerk))


def _run(stream, lim, gap_at: int, gap: int, resume: bool, late: int = 0) -> Controller:
    """Stream to the controller with ``gap`` cycles unanswered from ``gap_at``; ``late``: the
    last answer before the gap came ``late`` cycles after its cycle (applied then, its
    extrapolation thrown away). The client then answers from the reference (``resume``) or
    jumps back onto the stream."""
    q = stream.q
    ctl = Controller(q[0])
    resumption = Resumption(stream, lim)
    sent = np.zeros((0, 7))
    cycles = np.zeros(0, dtype=np.int64)
    blend, blend_at = None, 0
    saved = (ctl.x.copy(), ctl.v.copy(), ctl.a.copy())  # the history after the answer to gap_at - 1
    k = 0
    while k < len(q) + 300:
        index = min(k, len(q) - 1)
        if k == gap_at:
            for _ in range(gap):
                ctl.extrapolate()
            if late:  # the late answer to gap_at - 1 lands after `late` extrapolated cycles: rewound onto it
                ctl.x, ctl.v, ctl.a = saved
                ctl.extrapolate()  # the next missed cycle, from the rewound history
                lag = late
            else:
                lag = 0
            k += gap
            index = min(k, len(q) - 1)
            if resume:
                ref = ctl.reported()
                age = match_history(ref, sent, cycles, k, DT).age
                command, blend = resumption.resume(ref, age, index)
                blend_at = k
            else:
                command = q[index]
            ctl.apply(command, cycles=1 + lag)
        else:
            if blend is not None and k - blend_at <= len(blend):
                command = resumption.planned(index) + blend[k - blend_at - 1]
            else:
                command = q[index]
            ctl.apply(command)
        if k == gap_at - 1:
            saved = (ctl.x.copy(), ctl.v.copy(), ctl.a.copy())
        sent = np.vstack([sent, command])[-64:]
        cycles = np.append(cycles, k)[-64:]
        k += 1
    assert np.allclose(ctl.x, q[-1], atol=1e-9)  # the motion ends at the goal
    return ctl


@pytest.mark.parametrize("gap", [2, 4, 8, 15])
def test_resuming_from_the_reference_stays_within_the_limits(fr3, stream, gap):
    lim = fr3.kin.limits
    # where the stream's jerk is largest: the worst place to lose cycles
    at = int(np.argmax(np.abs(np.diff(stream.q, 3, axis=0)).max(axis=1))) + 1
    assert _within(_run(stream, lim, at, gap, resume=True).peaks, lim, 0.95)
    if gap >= 4:  # jumping back onto the stream: a jerk over the limit
        assert not _within(_run(stream, lim, at, gap, resume=False).peaks, lim)


@pytest.mark.parametrize("late", [2, 5])
def test_a_late_answer_the_controller_rewound_to_is_matched_and_resumed(fr3, stream, late):
    """The controller applied the late answer and extrapolated from it: its history is
    ``late`` cycles older than the cycle answered next; the match finds the age and the resumed
    command is differenced over it within the limits."""
    lim = fr3.kin.limits
    at = len(stream.q) // 3
    assert _within(_run(stream, lim, at, late + 1, resume=True, late=late).peaks, lim, 0.95)


@pytest.mark.parametrize("at", [4, 5, 7, 10])
def test_a_late_answer_in_the_first_cycles_of_a_motion(fr3, at):
    """In a motion's first cycles the arm is nearly at rest: walking the reference back, the
    chain passes within the match tolerance of older commands at other ages. The newest
    command it matches is the one applied (the youngest match among all was wrong here: a
    jerk reflex in 12 of these 36 places)."""
    lim = fr3.kin.limits
    traj = parameterize(np.array([HOME, GOAL]), lim.velocity, lim.acceleration, 0.6, 0.6)
    # as the adapter streams it: from the controller's commanded joints, blended in
    stream = setpoint_stream(traj, lim, fr3.joint_names, DT, jerk_share_for(3), start=HOME + 1e-7)
    for late in (1, 2, 4):
        assert _within(_run(stream, lim, at, late + 1, resume=True, late=late).peaks, lim, 0.95)


def test_history_match_of_a_reference_and_its_extrapolations():
    rng = np.random.default_rng(1)
    sent = np.cumsum(rng.normal(0.0, 1e-4, (12, 7)), axis=0) + 1.0
    cycles = np.arange(100, 112)
    ctl = Controller(sent[-3])
    ctl.apply(sent[-2])
    ctl.apply(sent[-1])
    assert match_history(ctl.reported(), sent, cycles, 112, DT) == HistoryMatch(1, 111)  # answered on time
    for _ in range(4):
        ctl.extrapolate()
    assert match_history(ctl.reported(), sent, cycles, 116, DT) == HistoryMatch(1, 111)  # 4 extrapolated
    assert match_history(ctl.reported(), sent, cycles, 120, DT) == HistoryMatch(5, 111)  # 4 cycles behind
    # a reference that is no command sent (the motion's start, a hold): the ordinary single cycle
    nowhere = Reference(np.zeros(7), np.zeros(7), np.zeros(7))
    assert match_history(nowhere, sent, cycles, 112, DT) == HistoryMatch(1, None)
    # at rest every hypothesis matches: the newest command, the youngest age
    rest = np.ones((12, 7))
    still = Reference(np.ones(7), np.zeros(7), np.zeros(7))
    assert match_history(still, rest, cycles, 130, DT) == HistoryMatch(1, 111)


def test_a_chain_that_turns_around_near_rest_is_matched_where_its_predecessors_are():
    """A motion's first cycles, as franka-sim reported them: the answer to cycle 2 arrived
    after four cycles were extrapolated, was applied in their place and extrapolated once,
    and the state of cycle 7 reports that. Walked back at its constant acceleration the
    chain passes through the answer one cycle back (and through the two commands before it,
    a cycle further each), turns around and passes 3.2e-7 rad from it again four cycles
    back: matched there, the resumed command was a jerk reflex (5141 rad/s^3)."""
    start = np.radians([0.0, -10.0, 0.0, -130.0, 0.0, 110.0, 0.0])
    sent = np.tile(start, (3, 1))
    sent[:, 0] = [0.6983225345, 0.6983224295, 0.6983220095]  # joint 1 starting to move
    reported = Reference(np.r_[0.6983212828636169, start[1:]].astype(np.float32).astype(float),
                         np.r_[-0.0007349993684329093, np.zeros(6)], np.r_[-0.3149997293949127, np.zeros(6)])
    assert match_history(reported, sent, np.arange(3), 7, DT) == HistoryMatch(4, 2)


def test_a_state_continues_the_command_answered_before_it_only_when_it_applied_it_in_time():
    """The reference of the state after a command is that command, with the velocity of its
    backward difference, when the controller applied it in time (within 32-bit rounding);
    not when it extrapolated instead, nor when it applied it late over the gap since the
    command before (franka-sim's rewind), though the value is then the same."""
    q0 = HOME + 0.3
    ctl = Controller(q0)
    velocity = np.linspace(-0.8, 0.8, 7)
    for k in range(1, 4):
        ctl.apply(q0 + velocity * k * DT * k / 3)
    before = ctl.x.copy()
    applied = Controller(q0)
    applied.x, applied.v, applied.a = ctl.x.copy(), ctl.v.copy(), ctl.a.copy()
    command = before + (ctl.v + ctl.a * DT) * DT + 1e-6  # not quite the extrapolation
    applied.apply(command)
    assert continues(applied.reported(), command, (command - before) / DT, DT)
    missed = Controller(q0)
    missed.x, missed.v, missed.a = ctl.x.copy(), ctl.v.copy(), ctl.a.copy()
    missed.extrapolate()
    assert not continues(missed.reported(), command, (command - before) / DT, DT)
    late = Controller(q0)
    late.x, late.v, late.a = ctl.x.copy(), ctl.v.copy(), ctl.a.copy()
    late.apply(command, cycles=6)  # the same value, differenced over six cycles
    assert np.array_equal(late.reported().q, applied.reported().q)
    assert not continues(late.reported(), command, (command - before) / DT, DT)


def test_a_state_read_while_it_was_written_is_told_apart(fr3, stream):
    """The new position with the previous cycle's velocity (franka-sim publishes q_d, then
    dq_d, from another thread) is torn: a command continuing it would be a jerk of the
    acceleration over one cycle. A state applied in time, an extrapolation and a late
    command's reference are not torn."""
    q = stream.q
    i = int(np.argmax(np.abs(np.diff(q, 2, axis=0)).max(axis=1)))  # where the stream accelerates most
    ctl = Controller(q[0])
    for k in range(i + 1):
        ctl.apply(q[k])
    previous = ctl.reported(float32=False)
    ctl.apply(q[i + 1])
    applied_dq = (q[i + 1] - q[i]) / DT
    assert not torn(ctl.reported(), q[i + 1], applied_dq, DT)
    mixed = Reference(ctl.reported().q, previous.dq, ctl.reported().ddq)
    assert torn(mixed, q[i + 1], applied_dq, DT)
    # answered from, its jerk would be the acceleration over one cycle: above the limit
    command = Resumption(stream, fr3.kin.limits).command(mixed, 1)
    v = (command - q[i + 1]) / DT
    jerk = ((v - applied_dq) / DT - ctl.a) / DT
    assert np.max(np.abs(jerk) / fr3.kin.limits.jerk) > 1.0
    ctl.extrapolate()
    assert not torn(ctl.reported(), q[i + 2], (q[i + 2] - q[i + 1]) / DT, DT)  # another position


def test_a_reference_names_what_makes_it_unusable():
    good = Reference(np.zeros(7), np.zeros(7), np.zeros(7))
    assert good.problem() is None
    bad_q = np.zeros(7)
    bad_q[4] = np.inf
    assert Reference(bad_q, np.zeros(7), np.zeros(7)).problem() == "its reference q_d of joint 5 is inf"
    bad_ddq = np.zeros(7)
    bad_ddq[0] = np.nan
    assert Reference(np.zeros(7), np.zeros(7), bad_ddq).problem() == "its reference ddq_d of joint 1 is nan"
    assert Reference(np.zeros(7), np.zeros(6), np.zeros(7)).problem() == "its reference dq_d has 6 values, not 7"


def test_the_blend_tables_are_made_with_the_resumption_not_in_the_loop(fr3, stream):
    from recon_cli.backends.hardware import resume

    resume._blends.cache_clear()
    Resumption(stream, fr3.kin.limits)
    assert resume._blends.cache_info().currsize == 1


def test_the_chosen_blend_is_the_shortest_whose_differences_fit_the_budgets(fr3, stream):
    """The blend table checks every blend's first, second and third differences at once; the
    choice is the one of checking each blend and order on its own: the shortest blend whose
    velocity, acceleration and jerk stay within what the stream leaves of each limit (the
    longest when none does). The answering command alone is :meth:`Resumption.command`."""
    from recon_cli.backends.hardware.resume import BLEND_CYCLES, LIMIT_SHARE, _quintic

    lim = fr3.kin.limits
    resumption = Resumption(stream, lim)
    peaks = (stream.peak_velocity, stream.peak_acceleration, stream.peak_jerk)
    budgets = [np.maximum(LIMIT_SHARE * limit - peak, (1.0 - LIMIT_SHARE) * limit) * DT ** (order + 1)
               for order, (limit, peak) in enumerate(zip((lim.velocity, lim.acceleration, lim.jerk), peaks,
                                                         strict=True))]
    rng = np.random.default_rng(5)
    chosen = set()
    for _ in range(300):
        i = int(rng.integers(3, len(stream.q)))
        scale = 10.0 ** rng.uniform(-8, -4)
        q = stream.q
        ref = Reference(q[i - 1] + rng.normal(0, scale, 7), (q[i - 1] - q[i - 2]) / DT + rng.normal(0, scale / DT, 7),
                        (q[i - 1] - 2 * q[i - 2] + q[i - 3]) / DT**2 + rng.normal(0, scale / DT**2, 7))
        age = int(rng.integers(1, 5))
        command, blend = resumption.resume(ref, age, i)
        assert np.array_equal(command, resumption.command(ref, age))
        velocity = ref.dq + ref.ddq * (age * DT)
        before = command - velocity * DT
        offsets = np.vstack([before - (velocity - ref.ddq * DT) * DT, before, command]) - \
            q[np.clip(np.arange(i - 2, i + 1), 0, len(q) - 1)]
        expected = len(BLEND_CYCLES) - 1
        for k, cycles in enumerate(BLEND_CYCLES):
            series = np.vstack([offsets, _quintic(cycles) @ offsets])
            if all(np.all(np.abs(np.diff(series, order + 1, axis=0)).max(axis=0) <= budget * (1 + 1e-12))
                   for order, budget in enumerate(budgets)):
                expected = k
                break
        assert len(blend) == BLEND_CYCLES[expected]
        chosen.add(expected)
    assert len(chosen) >= 4  # the draws reach short and long blends
