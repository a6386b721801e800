"""Inverse kinematics: several distinct, collision-free solutions within the soft limits."""

from __future__ import annotations

import numpy as np
import pytest

from recon_cli.bench.ik import IKBenchConfig, sample_poses
from recon_cli.errors import InvalidViewError, UnreachableViewError
from recon_cli.geometry.transforms import pose_error
from recon_cli.geometry.view import View, look_at_pose
from recon_cli.robot.ik import IKOptions, IKStatus
from recon_cli.thesis import EQ_4_1_FOCUS


def _check_solutions(cell, T, result, k):
    assert result.status is IKStatus.SOLVED
    assert len(result.solutions) == k
    for s in result.solutions:
        dp, dr = pose_error(cell.kin.world_T_camera(s.q), T)
        assert dp < 1e-6 and dr < 1e-6
        assert cell.limits.within_soft(s.q)
        assert not cell.collision.in_collision(s.q)
    for i, a in enumerate(result.solutions):
        for b in result.solutions[i + 1:]:
            assert np.max(np.abs(a.q - b.q)) >= 0.1


@pytest.mark.parametrize("which", ["gantry", "ceiling"])
def test_ik_on_random_reachable_poses(which, request):
    cell = request.getfixturevalue(which)
    poses, _ = sample_poses(cell, IKBenchConfig(n_poses=30, seed=3), np.random.default_rng(3))
    rng = np.random.default_rng(4)
    for T in poses:
        result = cell.ik.solve(T, rng, options=IKOptions(max_solutions=3))
        _check_solutions(cell, T, result, 3)


def test_eq_4_1_views_are_reachable(gantry):
    rng = np.random.default_rng(0)
    for i in range(1, 25):
        view = View.from_degrees(EQ_4_1_FOCUS, 0.6, 70 if i <= 12 else 50, 30 * (i - 1))
        T = gantry.view_pose(view)
        result = gantry.solve_pose(T, rng, options=IKOptions(max_solutions=2))
        _check_solutions(gantry, T, result, 2)


def test_seed_gives_nearby_solution(gantry):
    """Seeded with a solution, the solver returns that solution first (no jump)."""
    rng = np.random.default_rng(1)
    T = gantry.view_pose(View.from_degrees(EQ_4_1_FOCUS, 0.6, 70, 90))
    first = gantry.ik.solve(T, rng, options=IKOptions(max_solutions=1)).solutions[0].q
    again = gantry.ik.solve(T, rng, seed=first, options=IKOptions(max_solutions=1))
    assert np.max(np.abs(again.solutions[0].q - first)) < 1e-5


def test_ik_is_deterministic_for_a_seed(gantry):
    T = gantry.view_pose(View.from_degrees(EQ_4_1_FOCUS, 0.6, 50, 210))
    a = gantry.ik.solve(T, np.random.default_rng(9))
    b = gantry.ik.solve(T, np.random.default_rng(9))
    assert all(np.array_equal(x.q, y.q) for x, y in zip(a.solutions, b.solutions, strict=True))


def test_unreachable_pose_is_reported(gantry):
    rng = np.random.default_rng(0)
    # camera 10 cm above the floor in a corner of the cell: beyond the arm's reach
    low = look_at_pose(np.array([0.7, 1.2, 0.1]), np.array([0.0, 0.0, 0.78]))
    result = gantry.ik.solve(low, rng, options=IKOptions(max_attempts=10))
    assert result.status is IKStatus.UNREACHABLE and not result.solutions
    with pytest.raises(UnreachableViewError, match="out of reach"):
        gantry.solve_pose(low, rng)


def test_view_inside_obstacles_is_refused(gantry):
    rng = np.random.default_rng(0)
    under = View.from_degrees((0.0, 0.0, 0.78), 0.2, 170, 0)
    with pytest.raises(InvalidViewError, match="under the table top"):
        gantry.solve_view(under, rng)
    in_cube = View.from_degrees((0.0, 0.0, 0.9), 0.05, 0, 0)
    with pytest.raises(InvalidViewError, match="object_box"):
        gantry.solve_view(in_cube, rng)
