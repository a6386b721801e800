"""Calibration boards: ChArUco (recon_cli.perception.charuco, also OpenCV's legacy pattern),
chessboard and asymmetric circle grid; their points in an image, the points' positions on the
board and the board's pose.

Every board has two frames:

- OpenCV's board frame, in which OpenCV states the board's points: origin at the first point
  (ChArUco: the board's top-left corner as ``generateImage`` draws it; chessboard: the first
  inner corner; circle grid: the first circle's centre), x along a row, y along a column
  (down the printed board), z into the board.
- recon's marker frame M (design notes): the same board turned by pi about OpenCV's x axis,
  its origin at OpenCV's (0, height): the lower-left corner of the printed board (ChArUco) or
  of the point grid (chessboard, circles), x as OpenCV's, y up the board, z out of it.

``opencv_board_T_marker`` of a board converts between the two; every pose recon computes
(``BoardPose.camera_T_marker``) is of M, and ``board_pose_in_opencv_frame`` states one in
OpenCV's frame for the outputs.

The detected points are put in one order whatever the board's orientation in the image:
chessboard corners so that the board is seen from its front and the corner square next to
the origin is black, circles so that the board is seen from its front. That needs a board
that does not look the same turned by 180 degrees: a chessboard of one even and one odd
inner-corner count, a circle grid of an odd number of rows (``parse_board`` refuses others).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING

import numpy as np

from recon_cli.errors import InputError, UnknownNameError
from recon_cli.lazy import lazy_module
from recon_cli.perception.board_pose import BoardPose, solve_pose
from recon_cli.perception.camera_model import Intrinsics
from recon_cli.perception.charuco import BoardSpec, detect

if TYPE_CHECKING:
    import cv2
else:
    cv2 = lazy_module("cv2")

#: points per side of a board (squares of a ChArUco board, inner corners of a chessboard,
#: circles of a circle grid's row or column) and the largest square or spacing [m]
BOARD_COUNTS = (2, 100)
BOARD_LENGTH = 1.0
#: the kinds of the ``--board-spec`` syntax (kind:...)
BOARD_KINDS = ("charuco", "chessboard", "circles")


def _marker_frame(height: float) -> np.ndarray:
    """opencv_board_T_marker of a board whose points span ``height`` [m] along OpenCV's y."""
    T = np.diag([1.0, -1.0, -1.0, 1.0])
    T[1, 3] = height
    return T


@dataclass(frozen=True)
class ChessboardSpec:
    """A chessboard of cols x rows inner corners (OpenCV's patternSize), squares of
    square_length [m]; the square in the corner next to the origin is black."""

    cols: int
    rows: int
    square_length: float  # [m]

    @property
    def size(self) -> tuple[float, float]:
        """Extent of the corner grid [m] along OpenCV's x and y."""
        return (self.cols - 1) * self.square_length, (self.rows - 1) * self.square_length

    def object_points(self) -> np.ndarray:
        """(cols * rows, 3) [m] in OpenCV's board frame, row by row: (j * s, i * s, 0)."""
        i, j = np.divmod(np.arange(self.cols * self.rows), self.cols)
        return np.c_[j * self.square_length, i * self.square_length, np.zeros(len(i))]

    def opencv_board_T_marker(self) -> np.ndarray:
        return _marker_frame(self.size[1])


@dataclass(frozen=True)
class CircleGridSpec:
    """An asymmetric circle grid of cols x rows circles (OpenCV's patternSize: circles per row,
    rows), dark circles on a light board; ``spacing`` [m] is OpenCV's s: circle i, j of the
    grid sits at ((2j + i % 2) s, i s, 0), so circles of one row lie 2 s apart and rows s."""

    cols: int
    rows: int
    spacing: float  # [m]

    @property
    def size(self) -> tuple[float, float]:
        """Extent of the circle centres [m] along OpenCV's x and y."""
        return (2 * (self.cols - 1) + 1) * self.spacing, (self.rows - 1) * self.spacing

    def object_points(self) -> np.ndarray:
        """(cols * rows, 3) [m] in OpenCV's board frame, row by row."""
        i, j = np.divmod(np.arange(self.cols * self.rows), self.cols)
        return np.c_[(2 * j + i % 2) * self.spacing, i * self.spacing, np.zeros(len(i))]

    def opencv_board_T_marker(self) -> np.ndarray:
        return _marker_frame(self.size[1])


#: every calibration board
Board = BoardSpec | ChessboardSpec | CircleGridSpec


def board_kind(board: Board) -> str:
    """charuco, chessboard or circles (the prefix of the ``--board-spec`` syntax)."""
    if isinstance(board, ChessboardSpec):
        return "chessboard"
    if isinstance(board, CircleGridSpec):
        return "circles"
    return "charuco"


