"""Realism profiles: ``ideal`` is the simulation as it was, bit for bit; ``thesis`` makes the
simulated cell differ from the model (encoder offsets, sag, base and hand-eye errors, a
distorted camera with other intrinsics, depth artefacts), seeded; profile errors are one line."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from recon_cli.backends.sim.camera import render_rgbd
from recon_cli.backends.sim.station import SimStation
from recon_cli.config import DEFAULTS
from recon_cli.errors import FileError, InputError
from recon_cli.geometry.transforms import invert, pose_error
from recon_cli.objects import load_object
from recon_cli.perception import sensor as fx
from recon_cli.perception.camera_model import distorted_pixel_maps, intrinsics_from_fovy
from recon_cli.perception.charuco import detect, estimate_pose, thesis_board
from recon_cli.realism import IDEAL, CameraErrors, RealismProfile, load_profile, parse_profile
from recon_cli.robot.ik import IKOptions
from recon_cli.robot.poses import named_configuration
from recon_cli.thesis import eq_4_1_views

RES = 0.25  # 400 x 300 images: the board is still found at 0.6 m


@pytest.fixture(scope="module")
def view_q(gantry):
    """Joint readings of eq. 4.1 view 1 (the cube stays out of the way of this view)."""
    ik = gantry.solve_view(eq_4_1_views()[0], np.random.default_rng(0), options=IKOptions(max_solutions=1))
    return ik.solutions[0].q


@pytest.fixture(scope="module")
def thesis() -> RealismProfile:
    return load_profile("thesis")


def _station(cell, profile, seed=0, res=RES, noise=True):
    start = named_configuration(cell.config.kind, "home", cell.joint_names)
    return SimStation(cell, load_object("bottle"), start, np.random.default_rng(seed), noise=noise, resolution=res,
                      realism=profile)


def _frame(cell, profile, q, seed=0, res=RES):
    with _station(cell, profile, seed, res) as st:
        st.robot.reset(q)
        frame = st.camera.capture()
        return frame, st.robot.measured_joints(), st.camera.world_T_camera_truth(), st.robot.true_joints()


# --------------------------------------------------------------------- ideal
def test_ideal_is_the_default_and_changes_nothing():
    assert load_profile("ideal") == IDEAL == DEFAULTS.realism
    assert IDEAL.is_ideal and not load_profile("thesis").is_ideal


def test_ideal_images_are_the_plain_simulation(gantry, view_q):
    """The ideal profile renders exactly what the simulation without profiles rendered:
    MuJoCo's image, then the sensor model, from the same generator."""
    frame, q_read, _, q_true = _frame(gantry, IDEAL, view_q, seed=5)
    with _station(gantry, IDEAL, seed=5) as st:  # the plain pipeline by hand, same seed
        st.robot.data.qpos[st.robot.scene.qpos_index] = view_q
        import mujoco

        mujoco.mj_forward(st.scene.model, st.data)
        color, depth = render_rgbd(st.camera.renderer, st.data, st.scene.camera_id)
        rng = st.camera.rng
        depth = st.scene.sensor.apply(depth, st.camera.intrinsics, rng, True)
        color = st.scene.sensor.apply_color(color, rng, True)
    assert np.array_equal(frame.color, color) and np.array_equal(frame.depth, depth)
    assert np.array_equal(q_read, view_q) and np.array_equal(q_true, view_q)
    assert frame.distortion is None and frame.intrinsics == st.scene.sensor.intrinsics(RES)


# --------------------------------------------------------------------- thesis: seeded, present
def test_thesis_is_seeded(gantry, view_q, thesis):
    a = _frame(gantry, thesis, view_q, seed=1)
    b = _frame(gantry, thesis, view_q, seed=1)
    c = _frame(gantry, thesis, view_q, seed=2)
    assert np.array_equal(a[0].color, b[0].color) and np.array_equal(a[0].depth, b[0].depth)
    assert np.array_equal(a[1], b[1]) and np.array_equal(a[2], b[2])
    assert not np.array_equal(a[0].depth, c[0].depth) and not np.array_equal(a[1], c[1])


