"""Computed-torque execution with integral action: tracking error, settling, scan pose error."""

from __future__ import annotations

import numpy as np
import pytest

from recon_cli.backends.sim.robot import SimRobot
from recon_cli.backends.sim.scene import build_scene, mujoco
from recon_cli.geometry.transforms import pose_error
from recon_cli.planning.checks import check_trajectory
from recon_cli.planning.trajectory import straight_line
from recon_cli.robot.poses import named_configuration


@pytest.fixture(scope="module")
def sim(gantry):
    scene = build_scene(gantry.config, None)
    data = mujoco.MjData(scene.model)
    return SimRobot(scene, data, gantry.kin)


def test_representative_move(gantry, sim):
    """A move of all nine joints at full speed: joints track within 1e-3, the robot
    settles, and the camera ends within 0.1 mm / 0.001 deg of its goal pose."""
    start = named_configuration(gantry.config.kind, "home", gantry.joint_names)
    goal = start + np.radians([0, 0, 30, -30, 30, 30, -30, 30, 60])
    goal[0], goal[1] = -0.6, -0.2
    traj = straight_line(start, goal, gantry.limits.velocity, gantry.limits.acceleration)
    assert check_trajectory(traj, gantry).ok
    sim.reset(start)
    report = sim.execute(traj)
    assert report.settled
    assert report.settle_time < 1.0
    assert np.max(report.max_tracking_error) < 1e-3
    q = sim.measured_joints()
    dp, dr = pose_error(gantry.kin.world_T_camera(q), gantry.kin.world_T_camera(goal))
    assert dp < 1e-4 and np.degrees(dr) < 1e-3


def test_hold_still_at_rest(gantry, sim):
    """Gravity is compensated: a zero-length trajectory leaves the robot where it is."""
    q = named_configuration(gantry.config.kind, "home", gantry.joint_names)
    q[3] = 0.6  # arm bent: gravity load on joint 2
    sim.reset(q)
    report = sim.execute(straight_line(q, q, gantry.limits.velocity, gantry.limits.acceleration))
    assert report.settled
    assert np.max(np.abs(sim.measured_joints() - q)) < 1e-5


def test_sim_station_is_a_station(gantry, rng):
    from recon_cli.backends.base import Station
    from recon_cli.backends.sim.station import SimStation
    from recon_cli.robot.poses import named_configuration

    home = named_configuration(gantry.config.kind, "home", gantry.joint_names)
    with SimStation(gantry, None, home, rng, noise=False, resolution=0.1) as station:
        assert isinstance(station, Station)
        assert station.ground_truth()["world_T_camera"].shape == (4, 4)