def board_text(board: Board) -> str:
    """The board in the ``--board-spec`` syntax, e.g. ``chessboard:9x6,0.025``."""
    if isinstance(board, ChessboardSpec):
        return f"chessboard:{board.cols}x{board.rows},{board.square_length:g}"
    if isinstance(board, CircleGridSpec):
        return f"circles:{board.cols}x{board.rows},{board.spacing:g}"
    return (f"charuco:{board.squares_x}x{board.squares_y},{board.square_length:g},{board.marker_length:g},"
            f"{board.dictionary}" + (",legacy" if board.legacy else ""))


def frame_text(board: Board) -> str:
    """OpenCV's board frame of this board, in words (the outputs' ``board_frame``)."""
    if isinstance(board, ChessboardSpec):
        where = (f"the first inner corner findChessboardCorners reports (beside the black corner square), x along "
                 f"a row of {board.cols} corners, y along the {board.rows} rows")
    elif isinstance(board, CircleGridSpec):
        where = (f"the first circle findCirclesGrid reports, x along a row of {board.cols} circles "
                 f"((2j + i % 2) * {board.spacing:g} m), y along the {board.rows} rows (i * {board.spacing:g} m)")
    else:
        where = (f"the board's top-left corner as CharucoBoard.generateImage draws it, x along the "
                 f"{board.squares_x} squares, y along the {board.squares_y} squares")
    return f"opencv: origin at {where}, z into the board"


def board_pose_in_opencv_frame(board: Board, world_T_marker: np.ndarray) -> np.ndarray:
    """world_T_board in OpenCV's board frame, from recon's world_T_marker (any parent frame:
    base_T_marker gives base_T_board)."""
    return np.asarray(world_T_marker, dtype=float) @ np.linalg.inv(board.opencv_board_T_marker())


def opencv_frame_fields(board: Board, parent_T_marker: np.ndarray, name: str = "world_T_board_opencv") -> dict:
    """The fields a report adds beside a board pose in recon's marker frame: the same pose in
    OpenCV's board frame under ``name`` and ``board_frame``, the frame in words."""
    return {name: board_pose_in_opencv_frame(board, parent_T_marker), "board_frame": frame_text(board)}


def board_dict(board: Board) -> dict:
    """The board for a JSON report: its kind, ``--board-spec`` text, dimensions and OpenCV frame."""
    return {"kind": board_kind(board), "text": board_text(board), **asdict(board), "board_frame": frame_text(board),
            "opencv_board_T_marker": board.opencv_board_T_marker()}


# --------------------------------------------------------------------- detection
@dataclass(frozen=True)
class BoardPoints:
    """A board's points found in one image: image_points (N, 2) [px], object_points (N, 3) [m]
    in OpenCV's board frame, ids (N,) the points' indices on the board (ChArUco corner ids,
    else row by row), markers: ArUco markers found (0 for boards without)."""

    image_points: np.ndarray
    object_points: np.ndarray
    ids: np.ndarray
    markers: int = 0

    @property
    def count(self) -> int:
        return len(self.ids)


@dataclass(frozen=True)
class BoardFound:
    points: BoardPoints
    pose: BoardPose


@dataclass(frozen=True)
class BoardMissing:
    """Why an image gives no board (one line)."""

    reason: str


def _grey(image: np.ndarray) -> np.ndarray:
    grey = np.asarray(cv2.cvtColor(image, cv2.COLOR_RGB2GRAY) if image.ndim == 3 else image)
    if grey.dtype != np.uint8:  # 16-bit or float images: stretched to 8 bits
        lo, hi = float(grey.min()), float(grey.max())
        grey = np.round((grey - lo) * (255.0 / max(hi - lo, 1e-12))).astype(np.uint8)
    return np.ascontiguousarray(grey)


def find_points(image: np.ndarray, board: Board, min_points: int = 8) -> BoardPoints | BoardMissing:
    """The board's points in one RGB (or grey) image and their places on the board, or why not."""
    grey = _grey(image)
    if isinstance(board, ChessboardSpec):
        return _chessboard(grey, board)
    if isinstance(board, CircleGridSpec):
        return _circles(grey, board)
    det = detect(grey, board)
    obj, img = board.match(det)
    if len(obj) < min_points:
        if det.n_corners == 0 and det.marker_count >= 4:
            other = "without ',legacy'" if board.legacy else "with ',legacy'"
            return BoardMissing(f"board not found ({det.marker_count} markers but no chessboard corners: squares_x "
                                f"and squares_y swapped, or a board of the other ChArUco pattern (try --board-spec "
                                f"{other}: OpenCV before 4.6 drew boards of an even squares_y differently)?)")
        return BoardMissing(f"board not found ({len(obj)} corners, {min_points} needed)")
    return BoardPoints(img, obj, det.ids.copy()[: len(obj)], det.marker_count)


