"""A scan waits for the settled robot: a move whose robot backend reports an unsettled
motion ends with RobotFault(kind="settle") before anything is scanned (the simulated robot
here, with a settling time-out it cannot meet; the ADS adapter's own settling fault is in
test_ads.py)."""

from __future__ import annotations

import numpy as np
import pytest

from recon_cli.acquisition import Acquisition
from recon_cli.backends.sim.robot import SettleCriterion, SimRobot
from recon_cli.backends.sim.scene import build_scene, mujoco
from recon_cli.errors import RobotFault
from recon_cli.reconstruction.scan_store import ScanStore
from recon_cli.robot.poses import named_configuration


@pytest.mark.parametrize("timeout", [3.0, 0.0])
def test_move_waits_for_the_settled_robot(gantry, tmp_path, timeout):
    scene = build_scene(gantry.config, None)
    robot = SimRobot(scene, mujoco.MjData(scene.model), gantry.kin, settle=SettleCriterion(timeout=timeout))
    start = named_configuration(gantry.config.kind, "home", gantry.joint_names)
    robot.reset(start)
    acquisition = Acquisition(gantry, robot, None, ScanStore(tmp_path), np.random.default_rng(0))
    goal = start.copy()
    goal[2] += 0.3
    if timeout > 0:  # the simulation settles as before
        move = acquisition.move_to_joints(goal)
        assert move.execution.settled and move.camera_position_error < 1e-4
        return
    with pytest.raises(RobotFault, match=r"the robot did not settle after the move to the view within its "
                                         r"settling time \(final error \w+ [\d.e-]+ (rad|m), ") as info:
        acquisition.move_to_joints(goal)
    assert info.value.kind == "settle" and info.value.joint in gantry.joint_names
    assert "no scan was taken" in info.value.one_line() and "\n" not in info.value.one_line()
    assert not list(tmp_path.iterdir())  # nothing written
