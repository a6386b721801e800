"""The simulated RGB-D camera: MuJoCo's offscreen renderer plus the sensor model.

MuJoCo renders colour and linear depth (distance along the optical axis, metres) of its
OpenGL camera; ``render_rgbd`` returns them in OpenCV pixel order (row 0 at the top).
The sensor model (range, grazing-angle dropout, Gaussian depth noise) is applied on top.

With a realism profile (recon_cli/realism.py) the pinhole render is first resampled into
the actual camera (its intrinsics and lens distortion: colour bilinear, depth bilinear on
smooth surfaces and nearest across depth edges; both cameras share centre and orientation,
so the depth along the optical axis carries over), then the profile's depth artefacts and
image effects are applied. The frame reports the camera recon is told about (the profile's
assumed camera, nominal by default), not the actual one.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from recon_cli.backends.base import RGBDFrame
from recon_cli.backends.sim.scene import SimScene, mujoco
from recon_cli.errors import InputError
from recon_cli.perception import sensor as sensor_effects
from recon_cli.perception.camera_model import (
    Intrinsics,
    distorted_pixel_maps,
    intrinsics_from_fovy,
    opencv_from_opengl,
)
from recon_cli.perception.sensor import SensorModel
from recon_cli.realism import IDEAL, CameraSpec, DepthArtefacts, RealismProfile

#: [m] a 3 x 3 depth neighbourhood spanning less is a smooth surface (bilinear resampling)
SMOOTH_DEPTH_RANGE = 0.003


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


def resample_rgbd(color: np.ndarray, depth: np.ndarray, map_x: np.ndarray, map_y: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Colour and depth of a pinhole render resampled at (map_x, map_y) (one position per
    output pixel): colour bilinear, depth bilinear where the render's 3 x 3 neighbourhood is
    smooth (spans < SMOOTH_DEPTH_RANGE) and nearest elsewhere; 0 outside the render."""
    import cv2

    def remap(image: np.ndarray, interpolation: int) -> np.ndarray:
        return cv2.remap(image, map_x, map_y, interpolation, borderMode=cv2.BORDER_CONSTANT, borderValue=0)

    color_out = remap(color, cv2.INTER_LINEAR)
    kernel = np.ones((3, 3), np.uint8)
    span = cv2.dilate(depth, kernel) - cv2.erode(np.where(depth > 0, depth, np.inf), kernel)
    smooth = remap((span < SMOOTH_DEPTH_RANGE).astype(np.uint8), cv2.INTER_NEAREST)
    near = remap(depth, cv2.INTER_NEAREST)
    linear = remap(depth, cv2.INTER_LINEAR)
    return color_out, np.where(smooth > 0, linear, near)


#: a realism profile's camera may differ from the cell's sensor in field of view by this share
#: at most (calibration errors are fractions of a percent; more is another camera)
CAMERA_FIT = 0.05


def _check_camera_fits(realism: RealismProfile, role: str, spec: CameraSpec | None, sensor: SensorModel) -> None:
    """Refuse a profile camera that is another camera than the cell's sensor (a profile written
    for another cell): its horizontal field of view or aspect ratio differs by more than
    :data:`CAMERA_FIT`."""
    if spec is None:
        return
    fov = 2.0 * math.atan(spec.width / (2.0 * spec.fx))
    aspect, own = spec.width / spec.height, sensor.width / sensor.height
    if abs(fov / sensor.hfov - 1.0) > CAMERA_FIT or abs(aspect / own - 1.0) > CAMERA_FIT:
        raise InputError(
            f"realism profile {realism.name}: camera.{role} ({spec.width} x {spec.height} px, "
            f"{math.degrees(fov):.1f} deg wide) is not the cell's sensor {sensor.name} ({sensor.width} x "
            f"{sensor.height} px, {math.degrees(sensor.hfov):.1f} deg wide)",
            hint="use --realism lab (the thesis' errors with the cell's own camera) or ideal, or write a profile "
                 "for this cell's camera (docs/simulation.md)")


