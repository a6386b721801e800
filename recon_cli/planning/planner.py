"""Collision-free motion planning with OMPL (thesis 2.2, 3.1).

A request goes from a start configuration to a joint goal or to a camera pose (any of
several IK solutions, OMPL goal states). The state space is the cell's joint space within
the soft limits; a state is valid when the collision model says it is free; a motion is
valid when every configuration on the straight segment is free at a resolution where no
robot point moves more than ``max_step`` between samples (``CollisionModel.segment_free``:
inflated copies of the robot prove stretches free, exact checks only where something is
near; batched in C++).
After the search the path is simplified (shortcutting, smoothing), time-
parameterized with toppra and checked once more along its dense course. Failures are
results (``PlanStatus``), never exceptions.

Repeatability: a request's ``seed`` decides its path. OMPL gives every random generator it
creates (planner, state sampler, nearest-neighbour structure, path simplifier) the next
number of one process-wide seed sequence; each search restarts that sequence from the
request's seed (:func:`restart_ompl_seeds`) before it creates them, and the simplification
from a second seed derived from it. The planners stop at their first solution and the
simplifications are bounded by iteration counts, so the time limits are only safety
stops: the same request with the same seed gives the same path, in any process and after
any other requests. Exceptions: PRM and PRM* look for a solution in a second thread while
the roadmap grows, so where they stop (and then the path) can depend on timing.
"""

from __future__ import annotations

import contextlib
import os
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, replace
from enum import StrEnum
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt

from recon_cli.planning.checks import TrajectoryCheck, check_trajectory
from recon_cli.planning.options import PLANNERS as PLANNERS  # re-exported
from recon_cli.planning.options import SIMPLIFICATIONS as SIMPLIFICATIONS  # re-exported
from recon_cli.planning.options import PlanOptions as PlanOptions  # re-exported
from recon_cli.planning.trajectory import Trajectory, parameterize, stop_and_go
from recon_cli.robot.cell import Cell
from recon_cli.robot.ik import IKOptions

#: [rad or m] a start this close outside the soft limits is clipped onto them
START_TOLERANCE = 1e-3


class _OmplState(Protocol):
    """A state of OMPL's RealVectorStateSpace: joint i by index."""

    def __getitem__(self, i: int) -> float: ...

    def __setitem__(self, i: int, value: float) -> None: ...


class PlanStatus(StrEnum):
    SOLVED = "solved"
    TIMEOUT = "timeout"  # no exact solution within the time limit
    INVALID_START = "invalid_start"  # start in collision or outside the soft limits
    INVALID_GOAL = "invalid_goal"  # goal in collision / outside limits / no IK solution
    TRAJECTORY_REJECTED = "trajectory_rejected"  # the timed trajectory failed its final check


@dataclass(frozen=True)
class PlanResult:
    status: PlanStatus
    planner: str
    plan_time: float  # [s] search
    simplify_time: float  # [s]
    total_time: float  # [s] IK + search + simplification + timing + final check
    path: npt.NDArray[np.float64] | None = None  # (K, n) simplified waypoints
    trajectory: Trajectory | None = None
    check: TrajectoryCheck | None = None
    message: str = ""
    attempts: int = 1  # searches run (a rejected trajectory is re-planned)

    @property
    def ok(self) -> bool:
        return self.status is PlanStatus.SOLVED

    @property
    def path_length(self) -> float:
        """Sum of absolute joint differences along the path (rad and m mixed, as MoveIt)."""
        if self.path is None:
            return float("nan")
        return float(np.sum(np.abs(np.diff(self.path, axis=0))))


#: OMPL's seed sequence is process-wide: one search at a time creates its generators
_OMPL_SEEDS = threading.Lock()
#: seed stream of the state space's set-up (requests use their attempt numbers, from 1)
SETUP_STREAM = 0


def ompl_seed(seed: int, *stream: int) -> int:
    """A seed for OMPL (a positive 31-bit number) from a request's seed (a non-negative
    integer) and stream indices (search attempt, search or simplification): independent
    streams for different indices, the same numbers for the same arguments."""
    if int(seed) < 0:
        raise ValueError(f"seed {seed} is negative")
    state = np.random.SeedSequence([int(seed), *(int(k) for k in stream)]).generate_state(1)[0]
    return int(state) % (2**31 - 2) + 1


