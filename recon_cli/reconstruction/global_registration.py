"""Global registration (thesis 2.4.2): the camera pose of each scan in the marker frame M.

The ChArUco board in the colour image gives marker_T_camera directly (detect the markers,
interpolate the chessboard corners, solvePnP with the scan's intrinsics). When the board is
not found (too few corners: occluded, out of view, no colour image), the pose comes from
the measured joint angles by forward kinematics and the cell's calibrated world_T_marker.
Each pose records its source, so a report can say which scans relied on the robot.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

import numpy as np

from recon_cli.geometry.transforms import invert
from recon_cli.perception.charuco import BoardSpec, detect, estimate_pose
from recon_cli.reconstruction.options import MAX_REPROJECTION_PX
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

    def to_dict(self) -> dict:
        return {"scan": self.index, "source": self.source.value, "corners": self.corners,
                "reprojection_px": self.reprojection_px, "reason": self.reason,
                "marker_T_camera": self.marker_T_camera}


def global_pose(scan: Scan, board: BoardSpec, world_T_marker: np.ndarray | None,
                min_corners: int = 6, use_board: bool = True,
                max_reprojection_px: float = MAX_REPROJECTION_PX) -> GlobalPose | None:
    """The scan's camera pose in M: from the board when found with a reprojection RMS of at
    most ``max_reprojection_px``, else from kinematics (a poorer board pose is still used
    when there is no world_T_marker). None when neither is available."""
    corners, reason = 0, "board not used"
    if use_board:
        if scan.color is None:
            reason = "scan has no colour image"
        else:
            detection = detect(scan.color, board)
            corners = detection.n_corners
            board_pose = estimate_pose(detection, board, scan.intrinsics, min_corners=min_corners)
            if board_pose is not None:
                charuco = GlobalPose(scan.index, invert(board_pose.camera_T_marker), PoseSource.CHARUCO,
                                     corners, board_pose.reprojection_rms)
                if board_pose.reprojection_rms <= max_reprojection_px or world_T_marker is None:
                    return charuco
                reason = (f"board pose rejected (reprojection {board_pose.reprojection_rms:.2f} px > "
                          f"{max_reprojection_px:g} px)")
            else:
                reason = f"board not found ({corners} corners, {min_corners} needed)"
    if world_T_marker is None:
        return None
    return GlobalPose(scan.index, invert(world_T_marker) @ scan.world_T_camera_fk, PoseSource.KINEMATICS,
                      corners, None, reason)
