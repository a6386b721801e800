"""How far the sequence optimizer's tour is from the optimal one (``recon bench tour``).

Per seed, the problem of ``recon bench sequence`` (:class:`SequenceProblem`: the 24 views of
eq. 4.1 from the Table 4.1 start, the thesis' velocity and acceleration scaling):

1. case D (ours) exactly as ``recon bench sequence`` runs it on the same seed: the graph's IK
   solutions seeded view by view, the graph optimization of Table 2.3, then
   ``local_search_sequence``, planning lazily;
2. the rest of the cost matrix among the same vertices is planned with the same planner, so
   every edge holds a planned duration and those D planned keep theirs: the planned cost
   matrix D saw where it planned and would have seen elsewhere;
3. the optimal open path on that matrix (:func:`solve_open_path`, proven optimal);
4. D's local search (2-opt/Or-opt) once more, from D's tour on the whole matrix: what the
   search finds when every duration is known, so the gap splits into what D did not know
   (its estimates of unplanned edges) and where its search stops (a local optimum);
5. for reference: case C (the lazy tree of Table 2.2, beta 1.5) on the same vertices, its
   planning requests answered from the same matrix, and case B as ``recon bench sequence``
   runs it (its own graph: the IK solutions before the graph optimization).

D's tour uses only edges of the matrix with the durations it planned, so the optimum is at
most D's duration; the gap is what a perfect order would save, and planning the whole matrix
(every pair of views) is what it would cost.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from recon_cli.bench.sequence import REQUEST_COST, SequenceProblem, run_case
from recon_cli.planning.options import PlanOptions
from recon_cli.planning.planner import seed_ompl
from recon_cli.planning.trajectory import Trajectory
from recon_cli.sequence.exact import path_cost, solve_open_path
from recon_cli.sequence.graph import EdgePlanner, ViewGraph
from recon_cli.sequence.optimize import improve_order, local_search_sequence, optimize_graph
from recon_cli.sequence.tsp import lazy_mst_sequence

#: beta of Table 2.2 and k_max of Table 2.3, as ``recon bench sequence`` runs cases B, C and D
BETA = 1.5
K_MAX = 120
#: the reduced problem of ``--quick``: every second view of eq. 4.1 (12 views, both rings)
QUICK_VIEW_STEP = 2

Progress = Callable[[str, int, int], None]


@dataclass(frozen=True)
class TourRow:
    seed: int  # the run's seed (that of run r of ``recon bench sequence --seed S``: S * 100003 + r)
    views: int
    ours: float  # case D's tour duration t_p [s]
    optimal: float  # the optimal tour's duration on the same planned matrix [s]
    lower_bound: float  # proven lower bound of the optimum [s] (= optimal when proven)
    proven_optimal: bool
    gap_s: float  # ours - optimal [s]
    gap_pct: float  # (ours - optimal) / optimal [%]
    search_full: float  # D's local search (2-opt/Or-opt) from D's tour on the whole planned matrix [s]
    case_c: float  # case C's tour on the same vertices and planned durations [s]
    case_b: float  # case B as ``recon bench sequence`` runs it (its own graph) [s]
    requests_ours: int  # planning requests of D
    requests_matrix: int  # planning requests of the whole matrix (D's included)
    failed_edges: int  # edges the planner found no path for (inf in the matrix)
    plan_seconds: float  # wall clock of planning the rest of the matrix [s]
    solve_seconds: float  # wall clock of the exact solve [s]
    solver_rounds: int  # integer programs solved (one per round of subtour cuts)
    order_ours: list[int]
    order_optimal: list[int]
    matrix: list[list[float]]  # (V, V) the planned durations [s] (inf: no path found), vertex 0 the start


def run_tour_bench(seeds: int, seed: int, views_step: int = 1, progress: Progress | None = None,
                   options: PlanOptions | None = None, time_limit: float = 600.0) -> list[TourRow]:
    """``seeds`` runs on the seeds of ``recon bench sequence --seed`` (its runs 0 ... seeds-1);
    ``views_step`` > 1 keeps every views_step-th view of eq. 4.1 (a smaller problem)."""
    seed_ompl(seed)
    problem = SequenceProblem(options)
    problem.poses = problem.poses[::views_step]
    return [tour_row(problem, seed * 100_003 + r, progress, time_limit) for r in range(seeds)]


def tour_row(problem: SequenceProblem, run_seed: int, progress: Progress | None = None,
             time_limit: float = 600.0) -> TourRow:
    label = f"seed {run_seed}"
    rng = np.random.default_rng(run_seed)
    graph = problem.graph(rng)
    graph, _ = optimize_graph(graph, lambda v: problem.ik(v, rng), K_MAX)
    planner = problem.edge_planner(rng)
    ours = local_search_sequence(graph, planner, BETA, tree_first=True, request_cost=REQUEST_COST)
    step = (lambda done, total: progress(label, done, total)) if progress else None
    t0 = time.perf_counter()
    plan_matrix(graph, planner, step)
    plan_seconds = time.perf_counter() - t0
    exact = solve_open_path(graph.cost, 0, time_limit, incumbent=ours.order)
    case_c = lazy_mst_sequence(ViewGraph(list(graph.configs), graph.lower_bound), matrix_planner(graph), BETA)
    case_b = run_case(problem, "B", run_seed, BETA, K_MAX)
    gap = ours.duration - exact.cost if np.isfinite(exact.cost) else float("nan")
    gap_pct = 100.0 * gap / exact.cost if exact.cost > 0.0 else 0.0
    searched = improve_order(graph.cost, ours.order)
    return TourRow(seed=run_seed, views=graph.size - 1, ours=ours.duration, optimal=exact.cost,
                   lower_bound=exact.lower_bound, proven_optimal=exact.proven_optimal, gap_s=gap,
                   gap_pct=gap_pct, search_full=path_cost(graph.cost, searched),
                   case_c=case_c.duration, case_b=case_b.duration, requests_ours=ours.requests,
                   requests_matrix=graph.requests, failed_edges=int(np.isinf(graph.cost).sum() // 2),
                   plan_seconds=plan_seconds, solve_seconds=exact.seconds, solver_rounds=exact.rounds,
                   order_ours=list(ours.order), order_optimal=list(exact.order), matrix=graph.cost.tolist())


def plan_matrix(graph: ViewGraph, planner: EdgePlanner, progress: Callable[[int, int], None] | None = None) -> None:
    """Plan every edge of the graph that is not planned yet (each pair once)."""
    pending = [(i, j) for i in range(graph.size) for j in range(i + 1, graph.size) if not graph.exact[i, j]]
    for k, (i, j) in enumerate(pending, 1):
        graph.plan(i, j, planner)
        if progress:
            progress(k, len(pending))


def matrix_planner(graph: ViewGraph) -> EdgePlanner:
    """An edge planner that answers from ``graph``'s planned trajectories (its configurations
    only): another sequence method sees exactly the same planned durations."""
    vertex = {q.tobytes(): k for k, q in enumerate(graph.configs)}

    def plan(a: np.ndarray, b: np.ndarray) -> Trajectory | None:
        return graph.trajectory(vertex[np.asarray(a).tobytes()], vertex[np.asarray(b).tobytes()])

    return plan


def summarize_tours(rows: list[TourRow]) -> dict:
    """Means over the seeds; what closing the gap would save and what it would cost."""
    def mean(values) -> float:
        return float(np.mean(values)) if len(values) else float("nan")

    return {"seeds": len(rows), "views": rows[0].views if rows else 0,
            "ours_mean": mean([r.ours for r in rows]), "optimal_mean": mean([r.optimal for r in rows]),
            "gap_s_mean": mean([r.gap_s for r in rows]), "gap_s_max": max((r.gap_s for r in rows), default=0.0),
            "gap_pct_mean": mean([r.gap_pct for r in rows]),
            "gap_pct_max": max((r.gap_pct for r in rows), default=0.0),
            "search_full_mean": mean([r.search_full for r in rows]),
            "case_c_mean": mean([r.case_c for r in rows]), "case_b_mean": mean([r.case_b for r in rows]),
            "all_proven_optimal": all(r.proven_optimal for r in rows),
            "requests_ours_mean": mean([r.requests_ours for r in rows]),
            "requests_matrix_mean": mean([r.requests_matrix for r in rows]),
            "plan_seconds_mean": mean([r.plan_seconds for r in rows]),
            "solve_seconds_mean": mean([r.solve_seconds for r in rows]),
            "solve_seconds_max": max((r.solve_seconds for r in rows), default=0.0)}


def tour_png(path, rows: list[TourRow]) -> None:
    """Per seed: the tour durations of B, C, D and the optimum, the gap written over D."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(max(6.0, 1.4 * len(rows) + 3.5), 4))
    x = np.arange(len(rows))
    bars = (("B (own graph)", [r.case_b for r in rows], "0.75"), ("C", [r.case_c for r in rows], "tab:blue"),
            ("D (ours)", [r.ours for r in rows], "tab:orange"), ("optimal", [r.optimal for r in rows], "tab:green"))
    width = 0.8 / len(bars)
    for k, (name, values, color) in enumerate(bars):
        ax.bar(x + (k - 1.5) * width, values, width, label=name, color=color)
    for i, r in enumerate(rows):
        ax.annotate(f"+{r.gap_pct:.1f} %", (x[i] + 0.5 * width, r.ours), ha="center", va="bottom", fontsize=7)
    ax.set_xticks(x, [str(r.seed) for r in rows])
    ax.set_xlabel("seed")
    ax.set_ylabel("total trajectory duration t_p [s]")
    views = rows[0].views if rows else 0
    ax.set_title(f"eq. 4.1, {views} views: tours on the same planned durations")
    ax.grid(alpha=0.3, axis="y")
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
