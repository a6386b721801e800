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
