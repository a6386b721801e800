"""Collision model: Table 4.1 states are free, each kind of collision is named."""

from __future__ import annotations

import numpy as np
import pytest

from recon_cli.thesis import TABLE_4_1_GOAL, TABLE_4_1_START

DEG = np.pi / 180.0


@pytest.mark.parametrize("q", [TABLE_4_1_START, TABLE_4_1_GOAL], ids=["start", "goal"])
def test_table_4_1_states_free_and_within_limits(gantry, q):
    assert gantry.collision.object_box is not None  # the 0.3 m cube is on the table
    assert gantry.limits.within_soft(q)
    report = gantry.collision.check(q)
    assert not report.colliding, report.pairs
    d = gantry.collision.distance(q)
    assert d.environment > 0 and d.self_ > 0


def _has_pair(pairs, a, b):
    return any((a in x and b in y) or (b in x and a in y) for x, y in pairs)


def test_robot_table_collision_is_named(gantry):
    q = np.zeros(9)  # gantry over the table centre, arm hanging straight down into it
    report = gantry.collision.check(q)
    assert report.colliding
    assert _has_pair(report.pairs, "arm_link_7/", "table_link_2/table_top")
    assert gantry.collision.distance(q).environment <= 0.0


def test_robot_frame_collision_is_named(gantry):
    q = TABLE_4_1_START.copy()
    q[1] = -0.8  # carriage driven into the wall at x = -0.96
    q[3] = 90 * DEG
    report = gantry.collision.check(q)
    assert _has_pair(report.pairs, "base_link_1/carriage", "frame_link/wall_x_neg")


def test_self_collision_is_named(gantry):
    q = TABLE_4_1_START.copy()
    q[7] = 110 * DEG  # wrist bent: link 5 hits the camera bracket
    report = gantry.collision.check(q)
    assert report.pairs == (("arm_link_5/arm_link_5_capsule", "camera_link_0/camera_bracket"),)
    d = gantry.collision.distance(q)
    assert d.self_ <= 0.0 and d.environment > 0.0


def test_object_box_is_an_obstacle(gantry):
    """The straight arm over the table hits the cube before the table top."""
    q = np.zeros(9)
    q[2 + 1] = 0.0
    pairs = gantry.collision.check(q).pairs
    assert _has_pair(pairs, "arm_link_", "object/object_box")


def test_check_agrees_with_distance_sign(gantry, rng):
    agree = 0
    for _ in range(200):
        q = gantry.limits.sample_soft(rng)
        colliding = gantry.collision.in_collision(q)
        d = gantry.collision.distance(q).minimum
        agree += colliding == (d <= 1e-9)
    assert agree == 200


def test_capsule_is_exact(gantry):
    """A point just outside the capsule's rounded end is free, just inside collides."""
    import fcl

    shape = next(s for s in gantry.collision.robot_shapes if s.link == "arm_link_3")
    r, length = shape.dims
    cap = fcl.CollisionObject(fcl.Capsule(r, length), fcl.Transform())
    for gap, hit in ((+1e-4, False), (-1e-4, True)):
        probe = fcl.CollisionObject(fcl.Sphere(1e-5),
                                    fcl.Transform(np.array([0, 0, length / 2 + r + gap])))
        assert fcl.collide(cap, probe, fcl.CollisionRequest(), fcl.CollisionResult()) == hit


def test_declared_gaps_are_constant(gantry):
    """collision.yaml skips carriage/base vs rails: their vertical gap never changes."""
    from recon_cli.robot.collision import allowed_shape_pairs

    cm = gantry.collision
    rng = np.random.default_rng(0)
    labels = {s.label: s for s in cm.env_shapes}
    for pair in allowed_shape_pairs():
        robot_label, env_label = sorted(pair, key=lambda x: x.startswith("frame_link"))
        shape = next(s for s in cm.robot_shapes if s.label == robot_label)
        rail = labels[env_label]
        rail_bottom = rail.joint_T_shape[2, 3] - rail.dims[2] / 2
        tops = []
        for _ in range(50):
            q = gantry.limits.sample_soft(rng)
            T = cm.shape_poses(q)[cm.robot_shapes.index(shape)]
            half = np.asarray(shape.dims) / 2 if shape.kind == "box" else np.array([0, 0, shape.dims[1] / 2])
            top = T[2, 3] + np.abs(T[2, :3]) @ half
            tops.append(top)
        assert np.ptp(tops) < 1e-9 and max(tops) < rail_bottom