def test_encoder_offsets_and_sag_move_the_true_robot(gantry, view_q, thesis):
    with _station(gantry, thesis, seed=3) as st:
        st.robot.reset(view_q)
        sensor, truth = st.robot.joint_sensor, st.truth
        q_true = st.robot.true_joints()
        # reading = true + offset + compliance * gravity torque (+ noise of a few micro-degrees)
        expected = q_true + truth.offsets + sensor.deflection(q_true)
        read = st.robot.measured_joints()
        assert np.abs(read - expected).max() < 10 * max(truth.noise_std.max(), 1e-12)
        assert np.allclose(sensor.sense(q_true), view_q, atol=1e-12)  # reset put the reading at view_q
        sag = np.degrees(np.abs(sensor.deflection(q_true)))
        assert 0.01 < sag.max() < 0.5  # hundredths of a degree at 20-60 kN m/rad (RP.H)
        # forward kinematics of the readings vs the true camera: millimetres, as on an uncalibrated robot
        dp, dr = pose_error(gantry.kin.world_T_camera(read), st.camera.world_T_camera_truth())
    assert 1e-3 < dp < 15e-3 and math.radians(0.02) < dr < math.radians(1.0)


def test_offsets_alone_give_the_expected_camera_error(gantry, view_q):
    """With encoder offsets only, the true camera is where forward kinematics of (reading -
    offsets) puts it: the error is exactly the offsets' effect, of order reach x offset."""
    p = parse_profile("kinematics: {joint_offset_std_deg: 0.05}", "offsets.yaml")
    with _station(gantry, p, seed=4) as st:
        st.robot.reset(view_q)
        read = st.robot.measured_joints()
        truth = st.camera.world_T_camera_truth()
        offsets = st.truth.offsets
    assert np.allclose(read, view_q)
    assert pose_error(gantry.kin.world_T_camera(read - offsets), truth)[0] < 1e-6
    dp, _ = pose_error(gantry.kin.world_T_camera(read), truth)
    scale = 1.2 * np.linalg.norm(offsets[2:])  # about 1.2 m of lever from the shoulder to the camera
    assert 0.2 * scale < dp < 2.0 * scale


def test_distorted_camera_and_calibrated_assumption(gantry, view_q, thesis):
    """The actual camera has lens distortion and other intrinsics; recon is told the nominal
    pinhole, so the board pose is about a millimetre off; told the actual camera (a perfect
    calibration), the same images give the board within a few tenths."""
    cam_only = RealismProfile(name="camera", camera=thesis.camera)
    K_full = cam_only.camera.actual.intrinsics(1600, 1200)
    mx, my = distorted_pixel_maps(K_full, cam_only.camera.actual.distortion, K_full)
    assert math.hypot(mx[0, 0], my[0, 0]) > 5.0  # the corner pixel sees a ray 6-7 px further in
    ideal, _, T_true, _ = _frame(gantry, IDEAL, view_q, res=0.5)
    nominal, _, T_true2, _ = _frame(gantry, cam_only, view_q, res=0.5)
    assert np.array_equal(T_true, T_true2)  # no kinematic error in this profile
    assert nominal.intrinsics == ideal.intrinsics and nominal.distortion is None
    assert np.mean(np.abs(nominal.color.astype(int) - ideal.color.astype(int))) > 1.0
    calibrated, _, _, _ = _frame(gantry, cam_only.with_assumed_camera(cam_only.camera.actual), view_q, res=0.5)
    assert calibrated.distortion == cam_only.camera.actual.distortion
    board = thesis_board()
    truth = invert(T_true) @ gantry.world_T_marker
    errors = []
    for f in (nominal, calibrated):
        pose = estimate_pose(detect(f.color, board), board, f.intrinsics, f.distortion)
        errors.append(pose_error(pose.camera_T_marker, truth)[0])
    assert errors[0] > 0.5e-3 and errors[1] < 0.4e-3 < errors[0]


