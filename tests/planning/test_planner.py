"""OMPL planning on the Table 4.1 problem: solved, checked, typed failures."""

from __future__ import annotations

import numpy as np
import pytest

from recon_cli.errors import UnknownNameError
from recon_cli.planning.checks import check_trajectory
from recon_cli.planning.planner import MotionPlanner, PlanOptions, PlanStatus
from recon_cli.thesis import TABLE_4_1_GOAL, TABLE_4_1_START


@pytest.fixture(scope="module")
def planner(gantry):
    return MotionPlanner(gantry, PlanOptions())


def test_table_4_1_is_solved_and_the_trajectory_is_safe(gantry, planner):
    for seed in range(3):
        r = planner.plan_to_joints(TABLE_4_1_START, TABLE_4_1_GOAL, seed=seed)
        assert r.ok, r.message
        traj = r.trajectory
        assert np.allclose(traj.start, TABLE_4_1_START) and np.allclose(traj.goal, TABLE_4_1_GOAL)
        # limits, independently of the planner's own check
        t = np.linspace(0, traj.duration, 4000)
        q, qd, qdd = traj.sample(t)
        lim = gantry.limits
        assert np.all(q >= lim.soft_lower - 1e-9) and np.all(q <= lim.soft_upper + 1e-9)
        assert np.all(np.abs(qd) <= lim.velocity * 0.15 + 1e-9)
        assert np.all(np.abs(qdd) <= lim.acceleration * 0.3 + 1e-9)
        # collision-free at a resolution where no robot point moves more than 5 mm, checked
        # sample by sample with the plain (unswept) check
        n = int(1.2 * np.max(gantry.collision.point_step_bound(np.diff(q, axis=0))) / 0.005 * len(t)) + 1
        dense = traj.sample(np.linspace(0, traj.duration, max(n, len(t))))[0]
        step = gantry.collision.point_step_bound(np.diff(dense, axis=0))
        assert np.max(step) <= 0.005
        assert gantry.collision.first_collision(dense) == -1
        assert check_trajectory(traj, gantry, 0.15, 0.3).ok


def test_segment_check_equals_dense_sampling(gantry):
    cm = gantry.collision
    rng = np.random.default_rng(5)
    for _ in range(150):
        a = gantry.limits.sample_soft(rng)
        while cm.in_collision(a):
            a = gantry.limits.sample_soft(rng)
        b = gantry.limits.clip_soft(a + rng.normal(scale=0.4, size=a.shape))
        n = max(1, int(np.ceil(cm.point_step_bound(b - a) / 0.005)))
        dense = a + (np.arange(n + 1) / n)[:, None] * (b - a)
        assert cm.segment_free(a, b) == (cm.first_collision(dense) == -1)


def test_invalid_start_and_goal_are_results(gantry, planner):
    inside_table = np.zeros(9)
    r = planner.plan_to_joints(inside_table, TABLE_4_1_GOAL)
    assert r.status is PlanStatus.INVALID_START and "collision" in r.message
    r = planner.plan_to_joints(TABLE_4_1_START, inside_table)
    assert r.status is PlanStatus.INVALID_GOAL
    outside = TABLE_4_1_GOAL.copy()
    outside[2] = 3.0  # beyond the soft limit of arm_joint_1
    assert planner.plan_to_joints(TABLE_4_1_START, outside).status is PlanStatus.INVALID_GOAL


def test_timeout_is_a_result(gantry):
    quick = MotionPlanner(gantry, PlanOptions(time_limit=0.001))
    r = quick.plan_to_joints(TABLE_4_1_START, TABLE_4_1_GOAL)
    assert r.status in (PlanStatus.TIMEOUT, PlanStatus.SOLVED)  # 1 ms: a timeout, unless lucky
    assert r.status is PlanStatus.SOLVED or r.trajectory is None


@pytest.mark.parametrize("name", ["RRT", "KPIECE1", "RRTstar", "PRM", "BITstar"])
def test_other_planners_by_name(gantry, name):
    r = MotionPlanner(gantry, PlanOptions(planner=name, time_limit=10.0)).plan_to_joints(
        TABLE_4_1_START, TABLE_4_1_GOAL, seed=1)
    assert r.status in (PlanStatus.SOLVED, PlanStatus.TIMEOUT)
    if r.ok:
        assert r.check.ok


def test_unknown_planner():
    with pytest.raises(UnknownNameError, match="RRTConnect"):
        PlanOptions(planner="EST")