def find_pose(image: np.ndarray, board: Board, K: Intrinsics, dist: np.ndarray | tuple[float, ...] | None = None,
              min_points: int = 8) -> BoardFound | BoardMissing:
    """The board's points in one image and its pose by solvePnP (camera_T_marker), or why not."""
    points = find_points(image, board, min_points)
    if isinstance(points, BoardMissing):
        return points
    pose = solve_pose(points.object_points, points.image_points, K, dist, board.opencv_board_T_marker())
    if pose is None:
        return BoardMissing(f"board found ({points.count} points) but its points fix no pose")
    return BoardFound(points, pose)


def _front(grid: np.ndarray) -> bool:
    """Whether the board's x and y axes (grid (rows, cols, 2) [px]) appear as the image's x
    and y do: the board is seen from its front with OpenCV's z pointing away from the camera."""
    dx = np.mean(grid[:, -1] - grid[:, 0], axis=0)
    dy = np.mean(grid[-1, :] - grid[0, :], axis=0)
    return bool(dx[0] * dy[1] - dx[1] * dy[0] > 0)


def _chessboard(grey: np.ndarray, board: ChessboardSpec) -> BoardPoints | BoardMissing:
    size = (board.cols, board.rows)
    ok, corners = cv2.findChessboardCornersSB(grey, size, flags=cv2.CALIB_CB_NORMALIZE_IMAGE)
    if not ok:
        ok, corners = cv2.findChessboardCorners(grey, size, flags=cv2.CALIB_CB_ADAPTIVE_THRESH
                                                | cv2.CALIB_CB_NORMALIZE_IMAGE)
        if not ok:
            return BoardMissing(f"no chessboard of {board.cols} x {board.rows} inner corners found (the whole "
                                "board in sight with a light border around it? inner corners, not squares, counted?)")
    # both finders' corners refined on the saddle points (a window within 0.4 squares)
    spacing = np.min(np.linalg.norm(np.diff(corners.reshape(board.rows, board.cols, 2), axis=1), axis=2))
    half = int(np.clip(spacing * 0.4, 2, 11))
    corners = cv2.cornerSubPix(grey, np.ascontiguousarray(corners, dtype=np.float32), (half, half), (-1, -1),
                               (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 40, 0.001))
    grid = corners.reshape(board.rows, board.cols, 2).astype(np.float64)
    if not _front(grid):
        grid = grid[::-1]
    # the square beside corner 0 is black: the cells of even (row + column) are the dark ones
    centres = (grid[:-1, :-1] + grid[1:, :-1] + grid[:-1, 1:] + grid[1:, 1:]) / 4
    x = np.clip(np.round(centres[..., 0]).astype(int), 0, grey.shape[1] - 1)
    y = np.clip(np.round(centres[..., 1]).astype(int), 0, grey.shape[0] - 1)
    values = cv2.GaussianBlur(grey, (5, 5), 0)[y, x].astype(float)
    even = (np.add.outer(np.arange(board.rows - 1), np.arange(board.cols - 1)) % 2) == 0
    if values[even].mean() > values[~even].mean():
        grid = grid[::-1, ::-1]
    n = board.cols * board.rows
    return BoardPoints(grid.reshape(-1, 2), board.object_points(), np.arange(n))


def _circles(grey: np.ndarray, board: CircleGridSpec) -> BoardPoints | BoardMissing:
    size = (board.cols, board.rows)
    params = cv2.SimpleBlobDetector.Params()
    params.minArea = 8
    params.maxArea = float(grey.shape[0] * grey.shape[1]) / (board.cols * board.rows)  # large circles close up
    detector = cv2.SimpleBlobDetector.create(params)
    for img in (grey, 255 - grey):  # dark circles on a light board, else light on dark
        ok, centres = cv2.findCirclesGrid(img, size, flags=cv2.CALIB_CB_ASYMMETRIC_GRID, blobDetector=detector)
        if ok:
            break
    else:
        return BoardMissing(f"no asymmetric circle grid of {board.cols} x {board.rows} circles found (the whole "
                            "grid in sight? circles per row first, e.g. 4x11?)")
    grid = centres.reshape(board.rows, board.cols, 2).astype(np.float64)
    if not _front(grid):
        grid = grid[::-1]  # the grid of an odd number of rows is symmetric about its middle row
    return BoardPoints(grid.reshape(-1, 2), board.object_points(), np.arange(board.cols * board.rows))


# ---------------------------------------------------------------- --board-spec
SYNTAX = ("charuco:COLSxROWS,SQUARE,MARKER,DICTIONARY[,legacy] (or COLS,ROWS,SQUARE,MARKER,DICTIONARY), "
          "chessboard:COLSxROWS,SQUARE (inner corners), circles:COLSxROWS,SPACING (lengths in metres)")
