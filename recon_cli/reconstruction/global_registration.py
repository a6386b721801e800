"""Global registration (thesis 2.4.2): the camera pose of each scan in the marker frame M.

The ChArUco board in the colour image gives marker_T_camera directly (detect the markers,
interpolate the chessboard corners, solvePnP with the scan's intrinsics). When the board is
not found (too few corners: occluded, out of view, no colour image), the pose comes from
the measured joint angles by forward kinematics and the cell's calibrated world_T_marker.
Each pose records its source, so a report can say which scans relied on the robot. When a
session has both, the kinematic poses are corrected by the board poses of its other scans
(:func:`kinematic_correction`: a constant error on the world side, such as the robot base,
and one on the flange side, such as the hand-eye transform; ``correct_kinematics``).

Either pose is then refined with the scan's own depth (``board_plane``): the board is a
plane at z = 0 of M, and the depth image sees it. The pose is shifted along the board
normal until the depth points on the board lie on that plane, so the camera's height above
the board comes from metric depth. A board pose from a camera whose intrinsics are slightly
off (the thesis' Table 4.2 errors: 0.2 % in focal length) is millimetres off along the
viewing ray while its depth is not; from all around the object, the scans' shifts toward
their cameras cancel sideways but add up upward, which no pairwise registration can see.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from enum import StrEnum

import numpy as np

from recon_cli.geometry.transforms import invert, transform_points
from recon_cli.perception.charuco import BoardSpec, detect, estimate_pose
from recon_cli.reconstruction.options import MAX_BOARD_SIGMA, MAX_REPROJECTION_PX
from recon_cli.reconstruction.scan_store import Scan


class PoseSource(StrEnum):
    CHARUCO = "charuco"
    KINEMATICS = "kinematics"  # measured joints + forward kinematics + world_T_marker


@dataclass(frozen=True)
class GlobalPose:
    """Camera pose of one scan in the marker frame and where it came from."""

    index: int
    marker_T_camera: np.ndarray
    source: PoseSource
    corners: int  # ChArUco corners found (0 without colour image)
    reprojection_px: float | None  # RMS reprojection error of the board pose
    reason: str = ""  # why the board was not used
    unrefined: np.ndarray | None = None  # the pose before the board-plane refinement
    plane_points: int = 0  # depth points on the board that refined it

    @property
    def source_pose(self) -> np.ndarray:
        """The board's (or the kinematics') own pose, without the board-plane refinement."""
        return self.marker_T_camera if self.unrefined is None else self.unrefined

    def to_dict(self) -> dict:
        return {"scan": self.index, "source": self.source.value, "corners": self.corners,
                "reprojection_px": self.reprojection_px, "reason": self.reason,
                "marker_T_camera": self.marker_T_camera, "unrefined_marker_T_camera": self.unrefined,
                "board_plane_points": self.plane_points}


def global_pose(scan: Scan, board: BoardSpec, world_T_marker: np.ndarray | None,
                min_corners: int = 6, use_board: bool = True,
                max_reprojection_px: float = MAX_REPROJECTION_PX, board_plane: bool = True,
                max_board_sigma: float = MAX_BOARD_SIGMA) -> GlobalPose | None:
    """The scan's camera pose in M: from the board when found with a reprojection RMS of at
    most ``max_reprojection_px`` whose corners fix the camera position to ``max_board_sigma``
    (standard deviation), else from kinematics (a poorer board pose is still used
    when there is no world_T_marker), then refined by the board plane in the scan's depth
    (``board_plane``, see the module docstring). None when neither is available."""
    pose = _global_pose(scan, board, world_T_marker, min_corners, use_board, max_reprojection_px, max_board_sigma)
    if pose is None or not board_plane:
        return pose
    refined = refine_by_board_plane(scan.points_camera(), pose.marker_T_camera, board.size)
    if refined is None:
        return pose
    T, n = refined
    return replace(pose, marker_T_camera=T, unrefined=pose.marker_T_camera, plane_points=n)


def refine_by_board_plane(points_camera: np.ndarray, marker_T_camera: np.ndarray, board_size: tuple[float, float],
                          band: float = 0.005, inset: float = 0.01, min_points: int = 200
                          ) -> tuple[np.ndarray, int] | None:
    """The camera pose shifted along the board normal so that the depth points on the board
    lie at z = 0 of M on average.

    points_camera (N, 3) [m]: the scan's depth points; the board's points are those within
    ``band`` of z = 0 over the printed area (``inset`` inside its edges); a plane is fitted
    to them (least squares, outliers beyond 3 sigma dropped twice) and its height at their
    centroid is removed. Only the height: a tilt fitted to depth seen through slightly wrong
    intrinsics is sheared, while the board's tilt errors turn with the view and average out
    over the scans. None when fewer than ``min_points`` points are left.
    """
    P = transform_points(marker_T_camera, points_camera[::3])
    sx, sy = board_size
    sel = ((P[:, 0] > inset) & (P[:, 0] < sx - inset) & (P[:, 1] > inset) & (P[:, 1] < sy - inset)
           & (np.abs(P[:, 2]) < band))
    Q = P[sel]
    for _ in range(3):
        if len(Q) < min_points:
            return None
        A = np.column_stack([Q[:, 0], Q[:, 1], np.ones(len(Q))])
        coef, *_ = np.linalg.lstsq(A, Q[:, 2], rcond=None)
        r = Q[:, 2] - A @ coef
        keep = np.abs(r) <= max(3.0 * float(np.std(r)), 1e-4)
        if keep.all():
            break
        Q = Q[keep]
    centroid = Q[:, :2].mean(axis=0)
    C = np.eye(4)
    C[2, 3] = -float(coef[0] * centroid[0] + coef[1] * centroid[1] + coef[2])
    return C @ marker_T_camera, len(Q)


def _global_pose(scan: Scan, board: BoardSpec, world_T_marker: np.ndarray | None, min_corners: int,
                 use_board: bool, max_reprojection_px: float, max_board_sigma: float) -> GlobalPose | None:
    corners, reason = 0, "board not used"
    if use_board:
        if scan.color is None:
            reason = "scan has no colour image"
        else:
            detection = detect(scan.color, board)
            corners = detection.n_corners
            board_pose = estimate_pose(detection, board, scan.intrinsics, scan.distortion, min_corners=min_corners)
            if board_pose is not None:
                charuco = GlobalPose(scan.index, invert(board_pose.camera_T_marker), PoseSource.CHARUCO,
                                     corners, board_pose.reprojection_rms)
                sharp = board_pose.reprojection_rms <= max_reprojection_px
                fixed = board_pose.position_sigma <= max_board_sigma
                if (sharp and fixed) or world_T_marker is None:
                    return charuco
                reason = (f"board pose rejected (reprojection {board_pose.reprojection_rms:.2f} px > "
                          f"{max_reprojection_px:g} px)" if not sharp else
                          f"board pose rejected ({corners} corners fix the camera to "
                          f"{board_pose.position_sigma * 1e3:.1f} mm > {max_board_sigma * 1e3:g} mm)")
            elif corners >= min_corners:
                reason = f"board corners do not fix a pose ({corners} corners, degenerate fit)"
            else:
                reason = f"board not found ({corners} corners, {min_corners} needed)"
    if world_T_marker is None:
        return None
    return GlobalPose(scan.index, invert(world_T_marker) @ scan.world_T_camera_fk, PoseSource.KINEMATICS,
                      corners, None, reason)


# --------------------------------------------------------------------- kinematic fallback
@dataclass(frozen=True)
class KinematicCorrection:
    """Forward-kinematics poses corrected by the session's board poses:
    marker_T_camera ~ marker_T_model @ fk @ camera_T_model, fitted on the scans that have
    both. marker_T_model takes up what is wrong on the world side (robot base, board), and
    camera_T_model what is wrong on the flange side (hand-eye); joint offsets and sag are
    configuration-dependent and stay. ``before`` and ``after``: mean translation [m] between
    the board poses and the (corrected) kinematic ones on those scans."""

    marker_T_model: np.ndarray  # (4, 4) left factor
    camera_T_model: np.ndarray  # (4, 4) right factor
    scans: int
    before: float
    after: float

    def apply(self, marker_T_camera_fk: np.ndarray) -> np.ndarray:
        return self.marker_T_model @ marker_T_camera_fk @ self.camera_T_model

    def to_dict(self) -> dict:
        return {"marker_T_model": self.marker_T_model, "camera_T_model": self.camera_T_model, "scans": self.scans,
                "board_vs_kinematics_mm": self.before * 1e3, "board_vs_corrected_mm": self.after * 1e3}


def _mean_pose(poses: list[np.ndarray]) -> np.ndarray:
    """Chordal mean of rotations (SVD), mean of translations."""
    U, _, Vt = np.linalg.svd(sum(T[:3, :3] for T in poses))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    out = np.eye(4)
    out[:3, :3] = U @ D @ Vt
    out[:3, 3] = np.mean([T[:3, 3] for T in poses], axis=0)
    return out


def kinematic_correction(board: list[np.ndarray], kinematics: list[np.ndarray], min_scans: int = 4,
                         iterations: int = 20) -> KinematicCorrection | None:
    """Fit the correction of forward-kinematics poses (marker frame) to board poses of the
    same scans by alternating means (left factor, then right factor). None with fewer than
    ``min_scans`` pairs, or when it does not at least halve the mean disagreement (a robot
    that agrees with the board up to the board's own noise needs no correction)."""
    if len(board) < min_scans:
        return None
    L, R = np.eye(4), np.eye(4)
    for _ in range(iterations):
        L = _mean_pose([B @ invert(F @ R) for B, F in zip(board, kinematics, strict=True)])
        R = _mean_pose([invert(L @ F) @ B for B, F in zip(board, kinematics, strict=True)])
    before = float(np.mean([np.linalg.norm(B[:3, 3] - F[:3, 3]) for B, F in zip(board, kinematics, strict=True)]))
    after = float(np.mean([np.linalg.norm(B[:3, 3] - (L @ F @ R)[:3, 3])
                           for B, F in zip(board, kinematics, strict=True)]))
    if after > 0.5 * before:
        return None
    return KinematicCorrection(L, R, len(board), before, after)


def corrected_pose(scan: Scan, pose: GlobalPose, marker_T_camera: np.ndarray, board: BoardSpec,
                   board_plane: bool = True) -> GlobalPose:
    """A kinematic pose replaced by its corrected one (then refined by the board plane)."""
    refined = refine_by_board_plane(scan.points_camera(), marker_T_camera, board.size) if board_plane else None
    reason = f"{pose.reason}; kinematics corrected by the board scans"
    if refined is None:
        return replace(pose, marker_T_camera=marker_T_camera, unrefined=None, plane_points=0, reason=reason)
    return replace(pose, marker_T_camera=refined[0], unrefined=marker_T_camera, plane_points=refined[1],
                   reason=reason)