def test_certified_pairs(gantry):
    labels = {(a, b) for a, b, _ in gantry.collision.certified_pairs}
    assert ("arm_link_6/arm_link_6_capsule", "camera_link_1/camera_housing") in labels
    assert all(d > 0 for _, _, d in gantry.collision.certified_pairs)


def test_certified_env_pairs_hold_over_random_configurations(gantry):
    """Robot-environment pairs proven separated (the arm base under the roof, ...) really
    keep at least their certified distance, over random configurations in the hard limits."""
    import fcl

    cm = gantry.collision
    labels = {(a, b) for a, b, _ in cm.certified_env_pairs}
    assert ("arm_link_0/arm_base_box", "frame_link/roof") in labels
    rng = np.random.default_rng(3)
    robot = [s.label for s in cm.robot_shapes]
    env = [s.label for s in cm.env_shapes]
    for _ in range(200):
        q = rng.uniform(gantry.limits.lower, gantry.limits.upper)
        poses = cm.shape_poses(q)
        for a, b, bound in cm.certified_env_pairs:
            r = robot.index(a)
            d = fcl.distance(cm._place(r, poses, set()), cm._env_objs[env.index(b)], fcl.DistanceRequest(),
                             fcl.DistanceResult())
            assert d >= bound - 1e-9


def test_pair_field_is_a_lower_bound(gantry):
    """The distance tables of two-joint pairs (wrist and camera) never exceed the exact
    distance, at configurations and along motions."""
    import fcl

    cm = gantry.collision
    assert len(cm._fields) >= 2
    rng = np.random.default_rng(4)
    for p, field in cm._fields:
        i, j = cm._self_pairs[p]
        qs = rng.uniform(gantry.limits.lower, gantry.limits.upper, size=(300, 9))
        exact = []
        for q in qs:
            poses = cm.shape_poses(q)
            placed: set[int] = set()
            exact.append(fcl.distance(cm._place(i, poses, placed), cm._place(j, poses, placed),
                                      fcl.DistanceRequest(), fcl.DistanceResult()))
        assert np.all(field.at(qs) <= np.array(exact) + 1e-9)
        for a, b in zip(qs[:20], qs[20:40], strict=True):
            t = np.linspace(0, 1, 400)
            dense = [fcl.distance(cm._place(i, P, set()), cm._place(j, P, set()), fcl.DistanceRequest(),
                                  fcl.DistanceResult()) for P in cm.shape_poses_batch(a + t[:, None] * (b - a))]
            assert field.along(a, b) <= min(dense) + 1e-9


def test_segment_free_agrees_with_dense_sampling(gantry):
    """The planner's motion check says 'free' only for motions that are free at 2 mm steps
    of robot-point motion."""
    cm = gantry.collision
    rng = np.random.default_rng(5)
    seen = {True: 0, False: 0}
    for _ in range(60):
        a = gantry.limits.sample_soft(rng)
        if cm.in_collision(a):
            continue
        b = a + rng.normal(0.0, 0.3, 9)
        b = gantry.limits.clip_soft(b)
        steps = int(np.ceil(float(cm.point_step_bound(b - a)) / 0.002)) + 1
        dense = a + np.linspace(0, 1, steps)[:, None] * (b - a)
        free = cm.segment_free(a, b)
        seen[free] += 1
        if free:
            assert cm.first_collision(dense) == -1
    assert seen[True] > 5
