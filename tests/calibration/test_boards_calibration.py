"""Camera calibration from a chessboard and from a circle grid (rendered views of a known
pinhole camera, tests/perception/test_boards.py), and ``--board`` on the command line."""

from __future__ import annotations

import json

import cv2
import pytest

from recon_cli.calibration.intrinsics import DistortionModel, calibrate_intrinsics, find_boards
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
    code, out = _run(capsys, "calibrate", "intrinsics", tmp_path, "--board", "chessboard:9x6,0.025", "--out",
                     tmp_path / "o")
    assert code == 0, out
    report = json.loads((tmp_path / "o" / "intrinsics.json").read_text())
    assert report["board"]["text"] == "chessboard:9x6,0.025" and report["board_frame"].startswith("opencv: origin")
    assert len(report["views"][0]["camera_T_board_opencv"]) == 4
    code, out = _run(capsys, "calibrate", "intrinsics", tmp_path, "--board", "chessboard:8x6,0.025", "--out",
                     tmp_path / "o2")
    assert code == 1 and "ambiguous" in out and len(out.strip().splitlines()) == 1, out
    assert not (tmp_path / "o2").exists()
    # the simulation shows a ChArUco board only
    code, out = _run(capsys, "calibrate", "handeye", "--board", "circles:4x11,0.02", "--out", tmp_path / "o3")
    assert code == 1 and "the simulation shows a ChArUco board" in out and len(out.strip().splitlines()) == 1, out
