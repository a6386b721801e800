"""Sequence optimization on small metric instances: every view once, the 2 beta bound
against brute force, no edge planned twice, view selection, graph optimization."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from recon_cli.planning.trajectory import Trajectory
from recon_cli.sequence.graph import ViewGraph
from recon_cli.sequence.optimize import improve_order, local_search_sequence, optimize_graph
from recon_cli.sequence.tsp import lazy_mst_sequence, minimum_spanning_tree, preorder
from recon_cli.sequence.view_selection import optimize_tree, select_view


def _instance(m: int, seed: int):
    """Points in the plane: exact cost = Euclidean distance (a metric), lower bound = the
    distance shrunk by a random factor in [0.5, 1] per pair (always <= exact)."""
    rng = np.random.default_rng(seed)
    pts = [rng.uniform(0, 10, 2) for _ in range(m + 1)]
    shrink = {}

    def lower(a, b):
        key = (tuple(np.round(a, 9)), tuple(np.round(b, 9)))
        key = min(key, key[::-1])
        if key not in shrink:
            shrink[key] = rng.uniform(0.5, 1.0)
        return float(np.linalg.norm(a - b)) * shrink[key]

    planned: list[tuple] = []

    def planner(a, b):
        planned.append((tuple(a), tuple(b)))
        d = float(np.linalg.norm(a - b))
        times = np.array([0.0, d])
        q = np.stack([a, b])
        return Trajectory(times, q, np.zeros_like(q), np.zeros_like(q))

    return pts, lower, planner, planned


def _optimum(pts) -> float:
    best = np.inf
    for perm in itertools.permutations(range(1, len(pts))):
        order = (0, *perm)
        best = min(best, sum(np.linalg.norm(pts[a] - pts[b]) for a, b in zip(order[:-1], order[1:], strict=True)))
    return best


@pytest.mark.parametrize("seed", range(12))
@pytest.mark.parametrize("beta", [1.0, 1.5])
def test_lazy_mst_visits_all_once_within_2_beta_of_the_optimum(seed, beta):
    m = 3 + seed % 6  # 3..8 views
    pts, lower, planner, planned = _instance(m, seed)
    graph = ViewGraph(pts, lower)
    result = lazy_mst_sequence(graph, planner, beta)
    assert result.order[0] == 0 and sorted(result.order) == list(range(m + 1))
    exact = sum(np.linalg.norm(pts[a] - pts[b]) for a, b in zip(result.order[:-1], result.order[1:], strict=True))
    assert result.duration == pytest.approx(exact)
    assert result.duration <= 2 * beta * _optimum(pts) + 1e-9
    # no edge planned twice (in either direction), and the count matches
    edges = [frozenset(e) for e in planned]
    assert len(edges) == len(set(edges)) == result.requests


@pytest.mark.parametrize("seed", range(6))
def test_local_search_sequence(seed):
    m = 8
    pts, lower, planner, planned = _instance(m, 100 + seed)
    result = local_search_sequence(ViewGraph(pts, lower), planner, 1.5, request_cost=0.0)
    assert sorted(result.order) == list(range(m + 1)) and result.order[0] == 0
    edges = [frozenset(e) for e in planned]
    assert len(edges) == len(set(edges))
    tree = lazy_mst_sequence(ViewGraph(pts, lower), _instance(m, 100 + seed)[2], 1.5)
    assert result.duration <= tree.duration + 1e-9  # local search never loses to the preorder


def test_improve_order_reaches_the_optimum_on_small_instances():
    for seed in range(10):
        pts, *_ = _instance(7, 200 + seed)
        cost = np.array([[np.linalg.norm(a - b) for b in pts] for a in pts])
        order = improve_order(cost, list(range(len(pts))))
        got = sum(cost[a, b] for a, b in zip(order[:-1], order[1:], strict=True))
        assert got <= 1.10 * _optimum(pts)  # 2-opt + Or-opt: within 10 % here


def test_preorder_and_mst():
    cost = np.array([[0, 1, 4, 5], [1, 0, 2, 6], [4, 2, 0, 3], [5, 6, 3, 0]], float)
    tree = minimum_spanning_tree(cost)
    assert tree == [(0, 1), (1, 2), (2, 3)]
    assert preorder(tree, 4, cost) == [0, 1, 2, 3]
    star = [(0, 1), (0, 2), (0, 3)]
    assert preorder(star, 4, cost) == [0, 1, 2, 3]  # children by increasing edge cost


def test_reversed_edge_is_reused():
    pts, lower, planner, planned = _instance(3, 7)
    g = ViewGraph(pts, lower)
    g.plan(2, 1, planner)
    assert g.plan(1, 2, planner) == g.cost[1, 2] and g.requests == 1
    fwd, back = g.trajectory(1, 2), g.trajectory(2, 1)
    assert np.allclose(fwd.start, back.goal) and np.allclose(fwd.goal, back.start)
    assert back.duration == pytest.approx(fwd.duration)


def test_graph_optimization_lowers_the_preorder_estimate():
    rng = np.random.default_rng(0)
    pts, lower, *_ = _instance(6, 9)
    graph = ViewGraph(pts, lower)
    from recon_cli.sequence.optimize import preorder_cost

    before = preorder_cost(graph)[1]
    # a "new IK solution" of a view: the same point moved a little (what another arm pose
    # of the same camera pose means for the joint-space distances)
    better, draws = optimize_graph(graph, lambda v: pts[v] + rng.normal(0, 0.5, 2), k_max=30)
    assert preorder_cost(better)[1] <= before and draws > 30


def test_view_selection_plans_lazily_until_the_cheapest_is_exact():
    q0 = np.zeros(2)
    configs = [np.array([3.0, 0.0]), np.array([1.0, 0.0]), np.array([2.0, 0.0])]
    calls = []

    def planner(a, b):
        calls.append(tuple(b))
        d = 5.0 if b[0] == 1.0 else float(np.linalg.norm(b - a))  # the nearest is blocked: long way round
        return Trajectory(np.array([0.0, d]), np.stack([a, b]), np.zeros((2, 2)), np.zeros((2, 2)))

    lower = lambda a, b: float(np.linalg.norm(b - a))  # noqa: E731
    sel = select_view(q0, configs, lower, planner)
    assert sel.index == 2 and sel.duration == pytest.approx(2.0)
    assert calls == [(1.0, 0.0), (2.0, 0.0)] and sel.requests == 2  # the 3 m view never planned
    unreachable = select_view(q0, configs, lower, lambda a, b: None)
    assert unreachable.index is None and unreachable.requests == 3
    rng = np.random.default_rng(1)
    improved = optimize_tree(q0, configs, lower, lambda v: configs[v] * rng.uniform(0.5, 1.5), k_max=10)
    assert sum(lower(q0, c) for c in improved) <= sum(lower(q0, c) for c in configs)