EXAMPLES = "e.g. charuco:5x7,0.04,0.02,DICT_6X6_250, chessboard:9x6,0.025 or circles:4x11,0.02"


def parse_board(text: str, what: str = "--board-spec") -> Board:
    """A board of the ``--board-spec`` syntax (SYNTAX); anything else is a one-line InputError that
    names ``what`` (the option or key) and the text."""
    raw = text.strip()
    kind, sep, rest = raw.partition(":")
    kind = kind.strip().lower()
    if not sep:
        kind, rest = "charuco-plain", raw
    elif kind not in BOARD_KINDS:
        raise UnknownNameError("board kind", kind, BOARD_KINDS)
    parts = [p.strip() for p in rest.split(",")]

    def bad(why: str, hint: str = EXAMPLES) -> InputError:
        return InputError(f"{what} '{raw}': {why}", hint=hint)

    def counts(field: str, unit: str) -> tuple[int, int]:
        a, x, b = field.lower().partition("x")
        try:
            if not x:
                raise ValueError
            c, r = int(a), int(b)
        except ValueError:
            raise bad(f"'{field}' is not COLSxROWS") from None
        lo, hi = BOARD_COUNTS
        if not (lo <= c <= hi and lo <= r <= hi):
            raise bad(f"{c} x {r} {unit} is outside {lo} ... {hi} per side")
        return c, r

    def length(field: str, name: str) -> float:
        try:
            v = float(field)
        except ValueError:
            raise bad(f"{name} '{field}' is not a number") from None
        if not 0 < v <= BOARD_LENGTH:  # NaN too
            raise bad(f"{name} {field} is outside (0, {BOARD_LENGTH:g}] m", hint="give lengths in metres")
        return v

    if kind == "chessboard":
        if len(parts) != 2:
            raise bad("is not chessboard:COLSxROWS,SQUARE", hint="e.g. chessboard:9x6,0.025 (inner corners, metres)")
        c, r = counts(parts[0], "inner corners")
        if (c + r) % 2 == 0:
            raise bad(f"{c} x {r} inner corners look the same turned by 180 degrees, so the board's origin is "
                      "ambiguous", hint="use a board of one even and one odd inner-corner count, e.g. 9x6")
        return ChessboardSpec(c, r, length(parts[1], "the square"))
    if kind == "circles":
        if len(parts) != 2:
            raise bad("is not circles:COLSxROWS,SPACING", hint="e.g. circles:4x11,0.02 (circles per row x rows, "
                                                               "metres)")
        c, r = counts(parts[0], "circles")
        if r % 2 == 0 or r < 3:
            raise bad(f"an asymmetric grid of {r} rows looks the same turned by 180 degrees, so its origin is "
                      "ambiguous", hint="use an odd number of rows, e.g. circles:4x11,0.02")
        return CircleGridSpec(c, r, length(parts[1], "the spacing"))
    if kind == "charuco":
        legacy = len(parts) == 5 and parts[-1].lower() == "legacy"
        if legacy:
            parts = parts[:-1]
        if len(parts) != 4:
            raise bad("is not charuco:COLSxROWS,SQUARE,MARKER,DICTIONARY[,legacy]",
                      hint="e.g. charuco:5x7,0.04,0.02,DICT_6X6_250 (squares, metres)")
        sx, sy = counts(parts[0], "squares")
        rest_parts = parts[1:]
    else:
        if len(parts) != 5:
            raise bad("is not one of " + SYNTAX, hint=EXAMPLES)
        legacy = False
        try:
            sx, sy = int(parts[0]), int(parts[1])
        except ValueError:
            raise bad(f"'{parts[0]},{parts[1]}' are not squares_x,squares_y") from None
        sx, sy = counts(f"{sx}x{sy}", "squares")
        rest_parts = parts[2:]
    square, marker = length(rest_parts[0], "the square"), length(rest_parts[1], "the marker")
    name = rest_parts[2].upper()
    dictionaries = sorted(n for n in dir(cv2.aruco) if n.startswith("DICT_") and not n.endswith("_SIZE"))
    if name not in dictionaries:
        raise UnknownNameError("ArUco dictionary", name, dictionaries)
    if marker >= square:
        raise bad(f"the marker ({marker:g} m) must be smaller than the square ({square:g} m)")
    markers = sx * sy // 2
    available = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, name)).bytesList.shape[0]
    if markers > available:
        raise bad(f"{sx} x {sy} squares hold {markers} markers, more than the {available} of {name}",
                  hint="use fewer squares or a larger dictionary, e.g. DICT_6X6_1000")
    return BoardSpec(sx, sy, square, marker, name, legacy)
