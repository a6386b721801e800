"""The MuJoCo scene comes from the same URDF: FK agrees with pinocchio; rendered depth is
metric; the OpenGL/OpenCV conventions and intrinsics are named, tested functions."""

from __future__ import annotations

import math

import numpy as np
import pytest

from recon_cli.backends.sim.camera import camera_intrinsics, render_rgbd, world_T_camera_gl
from recon_cli.backends.sim.scene import build_scene, mujoco
from recon_cli.geometry.transforms import pose_error, rpy_to_matrix
from recon_cli.perception.camera_model import (
    GL_T_CV,
    intrinsics_from_fovy,
    opencv_from_opengl,
    opengl_from_opencv,
)
from recon_cli.perception.sensor import motioncam_3d_m


@pytest.mark.parametrize("which", ["gantry", "ceiling"])
def test_mujoco_camera_matches_pinocchio(which, request):
    cell = request.getfixturevalue(which)
    scene = build_scene(cell.config, None)
    data = mujoco.MjData(scene.model)
    rng = np.random.default_rng(7)
    worst_p = worst_r = 0.0
    for _ in range(1000):
        q = rng.uniform(cell.limits.lower, cell.limits.upper)
        data.qpos[scene.qpos_index] = q
        mujoco.mj_kinematics(scene.model, data)
        mujoco.mj_camlight(scene.model, data)
        T_mj = opencv_from_opengl(world_T_camera_gl(data, scene.camera_id))
        dp, dr = pose_error(T_mj, cell.kin.world_T_camera(q))
        worst_p, worst_r = max(worst_p, dp), max(worst_r, dr)
    assert worst_p < 1e-6 and worst_r < 1e-6


def test_opengl_opencv_convention():
    # an OpenCV camera looks along its +z; the OpenGL camera of the same pose along its -z
    T_cv = np.eye(4)
    T_cv[:3, :3] = rpy_to_matrix(0.3, -0.2, 1.0)
    T_gl = opengl_from_opencv(T_cv)
    assert T_gl[:3, 2] == pytest.approx(-T_cv[:3, 2])  # same viewing direction
    assert T_gl[:3, 1] == pytest.approx(-T_cv[:3, 1])  # y up vs y down
    assert T_gl[:3, 0] == pytest.approx(T_cv[:3, 0])  # x right in both
    assert opencv_from_opengl(T_gl) == pytest.approx(T_cv)
    assert GL_T_CV @ GL_T_CV == pytest.approx(np.eye(4))


def test_intrinsics_from_fovy():
    K = intrinsics_from_fovy(1600, 1200, math.radians(38.0))
    assert K.fx == K.fy == pytest.approx(600 / math.tan(math.radians(19.0)))
    assert (K.cx, K.cy) == (799.5, 599.5)  # pixel centres at integers (OpenCV)
    assert K.fovy == pytest.approx(math.radians(38.0))


def test_sensor_figures():
    s = motioncam_3d_m()
    K = s.intrinsics()
    assert (K.width, K.height) == (1600, 1200)
    # scan width 0.862 m at the far end of the 0.497-0.939 m range (datasheet, thesis cell)
    assert 2 * 0.939 * math.tan(K.fovx / 2) == pytest.approx(0.862, abs=1e-3)
    assert K.fx == pytest.approx(1742.92, abs=0.1)  # the thesis' Gazebo camera
    assert s.sigma(0.718) == pytest.approx(0.00025)