def restart_ompl_seeds(seed: int) -> None:
    """Restart OMPL's process-wide seed sequence at ``seed`` (> 0): every random generator
    OMPL creates from now on (each takes the next number of that sequence) draws the same
    numbers as after any other restart at ``seed``. Generators that exist already keep
    their state. OMPL logs "Changing seed now will not lead to deterministic sampling" when
    generators exist already, which holds for those only; that message is silenced."""
    from ompl import util as ou

    level = ou.getLogLevel()
    ou.setLogLevel(ou.LOG_NONE)
    try:
        ou.RNG.setSeed(int(seed))
    finally:
        ou.setLogLevel(level)


def seed_ompl(seed: int) -> None:
    """Restart OMPL's seed sequence from a command's --seed. Not needed for repeatable
    planning (every request restarts it from its own seed); kept for callers that seeded
    OMPL once per command."""
    restart_ompl_seeds(ompl_seed(seed))


@contextlib.contextmanager
def _quiet_ompl() -> Iterator[None]:
    from ompl import util as ou

    level = ou.getLogLevel()
    ou.setLogLevel(ou.LOG_ERROR if os.environ.get("RECON_OMPL_DEBUG") is None else ou.LOG_DEBUG)
    try:
        yield
    finally:
        ou.setLogLevel(level)


