"""The view graph of sequence optimization (thesis 2.3): vertex 0 is the start
configuration, vertices 1..m one IK solution per view; edge weights are trajectory durations
t_p, lower bounds (eqs. 2.16-2.21) until the edge is planned ("exact").

Edges are undirected: a trajectory planned from i to j, played backwards, goes from j to i in
the same time along the same checked course, so no edge is ever planned twice.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from recon_cli.planning.trajectory import Trajectory, reverse

#: plans one edge: (q_from, q_to) -> trajectory, or None when no path was found
EdgePlanner = Callable[[np.ndarray, np.ndarray], Trajectory | None]
#: lower bound of the duration between two configurations [s]
LowerBound = Callable[[np.ndarray, np.ndarray], float]


@dataclass
class ViewGraph:
    configs: list[np.ndarray]
    lower_bound: LowerBound
    cost: np.ndarray = field(init=False)  # (V, V) symmetric, [s]
    exact: np.ndarray = field(init=False)  # (V, V) bool
    paths: dict[tuple[int, int], Trajectory] = field(init=False, default_factory=dict)  # i < j, from i to j
    requests: int = field(init=False, default=0)
    planned: list[tuple[int, int]] = field(init=False, default_factory=list)  # in planning order

    def __post_init__(self) -> None:
        V = len(self.configs)
        self.cost = np.zeros((V, V))
        self.exact = np.zeros((V, V), dtype=bool)
        np.fill_diagonal(self.exact, True)
        for i in range(V):
            for j in range(i + 1, V):
                self.cost[i, j] = self.cost[j, i] = self.lower_bound(self.configs[i], self.configs[j])

    @property
    def size(self) -> int:
        return len(self.configs)

    def replace_vertex(self, k: int, q: np.ndarray) -> ViewGraph:
        """A copy with vertex k's configuration replaced and its edges reset to lower bounds."""
        g = ViewGraph.__new__(ViewGraph)
        g.configs = list(self.configs)
        g.configs[k] = np.asarray(q, dtype=float)
        g.lower_bound = self.lower_bound
        g.cost, g.exact = self.cost.copy(), self.exact.copy()
        g.paths = {e: p for e, p in self.paths.items() if k not in e}
        g.requests, g.planned = self.requests, list(self.planned)
        for j in range(self.size):
            if j != k:
                g.cost[k, j] = g.cost[j, k] = self.lower_bound(g.configs[k], g.configs[j])
                g.exact[k, j] = g.exact[j, k] = False
        return g

    def plan(self, i: int, j: int, planner: EdgePlanner) -> float:
        """Plan edge (i, j) (once), make it exact; returns its duration (inf: no path)."""
        if self.exact[i, j]:
            return float(self.cost[i, j])
        a, b = min(i, j), max(i, j)
        traj = planner(self.configs[a], self.configs[b])
        self.requests += 1
        self.planned.append((a, b))
        duration = np.inf if traj is None else traj.duration
        if traj is not None:
            self.paths[(a, b)] = traj
        self.cost[i, j] = self.cost[j, i] = duration
        self.exact[i, j] = self.exact[j, i] = True
        return duration

    def trajectory(self, i: int, j: int) -> Trajectory | None:
        """The planned trajectory from i to j (reversed when it was planned from j to i)."""
        if (i, j) in self.paths:
            return self.paths[(i, j)]
        if (j, i) in self.paths:
            return reverse(self.paths[(j, i)])
        return None

    def sequence_cost(self, order: list[int]) -> float:
        return float(sum(self.cost[a, b] for a, b in zip(order[:-1], order[1:], strict=True)))
