"""Batched forward kinematics equals pinocchio's."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from recon_cli.robot.batch_fk import BatchFK


@pytest.mark.parametrize("which", ["gantry", "ceiling"])
def test_batch_fk_equals_pinocchio(which, request):
    cell = request.getfixturevalue(which)
    model, data = cell.kin.model, cell.kin.model.createData()
    rng = np.random.default_rng(3)
    Q = rng.uniform(cell.limits.lower, cell.limits.upper, size=(200, model.nq))
    oMi = BatchFK(model).joint_poses(Q)
    for k, q in enumerate(Q):
        pin.forwardKinematics(model, data, q)
        for j in range(model.njoints):
            assert np.max(np.abs(oMi[k, j] - data.oMi[j].homogeneous)) < 1e-12


def test_joints_about_any_axis_match_pinocchio():
    """A URDF axis other than a coordinate axis (0 0 -1, or skew) gives pinocchio's unaligned
    joints; the batch evaluates them too."""
    import pinocchio as pin

    from recon_cli.robot.batch_fk import BatchFK

    xml = """<robot name="r"><link name="a"/><link name="b"/><link name="c"/><link name="d"/>
    <joint name="j1" type="revolute"><parent link="a"/><child link="b"/><origin xyz="0.1 0.2 0.3" rpy="0.1 0.2 0.3"/>
      <axis xyz="0.3 -0.5 0.8"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
    <joint name="j2" type="prismatic"><parent link="b"/><child link="c"/><origin xyz="0.1 0 0.3"/>
      <axis xyz="0 0 -1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
    <joint name="j3" type="revolute"><parent link="c"/><child link="d"/><origin xyz="0 0.2 0"/>
      <axis xyz="0 -1 0"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint></robot>"""
    model = pin.buildModelFromXML(xml)
    assert "Unaligned" in model.joints[1].shortname() and "Unaligned" in model.joints[2].shortname()
    data = model.createData()
    Q = np.random.default_rng(0).uniform(-2, 2, (20, model.nq))
    poses = BatchFK(model).joint_poses(Q)
    for k, q in enumerate(Q):
        pin.forwardKinematics(model, data, q)
        for j in range(model.njoints):
            assert np.allclose(poses[k, j], data.oMi[j].homogeneous, atol=1e-12)
