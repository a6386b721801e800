"""Forward kinematics against an independent chain of the documented transforms (eq. 2.10)
and the Jacobian against finite differences."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

PI = np.pi


def T(xyz=(0, 0, 0), rpy=(0, 0, 0)):
    """URDF origin: fixed-axis x-y-z (roll, pitch, yaw), computed with scipy."""
    out = np.eye(4)
    out[:3, :3] = Rotation.from_euler("xyz", rpy).as_matrix()
    out[:3, 3] = xyz
    return out


def Rz(q):
    return T(rpy=(0, 0, q))


# the iiwa joints of ../shared/CELL_FACTS.md section 3.1: (xyz, rpy) of each joint origin
IIWA = [((0, 0, 0.1525), (0, 0, 0)), ((0, 0, 0.2075), (PI / 2, 0, PI)),
        ((0, 0.2325, 0), (PI / 2, 0, PI)), ((0, 0, 0.1875), (PI / 2, 0, 0)),
        ((0, 0.2125, 0), (-PI / 2, PI, 0)), ((0, 0, 0.1875), (PI / 2, 0, 0)),
        ((0, 0.081, 0), (-PI / 2, PI, 0))]
# flange -> bracket -> calibrated optical frame (CELL_FACTS 4.1, 4.2)
CAMERA = T((0, 0, 0.0723)) @ T((-0.0288531, -0.1731820, 0.0608131),
                               (1.5825099281614061, -0.004777686036830654, -1.5623068917337075))


def chain_gantry(q):
    M = T((-0.0730, 0, 1.9231)) @ T((0, q[0], 0))  # axis a along y
    M = M @ T((0, 0, -0.0808)) @ T((q[1], 0, 0))  # axis b along x
    M = M @ T((0, 0, -0.0297), (0, PI, 0))  # iiwa base, headlong
    for (xyz, rpy), qi in zip(IIWA, q[2:], strict=True):
        M = M @ T(xyz, rpy) @ Rz(qi)
    return M @ CAMERA


def chain_ceiling(q):
    M = T((0, 0, 1.8126)) @ T(rpy=(0, PI, 0))
    for (xyz, rpy), qi in zip(IIWA, q, strict=True):
        M = M @ T(xyz, rpy) @ Rz(qi)
    return M @ CAMERA


@pytest.mark.parametrize("which", ["gantry", "ceiling"])
def test_fk_matches_independent_chain(which, request, rng):
    cell = request.getfixturevalue(which)
    chain = chain_gantry if which == "gantry" else chain_ceiling
    worst = 0.0
    for _ in range(1000):
        q = rng.uniform(cell.limits.lower, cell.limits.upper)
        worst = max(worst, np.max(np.abs(cell.kin.world_T_camera(q) - chain(q))))
    assert worst < 1e-9


def test_home_pose_matches_cell_facts(gantry):
    """CELL_FACTS 3.1: at home (base_joint_1 = -1) the flange is at (-0.073, -1, 0.5516)."""
    q = np.zeros(9)
    q[0] = -1.0
    flange = gantry.kin.frame_pose(q, "arm_link_7")
    assert flange[:3, 3] == pytest.approx([-0.073, -1.0, 0.5516], abs=1e-9)
    assert flange[:3, 2] == pytest.approx([0, 0, -1], abs=1e-12)
    # the optical frame looks along world +x at home, sideways from the flange
    assert gantry.kin.world_T_camera(q)[:3, 2] == pytest.approx([1, 0, 0], abs=0.02)


def test_marker_frame_is_board_corner(gantry):
    M = gantry.world_T_marker
    assert M[:3, 3] == pytest.approx([0.1225, -0.1925, 0.683])
    assert M[:3, 0] == pytest.approx([0, 1, 0])  # board x along world +y
    assert M[:3, 2] == pytest.approx([0, 0, 1])


@pytest.mark.parametrize("which", ["gantry", "ceiling"])
def test_jacobian_matches_finite_differences(which, request, rng):
    cell = request.getfixturevalue(which)
    eps = 1e-6
    for _ in range(20):
        q = rng.uniform(cell.limits.soft_lower, cell.limits.soft_upper)
        J = cell.kin.camera_jacobian(q)  # (6, n): world-aligned v, omega
        T0 = cell.kin.world_T_camera(q)
        for i in range(cell.kin.nq):
            dq = np.zeros(cell.kin.nq)
            dq[i] = eps
            Tp, Tm = cell.kin.world_T_camera(q + dq), cell.kin.world_T_camera(q - dq)
            v = (Tp[:3, 3] - Tm[:3, 3]) / (2 * eps)
            dR = (Tp[:3, :3] - Tm[:3, :3]) / (2 * eps)
            W = dR @ T0[:3, :3].T
            w = np.array([W[2, 1], W[0, 2], W[1, 0]])
            assert J[:3, i] == pytest.approx(v, abs=1e-6)
            assert J[3:, i] == pytest.approx(w, abs=1e-6)
