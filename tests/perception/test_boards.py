"""The three board kinds, rendered with OpenCV, seen through a pinhole camera at a known pose,
found and posed by solvePnP; the board frames; the ``--board-spec`` syntax.

Rendering: the printed board is a texture (ChArUco: ``CharucoBoard.generateImage``;
chessboard and circle grid drawn with numpy and cv2) mapped into a 960 x 720 image by the
homography K [r1 r2 t] of the true pose (``cv2.warpPerspective``). The PnP pose must agree
with the truth within 0.5 mm and 0.05 degree (the board 0.45 ... 0.6 m away, tilted 25 ... 35
degrees), also when the board is turned upside down in the image.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from recon_cli.errors import InputError
from recon_cli.perception.boards import (
    BoardFound,
    BoardMissing,
    ChessboardSpec,
    CircleGridSpec,
    board_dict,
    board_pose_in_opencv_frame,
    board_text,
    find_points,
    find_pose,
    frame_text,
    opencv_frame_fields,
    parse_board,
)
from recon_cli.perception.camera_model import Intrinsics
from recon_cli.perception.charuco import BoardSpec

K = Intrinsics(960, 720, 900.0, 900.0, 480.0, 360.0)
PPM = 5000.0  # texture pixels per metre
MARGIN = 100  # light texture border [px]
#: the accepted pose error against the truth [m], [rad] (found: below 0.18 mm, 0.025 deg; the
#: circles' 0.1 ... 0.18 mm are the perspective shift of an ellipse's centre)
TRANSLATION_BOUND = 0.5e-3
ROTATION_BOUND = np.radians(0.05)


def _texture(board) -> tuple[np.ndarray, np.ndarray]:
    """The printed board (grey, light border) and tex_T_board: texture pixel of a point in
    OpenCV's board frame (3x3, a 2D similarity; pixel centres at integer coordinates)."""
    if isinstance(board, BoardSpec):
        img = board.image(PPM)
        origin = 0.0  # the board's top-left corner
    elif isinstance(board, ChessboardSpec):
        s = round(board.square_length * PPM)
        cells = np.indices((board.rows + 1, board.cols + 1)).sum(axis=0) % 2  # 0: black, at the top-left
        img = np.kron(np.where(cells == 0, 0, 255).astype(np.uint8), np.ones((s, s), np.uint8))
        origin = board.square_length  # the first inner corner, one square in
    else:
        s = board.spacing
        w, h = board.size[0] + 2 * s, board.size[1] + 2 * s
        img = np.full((round(h * PPM), round(w * PPM)), 255, np.uint8)
        for x, y, _ in board.object_points():
            centre = (round((x + s) * PPM * 16), round((y + s) * PPM * 16))
            cv2.circle(img, centre, round(0.35 * s * PPM * 16), 0, -1, cv2.LINE_AA, shift=4)
        origin = s
    img = cv2.copyMakeBorder(img, MARGIN, MARGIN, MARGIN, MARGIN, cv2.BORDER_CONSTANT, value=255)
    off = origin * PPM + MARGIN - 0.5
    return img, np.array([[PPM, 0, off], [0, PPM, off], [0, 0, 1.0]])


def _pose(board, tilt_deg: float, roll_deg: float, distance: float) -> np.ndarray:
    """camera_T_board (OpenCV's board frame): the board's centre on the optical axis at
    ``distance``, tilted about the board's x axis and rolled about the optical axis."""
    Rx = cv2.Rodrigues(np.array([np.radians(tilt_deg), 0.0, 0.0]))[0]
    Rz = cv2.Rodrigues(np.array([0.0, 0.0, np.radians(roll_deg)]))[0]
    R = Rz @ Rx
    centre = np.r_[np.asarray(board.size) / 2, 0.0]
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = np.array([0.01, -0.02, distance]) - R @ centre
    return T


def _render(board, camera_T_board: np.ndarray) -> np.ndarray:
    tex, tex_T_board = _texture(board)
    H = K.matrix() @ camera_T_board[:3, [0, 1, 3]] @ np.linalg.inv(tex_T_board)
    tex = cv2.GaussianBlur(tex, (0, 0), 1.5)  # against aliasing: the texture is shrunk about 3 times
    return cv2.warpPerspective(tex, H, (K.width, K.height), flags=cv2.INTER_LINEAR, borderValue=170)


