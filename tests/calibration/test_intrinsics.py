"""Camera calibration: exact on synthetic corners, and on OpenCV's real ChArUco photos
(../shared/data/charuco_real) close to OpenCV's own calibration of them; the board detection
against the marker corners OpenCV's test expects; camera files round trip."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from recon_cli.calibration.camera_file import CameraCalibration, load_camera_file, write_camera_file
from recon_cli.calibration.intrinsics import (
    BoardView,
    DistortionModel,
    calibrate_intrinsics,
    find_board,
    find_boards,
    plot_reprojection,
)
from recon_cli.calibration.observations import observe
from recon_cli.errors import FileError, InputError
from recon_cli.perception.camera_model import Intrinsics
from recon_cli.perception.charuco import BoardSpec
from recon_cli.workflows.calibrate import IntrinsicsOptions, board_images, run_intrinsics

from ..conftest import SHARED_DATA

CHARUCO = SHARED_DATA / "charuco_real"
TUTORIAL_BOARD = BoardSpec(5, 7, 0.04, 0.02, "DICT_6X6_250")
TRUE = CameraCalibration(Intrinsics(800, 600, 869.47, 869.96, 399.55, 301.23),
                         (0.0133, -0.1723, 4.9e-5, -4.0e-5, 0.6177))  # the thesis camera at 800 x 600


def _synthetic_views(camera: CameraCalibration, n: int = 12, noise: float = 0.0, seed: int = 0) -> list[BoardView]:
    """The thesis board's corners projected from tilted poses (no rendering)."""
    from recon_cli.perception.charuco import thesis_board

    rng = np.random.default_rng(seed)
    board = thesis_board().board()
    obj = np.asarray(board.getChessboardCorners(), dtype=np.float64)
    centre = obj.mean(axis=0)
    K, dist = camera.intrinsics.matrix(), camera.distortion_array
    views = []
    for k in range(n):
        tilt = np.radians(35.0) * np.array([np.cos(2.4 * k), np.sin(2.4 * k), 0.0]) * (0.4 + 0.6 * ((k * 0.618) % 1))
        R = cv2.Rodrigues(tilt + np.array([0.0, 0.0, 0.5 * np.sin(k)]))[0]
        t = np.array([0.04 * np.cos(k), 0.03 * np.sin(1.3 * k), 0.45]) - R @ centre
        img, _ = cv2.projectPoints(obj, cv2.Rodrigues(R)[0], t, K, dist)
        img = img.reshape(-1, 2) + rng.normal(scale=noise, size=(len(obj), 2))
        inside = np.all((img >= 0) & (img < [camera.intrinsics.width, camera.intrinsics.height]), axis=1)
        views.append(BoardView(f"v{k}", (camera.intrinsics.width, camera.intrinsics.height),
                               np.flatnonzero(inside), obj[inside], img[inside], 0))
    return views


def test_exact_corners_give_the_camera_back():
    r = calibrate_intrinsics(_synthetic_views(TRUE))
    K, T = r.camera.intrinsics, TRUE.intrinsics
    assert abs(K.fx / T.fx - 1) < 1e-6 and abs(K.fy / T.fy - 1) < 1e-6
    assert abs(K.cx - T.cx) < 1e-4 and abs(K.cy - T.cy) < 1e-4
    assert np.allclose(r.camera.distortion, TRUE.distortion, atol=1e-5)
    assert r.rms < 1e-4 and len(r.views) == 12


def test_noisy_corners_focal_within_0_2_percent():
    r = calibrate_intrinsics(_synthetic_views(TRUE, n=16, noise=0.1, seed=1))
    assert abs(r.camera.intrinsics.fx / TRUE.intrinsics.fx - 1) < 0.002
    assert 0.1 < r.rms < 0.16  # the noise itself: 0.1 px per coordinate, 0.14 px per corner
    assert r.std["fx"] < 2.0 and set(r.std) >= {"fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3"}


def test_distortion_models_fix_coefficients():
    r = calibrate_intrinsics(_synthetic_views(TRUE), DistortionModel.RADIAL)
    assert r.camera.distortion[2:] == (0.0, 0.0, 0.0)
    barrel = CameraCalibration(TRUE.intrinsics, (-0.25, 0.1, 0.0, 0.0, 0.0))
    r = calibrate_intrinsics(_synthetic_views(barrel), DistortionModel.NONE)
    assert r.camera.distortion == (0.0,) * 5 and r.rms > 0.5  # a pinhole cannot explain the distortion
    r = calibrate_intrinsics(_synthetic_views(barrel), DistortionModel.RADIAL)
    assert r.rms < 1e-4 and np.allclose(r.camera.distortion[:2], (-0.25, 0.1), atol=1e-6)


def test_user_errors_are_one_line(tmp_path):
    views = _synthetic_views(TRUE, n=2)
    with pytest.raises(InputError, match="at least 3 images, found it in 2"):
        calibrate_intrinsics(views)
    other = _synthetic_views(CameraCalibration(Intrinsics(640, 480, 500, 500, 320, 240)), n=2)
    with pytest.raises(InputError, match="different sizes"):
        calibrate_intrinsics(views + other)
    with pytest.raises(FileError, match="holds no images"):
        board_images(tmp_path)
    (tmp_path / "x.png").write_bytes(b"not a png")
    with pytest.raises(FileError, match="cannot be read as an image"):
        board_images(tmp_path)
    with pytest.raises(FileError, match="does not exist"):
        load_camera_file(tmp_path / "none.yaml")
    (tmp_path / "bad.yaml").write_text("format: 1\ncamera: {width: 640, height: 480, fx: -1, fy: 1, cx: 1, cy: 1}\n")
    with pytest.raises(InputError, match=r"bad.yaml:2: camera.fx = -1 px is outside \[1, 100000\] px"):
        load_camera_file(tmp_path / "bad.yaml")


