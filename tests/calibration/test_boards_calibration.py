"""Camera calibration from a chessboard and from a circle grid (rendered views of a known
pinhole camera, tests/perception/test_boards.py), and ``--board-spec`` on the command line."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from recon_cli.calibration.intrinsics import DistortionModel, calibrate_intrinsics, find_boards
from recon_cli.geometry.transforms import invert, pose_error
from recon_cli.perception.boards import board_pose_in_opencv_frame
from recon_cli.workflows.handeye_dataset import DatasetHandEyeOptions, run_handeye_dataset
from tests.perception.test_boards import BOARDS, K, _pose, _render

POSES = [(25, 10, 0.5), (-30, 180, 0.55), (30, 95, 0.45), (20, -60, 0.5), (-25, 40, 0.6), (35, 200, 0.5)]


@pytest.mark.parametrize("name", ["chessboard", "circles", "charuco_legacy"])
def test_intrinsics_from_every_board_kind(name: str) -> None:
    board = BOARDS[name]
    images = [(f"v{k}", _render(board, _pose(board, *p))) for k, p in enumerate(POSES)]
    views, skipped = find_boards(images, board)
    assert len(views) == len(POSES) and not skipped
    r = calibrate_intrinsics(views, DistortionModel.RADIAL)
    c = r.camera.intrinsics
    assert r.rms < 0.2
    assert abs(c.fx - K.fx) < 3.0 and abs(c.fy - K.fy) < 3.0  # [px] of 900
    assert abs(c.cx - K.cx) < 3.0 and abs(c.cy - K.cy) < 3.0


def test_board_option_on_the_command_line(tmp_path, capsys) -> None:
    from tests.calibration.test_inputs import _run

    board = BOARDS["chessboard"]
    for k, p in enumerate(POSES):
        cv2.imwrite(str(tmp_path / f"v{k}.png"), _render(board, _pose(board, *p)))
    code, out = _run(capsys, "calibrate", "intrinsics", tmp_path, "--board-spec", "chessboard:9x6,0.025", "--out",
                     tmp_path / "o")
    assert code == 0, out
    report = json.loads((tmp_path / "o" / "intrinsics.json").read_text())
    assert report["board"]["text"] == "chessboard:9x6,0.025" and report["board_frame"].startswith("opencv: origin")
    assert len(report["views"][0]["camera_T_board_opencv"]) == 4
    code, out = _run(capsys, "calibrate", "intrinsics", tmp_path, "--board-spec", "chessboard:8x6,0.025", "--out",
                     tmp_path / "o2")
    assert code == 1 and "ambiguous" in out and len(out.strip().splitlines()) == 1, out
    assert not (tmp_path / "o2").exists()
    # the simulation shows a ChArUco board only
    code, out = _run(capsys, "calibrate", "handeye", "--board-spec", "circles:4x11,0.02", "--out", tmp_path / "o3")
    assert code == 1 and "the simulation shows a ChArUco board" in out and len(out.strip().splitlines()) == 1, out


FLANGE_T_CAMERA = np.array([[0.0, -1.0, 0.0, 0.04], [1.0, 0.0, 0.0, -0.06], [0.0, 0.0, 1.0, 0.11], [0, 0, 0, 1.0]])
BASE_T_MARKER = np.array([[1.0, 0.0, 0.0, 0.55], [0.0, 1.0, 0.0, 0.10], [0.0, 0.0, 1.0, 0.02], [0, 0, 0, 1.0]])
#: camera poses: tilt about the board's x and y [deg], roll about the optical axis [deg], distance [m]
HAND_EYE_POSES = [(25, 0, 10, 0.5), (-25, 10, 100, 0.55), (0, 30, -40, 0.5), (15, -25, 170, 0.45),
                  (-20, -20, 60, 0.6), (30, 15, -120, 0.5), (-10, 30, 20, 0.55), (20, 20, -80, 0.5)]


def _camera_T_board(board, tx: float, ty: float, roll: float, distance: float) -> np.ndarray:
    """camera_T_board (OpenCV's board frame): the board's centre on the optical axis."""
    R = (Rotation.from_euler("z", roll, degrees=True) * Rotation.from_euler("y", ty, degrees=True)
         * Rotation.from_euler("x", tx, degrees=True)).as_matrix()
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = np.array([0.0, 0.0, distance]) - R @ np.r_[np.asarray(board.size) / 2, 0.0]
    return T


@pytest.mark.parametrize("name", ["chessboard", "circles"])
def test_hand_eye_from_a_data_set_of_another_board(name: str, tmp_path) -> None:
    """Eye-in-hand from rendered views and libfranka's O_T_EE (column-major JSON): the mount and
    the board (recon's marker frame, and OpenCV's through board_pose_in_opencv_frame) within
    1 mm and 0.1 degree of the truth."""
    board = BOARDS[name]
    (tmp_path / "data" / "images").mkdir(parents=True)
    (tmp_path / "data" / "poses").mkdir()
    for k, p in enumerate(HAND_EYE_POSES):
        C = _camera_T_board(board, *p)  # camera_T_board in OpenCV's frame
        cv2.imwrite(str(tmp_path / "data" / "images" / f"{k}.png"), _render(board, C))
        camera_T_marker = C @ board.opencv_board_T_marker()
        F = BASE_T_MARKER @ invert(camera_T_marker) @ invert(FLANGE_T_CAMERA)
        (tmp_path / "data" / "poses" / f"{k}.json").write_text(json.dumps({"O_T_EE": F.T.ravel().tolist()}))
    r = run_handeye_dataset(DatasetHandEyeOptions(tmp_path / "data", tmp_path / "out", board=board, accept=True,
                                                  intrinsics=(K.fx, K.fy, K.cx, K.cy)))
    assert len(r.used) == len(HAND_EYE_POSES) and not r.skipped, r.skipped
    named = r.solution.named()
    for got, want in ((named["flange_T_camera"], FLANGE_T_CAMERA), (named["base_T_board"], BASE_T_MARKER)):
        dt, dr = pose_error(got, want)
        assert dt < 1e-3 and np.degrees(dr) < 0.1, (dt, np.degrees(dr))
    base_T_board_cv = board_pose_in_opencv_frame(board, named["base_T_board"])
    dt, dr = pose_error(base_T_board_cv, BASE_T_MARKER @ invert(board.opencv_board_T_marker()))
    assert dt < 1e-3 and np.degrees(dr) < 0.1


def test_a_mapping_names_its_board_in_the_board_syntax(tmp_path) -> None:
    from recon_cli.calibration.dataset import read_mapping
    from recon_cli.errors import InputError
    from recon_cli.perception.boards import ChessboardSpec

    mapping = tmp_path / "mapping.yaml"
    mapping.write_text('board: "chessboard:9x6,0.025"\n')
    assert read_mapping(mapping).board == ChessboardSpec(9, 6, 0.025)
    mapping.write_text('board: "circles:4x10,0.02"\n')
    with pytest.raises(InputError) as info:
        read_mapping(mapping)
    line = info.value.one_line()
    assert "mapping.yaml:1: board 'circles:4x10,0.02'" in line and "odd number of rows" in line
