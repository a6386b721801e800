"""The simulated sensor posed at the joints a robot adapter measures: the camera part of a
station file's ``camera: {adapter: sim}`` (a stand-in camera for wiring a real robot, or
with the simulated robot a station made only of simulated parts)."""

from __future__ import annotations

import numpy as np

from recon_cli.backends.base import RGBDFrame, RobotBackend
from recon_cli.backends.sim.camera import SimCamera
from recon_cli.backends.sim.scene import BoardSheet, build_scene, mujoco
from recon_cli.objects import SceneObject
from recon_cli.robot.cell import Cell


class RenderedCamera:
    """CameraBackend: the cell's MuJoCo scene rendered where ``robot`` measures its joints."""

    def __init__(self, cell: Cell, scene_object: SceneObject | None, robot: RobotBackend, rng: np.random.Generator,
                 noise: bool, resolution: float) -> None:
        self.robot = robot
        self.scene = build_scene(cell.config, scene_object)
        self.data = mujoco.MjData(self.scene.model)
        self._camera = SimCamera(self.scene, self.data, rng, noise=noise, scale=resolution)
        self._board = BoardSheet(self.scene.model)
        self.intrinsics = self._camera.intrinsics

    def capture(self) -> RGBDFrame:
        self.data.qpos[self.scene.qpos_index] = self.robot.measured_joints()
        mujoco.mj_forward(self.scene.model, self.data)
        return self._camera.capture()

    def world_T_camera_truth(self) -> np.ndarray:
        """The pose the last frame was rendered from (OpenCV axes, world frame)."""
        return self._camera.world_T_camera_truth()

    def cover_board(self, covered: bool) -> None:
        """Lay a plain grey sheet over the printed board of the rendered scene (or take it away)."""
        self._board.cover(covered)

    def close(self) -> None:
        self._camera.close()
