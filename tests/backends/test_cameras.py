"""The hardware camera adapters through their real driver libraries, against stand-ins:

* GenICam: harvesters with the software GenTL producer shipped inside the genicam package
  (three "Viky" devices, serials 0/1/2, each streaming an RGBa8 image of a red, green or
  blue 20 x 20 px ball on white plus a planar Coord3D_ABC32f range component in mm whose C
  is 41 mm on the ball and 0 elsewhere; no trigger nodes, no Scan3dFocalLength);
* RealSense: pyrealsense2's software_device (tests/backends/realsense_standin.py).

Each is skipped with its reason only where the optional package (or the producer) is absent.
"""

from __future__ import annotations

import sys

import numpy as np
import pytest

from recon_cli.backends.base import CameraBackend
from recon_cli.errors import CameraFault, HardwareUnavailable, InputError

# --------------------------------------------------------------------- GenICam


def _producer():
    pytest.importorskip("harvesters", reason="the GenICam adapter needs harvesters (pip install 'recon-scan[genicam]')")
    pytest.importorskip("genicam", reason="the GenICam adapter needs genicam (pip install 'recon-scan[genicam]')")
    from recon_cli.backends.hardware.genicam import software_producer

    cti = software_producer()
    if cti is None:
        pytest.skip("the genicam package ships no software GenTL producer (.cti) here")
    return cti


@pytest.fixture()
def viky(monkeypatch):
    """The genicam package's software producer, found the way a real one is."""
    import os

    cti = _producer()
    monkeypatch.setenv("GENICAM_GENTL64_PATH", os.path.dirname(cti))
    return cti


def _genicam(**kw):
    from recon_cli.backends.hardware.genicam import GenICamConfig, open_camera

    return open_camera(GenICamConfig.from_mapping(kw, "cell.yaml: camera.genicam"))


@pytest.mark.parametrize(("serial", "channel"), [("0", 0), ("1", 1), ("2", 2)])
def test_genicam_device_by_serial_gives_its_ball_with_depth_from_coord3d(viky, serial, channel):
    with _genicam(serial=serial) as cam:
        assert isinstance(cam, CameraBackend)
        assert cam.producers == [viky] and cam.device["serial"] == serial
        assert cam.trigger == "free"  # the producer has no TriggerSoftware: one free-run frame per capture
        assert cam.coordinates.unit == 1e-3  # Scan3dDistanceUnit = Millimeter
        frames = [cam.capture() for _ in range(2)]
    for frame in frames:
        assert frame.color.shape == (400, 400, 3) and frame.color.dtype == np.uint8
        assert frame.depth.shape == (400, 400) and frame.depth.dtype == np.float64
        ball = frame.color.min(axis=2) < 128  # white background, a saturated ball
        assert ball.sum() == 400
        assert np.all(frame.color[ball][:, channel] == 255)  # red, green or blue by serial
        assert np.array_equal(ball, frame.depth > 0)  # depth exactly where the ball is
        z = frame.depth[ball]  # C [mm] * 1e-3: the ball's height, about 41-45 mm, one value per frame
        assert np.all(z == z[0]) and 0.03 < z[0] < 0.06
    assert frames[1].timestamp > frames[0].timestamp


def test_genicam_intrinsics_fitted_to_the_point_map_reproduce_it(viky):
    """Without intrinsics in the device or the station file they are fitted to the XYZ
    point map: the ball's back-projected pixels land on its A, B coordinates (pixel
    index x 1 mm)."""
    from recon_cli.perception.camera_model import backproject

    with _genicam(serial="0") as cam:
        frame = cam.capture()
        assert cam.intrinsics_source == "point map" and cam.fit_rms < 1e-6
    K = frame.intrinsics
    v, u = np.nonzero(frame.depth > 0)
    points = backproject(frame.depth, K)  # row-major over valid pixels
    assert np.allclose(points[:, 0], u * 1e-3, atol=1e-6) and np.allclose(points[:, 1], v * 1e-3, atol=1e-6)


