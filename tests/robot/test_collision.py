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
