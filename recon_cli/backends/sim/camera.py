"""The simulated RGB-D camera: MuJoCo's offscreen renderer plus the sensor model.

MuJoCo renders colour and linear depth (distance along the optical axis, metres) of its
OpenGL camera; ``render_rgbd`` returns them in OpenCV pixel order (row 0 at the top).
The sensor model (range, grazing-angle dropout, Gaussian depth noise) is applied on top.
"""

from __future__ import annotations

import numpy as np

from recon_cli.backends.base import RGBDFrame
from recon_cli.backends.sim.scene import SimScene, mujoco
from recon_cli.perception.camera_model import Intrinsics, intrinsics_from_fovy, opencv_from_opengl


def camera_intrinsics(model: mujoco.MjModel, camera_id: int, width: int, height: int) -> Intrinsics:
    """Intrinsics of a MuJoCo camera rendered at width x height (from its fovy)."""
    return intrinsics_from_fovy(width, height, np.radians(float(model.cam_fovy[camera_id])))


def world_T_camera_gl(data: mujoco.MjData, camera_id: int) -> np.ndarray:
    """World pose of a MuJoCo (OpenGL) camera frame in the current state."""
    T = np.eye(4)
    T[:3, :3] = data.cam_xmat[camera_id].reshape(3, 3)
    T[:3, 3] = data.cam_xpos[camera_id]
    return T


def render_rgbd(renderer: mujoco.Renderer, data: mujoco.MjData, camera_id: int
                ) -> tuple[np.ndarray, np.ndarray]:
    """Colour (H, W, 3) uint8 and ideal depth (H, W) [m] of a camera; 0 where nothing."""
    renderer.update_scene(data, camera=camera_id)
    color = renderer.render().copy()
    renderer.enable_depth_rendering()
    try:
        renderer.update_scene(data, camera=camera_id)
        depth = renderer.render().astype(np.float64)
    finally:
        renderer.disable_depth_rendering()
    far = renderer.model.vis.map.zfar * renderer.model.stat.extent
    depth[depth >= 0.999 * far] = 0.0
    return color, depth


class SimCamera:
    """CameraBackend of the simulation: renders the flange camera of a SimScene."""

    def __init__(self, scene: SimScene, data: mujoco.MjData, rng: np.random.Generator | None,
                 noise: bool = True, scale: float = 1.0) -> None:
        self.scene = scene
        self.data = data
        self.rng = rng
        self.noise = noise
        sensor = scene.sensor
        self.intrinsics = sensor.intrinsics(scale)
        self.renderer = mujoco.Renderer(scene.model, self.intrinsics.height, self.intrinsics.width)

    def close(self) -> None:
        self.renderer.close()

    def world_T_camera_truth(self) -> np.ndarray:
        """Ground-truth pose of the optical frame (OpenCV axes) in the world."""
        return opencv_from_opengl(world_T_camera_gl(self.data, self.scene.camera_id))

    def capture(self) -> RGBDFrame:
        mujoco.mj_forward(self.scene.model, self.data)
        color, depth = render_rgbd(self.renderer, self.data, self.scene.camera_id)
        depth = self.scene.sensor.apply(depth, self.intrinsics, self.rng, self.noise)
        color = self.scene.sensor.apply_color(color, self.rng, self.noise)
        return RGBDFrame(color, depth, self.intrinsics, float(self.data.time))