def test_depth_artefacts(gantry, view_q, thesis):
    frame, *_ = _frame(gantry, thesis, view_q)
    K = frame.intrinsics
    plain, *_ = _frame(gantry, RealismProfile(camera=thesis.camera), view_q)
    assert np.count_nonzero(frame.depth) < np.count_nonzero(plain.depth)  # dropouts
    # quantization: valid depths sit on the sensor's inverse-depth grid (steps growing with z^2)
    unit = thesis.depth.quantization / 0.718 ** 2
    k = 1.0 / frame.depth[frame.depth > 0] / unit
    assert np.abs(k - np.round(k)).max() < 1e-6
    # flying pixels only at edges, between the depths of the neighbours
    rng = np.random.default_rng(0)
    d = np.full((20, 20), 0.6)
    d[:, 10:] = 0.7
    f = fx.flying_pixels(d, 1.0, 0.01, rng)
    changed = f != d
    assert changed[:, 9:11].all() and not changed[:, :9].any() and not changed[:, 11:].any()
    assert (f[changed] >= 0.6).all() and (f[changed] <= 0.7).all()
    # multipath: nothing on a plane, a bias at the bottom of a groove
    K = intrinsics_from_fovy(60, 60, 0.5)
    plane = np.full((60, 60), 0.6)
    assert np.array_equal(fx.multipath(plane, K, 0.02, 0.02), plane)
    groove = plane.copy()
    groove[:, 28:32] = 0.61
    biased = fx.multipath(groove, K, 0.02, 0.02)
    assert biased[30, 30] > groove[30, 30] and np.array_equal(biased[:, :20], groove[:, :20])


# --------------------------------------------------------------------- profile files
@pytest.mark.parametrize("text, where", [
    ("kinematics: {joint_offset_deg: 0.1}", "kinematics.joint_offset_deg is not a known key"),
    ("kinematics: {base_error: {translation_mm: fast}}",
     "kinematics.base_error.translation_mm is a text of 4 characters, not a number"),
    ("camera: {actual: {fx: 1700, fy: 1700, cx: 800}}", "camera.actual lacks cy"),
    ("camera: {actual: {fx: 1700, fy: 1700, cx: 800, cy: 600, distortion: [1, 2]}}", "camera.actual.distortion"),
    ("depth: {grazing_dropout_deg: [80, 60]}", "depth.grazing_dropout_deg"),
    ("image: {exposure: -1}", "image.exposure = -1"),
    ("format: 2", "format = 2 is not 1"),
    ("depth: [1, 2", "broken.yaml:2: not valid YAML"),
    ("extends: perfect", "extends is not one of ideal, thesis, lab"),
])
def test_profile_errors_are_one_line(text, where):
    with pytest.raises(InputError) as exc:
        parse_profile(text, "broken.yaml")
    line = exc.value.one_line()
    assert "\n" not in line and line.startswith("broken.yaml") and where in line


def test_profile_file_errors(tmp_path, gantry):
    with pytest.raises(FileError, match="does not exist"):
        load_profile(tmp_path / "missing.yaml")
    with pytest.raises(InputError, match="unknown realism profile 'perfect'"):
        load_profile("perfect")
    path = tmp_path / "stiff.yaml"
    path.write_text("kinematics:\n  joint_stiffness: {elbow: 1000}\n")
    with pytest.raises(InputError, match=r"stiff.yaml: kinematics.joint_stiffness.elbow is not a joint"):
        _station(gantry, load_profile(path), res=0.05)
    # every key is optional: a profile of one effect is the ideal one with that effect
    p = parse_profile("image: {blur_sigma_px: 1}", "x.yaml")
    assert p.image.blur_sigma == 1.0 and p.camera == CameraErrors()
    assert dataclasses.replace(p, image=IDEAL.image) == dataclasses.replace(IDEAL, name="x", source="x.yaml")


def test_a_profile_extends_a_built_in_one():
    """``extends``: the built-in profile's sections, each key the profile gives replacing
    that key as a whole; ``lab`` is ``thesis`` with the cell's own camera."""
    from recon_cli.inputs.schema import load_schema
    from recon_cli.realism import BUILT_IN, PoseError

    thesis = load_profile("thesis")
    assert load_profile("lab") == dataclasses.replace(thesis, name="lab", source="robot/realism/lab.yaml",
                                                      camera=CameraErrors())
    p = parse_profile("extends: thesis\nkinematics:\n  base_error: {translation_mm: 5}\n", "more.yaml")
    assert p.name == "more" and p.camera == thesis.camera and p.depth == thesis.depth and p.image == thesis.image
    assert p.kinematics == dataclasses.replace(thesis.kinematics, base=PoseError(0.005, 0.0))
    assert parse_profile("extends: thesis\nkinematics:\n", "x.yaml").kinematics == thesis.kinematics
    assert tuple(load_schema("realism")["properties"]["extends"]["enum"]) == BUILT_IN
