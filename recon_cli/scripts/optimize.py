"""Sequence optimization of a script's moves (thesis 2.3): which moves may be reordered, and
their order by the view graph (IK per view, graph optimization, tour).

A run of at least two camera moves, each followed only by its scans, may be reordered
(scans are independent); anything else (set-up, joint moves, waits, registration, the
``<turn_over/>``) keeps its place and splits the runs: no move crosses the turn, and each
side's moves are ordered on their own. The tour's planned trajectories are returned with
it, so the run executes exactly what was planned (no edge is planned twice).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

import numpy as np

from recon_cli.errors import ReconError
from recon_cli.planning.lower_bound import duration_lower_bound
from recon_cli.planning.planner import MotionPlanner
from recon_cli.robot.ik import IKOptions
from recon_cli.scripts import commands as C
from recon_cli.scripts.state import RunState, SequenceMethod, SequenceReport
from recon_cli.sequence.graph import ViewGraph
from recon_cli.sequence.optimize import local_search_sequence, optimize_graph
from recon_cli.sequence.tsp import lazy_mst_sequence

if TYPE_CHECKING:
    from recon_cli.planning.trajectory import Trajectory
    from recon_cli.sequence.graph import ViewGraph


def movable_groups(commands: tuple[C.Command, ...]) -> dict[int, int]:
    """Runs of at least two camera moves, each followed only by its scans: {first index:
    end index}."""
    groups, k, n = {}, 0, len(commands)
    while k < n:
        start, moves = k, 0
        while k < n and isinstance(commands[k], C.Move):
            k += 1
            moves += 1
            while k < n and isinstance(commands[k], C.Scan):
                k += 1
        if moves >= 2:
            groups[start] = k
        k = max(k, start + 1) if moves == 0 else k
    return groups


def units(commands) -> list[tuple[C.Move, list[C.Command]]]:
    """(move, its scans) of a movable group."""
    out: list[tuple[C.Move, list[C.Command]]] = []
    for cmd in commands:
        if isinstance(cmd, C.Move):
            out.append((cmd, []))
        else:
            out[-1][1].append(cmd)
    return out


@dataclass(frozen=True)
class PlannedStep:
    move: C.Move
    scans: list[C.Command]
    vertex: int  # the view's vertex in the graph (0: where the robot started)


@dataclass(frozen=True)
class Tour:
    steps: list[PlannedStep]  # in tour order
    failed: list[tuple[C.Move, list[C.Command], ReconError]]  # moves without an IK solution
    report: SequenceReport | None
    graph: ViewGraph | None = None  # with the planned edges

    def trajectory(self, a: int, b: int) -> Trajectory | Literal[False]:
        """The planned trajectory from vertex a to b, or False (plan it at run time)."""
        traj = self.graph.trajectory(a, b) if self.graph is not None else None
        return traj if traj is not None else False


def plan_tour(state: RunState, group: list[tuple[C.Move, list[C.Command]]]) -> Tour:
    """Order a group's moves with the sequence optimizer, starting where the robot is."""

    state.ensure_session()
    cell, rng, plan = state.cell, state.rng, state.config.planner
    q0 = state.q_planned if state.dry_run else state.station.robot.measured_joints()
    configs, kept, poses, failed = [np.asarray(q0, dtype=float)], [], [], []
    for move, scans in group:
        try:  # each view's IK seeded with the previous view's solution (as the thesis)
            T = state.goal_pose(move)
            ik = cell.solve_pose(T, rng, seed=configs[-1], options=IKOptions(max_solutions=1))
        except ReconError as exc:  # reported in script order, like any failed move
            failed.append((move, scans, exc))
            continue
        configs.append(ik.solutions[0].q)
        kept.append((move, scans))
        poses.append(T)
    if not kept:
        return Tour([], failed, None)
    lim = cell.limits

    def lower(a, b):
        return duration_lower_bound(a, b, lim.velocity, lim.acceleration, plan.velocity_scale,
                                    plan.acceleration_scale)

    def redraw(v):
        try:
            r = cell.solve_pose(poses[v - 1], rng, options=IKOptions(max_solutions=1))
        except ReconError:
            return None
        return r.solutions[0].q

    planner = MotionPlanner(cell, plan)

    def plan_edge(a, b):
        r = planner.plan_to_joints(a, b, seed=int(rng.integers(1 << 30)))
        return r.trajectory if r.ok else None

    t = time.perf_counter()
    graph, draws = optimize_graph(ViewGraph(configs, lower), redraw, k_max=120)
    if state.options.sequence_method is SequenceMethod.THESIS:
        result = lazy_mst_sequence(graph, plan_edge, beta=1.5)
    else:
        result = local_search_sequence(graph, plan_edge, beta=1.5, request_cost=10.0)
    script_order = list(range(graph.size))
    report = SequenceReport(
        moves=len(kept), method=SequenceMethod(state.options.sequence_method), ik_draws=draws,
        order=[str(kept[v - 1][0].source) + f" #{v}" for v in result.order[1:]],
        planned_duration_s=result.duration, planning_requests=result.requests,
        script_order_lower_bound_s=float(sum(graph.lower_bound(graph.configs[a], graph.configs[b])
                                             for a, b in zip(script_order[:-1], script_order[1:], strict=True))),
        seconds=time.perf_counter() - t)
    steps = [PlannedStep(*kept[v - 1], v) for v in result.order[1:]]
    return Tour(steps, failed, report, graph)