def test_incidence_in_two_bands_is_the_whole_image_bit_for_bit():
    """The incidence angles are computed in two bands of rows at once: the same numbers as
    in one piece, at the seam too (an odd number of rows, a depth edge across the seam)."""
    from dataclasses import replace

    from recon_cli.perception.sensor import _incidence_band, _incidence_cos

    K = replace(motioncam_3d_m().intrinsics(0.25), cx=201.234, cy=149.891, fx=436.3, fy=437.1)
    h, w = 301, K.width
    K = replace(K, height=h)
    yy, xx = np.mgrid[0:h, 0:w]
    depth = 0.5 + 0.05 * np.sin(xx / 13.0) * np.cos(yy / 17.0)
    depth[:, :20] = 0.0
    depth[148:152, 40:120] = 0.8  # a step across the seam (rows 149/150)
    cos, edge = _incidence_cos(depth, K)
    whole = _incidence_band(depth, (np.arange(w) - K.cx) / K.fx, (np.arange(h) - K.cy) / K.fy)
    assert np.array_equal(cos, whole[0], equal_nan=True) and np.array_equal(edge, whole[1])
    assert edge[0].all() and edge[-1].all() and not edge[h // 2, 60]


def test_colour_noise_is_the_colour_plus_noise_rounded_and_clipped():
    """The colour model draws one standard normal per channel (float32) and keeps the
    colour + noise x std, rounded and clipped to 0..255, bit for bit, including saturation."""
    sensor = motioncam_3d_m()
    color = np.random.default_rng(4).integers(0, 256, (60, 80, 3), dtype=np.uint8)
    color[:5], color[-5:] = 0, 255
    noisy = sensor.apply_color(color, np.random.default_rng(9))
    draws = np.random.default_rng(9).standard_normal(color.shape, dtype=np.float32)
    expected = np.clip(np.rint(color.astype(np.float32) + draws * sensor.color_noise_std), 0, 255).astype(np.uint8)
    assert sensor.color_noise_std > 0 and noisy.dtype == np.uint8
    assert np.array_equal(noisy, expected) and not np.array_equal(noisy, color)
    assert sensor.apply_color(color, None) is color


def _probe_scene(geom_type, size, pos, quat, width=320, height=240, fovy=40.0):
    spec = mujoco.MjSpec()
    spec.visual.global_.offwidth, spec.visual.global_.offheight = width, height
    g = spec.worldbody.add_geom()
    g.type, g.size, g.pos, g.quat = geom_type, size, pos, quat
    cam = spec.worldbody.add_camera()
    cam.name = "probe"
    cam.fovy = fovy
    cam.pos = [0, 0, 0]  # OpenGL camera at the origin looking along -z
    model = spec.compile()
    model.vis.map.znear = 0.05 / model.stat.extent
    model.vis.map.zfar = 10.0 / model.stat.extent
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    renderer = mujoco.Renderer(model, height, width)
    try:
        _, depth = render_rgbd(renderer, data, model.camera("probe").id)
    finally:
        renderer.close()
    return depth, camera_intrinsics(model, model.camera("probe").id, width, height)


def _rays(K):
    u, v = np.meshgrid(np.arange(K.width), np.arange(K.height))
    # OpenCV ray directions with z = 1, expressed in the OpenGL camera frame (y, z flipped)
    return np.stack([(u - K.cx) / K.fx, -(v - K.cy) / K.fy, -np.ones_like(u, float)], axis=-1)


def test_depth_of_a_tilted_plane_is_metric():
    """A plane 0.7 m away, tilted by 20 deg about x: depth(u, v) follows the intrinsics."""
    tilt = math.radians(20)
    quat = [math.cos(tilt / 2), math.sin(tilt / 2), 0, 0]
    depth, K = _probe_scene(mujoco.mjtGeom.mjGEOM_PLANE, [3, 3, 0.1], [0, 0, -0.7], quat)
    n = np.array([0, -math.sin(tilt), math.cos(tilt)])  # plane normal (world = GL camera frame)
    p0 = np.array([0, 0, -0.7])
    rays = _rays(K)
    s = (p0 @ n) / (rays @ n)  # ray parameter = depth along the optical axis
    valid = depth > 0
    assert valid.mean() > 0.99
    err = np.abs(depth[valid] - s[valid])
    assert err.mean() < 1e-4 and np.percentile(err, 99) < 5e-4


def test_depth_of_a_box_is_metric():
    """A 0.2 x 0.1 x 0.1 m box whose near face is 0.6 m away; edges land on the right pixels."""
    depth, K = _probe_scene(mujoco.mjtGeom.mjGEOM_BOX, [0.1, 0.05, 0.05], [0.03, -0.02, -0.65],
                            [1, 0, 0, 0])
    rays = _rays(K)
    lo, hi = np.array([-0.07, -0.07, -0.70]), np.array([0.13, 0.03, -0.60])
    with np.errstate(divide="ignore", invalid="ignore"):
        t1, t2 = lo / rays, hi / rays
    tmin = np.nanmax(np.minimum(t1, t2), axis=-1)
    tmax = np.nanmin(np.maximum(t1, t2), axis=-1)
    hit = (tmin <= tmax) & (tmax > 0)
    expected = np.where(hit, tmin, 0.0)
    both = hit & (depth > 0)
    # silhouettes agree up to the pixels that the box edge crosses
    assert np.sum(hit != (depth > 0)) < 0.01 * hit.sum()
    err = np.abs(depth[both] - expected[both])
    assert err.mean() < 1e-4


def test_a_frame_without_a_body_is_placed_on_the_body_that_carries_it():
    """Where the scene holds no body of the camera frame's name (a link fused into its parent),
    the camera goes on the nearest body above it through fixed joints, at the frame's pose."""
    from recon_cli.backends.sim.scene import _place, frame_on_body, mujoco_urdf
    from recon_cli.robot.cell import Cell
    from recon_cli.robot.description import CellConfig

    fr3 = Cell(CellConfig(kind="fr3"))
    urdf = mujoco_urdf(fr3.config)
    spec = mujoco.MjSpec.from_string(urdf)
    spec.delete(spec.body("camera"))
    body, body_T_camera = frame_on_body(spec, urdf, "camera", "camera.frame")
    assert body.name == "camera_bracket" and not np.allclose(body_T_camera, np.eye(4))
    cam = body.add_camera()
    _place(cam, body_T_camera @ GL_T_CV)
    model = spec.compile()
    data = mujoco.MjData(model)
    q = fr3.config.cell_file.pose("home", fr3.joint_names)
    data.qpos[[model.jnt_qposadr[model.joint(n).id] for n in fr3.joint_names]] = q
    mujoco.mj_kinematics(model, data)
    mujoco.mj_camlight(model, data)
    dp, dr = pose_error(opencv_from_opengl(world_T_camera_gl(data, 0)), fr3.kin.world_T_camera(q))
    assert dp < 1e-9 and dr < 1e-9
