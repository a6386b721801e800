"""A board's pose from its points: solvePnP on the points found in an image and their
positions in OpenCV's board frame, with the pose's reprojection error and precision.

Every board kind (recon_cli.perception.boards) ends here: OpenCV's frame of the board is
carried into recon's marker frame M by the board's ``opencv_board_T_marker``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from recon_cli.lazy import lazy_module
from recon_cli.perception.camera_model import Intrinsics

if TYPE_CHECKING:
    import cv2
else:
    cv2 = lazy_module("cv2")


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



def solve_pose(obj: np.ndarray, img: np.ndarray, K: Intrinsics, dist: np.ndarray | tuple[float, ...] | None,
               opencv_board_T_marker: np.ndarray) -> BoardPose | None:
    """camera_T_marker from object points (N, 3) [m] in OpenCV's board frame and their image
    points (N, 2) [px]: IPPE, then Levenberg-Marquardt; None when the points fix no pose."""
    obj = np.asarray(obj, dtype=np.float64).reshape(-1, 1, 3)
    img = np.asarray(img, dtype=np.float64).reshape(-1, 1, 2)
    dist = np.zeros(5) if dist is None else np.asarray(dist, dtype=float)
    ok, rvec, tvec = cv2.solvePnP(obj, img, K.matrix(), dist, flags=cv2.SOLVEPNP_IPPE)
    if not ok:
        return None
    rvec, tvec = cv2.solvePnPRefineLM(obj, img, K.matrix(), dist, rvec, tvec)
    if not (np.all(np.isfinite(rvec)) and np.all(np.isfinite(tvec))):
        return None  # a degenerate point set (e.g. all on one line): no pose
    proj, jacobian = cv2.projectPoints(obj, rvec, tvec, K.matrix(), dist)
    residual = proj.reshape(-1, 2) - img.reshape(-1, 2)
    rms = float(np.sqrt(np.mean(np.sum(residual**2, axis=1))))
    sigma_p, sigma_r = _pose_sigmas(jacobian[:, :6], residual, rvec.reshape(3), tvec.reshape(3))
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(rvec)[0]
    T[:3, 3] = tvec.reshape(3)
    return BoardPose(T @ opencv_board_T_marker, rms, len(obj), sigma_p, sigma_r)


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