def test_genicam_station_file_overrides_intrinsics_unit_and_scale(viky):
    with _genicam(serial="1", intrinsics={"fx": 500.0, "fy": 501.0, "cx": 199.5, "cy": 200.5}, depth_unit=0.01,
                  coordinate_scale=2.0) as cam:
        frame = cam.capture()
        assert cam.intrinsics_source == "station file"
    k = frame.intrinsics
    assert (k.width, k.height, k.fx, k.fy, k.cx, k.cy) == (400, 400, 500.0, 501.0, 199.5, 200.5)
    z = frame.depth[frame.depth > 0]
    assert np.all(z == z[0]) and 0.03 * 20 < z[0] < 0.06 * 20  # C [mm] x 2 x 0.01 m instead of x 0.001 m


def test_genicam_features_set_nodes_in_order_mono8_texture(viky):
    with _genicam(serial="2", features={"ComponentSelector": "Intensity", "PixelFormat": "Mono8"}) as cam:
        frame = cam.capture()
    assert np.array_equal(frame.color[..., 0], frame.color[..., 1])  # grey
    dark = frame.color[..., 0] < 128
    assert np.array_equal(dark, frame.depth > 0)


def test_genicam_device_errors_are_one_line_with_what_was_found(viky):
    with pytest.raises(CameraFault, match=r"no GenICam device with serial '7' \(found: 0 .*, 1 .*, 2 .*\)"):
        _genicam(serial="7")
    with pytest.raises(CameraFault, match="3 GenICam devices found.*camera.genicam.serial"):
        _genicam()
    with pytest.raises(InputError, match="features.NoSuchNode: the device has no writable node"):
        _genicam(serial="0", features={"NoSuchNode": 1})
    with pytest.raises(InputError, match="no component 'Confidence'.*Intensity, Range"):
        _genicam(serial="0", texture_component="Confidence")


def test_genicam_time_out_and_skipped_frames(viky):
    with _genicam(serial="0", timeout=0.001) as cam:  # the producer streams at 20 Hz
        with pytest.raises(CameraFault, match=r"no frame from the GenICam device within 0.001 s; .*timeout"):
            cam.capture()
    with _genicam(serial="0", skip_frames=2) as cam:
        assert (cam.capture().depth > 0).sum() == 400


def test_genicam_close_is_idempotent_and_capture_after_close_fails(viky):
    cam = _genicam(serial="0")
    cam.close()
    cam.close()
    with pytest.raises(CameraFault, match="closed"):
        cam.capture()


def test_genicam_camera_leaves_ctrl_c_to_the_run(viky):
    """harvesters' acquirer installs a SIGINT handler of its own: with the camera open, Ctrl-C
    still raises KeyboardInterrupt (the run stops the robot), not only harvesters' stop."""
    import os
    import signal
    import time

    before = signal.getsignal(signal.SIGINT)
    with _genicam(serial="0") as cam:
        cam.capture()
        assert signal.getsignal(signal.SIGINT) is before
        with pytest.raises(KeyboardInterrupt):
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(1.0)


def test_genicam_config_is_checked_key_by_key():
    from recon_cli.backends.hardware.genicam import GenICamConfig

    with pytest.raises(InputError, match=r"cell.yaml: camera.genicam.exposure is not a known key; known keys: "
                                         r"coordinate_offset, .*trigger"):
        GenICamConfig.from_mapping({"exposure": 3}, "cell.yaml: camera.genicam")
    with pytest.raises(InputError, match="trigger is not one of software, free"):
        GenICamConfig.from_mapping({"trigger": "hardware"})
    with pytest.raises(InputError, match="timeout = -1.0 is not positive"):
        GenICamConfig.from_mapping({"timeout": -1})
    with pytest.raises(InputError, match="intrinsics lacks cy"):
        GenICamConfig.from_mapping({"intrinsics": {"fx": 1, "fy": 1, "cx": 1}})
    cfg = GenICamConfig.from_mapping({"cti": "/x/a.cti", "serial": 1234, "texture_component": None})
    assert cfg.cti == ("/x/a.cti",) and cfg.serial == "1234" and cfg.texture_component is None
    with pytest.raises(InputError, match="cti: /x/a.cti does not exist"):
        from recon_cli.backends.hardware.genicam import producer_files

        producer_files(cfg)


def test_genicam_without_harvesters_is_a_one_line_install_hint(monkeypatch):
    from recon_cli.backends.hardware.genicam import GenICamConfig, open_camera

    monkeypatch.setitem(sys.modules, "harvesters", None)
    monkeypatch.setitem(sys.modules, "harvesters.core", None)
    with pytest.raises(HardwareUnavailable) as info:
        open_camera(GenICamConfig())
    assert info.value.one_line().endswith("pip install 'recon-scan[genicam]'") and "\n" not in info.value.one_line()


