"""Moves (views, camera poses, joint goals, home), scans and waits.

Every move is planned with OMPL, timed with toppra, checked and executed by the session's
acquisition; in a dry run it is planned from the previous planned configuration only.
A scan belongs to the move before it: when that move failed, the scan is skipped.
"""

from __future__ import annotations

import time

import numpy as np

from recon_cli.acquisition import view_record
from recon_cli.errors import PlanningError, ScriptError
from recon_cli.planning.planner import MotionPlanner
from recon_cli.robot.poses import named_configuration
from recon_cli.scripts import commands as C
from recon_cli.scripts.handlers import handles
from recon_cli.scripts.handlers.fragments import make_fragment
from recon_cli.scripts.state import CommandReport, CommandStatus, RunState


def _move_report(report: CommandReport, plan) -> None:
    report.details.update(planner=plan.planner, plan_time_s=plan.total_time,
                          trajectory_s=None if plan.trajectory is None else plan.trajectory.duration)


@handles(C.MoveView, C.MovePose)
def move_to_pose(state: RunState, cmd: C.Move, report: CommandReport) -> None:

    state.ensure_session()
    state.move_failed = False
    T = state.goal_pose(cmd)
    if state.dry_run:
        plan = MotionPlanner(state.cell, state.config.planner).plan_to_pose(state.planned_start(), T, state.rng)
        if not plan.ok or plan.trajectory is None:
            raise PlanningError(f"cannot plan the move: {plan.status.value} ({plan.message})",
                                hint="try another view or a longer planning time")
        state.q_planned = plan.trajectory.goal
        report.status = CommandStatus.PLANNED
        _move_report(report, plan)
        return
    move = state.acquisition.move_to_pose(T, what="view")
    state.last_view = (cmd, T)
    _move_report(report, move.plan)


@handles(C.MoveJoints)
def move_joints(state: RunState, cmd: C.MoveJoints, report: CommandReport) -> None:

    state.ensure_session()
    state.move_failed = False
    q = np.asarray(cmd.values, dtype=float)
    if len(q) != state.cell.kin.nq:
        raise ScriptError(f"{cmd.source}: <joints> has {len(q)} values, the {state.config.cell.name} "
                          f"cell has {state.cell.kin.nq} joints", hint="one value per joint, in URDF order")
    if cmd.unit == "deg":
        q = np.where(state.cell.limits.prismatic, q, np.radians(q))
    start = state.planned_start() if state.dry_run else state.station.robot.measured_joints()
    plan = MotionPlanner(state.cell, state.config.planner).plan_to_joints(start, q,
                                                                          seed=int(state.rng.integers(1 << 30)))
    if not plan.ok or plan.trajectory is None:
        raise PlanningError(f"cannot move to the joint goal: {plan.status.value} ({plan.message})",
                            hint="check the values against the soft joint limits and the collision model")
    _move_report(report, plan)
    if state.dry_run:
        state.q_planned = plan.trajectory.goal
        report.status = CommandStatus.PLANNED
        return
    state.station.robot.execute(plan.trajectory)
    state.last_view = None


@handles(C.MoveHome)
def move_home(state: RunState, cmd: C.MoveHome, report: CommandReport) -> None:

    state.ensure_session()
    home = named_configuration(state.config.cell.kind, "home", state.cell.joint_names)
    move_joints(state, C.MoveJoints(cmd.source, tuple(home), "rad"), report)


def execute_planned(state: RunState, cmd: C.Move, traj, report: CommandReport) -> None:
    """A move of an optimized sequence: its planned trajectory, or (when the optimizer
    found no path, ``traj`` False) a normal planning request from where the robot is."""
    if traj is False:
        move_to_pose(state, cmd, report)
        return
    state.move_failed = False
    report.details.update(planner="sequence", trajectory_s=traj.duration)
    if state.dry_run:
        state.q_planned = traj.goal
        report.status = CommandStatus.PLANNED
        return
    q = state.station.robot.measured_joints()
    if np.max(np.abs(q - traj.start)) > 1e-3:  # not where the plan starts: plan afresh
        move_to_pose(state, cmd, report)
        return
    state.station.robot.execute(traj)
    state.last_view = (cmd, state.goal_pose(cmd))


@handles(C.Scan)
def scan(state: RunState, cmd: C.Scan, report: CommandReport) -> None:

    if state.move_failed:
        report.status, report.message = CommandStatus.SKIPPED, "the move before it failed"
        return
    if state.skipped_in_dry_run(report):
        return
    state.ensure_session()
    last = state.last_view
    view = last[0].view if last and isinstance(last[0], C.MoveView) else None
    T = last[1] if last else state.cell.kin.world_T_camera(state.station.robot.measured_joints())
    s = state.acquisition.scan(view_record(view, T), name=cmd.name, written=False)
    report.details.update(scan=s.index, points=int(np.count_nonzero(s.depth > 0)))
    state.registered = None  # a new scan invalidates earlier registration results
    # its pose and cloud now, while its images are in memory and it is being written: the
    # registration reuses them
    try:
        state.memo.keep(s, state.config.registration, state.store.session())
    finally:
        state.acquisition.settle()
    if isinstance(cmd, C.FragmentScan):

        make_fragment(state, cmd.name or f"scan_{s.index:04d}", s, report)


@handles(C.Wait)
def wait(state: RunState, cmd: C.Wait, report: CommandReport) -> None:
    if state.dry_run:
        report.message = "dry run: no wall-clock wait"
        return
    caps = state.ensure_session().capabilities
    if caps is None or not caps.wall_clock:
        report.message = "no physical robot or camera: the robot holds its pose; no wall-clock wait"
    else:  # pragma: no cover - hardware only
        time.sleep(cmd.seconds)
