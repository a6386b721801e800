"""Which views the view planner may take, and the baselines it is compared with.

* :class:`Feasibility`: a camera pose is feasible when the camera stays above the board
  plane (the thesis' rule) and a collision-free IK solution within the soft limits exists;
* :func:`lifted`: ours, beyond the thesis: an infeasible view is raised toward the vertical,
  still looking at the same surface point from the same distance;
* :func:`baseline_views`: views evenly spread on a sphere (Fibonacci spiral over the upper
  hemisphere) or random views, for ``recon bench viewplan``.
"""

from __future__ import annotations

from collections.abc import Callable
from enum import StrEnum

import numpy as np

from recon_cli.errors import ReconError
from recon_cli.geometry.view import look_at_pose
from recon_cli.robot.ik import IKOptions


class Method(StrEnum):
    """How the next views are chosen."""

    ELLIPSOID = "ellipsoid"  # the thesis' planner (Table 2.1)
    SPHERE = "sphere"  # baseline: evenly spread on a sphere
    RANDOM = "random"  # baseline: random directions


class Status(StrEnum):
    """State of a view in the planner's bookkeeping (and the colours of its pictures)."""

    COMPLETED = "completed"
    INFEASIBLE = "infeasible"
    PLANNED = "planned"
    ACTIVE = "active"


class Feasibility:
    """Feasibility test of camera poses in a cell (IK seeded near ``seed``)."""

    def __init__(self, cell, rng: np.random.Generator, min_height: float) -> None:
        self.cell = cell
        self.rng = rng
        self.min_height = min_height
        self.marker_T_world = np.linalg.inv(cell.world_T_marker)

    def __call__(self, world_T_camera: np.ndarray, seed: np.ndarray) -> np.ndarray | None:
        """An IK solution of the camera pose (collision-free, soft limits), or None."""

        if (self.marker_T_world @ world_T_camera)[2, 3] < self.min_height:
            return None  # the thesis' rule: the camera stays above the board
        try:
            r = self.cell.solve_pose(world_T_camera, self.rng, seed=seed,
                                     options=IKOptions(max_solutions=1, max_attempts=20))
        except ReconError:
            return None
        return r.solutions[0].q


def lifted(T: np.ndarray, target: np.ndarray, q: np.ndarray,
           feasible: Callable[[np.ndarray, np.ndarray], np.ndarray | None]):
    """An infeasible view (under or against the table, out of reach) raised in steps of
    15 deg toward the vertical, looking at the same surface point from the same distance;
    the first feasible one as (pose, configuration), else (T, None). A region next to the
    table is then seen from above instead of being left out (the thesis marks such samples
    infeasible, and they repel later samples)."""

    d = T[:3, 3] - target
    dist = float(np.linalg.norm(d))
    d /= dist
    elevation = np.arctan2(d[2], np.hypot(d[0], d[1]))
    azimuth = np.arctan2(d[1], d[0])
    for step in (15.0, 30.0, 45.0, 60.0):
        e = min(elevation + np.radians(step), np.radians(85.0))
        direction = np.array([np.cos(e) * np.cos(azimuth), np.cos(e) * np.sin(azimuth), np.sin(e)])
        pose = look_at_pose(target + dist * direction, target)
        config = feasible(pose, q)
        if config is not None:
            return pose, config
    return T, None


def baseline_views(method: Method, center: np.ndarray, radius: float, need: int, q: np.ndarray,
                   feasible: Callable[[np.ndarray, np.ndarray], np.ndarray | None], rng: np.random.Generator):
    """Baselines: ``need`` feasible views at ``radius`` around ``center``, evenly spread
    (sphere) or random; returns (feasible [(pose, configuration)], infeasible [pose])."""

    dirs = None
    if method is Method.SPHERE:  # Fibonacci spiral over the upper hemisphere
        k = np.arange(need) + 0.5
        z = 1.0 - k / need * 0.95  # cos(theta) from ~1 down to 0.05
        phi = np.pi * (3.0 - np.sqrt(5.0)) * k
        dirs = np.stack([np.sqrt(1 - z * z) * np.cos(phi), np.sqrt(1 - z * z) * np.sin(phi), z], 1)
    out: list[tuple[np.ndarray, np.ndarray]] = []
    infeasible: list[np.ndarray] = []
    tries = 0
    while len(out) < need and tries < 40 * need:
        if dirs is not None:
            if tries >= len(dirs):
                break
            d = dirs[tries]
        else:
            d = rng.normal(size=3)
            d[2] = abs(d[2])
            d /= np.linalg.norm(d)
        tries += 1
        T = look_at_pose(center + radius * d, center)
        config = feasible(T, q)
        if config is None:
            infeasible.append(T)
        else:
            out.append((T, config))
    return out, infeasible
