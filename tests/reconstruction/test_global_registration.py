"""Global registration under realism: the board-plane height refinement and the correction
of kinematic poses by the session's board poses (synthetic data, exact answers)."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from recon_cli.geometry.transforms import invert, pose_error
from recon_cli.reconstruction.global_registration import kinematic_correction, refine_by_board_plane


def _pose(rng, t_scale=0.5, r_scale=np.pi):
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(rng.normal(size=3) / np.sqrt(3) * r_scale).as_matrix()
    T[:3, 3] = rng.normal(size=3) * t_scale
    return T


def _small(rng, t, r_deg):
    T = np.eye(4)
    axis, shift = rng.normal(size=3), rng.normal(size=3)
    T[:3, :3] = Rotation.from_rotvec(axis / np.linalg.norm(axis) * np.radians(r_deg)).as_matrix()
    T[:3, 3] = shift / np.linalg.norm(shift) * t
    return T


def test_kinematic_correction_recovers_base_and_hand_eye_errors():
    rng = np.random.default_rng(0)
    L, R = _small(rng, 0.002, 0.1), _small(rng, 0.0005, 0.05)  # base error, hand-eye error
    fk = [_pose(rng) for _ in range(8)]
    board = [L @ F @ R @ _small(rng, 0.0002, 0.01) for F in fk]  # board poses with their own noise
    c = kinematic_correction(board, fk)
    assert c is not None and c.scans == 8 and c.after < 0.3 * c.before
    for F in (_pose(rng) for _ in range(5)):  # scans without the board
        dp, dr = pose_error(c.apply(F), L @ F @ R)
        assert dp < 0.3e-3 and dr < np.radians(0.02)


def test_no_correction_when_the_robot_agrees_with_the_board():
    rng = np.random.default_rng(1)
    fk = [_pose(rng) for _ in range(8)]
    board = [F @ _small(rng, 0.0001, 0.005) for F in fk]  # board noise only
    assert kinematic_correction(board, fk) is None
    assert kinematic_correction(board[:3], fk[:3]) is None  # too few scans


def test_board_plane_refinement_moves_the_height_only():
    rng = np.random.default_rng(2)
    size = (0.385, 0.245)
    # board points (marker frame) plus an object above it, seen from a camera 0.6 m away
    xy = rng.uniform([0.0, 0.0], size, size=(20000, 2))
    board = np.column_stack([xy, rng.normal(0.0, 2e-4, len(xy))])
    thing = np.column_stack([rng.uniform(0.15, 0.25, (3000, 2)), rng.uniform(0.01, 0.2, 3000)])
    marker_T_camera = np.eye(4)
    marker_T_camera[:3, :3] = Rotation.from_euler("x", 180 - 40, degrees=True).as_matrix()
    marker_T_camera[:3, 3] = [0.19, -0.35, 0.45]
    pts_camera = (invert(marker_T_camera) @ np.column_stack([np.vstack([board, thing]),
                                                             np.ones(len(board) + len(thing))]).T).T[:, :3]
    wrong = marker_T_camera.copy()
    wrong[:3, 3] += [0.0004, -0.0003, 0.0012]  # a board pose 1.2 mm too high
    refined, n = refine_by_board_plane(pts_camera, wrong, size)
    assert n > 1000
    assert abs(refined[2, 3] - marker_T_camera[2, 3]) < 5e-5  # the height is the depth's
    assert np.allclose(refined[:2, 3], wrong[:2, 3]) and np.allclose(refined[:3, :3], wrong[:3, :3])


def test_board_pose_sigma_grows_with_few_bunched_corners(monkeypatch):
    """The pose's standard deviation from the corners' configuration: the whole board seen
    from 0.6 m fixes the camera to a fraction of a millimetre, six bunched corners do not, and
    such a pose is replaced by the kinematic one with the reason."""
    import cv2

    from recon_cli.perception.camera_model import Intrinsics
    from recon_cli.perception.charuco import CharucoDetection, estimate_pose, thesis_board
    from recon_cli.reconstruction.global_registration import _global_pose
    from recon_cli.reconstruction.scan_store import Scan

    spec = thesis_board()
    K = Intrinsics(1600, 1200, 1742.9, 1742.9, 799.5, 599.5)
    corners3d = spec.board().getChessboardCorners()  # OpenCV board frame
    rvec, tvec = np.array([0.35, -0.2, 0.05]), np.array([-0.18, -0.1, 0.62])
    rng = np.random.default_rng(0)

    def detection(ids):
        px, _ = cv2.projectPoints(corners3d[ids], rvec, tvec, K.matrix(), np.zeros(5))
        px = px.reshape(-1, 2) + rng.normal(0.0, 0.1, (len(ids), 2))
        return CharucoDetection(px, np.asarray(ids), np.zeros((0, 4, 2)), np.zeros(0, dtype=int))

    whole = estimate_pose(detection(list(range(len(corners3d)))), spec, K)
    bunched = estimate_pose(detection([9, 10, 19, 20, 28, 29]), spec, K)
    assert whole.position_sigma < 0.0002 and whole.rotation_sigma < np.radians(0.02)
    assert bunched.position_sigma > 10 * whole.position_sigma

    scan = Scan(0, np.zeros((1200, 1600, 3), np.uint8), np.zeros((1200, 1600)), K, {}, np.eye(4))
    import recon_cli.reconstruction.global_registration as G

    monkeypatch.setattr(G, "detect", lambda image, board: detection([9, 10, 19, 20, 28, 29]))
    monkeypatch.setattr(G, "estimate_pose", lambda *a, **k: bunched)
    pose = _global_pose(scan, spec, np.eye(4), 6, True, 1.0, bunched.position_sigma * 0.5)
    assert pose.source.value == "kinematics" and "corners fix the camera to" in pose.reason
    pose = _global_pose(scan, spec, np.eye(4), 6, True, 1.0, bunched.position_sigma * 2.0)
    assert pose.source.value == "charuco"


def test_a_board_fit_that_fixes_no_pose_is_no_pose():
    """Corners that do not fix a pose (a singular or non-finite fit) give infinite
    uncertainty and no board pose, never a linear-algebra error (registration then falls
    back to kinematics for that scan)."""
    import numpy as np

    from recon_cli.perception.charuco import _pose_sigmas

    residual = np.zeros(12)
    rvec, tvec = np.zeros(3), np.array([0.0, 0.0, 0.5])
    assert _pose_sigmas(np.zeros((12, 6)), residual, rvec, tvec) == (float("inf"), float("inf"))
    J = np.full((12, 6), np.nan)
    assert _pose_sigmas(J, residual, rvec, tvec) == (float("inf"), float("inf"))
    J = np.ones((12, 6))
    J[0, 0] = 1e300
    assert _pose_sigmas(J, residual, rvec, tvec) == (float("inf"), float("inf"))
