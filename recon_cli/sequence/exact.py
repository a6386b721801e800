"""The optimal sequence: the shortest open path from the start vertex through every vertex of
a cost matrix, proven optimal by an integer program (``scipy.optimize.milp``, HiGHS).

What is optimized is what the sequence optimizer chooses among. A :class:`ViewGraph` holds
one vertex per view (vertex 0 the start configuration, vertex k one IK solution of view k);
which IK solution stands for a view is settled before the order is searched (thesis Table
2.3, ``optimize_graph``), and the path TSP solvers (``lazy_mst_sequence``,
``local_search_sequence``) choose only the order of those vertices: a path that starts at
vertex 0, visits every other vertex once and does not return. That is the problem solved
here, on the graph's matrix of planned durations; choosing among several IK solutions per
view as well (a generalized TSP) is not.

Formulation: a binary x_ij per arc i -> j with a finite cost (none into the start); every
vertex but the start is entered once, the start is left once, every other vertex is left
at most once. Such a solution is the path from the start plus, possibly, cycles apart from
it; each cycle's vertex set S gets the subtour cut sum_{i,j in S} x_ij <= |S| - 1
(Dantzig-Fulkerson-Johnson), added lazily: solve, find the cycles, cut them, solve again,
until the solution is one path. Pairs of opposite arcs are excluded from the start. Arcs
are directed, so an asymmetric matrix is solved as it is.

Every solve is of a relaxation of the problem (fewer cuts), so its optimum is a lower bound
of the optimal path; the first solution that is one path is optimal.
"""

from __future__ import annotations

import enum
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np


class TourStatus(enum.Enum):
    OPTIMAL = "optimal"  #: the order is proven optimal (within the solver's tolerance, 1e-6 s)
    TIME_LIMIT = "time limit"  #: stopped early: the order is the incumbent given, if any; see ``gap``
    INFEASIBLE = "infeasible"  #: no path through every vertex over the finite costs


@dataclass(frozen=True)
class ExactTour:
    """The result of :func:`solve_open_path`."""

    order: tuple[int, ...]  # vertices from the start; empty when no path is known
    cost: float  # sum of the costs along the order [s]; inf when no path is known
    lower_bound: float  # proven lower bound of the optimal cost [s]
    status: TourStatus
    seconds: float  # wall clock of the solve [s]
    rounds: int  # integer programs solved
    cuts: int  # subtour cuts added

    @property
    def proven_optimal(self) -> bool:
        return self.status is TourStatus.OPTIMAL

    @property
    def gap(self) -> float:
        """(cost - lower bound) / cost: 0 when proven optimal, inf when no path is known."""
        if self.proven_optimal:
            return 0.0
        if not np.isfinite(self.cost) or self.cost <= 0.0:
            return float("inf")
        return max(self.cost - self.lower_bound, 0.0) / self.cost


def path_cost(cost: np.ndarray, order: Sequence[int]) -> float:
    """Sum of cost[a, b] along the order [s]."""
    idx = np.asarray(order, dtype=int)
    return float(np.asarray(cost, dtype=float)[idx[:-1], idx[1:]].sum()) if len(idx) > 1 else 0.0


def solve_open_path(cost: np.ndarray, start: int = 0, time_limit: float = 300.0,
                    incumbent: Sequence[int] | None = None) -> ExactTour:
    """The shortest open path from ``start`` through every vertex of ``cost`` ((V, V), [s];
    inf: no edge; the diagonal is ignored). ``incumbent``: a known path (e.g. the optimizer's),
    returned with the proven gap when ``time_limit`` [s] ends the search first."""
    c = np.asarray(cost, dtype=float)
    n = len(c)
    if c.shape != (n, n) or n == 0:
        raise ValueError(f"the cost matrix must be square and not empty, got shape {c.shape}")
    if not 0 <= start < n:
        raise ValueError(f"start vertex {start} is not one of 0 ... {n - 1}")
    if np.isnan(c).any() or (c[np.isfinite(c)] < 0.0).any():
        raise ValueError("costs must be non-negative (inf: no edge), not NaN")
    t0 = time.perf_counter()
    if n == 1:
        return ExactTour((start,), 0.0, 0.0, TourStatus.OPTIMAL, time.perf_counter() - t0, 0, 0)
    model = _PathModel(c, start)
    upper = path_cost(c, incumbent) if incumbent is not None else float("inf")
    lower, rounds = 0.0, 0
    while True:
        remaining = time_limit - (time.perf_counter() - t0)
        if remaining <= 0.0:
            return _stopped(incumbent, upper, lower, t0, rounds, model.cuts)
        res = model.solve(remaining)
        rounds += 1
        if res.status == 2:
            return ExactTour((), float("inf"), float("inf"), TourStatus.INFEASIBLE, time.perf_counter() - t0,
                             rounds, model.cuts)
        if res.status != 0:  # time limit (or a solver fault): its dual bound still holds
            bound = getattr(res, "mip_dual_bound", None)
            if bound is not None and np.isfinite(bound):
                lower = max(lower, float(bound))
            return _stopped(incumbent, upper, lower, t0, rounds, model.cuts)
        lower = max(lower, float(res.fun))
        order, cycles = model.components(res.x)
        if not cycles:
            value = path_cost(c, order)
            return ExactTour(tuple(order), value, min(lower, value), TourStatus.OPTIMAL, time.perf_counter() - t0,
                             rounds, model.cuts)
        for cycle in cycles:
            model.cut(cycle)


