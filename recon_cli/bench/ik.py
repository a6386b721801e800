"""IK benchmark: random reachable camera poses around the table (``recon bench ik``).

Poses come from forward kinematics of random valid configurations: configurations are
drawn uniformly within the soft limits and kept when they are collision-free and their
camera looks at the table centre (the optical axis passes within ``focus_tolerance`` of
(0, 0, 0.78) m, at a distance r in [r_min, r_max] along the axis). Every pose is therefore
reachable; the solver then starts from its own seeds, never from the generating
configuration. Reported: success rate, time to the first solution and time per solution
when several are requested, and checks of every returned solution.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict, dataclass

import numpy as np

from recon_cli.geometry.transforms import pose_error
from recon_cli.robot.cell import Cell
from recon_cli.robot.ik import IKOptions

TABLE_CENTRE = np.array([0.0, 0.0, 0.78])


@dataclass(frozen=True)
class IKBenchConfig:
    n_poses: int = 500
    r_min: float = 0.45
    r_max: float = 0.8
    focus_tolerance: float = 0.1
    solutions: int = 4
    seed: int = 0


@dataclass(frozen=True)
class IKBenchResult:
    cell: str
    n_poses: int
    samples_drawn: int
    success_first: float  # share of poses with at least one solution (max_solutions = 1)
    median_ms_first: float  # median time to the first solution
    p90_ms_first: float
    success_multi: float  # share of poses with at least one solution (max_solutions = k)
    mean_solutions: float  # distinct solutions found per pose when asking for k
    median_ms_per_solution: float  # median of (solve time / solutions found), asking for k
    max_position_error_m: float
    max_rotation_error_rad: float
    all_within_soft_limits: bool
    all_collision_free: bool
    min_pairwise_separation: float  # smallest max-norm distance between two solutions

    def to_dict(self) -> dict:
        return asdict(self)


def sample_poses(cell: Cell, cfg: IKBenchConfig, rng: np.random.Generator,
                 progress: Callable[[int], None] | None = None
                 ) -> tuple[list[np.ndarray], int]:
    """Camera poses of random valid configurations that look at the table centre."""
    poses: list[np.ndarray] = []
    drawn = 0
    while len(poses) < cfg.n_poses:
        q = cell.limits.sample_soft(rng)
        drawn += 1
        T = cell.kin.world_T_camera(q)
        p, z = T[:3, 3], T[:3, 2]
        s = float((TABLE_CENTRE - p) @ z)
        if not (cfg.r_min <= s <= cfg.r_max):
            continue
        if np.linalg.norm(p + s * z - TABLE_CENTRE) > cfg.focus_tolerance:
            continue
        if cell.collision.in_collision(q):
            continue
        poses.append(T)
        if progress:
            progress(len(poses))
    return poses, drawn


def run_ik_bench(cell: Cell, cfg: IKBenchConfig,
                 progress: Callable[[str, int, int], None] | None = None) -> IKBenchResult:
    rng = np.random.default_rng(cfg.seed)
    poses, drawn = sample_poses(
        cell, cfg, rng, (lambda k: progress("sampling poses", k, cfg.n_poses)) if progress else None
    )
    solve_rng = np.random.default_rng(cfg.seed + 1)
    first_ok, first_ms = [], []
    multi_ok, per_solution_ms, counts = [], [], []
    max_dp = max_dr = 0.0
    within = free = True
    min_sep = np.inf
    one = IKOptions(max_solutions=1)
    many = IKOptions(max_solutions=cfg.solutions)
    for k, T in enumerate(poses):
        t0 = time.perf_counter()
        r1 = cell.ik.solve(T, solve_rng, options=one)
        first_ms.append((time.perf_counter() - t0) * 1e3)
        first_ok.append(r1.ok)
        t0 = time.perf_counter()
        rk = cell.ik.solve(T, solve_rng, options=many)
        dt = (time.perf_counter() - t0) * 1e3
        multi_ok.append(rk.ok)
        counts.append(len(rk.solutions))
        if rk.solutions:
            per_solution_ms.append(dt / len(rk.solutions))
        for sol in r1.solutions + rk.solutions:
            dp, dr = pose_error(cell.kin.world_T_camera(sol.q), T)
            max_dp, max_dr = max(max_dp, dp), max(max_dr, dr)
            within &= cell.limits.within_soft(sol.q)
            free &= not cell.collision.in_collision(sol.q)
        for i in range(len(rk.solutions)):
            for j in range(i + 1, len(rk.solutions)):
                sep = float(np.max(np.abs(rk.solutions[i].q - rk.solutions[j].q)))
                min_sep = min(min_sep, sep)
        if progress:
            progress("solving", k + 1, len(poses))
    return IKBenchResult(
        cell=cell.config.kind.value,
        n_poses=len(poses),
        samples_drawn=drawn,
        success_first=float(np.mean(first_ok)),
        median_ms_first=float(np.median(first_ms)),
        p90_ms_first=float(np.percentile(first_ms, 90)),
        success_multi=float(np.mean(multi_ok)),
        mean_solutions=float(np.mean(counts)),
        median_ms_per_solution=float(np.median(per_solution_ms)) if per_solution_ms else np.nan,
        max_position_error_m=max_dp,
        max_rotation_error_rad=max_dr,
        all_within_soft_limits=bool(within),
        all_collision_free=bool(free),
        min_pairwise_separation=float(min_sep),
    )
