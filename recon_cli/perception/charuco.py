"""The ChArUco board: definition, printable image, detection and pose (thesis 2.4.2, 4.2).

OpenCV's board frame has its origin at the top-left corner of the board image, x to the
right, y down the image and z into the board. recon's marker frame M (design notes) has
its origin at the lower-left corner, x along the 11-square side, y up the image and z out
of the board: ``opencv_board_T_marker`` converts between the two.
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

    def as_tuple(self) -> tuple[int, int, float, float, str]:
        return (self.squares_x, self.squares_y, self.square_length, self.marker_length, self.dictionary)

    @property
    def size(self) -> tuple[float, float]:
        """Printed area [m] along marker x and y."""
        return self.squares_x * self.square_length, self.squares_y * self.square_length

    def board(self) -> cv2.aruco.CharucoBoard:
        dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))
        return cv2.aruco.CharucoBoard((self.squares_x, self.squares_y), self.square_length,
                                      self.marker_length, dictionary)

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
                     float(d["marker_length"]), str(d["dictionary"]))


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


@dataclass(frozen=True)
class BoardPose:
    """camera_T_marker [4x4], the RMS reprojection error [px] of the corners used, and how
    well those corners fix the pose: the standard deviations of the camera's position [m]
    and orientation [rad] in the board's frame (largest principal axis; see estimate_pose)."""

    camera_T_marker: np.ndarray
    reprojection_rms: float
    n_corners: int
    position_sigma: float = 0.0
    rotation_sigma: float = 0.0


def estimate_pose(detection: CharucoDetection, spec: BoardSpec, K: Intrinsics,
                  dist: np.ndarray | tuple[float, ...] | None = None, min_corners: int = 6) -> BoardPose | None:
    """Board pose from the interpolated corners with solvePnP; None when too few corners or
    when they do not fix a pose."""
    if detection.n_corners < min_corners:
        return None
    board = spec.board()
    # OpenCV's stubs declare a sequence of corner arrays; the function takes one (N, 1, 2) array
    obj, img = board.matchImagePoints(detection.corners.reshape(-1, 1, 2).astype(np.float32),  # type: ignore[call-overload]
                                      detection.ids.reshape(-1, 1).astype(np.int32))
    if obj is None or len(obj) < min_corners:
        return None
    dist = np.zeros(5) if dist is None else np.asarray(dist, dtype=float)
    ok, rvec, tvec = cv2.solvePnP(obj, img, K.matrix(), dist, flags=cv2.SOLVEPNP_IPPE)
    if not ok:
        return None
    rvec, tvec = cv2.solvePnPRefineLM(obj, img, K.matrix(), dist, rvec, tvec)
    if not (np.all(np.isfinite(rvec)) and np.all(np.isfinite(tvec))):
        return None  # a degenerate corner set (e.g. all on one line): no pose
    proj, jacobian = cv2.projectPoints(obj, rvec, tvec, K.matrix(), dist)
    residual = proj.reshape(-1, 2) - img.reshape(-1, 2)
    rms = float(np.sqrt(np.mean(np.sum(residual**2, axis=1))))
    sigma_p, sigma_r = _pose_sigmas(jacobian[:, :6], residual, rvec.reshape(3), tvec.reshape(3))
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(rvec)[0]
    T[:3, 3] = tvec.reshape(3)
    return BoardPose(T @ spec.opencv_board_T_marker(), rms, len(obj), sigma_p, sigma_r)


#: [px] floor of the corner noise in the pose covariance (sub-pixel corners of a sharp image)
CORNER_SIGMA_FLOOR_PX = 0.1


def _pose_sigmas(J: np.ndarray, residual: np.ndarray, rvec: np.ndarray, tvec: np.ndarray) -> tuple[float, float]:
    """Standard deviations [m, rad] of the camera position and orientation in the board
    frame: the Gauss-Newton covariance s^2 (J^T J)^-1 of the pose (rvec, tvec), s^2 the
    corners' residual variance (at least CORNER_SIGMA_FLOOR_PX), carried to the camera
    centre -R^T t by its derivative; the largest principal axes. Few corners, bunched or
    seen at a grazing angle give large values."""
    m = residual.size
    s2 = max(float(np.sum(residual**2)) / max(m - 6, 1), CORNER_SIGMA_FLOOR_PX**2)
    try:
        with np.errstate(all="ignore"):
            C = s2 * np.linalg.inv(J.T @ J)
    except np.linalg.LinAlgError:
        return float("inf"), float("inf")
    if not np.all(np.isfinite(C)):  # a singular fit: the pose is not fixed by these corners
        return float("inf"), float("inf")

    def centre(p: np.ndarray) -> np.ndarray:
        return -cv2.Rodrigues(p[:3])[0].T @ p[3:]

    p0, D = np.r_[rvec, tvec], np.zeros((3, 6))
    for k in range(6):
        h = np.zeros(6)
        h[k] = 1e-6
        D[:, k] = (centre(p0 + h) - centre(p0 - h)) / 2e-6
    try:
        position = float(np.sqrt(max(np.linalg.eigvalsh(D @ C @ D.T).max(), 0.0)))
        rotation = float(np.sqrt(max(np.linalg.eigvalsh(C[:3, :3]).max(), 0.0)))
    except np.linalg.LinAlgError:
        return float("inf"), float("inf")
    return position, rotation
