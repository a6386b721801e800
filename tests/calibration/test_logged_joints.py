"""Joint positions logged beside flange poses: read from a pose file's keys, and the cell's
kinematics matched to the logged poses (up to a constant base and end-effector offset), or
the reason they do not match."""

from __future__ import annotations

import math

import numpy as np
import pytest

from recon_cli.calibration.logged_joints import JointChain, match_chain, record_joints
from recon_cli.geometry.transforms import invert, pose_error
from recon_cli.robot.description import CellConfig, CellName, expand_urdf
from recon_cli.robot.kinematics import Kinematics

#: libfranka's end effector of the Franka Hand: 0.1034 m along z, turned -45 deg about it
F_T_EE = np.array([[math.cos(-math.pi / 4), -math.sin(-math.pi / 4), 0, 0],
                   [math.sin(-math.pi / 4), math.cos(-math.pi / 4), 0, 0],
                   [0, 0, 1, 0.1034], [0, 0, 0, 1.0]])


@pytest.fixture(scope="module")
def fr3() -> Kinematics:
    config = CellConfig(kind=CellName.parse("fr3"))
    return Kinematics(expand_urdf(config), config.cell_file)


def _joints(kin: Kinematics, n: int, seed: int = 0) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    lo, hi = kin.limits.lower, kin.limits.upper
    return [rng.uniform(lo + 0.2, hi - 0.2) for _ in range(n)]


def _o_t_ee(kin: Kinematics, q: np.ndarray) -> np.ndarray:
    base = kin.frame_pose(q, kin.cell.base_link)
    return invert(base) @ kin.frame_pose(q, kin.cell.flange_link) @ F_T_EE


@pytest.mark.parametrize(("record", "want"), [
    ({"joint_pose": [0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7]}, [0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7]),
    ({"q": [0, 1, 2, 3, 2, 1, 0, 0.04, 0.04]}, [0, 1, 2, 3, 2, 1, 0]),  # libfranka's 9 with the fingers
    ({"joints": [0.1, 0.2, 0.3]}, None),  # too few
    ({"joints": [0.1, True, 0.3, 0.4, 0.5, 0.6, 0.7]}, None),  # not a number
    ({"joints": [0.1, float("nan"), 0.3, 0.4, 0.5, 0.6, 0.7]}, None),
    ({"joints": [10, 20, 30, 40, 50, 60, 70]}, None),  # degrees, not radians
    ({"O_T_EE": list(range(16))}, None),
    ([0.1, 0.2], None),
])
def test_joint_positions_of_a_pose_file(record, want):
    got = record_joints(record, 7)
    assert (got is None and want is None) or np.array_equal(got, np.array(want, dtype=float))


def test_the_cells_kinematics_match_libfrankas_logged_poses(fr3):
    q = _joints(fr3, 8)
    chain = match_chain(fr3, q, [_o_t_ee(fr3, x) for x in q])
    assert isinstance(chain, JointChain)
    assert pose_error(chain.right, F_T_EE)[0] < 1e-9
    for x in q:
        assert pose_error(chain.logged(x), _o_t_ee(fr3, x))[0] < 1e-9
    # poses in the cell's world (as forward kinematics of the joints gives them): no base offset
    chain = match_chain(fr3, q, [fr3.frame_pose(x, fr3.cell.flange_link) for x in q])
    assert isinstance(chain, JointChain) and np.allclose(chain.left, np.eye(4))


def test_poses_of_another_robot_are_refused_with_the_disagreement(fr3):
    q = _joints(fr3, 8)
    logged = [_o_t_ee(fr3, x) for x in q]
    logged[3] = logged[3] @ np.array([[1, 0, 0, 0.002], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])
    why = match_chain(fr3, q, logged)
    assert isinstance(why, str) and why.startswith("the cell fr3's kinematics do not give the logged poses")
    assert "2.0 mm" in why
    assert match_chain(fr3, [x[:6] for x in q], logged) == "6 joint positions, the cell fr3 has 7 joints"