def test_camera_file_round_trip_and_scaling(tmp_path):
    path = write_camera_file(tmp_path / "intrinsics.yaml", TRUE, {"rms_px": 0.05}, comment="test")
    back = load_camera_file(path)
    assert back == TRUE
    full = back.at_size(1600, 1200)
    assert full.intrinsics.fx == pytest.approx(2 * TRUE.intrinsics.fx)
    assert full.intrinsics.cx == pytest.approx(2 * (TRUE.intrinsics.cx + 0.5) - 0.5)
    assert full.at_size(800, 600).intrinsics.cx == pytest.approx(TRUE.intrinsics.cx)
    spec = back.to_camera_spec()  # what a realism profile's camera.assumed holds
    assert (spec.fx, spec.distortion) == (TRUE.intrinsics.fx, TRUE.distortion)


# --------------------------------------------------------------------- real photos
needs_photos = pytest.mark.skipif(not CHARUCO.exists(), reason="../shared/data/charuco_real is not here")


@needs_photos
@pytest.mark.parametrize("image", ["choriginal.jpg", "chocclusion_original.jpg"])
def test_board_detection_on_real_photos_matches_opencv_gold(image):
    """The detection half of both calibrations on photos no one here rendered: every marker
    OpenCV's own test expects within 1 px, then the board pose the hand-eye calibration uses."""
    gold = json.loads((CHARUCO / "gold_marker_corners_from_opencv_test.json").read_text())[image]
    rgb = cv2.cvtColor(cv2.imread(str(CHARUCO / "images" / image)), cv2.COLOR_BGR2RGB)
    view = find_board(image, rgb, TUTORIAL_BOARD)
    assert isinstance(view, BoardView) and view.markers == len(gold)
    from recon_cli.perception.charuco import detect

    det = detect(rgb, TUTORIAL_BOARD)
    found = dict(zip(det.marker_ids.tolist(), det.marker_corners, strict=True))
    for marker_id, corners in gold.items():
        assert np.max(np.abs(found[int(marker_id)] - np.reshape(corners, (4, 2)))) <= 1.0
    fs = cv2.FileStorage(str(CHARUCO / "params" / "tutorial_camera_charuco.yml"), cv2.FILE_STORAGE_READ)
    K, dist = fs.getNode("camera_matrix").mat(), fs.getNode("distortion_coefficients").mat().reshape(-1)
    camera = CameraCalibration(Intrinsics(640, 480, K[0, 0], K[1, 1], K[0, 2], K[1, 2]), tuple(dist))
    obs = observe(image, rgb, camera, np.eye(4), TUTORIAL_BOARD)
    assert obs.corners == (16 if "occlusion" in image else 24)
    assert obs.reprojection_px < 1.0
    assert 0.2 < obs.camera_T_marker[2, 3] < 1.0  # the board half a metre-ish in front (its units: metres)


@needs_photos
def test_intrinsics_of_real_photos(tmp_path):
    """OpenCV's tutorial calibrated its camera from img_00-03 (fx 452.5, fy 456.8, cx 317.7,
    cy 277.8 px, RMS 0.18 px): ours from the same photos, with the reprojection reported."""
    run = run_intrinsics(IntrinsicsOptions(CHARUCO / "images", tmp_path, TUTORIAL_BOARD, "img_*.jpg"))
    r = run.result
    K = r.camera.intrinsics
    print(f"real photos: {len(r.views)} views, RMS {r.rms:.3f} px (per view "
          + ", ".join(f"{v.rms:.3f}" for v in r.views) + f"), fx {K.fx:.1f} ± {r.std['fx']:.1f}, fy {K.fy:.1f}, "
          f"cx {K.cx:.1f}, cy {K.cy:.1f} px, k1..k3 " + ", ".join(f"{v:.4f}" for v in r.camera.distortion))
    assert len(r.views) == 4 and r.corners == 96 and r.rms < 0.3
    assert abs(K.fx - 452.51) < 2 * r.std["fx"] and abs(K.cx - 317.70) < 2.0
    assert all(v.rms < 0.3 for v in r.views)
    assert run.figure.exists() and run.camera_file.exists()
    assert json.loads(run.report.read_text())["rms_px"] == pytest.approx(r.rms)
    # every image of the folder: the diamond photo has no board, the board image another size
    views, skipped = find_boards(board_images(CHARUCO / "images"), TUTORIAL_BOARD)
    assert [s.name for s in skipped] == ["diamondmarkers.png"] and "board not found (0 corners" in skipped[0].reason
    with pytest.raises(InputError, match="different sizes"):
        calibrate_intrinsics(views)


def test_figure_is_written(tmp_path):
    r = calibrate_intrinsics(_synthetic_views(TRUE, noise=0.05))
    plot_reprojection(r, tmp_path / "f.png")
    assert (tmp_path / "f.png").stat().st_size > 10_000
