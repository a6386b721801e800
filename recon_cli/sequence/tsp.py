"""The lazy minimum-spanning-tree approximation of the path TSP (thesis 2.3.2, Table 2.2).

Edges start at lower bounds. Repeatedly: a minimum spanning tree T with cost kappa; while
c(T) <= beta kappa, plan a non-exact tree edge (its cost becomes the real trajectory
duration); when every tree edge is exact, the preorder traversal of T from the start vertex
is the sequence. With a metric cost the sequence costs at most 2 beta times the optimum.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from recon_cli.sequence.graph import EdgePlanner, ViewGraph


def minimum_spanning_tree(cost: np.ndarray) -> list[tuple[int, int]]:
    """Edges (i < j) of a minimum spanning tree of a complete graph (cost matrix, any
    non-negative values; infinite costs are used only when nothing else connects)."""
    c = np.asarray(cost, dtype=float)
    finite = np.isfinite(c)
    big = (c[finite].max() if finite.any() else 1.0) * 10.0 * len(c) + 1.0
    w = np.where(finite, c, big) + 1e-9  # scipy treats zeros as missing edges
    np.fill_diagonal(w, 0.0)
    from scipy.sparse.csgraph import minimum_spanning_tree as scipy_mst

    tree = scipy_mst(np.triu(w)).tocoo()
    return sorted((int(min(i, j)), int(max(i, j))) for i, j in zip(tree.row, tree.col, strict=True))


def tree_cost(cost: np.ndarray, edges: list[tuple[int, int]]) -> float:
    return float(sum(cost[i, j] for i, j in edges))


def preorder(edges: list[tuple[int, int]], n: int, cost: np.ndarray | None = None, root: int = 0) -> list[int]:
    """Depth-first preorder of a tree from ``root``; children in order of increasing edge cost."""
    children: dict[int, list[int]] = {v: [] for v in range(n)}
    for i, j in edges:
        children[i].append(j)
        children[j].append(i)
    order, seen, stack = [], set(), [root]
    while stack:
        v = stack.pop()
        if v in seen:
            continue
        seen.add(v)
        order.append(v)
        nxt = [c for c in children[v] if c not in seen]
        if cost is not None:
            nxt.sort(key=lambda c: cost[v, c])
        stack.extend(reversed(nxt))
    return order


@dataclass(frozen=True)
class SequenceResult:
    order: list[int]  # vertices, starting with 0
    requests: int  # planning requests made (tree edges and traversal edges)
    duration: float  # sum of the planned durations along the order [s]
    tree_rounds: int  # minimum spanning trees computed


def exact_tree(graph: ViewGraph, planner: EdgePlanner, beta: float = 1.5,
               pick: str = "preorder") -> tuple[list[tuple[int, int]], int]:
    """The loop of Table 2.2: minimum spanning trees on the current costs, non-exact tree
    edges planned while c(T) <= beta kappa, until a tree has only exact edges. ``pick``: the
    first non-exact edge in preorder (the thesis' implementation) or the "largest"
    estimate. Returns (tree, trees computed)."""
    if beta < 1.0:
        raise ValueError("beta must be at least 1")
    rounds = 0
    while True:
        tree = minimum_spanning_tree(graph.cost)
        rounds += 1
        kappa = tree_cost(graph.cost, tree)
        while tree_cost(graph.cost, tree) <= beta * kappa:
            pending = [e for e in tree if not graph.exact[e]]
            if not pending:
                return tree, rounds
            if pick == "largest":
                edge = max(pending, key=lambda e: graph.cost[e])
            else:
                rank = {v: k for k, v in enumerate(preorder(tree, graph.size, graph.cost))}
                edge = min(pending, key=lambda e: max(rank[e[0]], rank[e[1]]))
            graph.plan(*edge, planner)


def lazy_mst_sequence(graph: ViewGraph, planner: EdgePlanner, beta: float = 1.5) -> SequenceResult:
    """Table 2.2 on a graph whose edges are lower bounds (or already exact); then the
    traversal's remaining edges are planned (each edge at most once) and summed."""
    tree, rounds = exact_tree(graph, planner, beta)
    return finish(graph, preorder(tree, graph.size, graph.cost), planner, rounds)


def finish(graph: ViewGraph, order: list[int], planner: EdgePlanner, rounds: int = 0) -> SequenceResult:
    """Plan the edges of a sequence that are not planned yet; the result with its duration."""
    for a, b in zip(order[:-1], order[1:], strict=True):
        graph.plan(a, b, planner)
    return SequenceResult(order, graph.requests, graph.sequence_cost(order), rounds)
