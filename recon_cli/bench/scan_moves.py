"""Planner benchmark on any cell: the moves of a scan (``recon bench planners --cell NAME``).

Table 4.1 is a problem of the thesis' gantry cell only. On another cell the benchmark asks
for the moves a scan makes: the camera goes around the cell's object position at the
camera's scan distance. The problem set (seeded):

- ``pairs`` camera views: polar angle uniform in 20 ... 70 deg, azimuth uniform, focus
  :data:`FOCUS_HEIGHT` above the object position, radius the sensor's scan distance, each
  solved by recon's IK (collision-free, within the soft limits); views without a solution
  are drawn again;
- the requests: home to the first view, then view k to view k + 1;
- obstacles: everything of the cell (the table top, the board, ...) and an object box of
  :data:`OBJECT_BOX` on the object position, inflated by the safety distance like every
  other shape.

Every planner gets the same pairs: recon's OMPL planners in this process, and the peers
(:mod:`.mplib_peer`, :mod:`.vamp_peer`) in their own environments. A sampling profile of
recon's requests (cProfile, cumulative time per function) says where recon's time goes.
"""

from __future__ import annotations

import cProfile
import io
import math
import pstats
import time
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from recon_cli.bench.planners import RequestRow, request_seeds
from recon_cli.errors import ReconError
from recon_cli.geometry.view import View
from recon_cli.perception.sensor import cell_sensor
from recon_cli.planning.planner import MotionPlanner, PlanOptions
from recon_cli.robot.cell import Cell
from recon_cli.robot.collision import ObjectBox
from recon_cli.robot.description import CellConfig
from recon_cli.robot.ik import IKOptions

#: [m] edges of the object's collision box on the object position (a bottle or mug with margin)
OBJECT_BOX = (0.15, 0.15, 0.25)
#: [m] the views' focus point above the object position
FOCUS_HEIGHT = 0.1
#: [deg] range of the views' polar angle
THETA_RANGE = (20.0, 70.0)


@dataclass(frozen=True)
class ScanMoves:
    """The problem set: ``pairs`` (start, goal) joint vectors, the object box, the views."""

    cell: str
    pairs: tuple[tuple[np.ndarray, np.ndarray], ...]
    object_box: ObjectBox
    views: tuple[View, ...]
    distance: float


def scan_moves(cell: Cell, n: int, seed: int,
               accept: Callable[[list[np.ndarray]], list[bool]] | None = None,
               distance: float | None = None) -> ScanMoves:
    """``n`` requests of a scan around the cell's object position (see the module docstring).
    ``accept`` (optional) keeps only the goals every peer's own robot model takes as valid
    (asked for a batch of candidates at a time), so that every planner gets the same requests."""
    cf = cell.config.cell_file
    rng = np.random.default_rng(seed)
    position = np.asarray(cf.object_position, dtype=float)
    box = ObjectBox.on_table(OBJECT_BOX, (float(position[0]), float(position[1])), table_top_z=float(position[2]))
    cell.set_object_box(box)
    distance = cell_sensor(cf).default_distance if distance is None else distance
    focus = tuple(float(v) for v in position + np.array([0.0, 0.0, FOCUS_HEIGHT]))
    home = cf.pose("home", cell.joint_names)
    goals: list[np.ndarray] = []
    views: list[View] = []
    tries = 0
    while len(goals) < n:
        batch: list[tuple[np.ndarray, View]] = []
        while len(batch) < n - len(goals) + (0 if accept is None else n):
            tries += 1
            if tries > 50 * n:
                raise ReconError(f"the {cf.name} cell reaches too few views around its object position "
                                 f"({len(goals)} of {tries} drawn)", hint="check the cell with recon cell check")
            view = View(focus, distance, math.radians(rng.uniform(*THETA_RANGE)),  # type: ignore[arg-type]
                        math.radians(rng.uniform(0.0, 360.0)))
            try:
                result = cell.solve_view(view, rng, seed=home, options=IKOptions(max_solutions=1))
            except ReconError:
                continue
            batch.append((result.solutions[0].q, view))
        keep = [True] * len(batch) if accept is None else accept([q for q, _ in batch])
        for (q, view), ok in zip(batch, keep, strict=True):
            if ok and len(goals) < n:
                goals.append(q)
                views.append(view)
    starts = [home, *goals[:-1]]
    return ScanMoves(cf.name, tuple(zip(starts, goals, strict=True)), box, tuple(views), distance)


def run_scan_moves(config: CellConfig, planners: list[str], n: int, time_limit: float, seed: int,
                   progress: Callable[[str, int, int], None] | None = None,
                   options: PlanOptions = PlanOptions(),  # noqa: B008
                   accept: Callable[[Cell, list[np.ndarray]], list[bool]] | None = None,
                   distance: float | None = None) -> tuple[ScanMoves, list[RequestRow], str]:
    """The scan-move requests for each planner, and the profile of recon's planning (text)."""
    cell = Cell(config)
    problem = scan_moves(cell, n, seed, None if accept is None else (lambda qs: accept(cell, qs)), distance)
    seeds = request_seeds(seed, n)
    rows: list[RequestRow] = []
    profiler = cProfile.Profile()
    for name in planners:
        planner = MotionPlanner(cell, replace(options, planner=name, time_limit=time_limit))
        planner.plan_to_joints(*problem.pairs[0], seed=0)  # warm-up (imports, caches): not measured
        for k, ((start, goal), request_seed) in enumerate(zip(problem.pairs, seeds, strict=True)):
            t0 = time.perf_counter()
            profiler.enable()
            r = planner.plan_to_joints(start, goal, seed=request_seed)
            profiler.disable()
            total = time.perf_counter() - t0
            plan_time = r.plan_time + r.simplify_time
            rows.append(RequestRow(
                name, k, r.ok, r.status.value, plan_time, r.plan_time, r.simplify_time,
                max(total - plan_time, 0.0) if r.ok else 0.0, r.path_length if r.ok else float("nan"),
                float("nan") if r.trajectory is None else r.trajectory.duration, request_seed))
            if progress:
                progress(name, k + 1, n)
    text = io.StringIO()
    stats = pstats.Stats(profiler, stream=text)
    text.write("recon's planning requests, by cumulative time\n")
    stats.sort_stats("cumulative").print_stats(25)
    text.write("\nthe same, by own time\n")
    stats.sort_stats("tottime").print_stats(25)
    return problem, rows, text.getvalue()
