"""Collision model: Table 4.1 states are free, each kind of collision is named."""

from __future__ import annotations

import numpy as np
import pytest

from recon_cli.bench.scenarios import TABLE_4_1_GOAL, TABLE_4_1_START

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
