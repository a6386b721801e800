"""The ChArUco board: definition, printable image, detection and pose (thesis 2.4.2, 4.2).

OpenCV's board frame has its origin at the top-left corner of the board image, x to the
right, y down the image and z into the board. recon's marker frame M (design notes) has
its origin at the lower-left corner, x along the 11-square side, y up the image and z out
of the board: ``opencv_board_T_marker`` converts between the two.

OpenCV 4.6 changed the ChArUco pattern of boards with an even number of rows: the legacy
pattern (before 4.6) starts with a marker where the new one starts with a black square.
``legacy=True`` reads boards printed before 4.6 (``CharucoBoard.setLegacyPattern``).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from recon_cli.errors import InputError
from recon_cli.inputs.files import version_stamp
from recon_cli.inputs.schema import check
from recon_cli.inputs.yamlfile import line_of, read_yaml
from recon_cli.lazy import lazy_module
from recon_cli.paths import ROBOT_DIR
from recon_cli.perception.board_pose import (  # noqa: F401 (CORNER_SIGMA_FLOOR_PX, _pose_sigmas: used from here)
    CORNER_SIGMA_FLOOR_PX,
    BoardPose,
    _pose_sigmas,
    solve_pose,
)
from recon_cli.perception.camera_model import Intrinsics
from recon_cli.robot.cell_file import CellFile

if TYPE_CHECKING:
    import cv2
else:
    cv2 = lazy_module("cv2")


@dataclass(frozen=True)
class BoardSpec:
    squares_x: int
    squares_y: int
    square_length: float  # [m]
    marker_length: float  # [m]
    dictionary: str
    legacy: bool = False  # OpenCV's pattern before 4.6 (differs for an even squares_y)

    def as_tuple(self) -> tuple[int, int, float, float, str]:
        return (self.squares_x, self.squares_y, self.square_length, self.marker_length, self.dictionary)

    @property
    def size(self) -> tuple[float, float]:
        """Printed area [m] along marker x and y."""
        return self.squares_x * self.square_length, self.squares_y * self.square_length

    def board(self) -> cv2.aruco.CharucoBoard:
        dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))
        board = cv2.aruco.CharucoBoard((self.squares_x, self.squares_y), self.square_length,
                                       self.marker_length, dictionary)
        board.setLegacyPattern(self.legacy)
        return board

    def match(self, detection: CharucoDetection) -> tuple[np.ndarray, np.ndarray]:
        """The detected corners' positions in OpenCV's board frame (N, 3) [m] and in the image
        (N, 2) [px] (``CharucoBoard.matchImagePoints``)."""
        if detection.n_corners == 0:
            return np.zeros((0, 3)), np.zeros((0, 2))
        # OpenCV's stubs declare a sequence of corner arrays; the function takes one (N, 1, 2) array
        obj, img = self.board().matchImagePoints(detection.corners.reshape(-1, 1, 2).astype(np.float32),  # type: ignore[call-overload]
                                                 detection.ids.reshape(-1, 1).astype(np.int32))
        if obj is None:
            return np.zeros((0, 3)), np.zeros((0, 2))
        return np.asarray(obj, np.float64).reshape(-1, 3), np.asarray(img, np.float64).reshape(-1, 2)

    def image(self, pixels_per_metre: float = 4000.0) -> np.ndarray:
        """Grey image of the printed area, row 0 at the board's top edge (marker y max)."""
        w = round(self.size[0] * pixels_per_metre)
        h = round(self.size[1] * pixels_per_metre)
        return self.board().generateImage((w, h), marginSize=0, borderBits=1)

    def opencv_board_T_marker(self) -> np.ndarray:
        """Pose of the marker frame M in OpenCV's board frame (rotation by pi about x)."""
        T = np.diag([1.0, -1.0, -1.0, 1.0])
        T[1, 3] = self.size[1]
        return T


def thesis_board() -> BoardSpec:
    """The thesis' board (robot/board.yaml), the board of the gantry and ceiling cells."""
    return board_file(ROBOT_DIR / "board.yaml")


def recorded_board(values: tuple[int, int, float, float, str] | None) -> BoardSpec:
    """The board a scan store's session.json names (stores without one: the thesis' board)."""
    return thesis_board() if values is None else BoardSpec(*values)


def cell_board(cell: CellFile) -> BoardSpec:
    """The board of a cell (its cell file's ``board.spec``)."""
    return board_file(cell.board_file)


def board_file(path: Path) -> BoardSpec:
    """A board file, read and checked (one line naming ``file:line`` when it is wrong)."""
    return _board_file(path.resolve(), version_stamp(path))


@functools.lru_cache(maxsize=8)
def _board_file(path: Path, stamp: tuple[int, int]) -> BoardSpec:
    d = read_yaml(path, "board file")
    check(d, "board", path)
    if float(d["marker_length"]) >= float(d["square_length"]):
        raise InputError(f"{path}:{line_of(d, 'marker_length') or 1}: marker_length {float(d['marker_length']):g} m "
                         f"is not smaller than square_length {float(d['square_length']):g} m",
                         hint="a ChArUco marker sits inside its square")
    return BoardSpec(int(d["squares_x"]), int(d["squares_y"]), float(d["square_length"]),
                     float(d["marker_length"]), str(d["dictionary"]), bool(d.get("legacy", False)))


@dataclass(frozen=True)
class CharucoDetection:
    """Detected ChArUco corners. corners: (N, 2) pixels; ids: (N,) chessboard corner ids;
    marker_corners: (M, 4, 2) pixels of the detected ArUco markers, marker_ids: (M,)."""

    corners: np.ndarray
    ids: np.ndarray
    marker_corners: np.ndarray
    marker_ids: np.ndarray

    @property
    def marker_count(self) -> int:
        return len(self.marker_ids)

    @property
    def n_corners(self) -> int:
        return len(self.ids)


def detect(image: np.ndarray, spec: BoardSpec) -> CharucoDetection:
    """Find the board's markers and interpolate its chessboard corners (colour or grey)."""
    grey = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY) if image.ndim == 3 else image
    detector = cv2.aruco.CharucoDetector(spec.board())
    corners, ids, marker_corners, marker_ids = detector.detectBoard(grey)
    if marker_ids is None or len(marker_ids) == 0:
        markers, mids = np.zeros((0, 4, 2)), np.zeros(0, dtype=int)
    else:
        markers = np.stack([np.asarray(c, dtype=np.float64).reshape(4, 2) for c in marker_corners])
        mids = np.asarray(marker_ids).reshape(-1).astype(int)
    if ids is None or len(ids) == 0:
        return CharucoDetection(np.zeros((0, 2)), np.zeros(0, dtype=int), markers, mids)
    return CharucoDetection(corners.reshape(-1, 2).astype(np.float64), ids.reshape(-1).astype(int),
                            markers, mids)


def estimate_pose(detection: CharucoDetection, spec: BoardSpec, K: Intrinsics,
                  dist: np.ndarray | tuple[float, ...] | None = None, min_corners: int = 6) -> BoardPose | None:
    """Board pose from the interpolated corners with solvePnP; None when too few corners or
    when they do not fix a pose."""
    if detection.n_corners < min_corners:
        return None
    obj, img = spec.match(detection)
    if len(obj) < min_corners:
        return None
    return solve_pose(obj, img, K, dist, spec.opencv_board_T_marker())


