"""Choosing IK solutions for the views (thesis Table 2.3) and our own sequence improvement.

``optimize_graph``: vertex by vertex, draw a new IK solution for the view; keep the new graph
when the preorder traversal of its minimum spanning tree (on lower bounds) gets cheaper;
stop after k_max draws in a row without improvement.

``local_search_sequence`` (ours, beyond the thesis): the path TSP is solved far better than
the tree's 2-approximation by local search (2-opt segment reversals and Or-opt moves of one
to three consecutive views) on the current edge costs: exact durations where planned, lower
bounds elsewhere. Then the sequence's unplanned edges are planned, lazily, the one whose
estimate is largest first; as soon as a planned edge costs more than ``beta`` times its
estimate the search runs again with the new costs. With lower bounds that track the real
durations (the benchmark reports their ratio), the chosen sequence needs few more requests
than there are views.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from recon_cli.sequence.graph import EdgePlanner, ViewGraph
from recon_cli.sequence.tsp import SequenceResult, exact_tree, finish, minimum_spanning_tree, preorder

#: draws a new IK solution for vertex k (a view), or None when none was found
Redraw = Callable[[int], np.ndarray | None]


def preorder_cost(graph: ViewGraph) -> tuple[list[int], float]:
    order = preorder(minimum_spanning_tree(graph.cost), graph.size, graph.cost)
    return order, graph.sequence_cost(order)


def optimize_graph(graph: ViewGraph, redraw: Redraw, k_max: int,
                   score: Callable[[ViewGraph], float] | None = None) -> tuple[ViewGraph, int]:
    """Table 2.3 (with ``score`` = preorder cost on lower bounds, the thesis' choice).
    Returns the improved graph and the number of IK draws."""
    score = score or (lambda g: preorder_cost(g)[1])
    best = score(graph)
    k, draws = 0, 0
    while True:
        for v in range(1, graph.size):
            q = redraw(v)
            draws += 1
            if q is not None:
                candidate = graph.replace_vertex(v, q)
                c = score(candidate)
                if c < best:
                    graph, best, k = candidate, c, 0
                    continue
            k += 1
            if k > k_max:
                return graph, draws


def sequence_cost(cost: np.ndarray, order: list[int]) -> float:
    idx = np.asarray(order)
    return float(cost[idx[:-1], idx[1:]].sum())


def improve_order(cost: np.ndarray, order: list[int]) -> list[int]:
    """2-opt and Or-opt (segments of 1-3 vertices, both orientations) on an open path that
    starts at order[0], until no move improves the cost."""
    order = list(order)
    n = len(order)
    improved = True
    while improved:
        improved = False
        # 2-opt: reverse order[i..j]
        for i in range(1, n - 1):
            a = order[i - 1]
            for j in range(i + 1, n):
                b, c = order[i], order[j]
                after = order[j + 1] if j + 1 < n else None
                old = cost[a, b] + (cost[c, after] if after is not None else 0.0)
                new = cost[a, c] + (cost[b, after] if after is not None else 0.0)
                if new < old - 1e-9:
                    order[i:j + 1] = order[i:j + 1][::-1]
                    improved = True
        # Or-opt: move a segment of 1-3 vertices elsewhere
        for length in (1, 2, 3):
            i = 1
            while i + length <= n:
                seg = order[i:i + length]
                rest = order[:i] + order[i + length:]
                base = sequence_cost(cost, order)
                best, best_order = base, None
                for pos in range(1, len(rest) + 1):
                    for s in (seg, seg[::-1]):
                        cand = rest[:pos] + s + rest[pos:]
                        cand_cost = sequence_cost(cost, cand)
                        if cand_cost < best - 1e-9:
                            best, best_order = cand_cost, cand
                if best_order is not None:
                    order = best_order
                    improved = True
                i += 1
    return order


def local_search_sequence(graph: ViewGraph, planner: EdgePlanner, beta: float = 1.5,
                          tree_first: bool = True, request_cost: float = 0.0) -> SequenceResult:
    """Our sequence: the lazy tree of Table 2.2 first (its edges exact), then local search on
    exact costs and calibrated estimates (lower bound x the mean real/lower-bound ratio of
    the edges planned so far), lazy planning of the chosen edges, search again when an edge
    costs more than ``beta`` times its estimate."""
    rounds = exact_tree(graph, planner, beta, pick="largest")[1] if tree_first else 0
    lower = graph.cost.copy()  # lower bounds where not exact
    order = preorder(minimum_spanning_tree(graph.cost), graph.size, graph.cost)
    while True:
        planned = [e for e in graph.planned if np.isfinite(graph.cost[e])]
        ratio = float(np.mean([graph.cost[e] / max(_bound(graph, e), 1e-9) for e in planned])) if planned else 1.0
        estimate = np.where(graph.exact, graph.cost, lower * max(ratio, 1.0) + request_cost)
        order = improve_order(estimate, order)
        pending = [(a, b) for a, b in zip(order[:-1], order[1:], strict=True) if not graph.exact[a, b]]
        if not pending:
            return finish(graph, order, planner, rounds)
        surprised = False
        for a, b in sorted(pending, key=lambda e: -estimate[e]):
            if graph.plan(a, b, planner) > beta * estimate[a, b]:
                surprised = True
                break
        rounds += 1
        if not surprised:
            return finish(graph, order, planner, rounds)


def _bound(graph: ViewGraph, e: tuple[int, int]) -> float:
    return graph.lower_bound(graph.configs[e[0]], graph.configs[e[1]])
