"""Problem data of the thesis (chapter 4), in SI units and joint-vector order: the start and
goal of Table 4.1, the cube of sections 4.1/4.2, the 24 views of eq. 4.1. The benchmarks
(recon_cli.bench), ``recon capture --views eq-4.1``, ``recon cell`` and the tests use them.

Table 4.1 rounds the goal to whole degrees and centimetres; the exact values below are the
ones of the thesis' benchmark logs (the thesis cell facts, benchmark logs).
"""

from __future__ import annotations

import numpy as np

from recon_cli.geometry.view import View
from recon_cli.robot.collision import ObjectBox

#: start state of Table 4.1 (9-DoF gantry cell): base_joint_1 = -1 m, all others 0
TABLE_4_1_START = np.array([-1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])

#: goal state of Table 4.1 (9-DoF gantry cell), [m, m, rad x 7]
TABLE_4_1_GOAL = np.array([0.0102727, -0.330269, -1.50012, -1.62369, -0.638512, -1.40155,
                           -1.43857, -0.862087, -2.023])

#: the 0.3 m cube standing on the table top (world centre (0, 0, 0.83)) of sections 4.1/4.2
BENCH_CUBE = ObjectBox(center=(0.0, 0.0, 0.83), size=(0.3, 0.3, 0.3))

#: focus point of the 24-view scenario of eq. 4.1 [m, world]
EQ_4_1_FOCUS = (0.0, 0.0, 0.78)


def eq_4_1_views() -> list[View]:
    """The 24 views of thesis eq. 4.1 (section 4.2): f = (0, 0, 0.78) m, r = 0.6 m, alpha = 0,
    phi_i = 30 deg (i - 1), theta_i = 70 deg for i <= 12 and 50 deg after."""
    return [View.from_degrees(EQ_4_1_FOCUS, 0.6, 70.0 if i <= 12 else 50.0, 30.0 * (i - 1))
            for i in range(1, 25)]
