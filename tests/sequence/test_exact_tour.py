"""The exact open-path solver: brute force agrees, known instances, asymmetric costs,
missing edges, the time limit."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from recon_cli.sequence.exact import TourStatus, path_cost, solve_open_path
from recon_cli.sequence.optimize import improve_order


def _brute_force(cost: np.ndarray, start: int = 0) -> float:
    rest = [v for v in range(len(cost)) if v != start]
    return min(path_cost(cost, (start, *p)) for p in itertools.permutations(rest))


def _is_path(order, n: int, start: int = 0) -> bool:
    return order[0] == start and sorted(order) == list(range(n))


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("n", [7, 8])
def test_brute_force_agrees_on_random_symmetric_instances(seed, n):
    rng = np.random.default_rng(seed)
    points = rng.uniform(0.0, 1.0, (n, 9))  # like joint configurations
    cost = np.abs(points[:, None, :] - points[None, :, :]).max(axis=2) * 10.0  # a metric [s]
    result = solve_open_path(cost)
    assert result.proven_optimal and result.gap == 0.0 and result.status is TourStatus.OPTIMAL
    assert _is_path(result.order, n)
    assert result.cost == pytest.approx(_brute_force(cost), abs=1e-6)
    assert result.cost == pytest.approx(path_cost(cost, result.order))
    assert result.lower_bound <= result.cost + 1e-9 and result.seconds >= 0.0 and result.rounds >= 1


@pytest.mark.parametrize("seed", range(6))
def test_asymmetric_costs_are_solved_as_they_are(seed):
    rng = np.random.default_rng(100 + seed)
    n = 8
    cost = rng.uniform(1.0, 10.0, (n, n))  # asymmetric, not a metric
    start = int(rng.integers(n))
    result = solve_open_path(cost, start=start)
    assert result.proven_optimal and _is_path(result.order, n, start)
    best = _brute_force(cost, start)
    assert result.cost == pytest.approx(best, abs=1e-6)
    # the transposed matrix is another problem (every arc reversed), solved as such
    reversed_best = min(path_cost(cost.T, (start, *p)) for p in itertools.permutations(
        [v for v in range(n) if v != start]))
    assert solve_open_path(cost.T, start=start).cost == pytest.approx(reversed_best, abs=1e-6)


def test_one_way_costs_decide_the_direction():
    # a ring 0 -> 1 -> 2 -> 3 -> 4 is cheap one way, dear the other
    n = 5
    cost = np.full((n, n), 10.0)
    for i in range(n):
        cost[i, (i + 1) % n] = 1.0
    result = solve_open_path(cost)
    assert result.order == (0, 1, 2, 3, 4) and result.cost == pytest.approx(4.0)
    assert solve_open_path(cost.T).order == (0, 4, 3, 2, 1)


def test_points_on_a_line():
    # start at 0 between views at -1 and 2, 3: the near side first (1 + 3 + 1), not (2 + 1 + 4)
    x = np.array([0.0, -1.0, 2.0, 3.0])
    cost = np.abs(x[:, None] - x[None, :])
    result = solve_open_path(cost)
    assert result.order == (0, 1, 2, 3) and result.cost == pytest.approx(5.0)
    # from one end: the sorted order, the span
    x = np.array([0.0, 5.0, 1.0, 4.0, 2.0, 3.0, 7.0, 6.0])
    result = solve_open_path(np.abs(x[:, None] - x[None, :]))
    assert [x[v] for v in result.order] == sorted(x) and result.cost == pytest.approx(7.0)


def test_subtours_are_cut():
    # two clusters far apart: without cuts the solution is the path in one and a cycle in the other
    rng = np.random.default_rng(7)
    points = np.vstack([rng.normal(0.0, 0.1, (6, 2)), rng.normal(5.0, 0.1, (6, 2))])
    cost = np.linalg.norm(points[:, None] - points[None, :], axis=2)
    result = solve_open_path(cost)
    assert result.proven_optimal and _is_path(result.order, 12)
    assert result.cost <= path_cost(cost, improve_order(cost, list(range(12)))) + 1e-9
    jumps = sum(cost[a, b] > 2.0 for a, b in zip(result.order[:-1], result.order[1:], strict=True))
    assert jumps == 1


def test_missing_edges_are_avoided_or_infeasible():
    cost = np.array([[0.0, 1.0, 1.0], [1.0, 0.0, np.inf], [1.0, np.inf, 0.0]])
    result = solve_open_path(cost)  # 1 and 2 only meet through the start: no open path
    assert result.status is TourStatus.INFEASIBLE and result.order == () and not np.isfinite(result.cost)
    cost = np.array([[0.0, 1.0, 5.0], [1.0, 0.0, np.inf], [5.0, 2.0, 0.0]])
    result = solve_open_path(cost)  # 1 -> 2 is missing, 2 -> 1 is not
    assert result.proven_optimal and result.order == (0, 2, 1) and result.cost == pytest.approx(7.0)


def test_tiny_and_bad_inputs():
    assert solve_open_path(np.zeros((1, 1))).order == (0,)
    assert solve_open_path(np.array([[0.0, 3.0], [3.0, 0.0]])).cost == pytest.approx(3.0)
    with pytest.raises(ValueError, match="square"):
        solve_open_path(np.zeros((2, 3)))
    with pytest.raises(ValueError, match="start vertex"):
        solve_open_path(np.zeros((3, 3)), start=3)
    with pytest.raises(ValueError, match="non-negative"):
        solve_open_path(np.array([[0.0, -1.0], [1.0, 0.0]]))


def test_the_time_limit_returns_the_incumbent_with_its_gap():
    rng = np.random.default_rng(3)
    n = 30
    points = rng.uniform(0.0, 1.0, (n, 2))
    cost = np.linalg.norm(points[:, None] - points[None, :], axis=2)
    incumbent = list(range(n))
    result = solve_open_path(cost, time_limit=0.0, incumbent=incumbent)
    assert result.status is TourStatus.TIME_LIMIT and not result.proven_optimal
    assert result.order == tuple(incumbent) and result.cost == pytest.approx(path_cost(cost, incumbent))
    assert 0.0 < result.gap <= 1.0
    assert solve_open_path(cost, time_limit=0.0).gap == float("inf")


def test_local_search_is_never_better_than_the_optimum():
    rng = np.random.default_rng(11)
    for _ in range(5):
        points = rng.uniform(0.0, 1.0, (14, 7))
        cost = np.abs(points[:, None, :] - points[None, :, :]).max(axis=2)
        optimum = solve_open_path(cost)
        local = path_cost(cost, improve_order(cost, list(range(14))))
        assert optimum.proven_optimal and optimum.cost <= local + 1e-9
