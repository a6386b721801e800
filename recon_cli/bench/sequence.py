"""Sequence-optimization benchmark of thesis section 4.3 (``recon bench sequence``).

The 24 views of eq. 4.1 from the Table 4.1 start configuration (0.3 m cube on the table),
velocity scaling 0.15 and acceleration scaling 0.3 as the thesis benchmarked. Cases:

- A: script order (no optimization) on the same graph as B: every consecutive edge planned;
- B: Table 2.2 with beta = 1.5 on a graph whose IK solutions are found as the thesis'
  sequence optimizer found them (each seeded with the previous view's solution, in script
  order; CELL_FACTS 10.1);
- C: B after the graph optimization of Table 2.3 (k_max = 120; redraws from random seeds);
- D (ours): C's graph, the lazy tree of Table 2.2, then 2-opt/Or-opt local search on exact
  durations and calibrated estimates (a new planning request weighed as 10 s), lazy
  planning of the chosen edges (``local_search_sequence``);
- A0: what ``recon run`` does without optimization: script order, each move planned to the
  view's pose with four IK solutions found from the current configuration as goal states.
  Stronger than A (it picks IK solutions near the robot at every step), shown for honesty.

Per run: total trajectory duration t_p (sum of the durations of the 24 moves) and planning
requests n_req. Runs are independent and seeded.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from recon_cli.planning.lower_bound import duration_lower_bound
from recon_cli.planning.planner import MotionPlanner, PlanOptions, seed_ompl
from recon_cli.robot.cell import Cell
from recon_cli.robot.description import CellConfig
from recon_cli.robot.ik import IKOptions
from recon_cli.sequence.graph import ViewGraph
from recon_cli.sequence.optimize import local_search_sequence, optimize_graph
from recon_cli.sequence.tsp import finish, lazy_mst_sequence
from recon_cli.thesis import BENCH_CUBE, TABLE_4_1_START, eq_4_1_views

CASES = ("A", "B", "C", "D", "A0")
#: D weighs a new planning request like this much trajectory time [s] in its local search
REQUEST_COST = 10.0
THESIS = {"A": (141.81, 24.00), "B": (127.37, 27.40), "C": (120.33, 26.99)}


@dataclass(frozen=True)
class RunRow:
    case: str
    run: int
    duration: float  # t_p [s]
    requests: int
    seconds: float  # wall clock of the run
    order: list[int]
    lower_bound_ratio: float  # mean planned duration / its lower bound


class SequenceProblem:
    """The cell, the views and the planning functions of the benchmark."""

    def __init__(self, options: PlanOptions | None = None) -> None:
        self.cell = Cell(CellConfig(), object_box=BENCH_CUBE)
        self.options = options or PlanOptions()  # velocity x0.15, acceleration x0.3, as the thesis benchmarked
        self.planner = MotionPlanner(self.cell, self.options)
        self.poses = [self.cell.view_pose(v) for v in eq_4_1_views()]
        lim = self.cell.limits
        o = self.options
        self.lower_bound = lambda a, b: duration_lower_bound(a, b, lim.velocity, lim.acceleration,
                                                             o.velocity_scale, o.acceleration_scale)
        self.start = TABLE_4_1_START.copy()

    def ik(self, k: int, rng: np.random.Generator, seed: np.ndarray | None = None) -> np.ndarray | None:
        """One IK solution of view k (1-based vertex): the one found from ``seed`` when
        given, else from random seeds; None if none was found."""
        try:
            r = self.cell.solve_pose(self.poses[k - 1], rng, seed=seed, options=IKOptions(max_solutions=1))
        except Exception:  # noqa: BLE001 - unreachable views are simply not redrawn
            return None
        return r.solutions[0].q if r.solutions else None

    def edge_planner(self, rng: np.random.Generator):
        def plan(a: np.ndarray, b: np.ndarray):
            r = self.planner.plan_to_joints(a, b, seed=int(rng.integers(1 << 30)))
            return r.trajectory if r.ok else None
        return plan

    def graph(self, rng: np.random.Generator) -> ViewGraph:
        # as the thesis' sequence optimizer: each view's first IK solution seeded with the
        # previous vertex's joints (script order), re-samples from random seeds
        configs = [self.start]
        for k in range(1, len(self.poses) + 1):
            q = self.ik(k, rng, configs[-1])
            if q is None:
                raise RuntimeError(f"view {k} of eq. 4.1 has no IK solution")
            configs.append(q)
        return ViewGraph(configs, self.lower_bound)


def run_case(problem: SequenceProblem, case: str, seed: int, beta: float = 1.5, k_max: int = 120) -> RunRow:
    rng = np.random.default_rng(seed)
    t0 = time.perf_counter()
    if case == "A0":
        q, total, requests, ratios = problem.start, 0.0, 0, []
        for T in problem.poses:
            r = problem.planner.plan_to_pose(q, T, rng)
            requests += r.attempts
            trajectory = r.trajectory if r.ok else None
            if trajectory is None:
                total = np.inf
                break
            total += trajectory.duration
            ratios.append(trajectory.duration / max(problem.lower_bound(q, trajectory.goal), 1e-9))
            q = trajectory.goal
        order = list(range(len(problem.poses) + 1))
        return RunRow(case, seed, float(total), requests, time.perf_counter() - t0, order,
                      float(np.mean(ratios)) if ratios else float("nan"))
    graph = problem.graph(rng)
    redraw = lambda v: problem.ik(v, rng)  # noqa: E731
    if case == "A":
        planner = problem.edge_planner(rng)
        order = list(range(graph.size))
        result = finish(graph, order, planner)
        return RunRow(case, seed, result.duration, result.requests, time.perf_counter() - t0, order,
                      _bound_ratio(graph, problem))
    if case == "C":
        graph, _ = optimize_graph(graph, redraw, k_max)
    if case == "D":
        graph, _ = optimize_graph(graph, redraw, k_max)
    planner = problem.edge_planner(rng)
    result = (local_search_sequence(graph, planner, beta, tree_first=True, request_cost=REQUEST_COST)
              if case == "D" else lazy_mst_sequence(graph, planner, beta))
    return RunRow(case, seed, result.duration, result.requests, time.perf_counter() - t0, result.order,
                  _bound_ratio(graph, problem))


def _bound_ratio(graph: ViewGraph, problem: SequenceProblem) -> float:
    """Mean planned duration over its lower bound, for the edges planned in a run."""
    ratios = [graph.cost[e] / max(problem.lower_bound(graph.configs[e[0]], graph.configs[e[1]]), 1e-9)
              for e in graph.planned if np.isfinite(graph.cost[e])]
    return float(np.mean(ratios)) if ratios else float("nan")


def run_sequence_bench(runs: int, seed: int, cases=CASES,
                       progress: Callable[[str, int, int], None] | None = None,
                       options: PlanOptions | None = None) -> list[RunRow]:
    seed_ompl(seed)
    problem = SequenceProblem(options)
    rows = []
    for case in cases:
        for r in range(runs):
            rows.append(run_case(problem, case, seed * 100_003 + r))
            if progress:
                progress(f"case {case}", r + 1, runs)
    return rows


def summarize(rows: list[RunRow]) -> dict[str, dict]:
    out = {}
    base = np.mean([r.duration for r in rows if r.case == "A"]) if any(r.case == "A" for r in rows) else None
    for case in dict.fromkeys(r.case for r in rows):
        sel = [r for r in rows if r.case == case]
        d = np.array([r.duration for r in sel])
        ok = np.isfinite(d)
        mean = float(d[ok].mean()) if ok.any() else float("inf")
        out[case] = {"runs": len(sel), "failed": int((~ok).sum()), "t_p_mean": mean,
                     "t_p_median": float(np.median(d[ok])) if ok.any() else float("inf"),
                     "n_req_mean": float(np.mean([r.requests for r in sel])),
                     "n_req_max": int(max(r.requests for r in sel)),
                     "vs_A": None if base is None else (mean / base - 1.0),
                     "wall_s_mean": float(np.mean([r.seconds for r in sel])),
                     "planned_over_lower_bound": float(np.nanmean([r.lower_bound_ratio for r in sel])),
                     "thesis": THESIS.get(case)}
    return out


def ecdf_png(path, rows: list[RunRow]) -> None:
    """Empirical CDF of t_p per case, like thesis Figure 4.8."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    for case in dict.fromkeys(r.case for r in rows):
        d = np.sort([r.duration for r in rows if r.case == case and np.isfinite(r.duration)])
        if len(d):
            ax.step(d, np.arange(1, len(d) + 1) / len(d), where="post", label=f"case {case} (mean {d.mean():.1f} s)")
    ax.set_xlabel("total trajectory duration t_p [s]")
    ax.set_ylabel("F(t_p)")
    ax.set_title("eq. 4.1, 24 views from the Table 4.1 start (velocity x0.15, acceleration x0.3)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