def _stopped(incumbent: Sequence[int] | None, upper: float, lower: float, t0: float, rounds: int,
             cuts: int) -> ExactTour:
    order = tuple(int(v) for v in incumbent) if incumbent is not None else ()
    return ExactTour(order, upper, min(lower, upper), TourStatus.TIME_LIMIT, time.perf_counter() - t0, rounds, cuts)


class _PathModel:
    """The integer program of an open path from ``start``, with its subtour cuts."""

    def __init__(self, cost: np.ndarray, start: int) -> None:
        n = len(cost)
        self.n, self.start = n, start
        self.arcs = [(i, j) for i in range(n) for j in range(n)
                     if i != j and j != start and np.isfinite(cost[i, j])]
        self.index = {a: k for k, a in enumerate(self.arcs)}
        self.c = np.array([cost[a] for a in self.arcs])
        self.rows: list[list[int]] = []  # arc indices of each row
        self.lb: list[float] = []
        self.ub: list[float] = []
        for j in range(n):  # enter every vertex but the start once
            if j != start:
                self._row([self.index[(i, j)] for i in range(n) if (i, j) in self.index], 1.0, 1.0)
        for i in range(n):  # leave the start once, every other vertex at most once
            self._row([self.index[(i, j)] for j in range(n) if (i, j) in self.index],
                      1.0 if i == start else 0.0, 1.0)
        for i in range(n):  # no cycles of two vertices
            for j in range(i + 1, n):
                if (i, j) in self.index and (j, i) in self.index:
                    self._row([self.index[(i, j)], self.index[(j, i)]], 0.0, 1.0)
        self.cuts = 0

    def _row(self, arcs: list[int], lb: float, ub: float) -> None:
        self.rows.append(arcs)
        self.lb.append(lb)
        self.ub.append(ub)

    def cut(self, vertices: list[int]) -> None:
        """Subtour cut: at most |S| - 1 arcs inside the vertex set S."""
        inside = set(vertices)
        self._row([k for k, (i, j) in enumerate(self.arcs) if i in inside and j in inside], 0.0,
                  float(len(inside) - 1))
        self.cuts += 1

    def solve(self, time_limit: float):
        from scipy.optimize import Bounds, LinearConstraint, milp
        from scipy.sparse import csr_array

        indptr = np.cumsum([0] + [len(r) for r in self.rows])
        indices = np.concatenate([np.asarray(r, dtype=int) for r in self.rows]) if self.rows else np.zeros(0, int)
        a = csr_array((np.ones(len(indices)), indices, indptr), shape=(len(self.rows), len(self.arcs)))
        return milp(self.c, integrality=np.ones(len(self.arcs), dtype=np.int64), bounds=Bounds(0.0, 1.0),
                    constraints=LinearConstraint(a, np.array(self.lb), np.array(self.ub)),
                    options={"time_limit": max(time_limit, 1e-3), "mip_rel_gap": 0.0})

    def components(self, x: np.ndarray) -> tuple[list[int], list[list[int]]]:
        """The path from the start and the cycles apart from it, in a 0/1 solution."""
        succ = {self.arcs[k][0]: self.arcs[k][1] for k in np.flatnonzero(x > 0.5)}
        order, v = [self.start], self.start
        while v in succ:
            v = succ[v]
            order.append(v)
        seen = set(order)
        cycles = []
        for s in range(self.n):
            if s in seen:
                continue
            cycle, v = [], s
            while v not in seen:
                seen.add(v)
                cycle.append(v)
                v = succ[v]
            cycles.append(cycle)
        return order, cycles
