"""The lower bound of eqs. 2.16-2.21 on hand-computed cases and against toppra."""

from __future__ import annotations

import math

import numpy as np
import pytest

from recon_cli.planning.lower_bound import duration_lower_bound, joint_time_lower_bound
from recon_cli.planning.trajectory import straight_line


def test_short_stroke_never_reaches_the_velocity_limit():
    # Δs = 0.5 < v²/a = 4/1: t = 2 sqrt(0.5 / 1) (eq. 2.17)
    assert joint_time_lower_bound(0.5, 2.0, 1.0) == pytest.approx(2 * math.sqrt(0.5))


def test_long_stroke_cruises():
    # Δs = 10 >= v²/a = 4: t = 10 / 2 + 2 / 1 = 7 (eq. 2.19)
    assert joint_time_lower_bound(10.0, 2.0, 1.0) == pytest.approx(7.0)
    # both branches meet at Δs = v²/a
    assert joint_time_lower_bound(4.0, 2.0, 1.0) == pytest.approx(4.0)
    assert joint_time_lower_bound(4.0 - 1e-9, 2.0, 1.0) == pytest.approx(4.0)


def test_slowest_joint_bounds_the_motion_with_scaling():
    qa, qb = np.zeros(3), np.array([1.0, -3.0, 0.2])
    v, a = np.array([1.0, 1.0, 1.0]), np.array([1.0, 1.0, 1.0])
    # scaling 0.5 / 0.25: joint 2 (Δs 3): v = 0.5, a = 0.25, v²/a = 1 -> 3 / 0.5 + 0.5 / 0.25 = 8
    assert duration_lower_bound(qa, qb, v, a, 0.5, 0.25) == pytest.approx(8.0)
    assert duration_lower_bound(qa, qa, v, a) == 0.0


def test_lower_bound_never_above_toppra(gantry):
    rng = np.random.default_rng(11)
    lim = gantry.limits
    for _ in range(60):
        qa, qb = lim.sample_soft(rng), lim.sample_soft(rng)
        if rng.random() < 0.3:  # short motions too
            qb = lim.clip_soft(qa + rng.normal(scale=0.05, size=qa.shape))
        for vs, as_ in ((1.0, 1.0), (0.15, 0.3)):
            bound = duration_lower_bound(qa, qb, lim.velocity, lim.acceleration, vs, as_)
            traj = straight_line(qa, qb, lim.velocity, lim.acceleration, vs, as_)
            assert bound <= traj.duration + 1e-9
