"""The simulated station: scene, robot backend and camera backend of one session.

With a realism profile (recon_cli/realism.py) the scene is the true cell (the model's
description with the profile's base and hand-eye errors, recon_cli/backends/sim/truth.py),
the robot reads its joints through encoders with offsets, sag and noise, and the camera is
the profile's actual camera with its artefacts; the model recon works with stays the
``cell`` passed in.
"""

from __future__ import annotations

import numpy as np

from recon_cli.backends.base import Capabilities, Station
from recon_cli.backends.sim.camera import SimCamera
from recon_cli.backends.sim.robot import SimRobot
from recon_cli.backends.sim.scene import BoardSheet, build_scene, mujoco
from recon_cli.backends.sim.truth import JointSensor, TrueCell, true_cell
from recon_cli.config import DEFAULTS
from recon_cli.objects import SceneObject
from recon_cli.realism import IDEAL, RealismProfile
from recon_cli.robot.cell import Cell


def simulation_truth(robot: SimRobot, world_T_camera: np.ndarray, scene_object: SceneObject | None) -> dict:
    """What only a simulation knows at a capture: the true camera pose and joints, and the
    object; stored apart from the scan data, for evaluation."""
    truth = {"world_T_camera": world_T_camera,
             "joints": dict(zip(robot.joint_names, robot.true_joints().tolist(), strict=True))}
    if scene_object is not None:
        truth["object"] = scene_object.name
        truth["world_T_object"] = scene_object.world_T_object
    return truth


class SimStation(Station):
    """MuJoCo scene of a cell with an object; robot at rest at ``start``. Close it (or use it
    as a context manager) to free the offscreen renderer."""

    capabilities = Capabilities(simulated=True, ground_truth=True, cover_board=True, realism=True)
    robot: SimRobot
    camera: SimCamera

    def __init__(self, cell: Cell, scene_object: SceneObject | None, start: np.ndarray,
                 rng: np.random.Generator, noise: bool = DEFAULTS.sensor.noise,
                 resolution: float = DEFAULTS.sensor.resolution,
                 realism: RealismProfile = IDEAL) -> None:
        self.cell = cell
        self.scene_object = scene_object
        self.realism = realism
        self.truth: TrueCell | None = None
        sensor, camera_rng = None, None
        if not realism.is_ideal:  # its own generators: the session's stream stays as it is
            kin_rng, camera_rng = rng.spawn(2)
            if realism.kinematic_errors:
                self.truth = true_cell(cell, realism.kinematics, kin_rng, realism.source or realism.name)
                sensor = JointSensor(self.truth, kin_rng)
        self.scene = build_scene(cell.config if self.truth is None else self.truth.config, scene_object)
        self.data = mujoco.MjData(self.scene.model)
        self.robot = SimRobot(self.scene, self.data, cell.kin, joint_sensor=sensor)
        self.robot.reset(np.asarray(start, dtype=float))
        self.camera = SimCamera(self.scene, self.data, rng, noise=noise, scale=resolution, realism=realism,
                                realism_rng=camera_rng)
        self._board = BoardSheet(self.scene.model)

    def realism_record(self) -> dict:
        """What the realism profile drew for this session (ground truth, evaluation only)."""
        cam = self.camera
        record = {"profile": self.realism.to_dict(), "kinematics": None if self.truth is None else self.truth.to_dict()}
        if not self.realism.is_ideal:
            record["camera"] = {"actual_intrinsics": cam.actual_intrinsics.to_dict(),
                                "assumed_intrinsics": cam.intrinsics.to_dict(), "assumed_distortion": cam.distortion}
        return record

    def cover_board(self, covered: bool) -> None:
        """Lay a plain grey sheet over the printed ChArUco board (or take it away): the
        board is then not found and registration has to use the robot's kinematics."""
        self._board.cover(covered)

    def ground_truth(self) -> dict:
        """What only a simulation knows; stored apart from the scan data, for evaluation."""
        return simulation_truth(self.robot, self.camera.world_T_camera_truth(), self.scene_object)

    def close(self) -> None:
        self.camera.close()