class MotionPlanner:
    """OMPL planning in the joint space of one cell."""

    def __init__(self, cell: Cell, options: PlanOptions = PlanOptions()) -> None:  # noqa: B008
        from ompl import base as ob
        from ompl import geometric as og

        self.cell = cell
        self.options = options
        self._ob, self._og = ob, og
        n = cell.kin.nq
        self.n = n
        self.space = ob.RealVectorStateSpace(n)
        bounds = ob.RealVectorBounds(n)
        for i in range(n):
            bounds.setLow(i, float(cell.limits.soft_lower[i]))
            bounds.setHigh(i, float(cell.limits.soft_upper[i]))
        self.space.setBounds(bounds)
        self.setup = og.SimpleSetup(self.space)
        self.si = self.setup.getSpaceInformation()
        self.setup.setStateValidityChecker(self._state_valid)
        planner = self

        # ompl ships no type information: its classes are Any to mypy
        class _SegmentValidator(ob.MotionValidator):  # type: ignore[misc]
            def checkMotion(self, s1: _OmplState, s2: _OmplState) -> bool:  # noqa: N802 (OMPL's name)
                return planner._motion_valid(planner._vec(s1), planner._vec(s2))

        self._validator = _SegmentValidator(self.si)
        self.si.setMotionValidator(self._validator)
        with _OMPL_SEEDS, _quiet_ompl():
            # the space's set-up draws its default projection (a random linear map, used by
            # KPIECE and the like) from a fixed seed: the same in every planner and process,
            # and done before the first request, which then consumes its seeds as any other
            restart_ompl_seeds(ompl_seed(0, SETUP_STREAM))
            self.si.setup()
        self.stats = {"states": 0, "motions": 0}
        self._known_free: set[bytes] = set()  # configurations found free in this search

    # ------------------------------------------------------------------ validity
    def _vec(self, state: _OmplState) -> npt.NDArray[np.float64]:
        return np.array([state[i] for i in range(self.n)])

    def _state_valid(self, state: _OmplState) -> bool:
        self.stats["states"] += 1
        q = self._vec(state)
        valid = not self.cell.collision.in_collision(q)
        if valid:
            self._known_free.add(q.tobytes())
        return valid

    def _motion_valid(self, a: npt.NDArray[np.float64], b: npt.NDArray[np.float64]) -> bool:
        """States already found free (checked states, ends of free motions: the tree nodes)
        are not checked again as the end of a motion."""
        self.stats["motions"] += 1
        free = self.cell.collision.segment_free(a, b, self.options.max_step,
                                                end_known_free=b.tobytes() in self._known_free)
        if free:
            self._known_free.update((a.tobytes(), b.tobytes()))
        return free

    def _first_solution_objective(self) -> Any:
        """Path length with an infinite cost threshold: optimizing planners stop at their
        first exact solution instead of using up the time limit."""
        obj = self._ob.PathLengthOptimizationObjective(self.si)
        obj.setCostThreshold(self._ob.Cost(float("inf")))
        return obj

    # ------------------------------------------------------------------ requests
    def _state(self, q: npt.NDArray[np.float64]) -> _OmplState:
        s: _OmplState = self.si.allocState()
        for i in range(self.n):
            s[i] = float(q[i])
        return s

    def _config_problem(self, q: npt.NDArray[np.float64]) -> str | None:
        lim = self.cell.limits
        if not lim.within_soft(q, tol=1e-9):
            return "outside the soft joint limits"
        if not self.cell.collision.in_collision(q):
            return None
        a, b = self.cell.collision.check(q).pairs[0]
        return f"in collision ({a} with {b})"

    def plan_to_joints(self, q_start: npt.NDArray[np.float64],
                       q_goal: npt.NDArray[np.float64] | list[npt.NDArray[np.float64]], seed: int = 0) -> PlanResult:
        """Plan from q_start to a joint goal (or to whichever of several goals is reached).
        ``seed`` (a non-negative integer) decides the random choices of the search and the
        simplification: the same request with the same seed gives the same path."""
        t0 = time.perf_counter()
        opt = self.options
        goals = [np.asarray(q_goal, float)] if np.ndim(q_goal) == 1 else [np.asarray(g, float) for g in q_goal]
        q_start = np.asarray(q_start, float)
        lim = self.cell.limits
        if lim.within_soft(q_start, tol=START_TOLERANCE):
            # a robot that stopped at a soft limit measures a hair beyond it (tracking error):
            # start from the limit itself, which the executed trajectory then begins at
            q_start = lim.clip_soft(q_start)
        problem = self._config_problem(q_start)
        if problem:
            return PlanResult(PlanStatus.INVALID_START, opt.planner, 0.0, 0.0,
                              time.perf_counter() - t0, message=f"start configuration {problem}")
        valid_goals = [g for g in goals if self._config_problem(g) is None]
        if not valid_goals:
            return PlanResult(PlanStatus.INVALID_GOAL, opt.planner, 0.0, 0.0, time.perf_counter() - t0,
                              message=f"goal configuration {self._config_problem(goals[0])}")
        plan_time = simplify_time = 0.0
        attempts = 0
        last: PlanResult | None = None
        # a timed trajectory the final dense check rejects (rare: it samples other instants
        # than the planner did) is re-planned while the time limit lasts
        while True:
            attempts += 1
            remaining = opt.time_limit - plan_time - simplify_time
            if remaining <= 0.0:
                break
            found = self._search(q_start, valid_goals, remaining, seed, attempts)
            plan_time += found[1]
            simplify_time += found[2]
            if found[0] is None:
                break
            path = found[0]
            traj, check = self._time_and_check(path)
            message = "" if check.ok else (
                f"the timed trajectory collides ({check.collision[0][0]} with {check.collision[0][1]} at "
                f"t = {check.collision_time:.2f} s)" if check.collision else "the timed trajectory exceeds a limit")
            last = PlanResult(PlanStatus.SOLVED if check.ok else PlanStatus.TRAJECTORY_REJECTED, opt.planner,
                              plan_time, simplify_time, time.perf_counter() - t0, path,
                              traj if check.ok else None, check, message, attempts)
            if check.ok:
                return last
        if last is not None:
            return replace(last, plan_time=plan_time, simplify_time=simplify_time,
                           total_time=time.perf_counter() - t0, attempts=attempts)
        return PlanResult(PlanStatus.TIMEOUT, opt.planner, plan_time, simplify_time, time.perf_counter() - t0,
                          message=f"{opt.planner} found no path within {opt.time_limit:g} s", attempts=attempts)

    def _search(self, q_start: npt.NDArray[np.float64], goals: list[npt.NDArray[np.float64]], time_limit: float,
                seed: int, attempt: int) -> tuple[npt.NDArray[np.float64] | None, float, float]:
        """One OMPL search + simplification: (path (K, n) or None, search s, simplify s).
        The search's random generators are created after a restart of OMPL's seed sequence
        at (seed, attempt, 0), the simplifier's after one at (seed, attempt, 1)."""
        opt = self.options
        self._known_free = {np.asarray(q_start, float).tobytes()} | {np.asarray(g, float).tobytes() for g in goals}
        ob = self._ob
        with _OMPL_SEEDS, _quiet_ompl():
            self.setup.clear()  # the previous planner's clear() may create generators: before the restart
            self.setup.clearStartStates()
            self.setup.setStartState(self._state(q_start))
            if len(goals) == 1:
                self.setup.setGoalState(self._state(goals[0]))
            else:
                goal = ob.GoalStates(self.si)
                for g in goals:
                    goal.addState(self._state(g))
                self.setup.setGoal(goal)
            restart_ompl_seeds(ompl_seed(seed, attempt, 0))
            planner = getattr(self._og, opt.planner)(self.si)
            if opt.range > 0 and hasattr(planner, "setRange"):
                planner.setRange(opt.range)
            self.setup.setPlanner(planner)
            self.setup.setOptimizationObjective(self._first_solution_objective())
            self.setup.setup()
            # stop at the first exact solution (also planners that would go on improving it,
            # such as AORRTC); the time limit is a safety stop
            ptc = ob.plannerOrTerminationCondition(
                ob.timedPlannerTerminationCondition(time_limit),
                ob.exactSolnPlannerTerminationCondition(self.setup.getProblemDefinition()))
            t1 = time.perf_counter()
            status = self.setup.solve(ptc)
            search = time.perf_counter() - t1
            if not (bool(status) and self.setup.haveExactSolutionPath()):
                return None, search, 0.0
            t2 = time.perf_counter()
            path_geo = self.setup.getSolutionPath()
            # every step below is bounded by iteration counts (OMPL's defaults: as many
            # tries as the path has vertices), none by the clock
            restart_ompl_seeds(ompl_seed(seed, attempt, 1))
            if opt.simplify in ("reduce", "shortcut"):
                simplifier = self._og.PathSimplifier(self.si)
                simplifier.reduceVertices(path_geo)
                for _ in range(opt.shortcut_rounds if opt.simplify == "shortcut" else 0):
                    simplifier.partialShortcutPath(path_geo)
                    simplifier.reduceVertices(path_geo)
            elif opt.simplify == "full":
                # OMPL's simplifySolution with a simplifier of its own (goal and objective of
                # the request); it runs every step at least once, simplify_time only stops
                # the search for a better goal state early
                simplifier = self._og.PathSimplifier(self.si, self.setup.getGoal(),
                                                     self.setup.getOptimizationObjective())
                simplifier.simplify(path_geo, opt.simplify_time)
            simplify = time.perf_counter() - t2
            path = np.array([[path_geo.getState(k)[i] for i in range(self.n)]
                             for k in range(path_geo.getStateCount())])
        return path, search, simplify

    def _time_and_check(self, path: npt.NDArray[np.float64]) -> tuple[Trajectory, TrajectoryCheck]:
        """toppra along the path (a smooth spline through the waypoints); if that leaves the
        checked segments into a collision, stop-and-go along the segments themselves."""
        opt, lim = self.options, self.cell.limits
        traj = parameterize(path, lim.velocity, lim.acceleration, opt.velocity_scale, opt.acceleration_scale)
        check = check_trajectory(traj, self.cell, opt.velocity_scale, opt.acceleration_scale, opt.max_step)
        if not check.ok and len(path) > 2:
            traj = stop_and_go(path, lim.velocity, lim.acceleration, opt.velocity_scale, opt.acceleration_scale)
            check = check_trajectory(traj, self.cell, opt.velocity_scale, opt.acceleration_scale, opt.max_step)
        return traj, check

    def plan_to_pose(self, q_start: npt.NDArray[np.float64], world_T_camera: npt.NDArray[np.float64],
                     rng: np.random.Generator, what: str = "view") -> PlanResult:
        """Plan to a camera pose: IK (several solutions, raises when none), then plan to any."""
        ik = self.cell.solve_pose(world_T_camera, rng, seed=q_start,
                                  options=IKOptions(max_solutions=self.options.ik_solutions), what=what)
        step = self.cell.collision.point_step_bound
        goals = sorted((s.q for s in ik.solutions), key=lambda g: float(step(g - q_start)))
        result = self.plan_to_joints(q_start, goals, seed=int(rng.integers(1 << 30)))
        return result