def _error(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    d = np.linalg.inv(a) @ b
    return float(np.linalg.norm(d[:3, 3])), float(np.linalg.norm(cv2.Rodrigues(d[:3, :3])[0]))


BOARDS = {
    "charuco": BoardSpec(5, 7, 0.04, 0.02, "DICT_6X6_250"),
    "charuco_legacy": BoardSpec(5, 6, 0.04, 0.02, "DICT_6X6_250", legacy=True),
    "chessboard": ChessboardSpec(9, 6, 0.025),
    "circles": CircleGridSpec(4, 11, 0.02),
}


@pytest.mark.parametrize("name", list(BOARDS))
@pytest.mark.parametrize(("tilt", "roll", "distance"), [(25.0, 10.0, 0.5), (-35.0, 180.0, 0.6), (30.0, 95.0, 0.45)])
def test_rendered_board_pose(name: str, tilt: float, roll: float, distance: float) -> None:
    board = BOARDS[name]
    truth = _pose(board, tilt, roll, distance)
    found = find_pose(_render(board, truth), board, K)
    assert isinstance(found, BoardFound), found
    expected = truth @ board.opencv_board_T_marker()  # camera_T_marker
    dt, dr = _error(found.pose.camera_T_marker, expected)
    assert dt < TRANSLATION_BOUND and dr < ROTATION_BOUND, (dt, np.degrees(dr))
    assert found.pose.reprojection_rms < 0.3
    # the object points are OpenCV's board frame: projected with the true pose they hit the image points
    rvec = cv2.Rodrigues(truth[:3, :3])[0]
    proj = cv2.projectPoints(found.points.object_points, rvec, truth[:3, 3], K.matrix(), np.zeros(5))[0]
    assert np.max(np.linalg.norm(proj.reshape(-1, 2) - found.points.image_points, axis=1)) < 0.5


def test_legacy_board_needs_the_flag() -> None:
    legacy = BOARDS["charuco_legacy"]
    image = _render(legacy, _pose(legacy, 20.0, 0.0, 0.5))
    assert isinstance(find_pose(image, legacy, K), BoardFound)
    current = BoardSpec(5, 6, 0.04, 0.02, "DICT_6X6_250")
    missing = find_points(image, current)
    assert isinstance(missing, BoardMissing)
    assert "legacy" in missing.reason and "\n" not in missing.reason
    # and a board of the current pattern is not found as a legacy one
    image = _render(current, _pose(current, 20.0, 0.0, 0.5))
    assert isinstance(find_pose(image, current, K), BoardFound)
    missing = find_points(image, legacy)
    assert isinstance(missing, BoardMissing) and "without ',legacy'" in missing.reason


@pytest.mark.parametrize("name", ["chessboard", "circles"])
def test_board_not_in_sight(name: str) -> None:
    board = BOARDS[name]
    found = find_points(np.full((480, 640), 128, np.uint8), board)
    assert isinstance(found, BoardMissing) and "\n" not in found.reason


def test_board_frames() -> None:
    for board in BOARDS.values():
        T = board.opencv_board_T_marker()
        # marker frame M: z out of the board (OpenCV's -z), origin at OpenCV's (0, height)
        assert np.allclose(T[:3, 2], [0, 0, -1]) and np.allclose(T[:3, 3], [0, board.size[1], 0])
        world_T_marker = np.eye(4)
        world_T_marker[:3, 3] = [0.3, 0.1, 0.0]
        world_T_board = board_pose_in_opencv_frame(board, world_T_marker)
        assert np.allclose(world_T_board @ T, world_T_marker)
        assert frame_text(board).startswith("opencv: origin at") and "z into the board" in frame_text(board)
        assert board_dict(board)["board_frame"] == frame_text(board)
        fields = opencv_frame_fields(board, world_T_marker, "base_T_board_opencv")
        assert np.allclose(fields["base_T_board_opencv"], world_T_board) and fields["board_frame"] == frame_text(board)
        assert parse_board(board_text(board)) == board


def test_parse_board() -> None:
    assert parse_board("charuco:5x7,0.04,0.02,DICT_6X6_250") == BoardSpec(5, 7, 0.04, 0.02, "DICT_6X6_250")
    assert parse_board("5,7,0.04,0.02,dict_6x6_250") == BoardSpec(5, 7, 0.04, 0.02, "DICT_6X6_250")
    assert parse_board("charuco:5x6,0.04,0.02,DICT_6X6_250,legacy").legacy
    assert parse_board("chessboard:9x6,0.025") == ChessboardSpec(9, 6, 0.025)
    assert parse_board("circles:4x11,0.02") == CircleGridSpec(4, 11, 0.02)


@pytest.mark.parametrize(("text", "words"), [
    ("chessboard:9x6", "is not chessboard:COLSxROWS,SQUARE"),
    ("chessboard:9by6,0.025", "is not COLSxROWS"),
    ("chessboard:8x6,0.025", "ambiguous"),
    ("chessboard:9x6,25", "outside (0, 1] m"),
    ("chessboard:9x6,nan", "outside (0, 1] m"),
    ("circles:4x10,0.02", "odd number of rows"),
    ("circles:4x11", "is not circles:"),
    ("dots:4x11,0.02", "unknown board kind"),
    ("charuco:5x7,0.04,0.05,DICT_6X6_250", "smaller than the square"),
    ("charuco:5x7,0.04,0.02,DICT_NOPE", "unknown ArUco dictionary"),
    ("charuco:20x20,0.04,0.02,DICT_4X4_50", "more than the 50"),
    ("5,7,0.04,0.02", "is not one of"),
    ("charuco:1x7,0.04,0.02,DICT_6X6_250", "1 x 7 squares is outside 2 ... 100"),
])
def test_parse_board_refusals(text: str, words: str) -> None:
    with pytest.raises(InputError) as info:
        parse_board(text)
    line = info.value.one_line()
    assert words in line and "\n" not in line


REAL = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "charuco_real"


def test_real_charuco_photos_still_found() -> None:
    if not (REAL / "images").is_dir():
        pytest.skip(f"real ChArUco photos not here ({REAL})")
    board = parse_board("charuco:5x7,0.04,0.02,DICT_6X6_250")
    fs = cv2.FileStorage(str(REAL / "params" / "tutorial_camera_charuco.yml"), cv2.FILE_STORAGE_READ)
    M, dist = fs.getNode("camera_matrix").mat(), fs.getNode("distortion_coefficients").mat().reshape(-1)
    image = cv2.imread(str(REAL / "images" / "choriginal.jpg"))
    cam = Intrinsics(image.shape[1], image.shape[0], M[0, 0], M[1, 1], M[0, 2], M[1, 2])
    found = find_pose(cv2.cvtColor(image, cv2.COLOR_BGR2RGB), board, cam, dist)
    assert isinstance(found, BoardFound), found
    assert found.points.count == 24 and found.pose.reprojection_rms < 1.0
    # the legacy flag on this (odd-rows) board reads the same corners
    legacy = find_points(cv2.cvtColor(image, cv2.COLOR_BGR2RGB),
                         parse_board("charuco:5x7,0.04,0.02,DICT_6X6_250,legacy"))
    assert not isinstance(legacy, BoardMissing) and legacy.count == 24


def test_a_board_file_names_the_legacy_pattern(tmp_path: Path) -> None:
    from recon_cli.perception.charuco import board_file
    path = tmp_path / "board.yaml"
    path.write_text("squares_x: 5\nsquares_y: 6\nsquare_length: 0.04\nmarker_length: 0.02\n"
                    "dictionary: DICT_6X6_250\nlegacy: true\n")
    assert board_file(path) == BOARDS["charuco_legacy"]
    path.write_text("squares_x: 5\nsquares_y: 6\nsquare_length: 0.04\nmarker_length: 0.02\n"
                    "dictionary: DICT_6X6_250\nlegacy: maybe\n")
    with pytest.raises(InputError, match="legacy"):
        board_file(path)
