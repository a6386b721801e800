"""The batched C++ checker (pinocchio + coal) against the python-fcl reference on the same
shapes: configurations, inflated copies and straight motions."""

from __future__ import annotations

import fcl
import numpy as np


def _pair_distance(cm, poses, i: int, j: int) -> float:
    """python-fcl distance of a checker pair (indices: robot shapes, then environment)."""
    n_robot = len(cm.robot_shapes)
    placed: set[int] = set()
    a = cm._place(i, poses, placed)
    b = cm._place(j, poses, placed) if j < n_robot else cm._env_objs[j - n_robot]
    return fcl.distance(a, b, fcl.DistanceRequest(), fcl.DistanceResult())


def test_configuration_checks_agree_with_fcl(gantry, rng):
    cm = gantry.collision
    qs = rng.uniform(gantry.limits.soft_lower, gantry.limits.soft_upper, size=(1500, 9))
    reference = np.array([cm.check(q).colliding for q in qs])
    assert 0.2 < reference.mean() < 0.95  # both answers occur often
    assert np.array_equal(np.array([cm.in_collision(q) for q in qs]), reference)
    for start in (0, 10, 200):
        chunk = qs[start:start + 50]
        hits = np.nonzero(reference[start:start + 50])[0]
        assert cm.first_collision(chunk) == (int(hits[0]) if len(hits) else -1)


def test_inflated_copies_are_conservative(gantry, rng):
    """Where a copy inflated by G says free, every pair it checks is more than G apart
    (robot-environment) or 2G apart (robot-robot): the property the motion check rests on."""
    cm = gantry.collision
    checker = cm._batch
    n_robot = len(cm.robot_shapes)
    qs = rng.uniform(gantry.limits.soft_lower, gantry.limits.soft_upper, size=(400, 9))
    for level in checker.levels(0.005):
        free = qs[~level.batch(qs)]
        assert len(free) > 10
        for q in free[:60]:
            poses = cm.shape_poses(q)
            for i, j in checker._swept:
                need = level.grow * (2.0 if j < n_robot else 1.0)
                assert _pair_distance(cm, poses, i, j) > need - 1e-9


def test_free_motions_are_free_for_fcl_at_2mm(gantry):
    """segment_free says 'free' only for motions python-fcl finds free at every sample of
    2 mm robot-point motion."""
    cm = gantry.collision
    rng = np.random.default_rng(11)
    seen = {True: 0, False: 0}
    while min(seen.values()) < 10:
        a = gantry.limits.sample_soft(rng)
        if cm.in_collision(a):
            continue
        b = gantry.limits.clip_soft(a + rng.normal(0.0, 0.25, 9))
        steps = int(np.ceil(float(cm.point_step_bound(b - a)) / 0.002)) + 1
        dense = a + np.linspace(0.0, 1.0, steps)[:, None] * (b - a)
        free = cm.segment_free(a, b)
        if free:
            assert not any(cm.check(q).colliding for q in dense)
        seen[free] += 1


def test_first_collision_of_a_dense_course_matches_fcl(gantry):
    """A densely sampled course (grouped by accumulated motion, inflated copies first) gives
    the same first colliding sample as python-fcl sample by sample."""
    cm = gantry.collision
    rng = np.random.default_rng(3)
    found = 0
    for _ in range(40):
        a = gantry.limits.sample_soft(rng)
        b = gantry.limits.sample_soft(rng)
        steps = int(np.ceil(float(cm.point_step_bound(b - a)) / 0.005)) + 1
        dense = a + np.linspace(0.0, 1.0, steps)[:, None] * (b - a)
        reference = next((k for k, q in enumerate(dense) if cm.check(q).colliding), -1)
        assert cm.first_collision(dense) == reference
        found += reference > 0
    assert found >= 10
