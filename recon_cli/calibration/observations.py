"""Board observations from a scan store: per scan, the flange pose from forward kinematics of
its measured joints and the board pose its colour image shows.

The kinematics are the model's (the cell description recon plans with), so a calibration
absorbs whatever differs between model and robot at the camera, as the thesis' did. The
board pose uses the scan's own intrinsics and distortion, or a calibrated camera (the
``intrinsics.yaml`` of ``recon calibrate intrinsics``) scaled to the scan's image size.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from recon_cli.calibration.camera_file import CameraCalibration
from recon_cli.calibration.handeye import BoardObservation
from recon_cli.calibration.intrinsics import SkippedImage
from recon_cli.errors import FileError, InputError, MetadataError
from recon_cli.perception.boards import Board, BoardMissing, find_pose
from recon_cli.reconstruction.scan_store import ScanStore, read_scan

MIN_CORNERS = 8


@dataclass(frozen=True)
class ScanObservations:
    """What a scan store gave: the usable views, the scans without a usable board, and the
    simulation's ground truth per usable view (None on a real cell)."""

    observations: list[BoardObservation]
    skipped: list[SkippedImage]
    truth: list[dict | None]


def scan_camera(scan, camera: CameraCalibration | None) -> CameraCalibration:
    """The camera a scan's image is seen with: the calibrated one (scaled) or the scan's own."""
    K = scan.intrinsics
    if camera is not None:
        return camera.at_size(K.width, K.height)
    return CameraCalibration(K, tuple(scan.distortion) if scan.distortion is not None else (0.0,) * 5)


def observe(name: str, color: np.ndarray, camera: CameraCalibration, world_T_flange: np.ndarray,
            board: Board, min_corners: int = MIN_CORNERS) -> BoardObservation | SkippedImage:
    """One view: the board pose in the colour image, paired with the flange pose."""
    found = find_pose(color, board, camera.intrinsics, camera.distortion_array, min_corners)
    if isinstance(found, BoardMissing):
        return SkippedImage(name, found.reason)
    return BoardObservation(name, np.asarray(world_T_flange, dtype=float), found.pose.camera_T_marker,
                            found.pose.n_corners, found.pose.reprojection_rms)


def scan_observations(folder: Path, board: Board, kin, camera: CameraCalibration | None = None,
                      min_corners: int = MIN_CORNERS) -> ScanObservations:
    """Board observations of every scan in a scan store (broken scans skipped with their
    reason). ``kin``: the model's Kinematics (recon_cli.robot.kinematics)."""

    folder = Path(folder)
    if not folder.is_dir():
        raise FileError(f"scan store {folder} does not exist", hint="record board views first "
                                                                    "(recon calibrate handeye without --scan-store)")
    store = ScanStore(folder)
    folders = store.scan_folders()
    if not folders:
        raise FileError(f"{folder} holds no scan_NNNN folders", hint="pass the folder that holds session.json "
                                                                     "and the scans (a script run's <out>/scans)")
    obs, skipped, truth = [], [], []
    names = tuple(kin.joint_names)
    for _, path in folders:
        name = path.name
        try:
            scan = read_scan(path)
        except (MetadataError, FileError) as exc:
            skipped.append(SkippedImage(name, exc.one_line()))
            continue
        if scan.color is None:
            skipped.append(SkippedImage(name, "scan has no colour image"))
            continue
        missing = [j for j in names if j not in scan.joints]
        if missing:
            raise InputError(f"{path / 'scan.json'}: joints {', '.join(missing)} of the "
                             f"{len(names)}-joint model are not recorded",
                             hint="calibrate with the cell the scans were recorded with (--station or --cell)")
        q = np.array([scan.joints[j] for j in names], dtype=float)
        found = observe(name, scan.color, scan_camera(scan, camera), kin.frame_pose(q, kin.cell.flange_link), board,
                        min_corners)
        if isinstance(found, SkippedImage):
            skipped.append(found)
            continue
        obs.append(replace(found, base_position=kin.frame_pose(q, kin.cell.base_link)[:3, 3].copy()))
        truth.append(scan.ground_truth)
    return ScanObservations(obs, skipped, truth)