class SimCamera:
    """CameraBackend of the simulation: renders the flange camera of a SimScene.

    realism: the profile's camera, depth and image effects; realism_rng: the generator of
    their random draws (the depth and colour noise of the sensor model use ``rng``, as
    without a profile)."""

    def __init__(self, scene: SimScene, data: mujoco.MjData, rng: np.random.Generator | None,
                 noise: bool = True, scale: float = 1.0, realism: RealismProfile = IDEAL,
                 realism_rng: np.random.Generator | None = None) -> None:
        self.scene = scene
        self.data = data
        self.rng = rng
        self.noise = noise
        sensor = scene.sensor
        self.intrinsics = sensor.intrinsics(scale)
        self.renderer = mujoco.Renderer(scene.model, self.intrinsics.height, self.intrinsics.width)
        self.distortion: tuple[float, ...] | None = None
        self.realism = realism
        self._ideal = realism.is_ideal
        if not self._ideal:
            if realism_rng is None:
                raise ValueError("a realism profile's effects need their generator (realism_rng)")
            self._set_up_realism(realism, realism_rng)

    def _set_up_realism(self, realism: RealismProfile, rng: np.random.Generator) -> None:
        render = self.intrinsics  # the pinhole MuJoCo renders
        w, h = render.width, render.height
        cam = realism.camera
        for role, spec in (("actual", cam.actual), ("assumed", cam.assumed)):
            _check_camera_fits(realism, role, spec, self.scene.sensor)
        self.render_intrinsics = render
        self.actual_intrinsics = cam.actual.intrinsics(w, h) if cam.actual is not None else render
        self._maps = None if cam.actual is None else distorted_pixel_maps(self.actual_intrinsics,
                                                                          cam.actual.distortion, render)
        if cam.assumed is not None:  # what recon is told (scan.json)
            self.intrinsics = cam.assumed.intrinsics(w, h)
            self.distortion = cam.assumed.distortion if cam.assumed.distorted else None
        self._realism_rng = rng
        self._blur = realism.image.blur_sigma * w / self.scene.sensor.width
        noise_std = realism.image.noise_std
        self._sensor = (self.scene.sensor if noise_std is None
                        else dataclasses.replace(self.scene.sensor, color_noise_std=noise_std))

    def close(self) -> None:
        self.renderer.close()

    def world_T_camera_truth(self) -> np.ndarray:
        """Ground-truth pose of the optical frame (OpenCV axes) in the world."""
        return opencv_from_opengl(world_T_camera_gl(self.data, self.scene.camera_id))

    def capture(self) -> RGBDFrame:
        mujoco.mj_forward(self.scene.model, self.data)
        color, depth = render_rgbd(self.renderer, self.data, self.scene.camera_id)
        if not self._ideal:
            color, depth = self._realism_effects(color, depth)
            return RGBDFrame(color, depth, self.intrinsics, float(self.data.time), self.distortion)
        depth = self.scene.sensor.apply(depth, self.intrinsics, self.rng, self.noise)
        color = self.scene.sensor.apply_color(color, self.rng, self.noise)
        return RGBDFrame(color, depth, self.intrinsics, float(self.data.time))

    def _realism_effects(self, color: np.ndarray, depth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The actual camera's images: resampled into its intrinsics and distortion, depth
        artefacts, the sensor model, quantization; exposure, blur and noise of the colour."""
        if self._maps is not None:
            color, depth = resample_rgbd(color, depth, *self._maps)
        K, art, rng, fx = self.actual_intrinsics, self.realism.depth, self._realism_rng, sensor_effects
        if art != DepthArtefacts():
            depth = fx.multipath(depth, K, art.multipath_gain, art.multipath_window)
            depth = fx.flying_pixels(depth, art.flying_pixel_share, art.edge_jump, rng)
            depth = fx.dropouts(depth, color, K, art.grazing, art.dark_level, art.saturated_level, rng,
                                art.dark_dropout)
        depth = self._sensor.apply(depth, K, self.rng, self.noise)
        depth = fx.quantize_depth(depth, art.quantization, self._sensor.noise_z_ref)
        color = fx.image_effects(color, self.realism.image.exposure, self._blur)
        color = self._sensor.apply_color(color, self.rng, self.noise)
        return color, depth
