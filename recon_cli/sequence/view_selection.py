"""Next-view selection (thesis 2.3.3, Tables 2.4 and 2.5) for the autonomous mode.

A star with the current configuration at its root and one IK solution per candidate view
as leaves; edges start at lower bounds. Repeatedly take the cheapest edge: if it is exact
(planned) its view is the next one, else plan it and look again. ``optimize_tree`` first
redraws IK solutions that lower the sum of the edge estimates (Table 2.5).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from recon_cli.planning.trajectory import Trajectory
from recon_cli.sequence.graph import EdgePlanner, LowerBound


@dataclass(frozen=True)
class Selection:
    index: int | None  # candidate chosen (None: no candidate can be reached)
    trajectory: Trajectory | None
    duration: float
    requests: int
    configs: list[np.ndarray]  # the IK solution used per candidate


def optimize_tree(q0: np.ndarray, configs: list[np.ndarray], lower_bound: LowerBound,
                  redraw: Callable[[int], np.ndarray | None], k_max: int) -> list[np.ndarray]:
    """Table 2.5: keep a redrawn IK solution when it lowers the star's total estimate."""
    configs = list(configs)
    k = 0
    while configs:
        for v in range(len(configs)):
            q = redraw(v)
            if q is not None and lower_bound(q0, q) < lower_bound(q0, configs[v]):
                configs[v], k = q, 0
                continue
            k += 1
            if k > k_max:
                return configs
    return configs


def select_view(q0: np.ndarray, configs: list[np.ndarray], lower_bound: LowerBound,
                planner: EdgePlanner) -> Selection:
    """Table 2.4: the reachable candidate with the shortest planned trajectory."""
    cost = np.array([lower_bound(q0, q) for q in configs])
    exact = np.zeros(len(configs), dtype=bool)
    paths: dict[int, Trajectory] = {}
    requests = 0
    while len(configs):
        k = int(np.argmin(cost))
        if not np.isfinite(cost[k]):
            break
        if exact[k]:
            return Selection(k, paths[k], float(cost[k]), requests, list(configs))
        traj = planner(q0, configs[k])
        requests += 1
        exact[k] = True
        if traj is None:
            cost[k] = np.inf
        else:
            paths[k], cost[k] = traj, traj.duration
    return Selection(None, None, float("inf"), requests, list(configs))