# --------------------------------------------------------------------- GenICam conversions (no device)
def test_range_parts_interleaved_planar_and_c16_with_scale_and_invalid_value():
    from recon_cli.backends.hardware.genicam import Coordinates, depth_and_points, range_parts

    h, w = 3, 4
    xyz = np.random.default_rng(0).uniform(1.0, 2.0, (h, w, 3)).astype(np.float32)
    xyz[0, 0] = np.nan
    ab, c, *_ = range_parts([("Coord3D_ABC32f", xyz.ravel(), w, h)])
    depth, points = depth_and_points(ab, c, Coordinates(unit=1e-3))
    assert depth[0, 0] == 0 and np.isnan(points[0, 0]).all()
    assert np.allclose(depth[1:], xyz[1:, :, 2] * 1e-3) and np.allclose(points[1, 1], xyz[1, 1] * 1e-3)
    planar = [("Coord3D_A32f", xyz[..., 0].ravel(), w, h), ("Coord3D_B32f", xyz[..., 1].ravel(), w, h),
              ("Coord3D_C32f", xyz[..., 2].ravel(), w, h)]
    ab2, c2, *_ = range_parts(planar)
    assert np.array_equal(ab2, ab, equal_nan=True) and np.array_equal(c2, c, equal_nan=True)
    raw = np.array([[0, 1000, 65535, 20000]], np.uint16)
    ab3, c3, *_ = range_parts([("Coord3D_C16", raw.ravel(), 4, 1)])
    depth3, points3 = depth_and_points(ab3, c3, Coordinates((1, 1, 0.05), (0, 0, 10.0), invalid=65535, unit=1e-3))
    assert points3 is None
    assert np.allclose(depth3, [[0.010, 0.060, 0.0, 1.010]])  # (raw * 0.05 + 10) mm; 65535 = no data
    with pytest.raises(CameraFault, match=r"no Coord3D range data in the frame \(parts: Mono8\)"):
        range_parts([("Mono8", raw.ravel(), 4, 1)])


def test_color_from_texture_formats():
    from recon_cli.backends.hardware.genicam import color_from_texture

    rgb = np.arange(2 * 3 * 3, dtype=np.uint8).reshape(2, 3, 3)
    assert np.array_equal(color_from_texture(rgb.ravel(), "RGB8", 3, 2), rgb)
    assert np.array_equal(color_from_texture(rgb[..., ::-1].ravel(), "BGR8", 3, 2), rgb)
    rgba = np.concatenate([rgb, np.full((2, 3, 1), 7, np.uint8)], axis=2)
    assert np.array_equal(color_from_texture(rgba.ravel(), "RGBa8", 3, 2), rgb)
    mono12 = np.array([0, 4095, 2048, 16], np.uint16)
    out = color_from_texture(mono12, "Mono12", 2, 2)
    assert out.shape == (2, 2, 3) and list(out[..., 0].ravel()) == [0, 255, 128, 1]
    with pytest.raises(CameraFault, match="texture pixel format YUV422_8 is not supported"):
        color_from_texture(mono12, "YUV422_8", 2, 2)


def test_fit_intrinsics_recovers_a_pinhole_and_refuses_a_non_pinhole_grid():
    from recon_cli.backends.hardware.genicam import fit_intrinsics

    h, w = 60, 80
    fx, fy, cx, cy = 70.0, 72.0, 39.0, 31.0
    v, u = np.mgrid[0:h, 0:w]
    z = 0.5 + 0.2 * np.sin(u / 9.0) * np.cos(v / 7.0)  # a wavy surface
    pts = np.stack([(u - cx) / fx * z, (v - cy) / fy * z, z], axis=2)
    values, rms = fit_intrinsics(pts)
    assert np.allclose(values, (fx, fy, cx, cy), atol=1e-6) and rms < 1e-6
    ortho = np.stack([u * 1e-3, v * 1e-3, z], axis=2)  # x, y do not scale with depth
    assert fit_intrinsics(ortho)[1] > 1.0


# --------------------------------------------------------------------- RealSense
@pytest.fixture()
def realsense():
    pytest.importorskip("pyrealsense2", reason="the RealSense adapter needs pyrealsense2 "
                                               "(pip install 'recon-scan[realsense]')")
    from .realsense_standin import SoftwareRealSense

    stand_in = SoftwareRealSense().start()
    yield stand_in
    stand_in.stop()


def _realsense(device, **kw):
    from recon_cli.backends.hardware.realsense import RealSenseConfig, open_camera

    cfg = RealSenseConfig.from_mapping({"width": 64, "height": 48, "warmup_frames": 2, **kw}, "camera.realsense")
    return open_camera(cfg, device=device)


def test_realsense_depth_intrinsics_and_colour_aligned_to_depth(realsense):
    with _realsense(realsense.device, serial="SW-0001") as cam:
        assert isinstance(cam, CameraBackend)
        assert cam.serial == "SW-0001" and cam.depth_units == pytest.approx(1e-4)
        frame = cam.capture()
    assert frame.depth.shape == (48, 64) and frame.color.shape == (48, 64, 3) and frame.color.dtype == np.uint8
    assert np.allclose(frame.depth, 0.5, atol=1e-6)  # z16 5000 x 1e-4 m
    k = frame.intrinsics
    assert (k.width, k.height, k.fx, k.fy, k.cx, k.cy) == (64, 48, 50.0, 50.0, 32.0, 24.0)
    assert frame.distortion is None  # Brown-Conrady with zero coefficients
    # the colour camera is 5 cm to the side: white (columns < 32 in colour) appears at
    # depth columns 5 ... 36, the first 5 see nothing of the colour image
    shift = round(realsense.f * realsense.baseline / realsense.depth)
    white = frame.color[:, :, 0] == 255
    assert shift == 5
    assert white[:, shift: 32 + shift].all() and not white[:, 32 + shift + 1:].any() and not white[:, :shift].any()


def test_realsense_capture_returns_a_frame_pushed_after_it_was_called(realsense):
    with _realsense(realsense.device, skip_frames=1) as cam:
        for _ in range(3):
            before = realsense.pushed
            frame = cam.capture()
            assert round(frame.timestamp * 1e3) > before  # frame n has timestamp n ms


def test_realsense_missing_mode_and_serial_are_one_line(realsense):
    from recon_cli.backends.hardware.realsense import choose_device

    with pytest.raises(CameraFault, match=r"no depth stream 640x480@30 z16 \(offered: 64x48@30 z16\)"):
        _realsense(realsense.device, width=640, height=480)
    with pytest.raises(CameraFault, match="has serial 'SW-0001', not '123'"):
        _realsense(realsense.device, serial="123")
    import pyrealsense2 as rs

    with pytest.raises(CameraFault, match=r"no RealSense device with serial '9' \(found: SW-0001\)"):
        choose_device(rs, [realsense.device], "9")
    with pytest.raises(CameraFault, match="no RealSense device found"):
        choose_device(rs, [], None)


def test_realsense_config_and_missing_driver(monkeypatch):
    from recon_cli.backends.hardware.realsense import RealSenseConfig, open_camera

    with pytest.raises(InputError, match="camera.realsense.exposure is not a known key; known keys: color_height"):
        RealSenseConfig.from_mapping({"exposure": 1})
    with pytest.raises(InputError, match="fps = 29.5 is not an integer"):
        RealSenseConfig.from_mapping({"fps": 29.5})
    with pytest.raises(InputError, match="both color_width and color_height"):
        RealSenseConfig.from_mapping({"color_width": 1280})
    assert RealSenseConfig.from_mapping({"color_width": 1280, "color_height": 720}).color_size == (1280, 720)
    monkeypatch.setitem(sys.modules, "pyrealsense2", None)
    with pytest.raises(HardwareUnavailable, match=r"pip install 'recon-scan\[realsense\]'"):
        open_camera(RealSenseConfig())


def test_station_check_with_the_software_genicam_camera(viky, tmp_path, capsys):
    """``recon station check`` of a station whose camera is the GenTL software producer (the
    robot is the simulated one): it opens the camera by serial and prints the frame."""
    from recon_cli.cli import main

    path = tmp_path / "cell.yaml"
    path.write_text('format: 1\nname: gentl\nrobot: {adapter: sim}\ncamera:\n  adapter: genicam\n'
                    '  genicam: {serial: "2", timeout: 5}\n')
    assert main(["station", "check", str(path)]) == 0
    out = capsys.readouterr().out
    assert "camera genicam" in out and "frame: 400 x 400 px" in out and "depth 0.0" in out
