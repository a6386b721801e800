"""Hand-eye calibration on synthetic exact data: every OpenCV method and the refinement
recover the transforms; pose diversity warnings; the user's errors are one line."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from recon_cli.calibration.handeye import (
    BoardObservation,
    DiversityIssue,
    HandEyeMethod,
    SolverFailed,
    mean_pose,
    pose_diversity,
    solve_hand_eye,
    view_residuals,
)
from recon_cli.calibration.refine import corrected, refine_hand_eye
from recon_cli.calibration.views import BoardViewOptions, board_views
from recon_cli.errors import InputError, UnknownNameError
from recon_cli.geometry.transforms import invert, pose_error
from recon_cli.geometry.view import Frame, View
from recon_cli.perception.charuco import thesis_board


def _rigid(rng: np.random.Generator, max_deg: float, max_m: float) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(rng.normal(size=3) * np.radians(max_deg) / 2).as_matrix()
    T[:3, 3] = rng.uniform(-max_m, max_m, size=3)
    return T


def _exact(n: int = 12, seed: int = 0):
    """world_T_flange, and the board poses they imply for a known flange_T_camera X and
    world_T_marker W (no noise)."""
    rng = np.random.default_rng(seed)
    X, W = _rigid(rng, 90, 0.2), _rigid(rng, 30, 0.8)
    obs = []
    for k in range(n):
        F = _rigid(rng, 80, 0.5)
        obs.append(BoardObservation(f"v{k}", F, invert(X) @ invert(F) @ W, base_position=F[:3, 3].copy()))
    return obs, X, W


@pytest.mark.parametrize("method", list(HandEyeMethod))
def test_every_method_recovers_exact_data(method):
    obs, X, W = _exact()
    s = solve_hand_eye(obs, method)
    for got, want in ((s.flange_T_camera, X), (s.world_T_marker, W)):
        dt, dr = pose_error(got, want)
        assert dt < 1e-9 and dr < 1e-9
    res = view_residuals(obs, s.flange_T_camera, s.world_T_marker)
    assert max(r.translation for r in res) < 1e-9 and max(r.rotation for r in res) < 1e-9


def test_all_methods_agree_to_1e_6():
    obs, _, _ = _exact(n=8, seed=3)
    sols = [solve_hand_eye(obs, m) for m in HandEyeMethod]
    for s in sols[1:]:
        assert np.max(np.abs(s.flange_T_camera - sols[0].flange_T_camera)) < 1e-6
        assert np.max(np.abs(s.world_T_marker - sols[0].world_T_marker)) < 1e-6


def test_method_names_and_flags():
    import cv2

    assert HandEyeMethod.parse("Daniilidis") is HandEyeMethod.DANIILIDIS
    assert HandEyeMethod.TSAI.opencv_flag() == cv2.CALIB_HAND_EYE_TSAI
    assert HandEyeMethod.LI.opencv_flag() == cv2.CALIB_ROBOT_WORLD_HAND_EYE_LI
    assert [m.robot_world for m in HandEyeMethod].count(True) == 2
    with pytest.raises(UnknownNameError, match="tsai, park, horaud, andreff, daniilidis, shah, li"):
        HandEyeMethod.parse("kabsch")


def test_opencv_has_both_solvers():
    """pyproject pins OpenCV 4.x: the 5.0 wheels lack these two functions."""
    import cv2

    assert hasattr(cv2, "calibrateHandEye") and hasattr(cv2, "calibrateRobotWorldHandEye"), cv2.__version__


def test_too_few_views_is_one_line():
    obs, _, _ = _exact(n=2)
    with pytest.raises(InputError, match="at least 3 views") as exc:
        solve_hand_eye(obs)
    assert "\n" not in str(exc.value) and "record" in str(exc.value)


def test_refinement_recovers_a_base_rotation_carried_by_linear_axes():
    """The robot base turned by 0.2 deg against the model, carried to other places by the
    linear axes between views: OpenCV's solution is biased, the refinement is exact."""
    rng = np.random.default_rng(7)
    X, W = _rigid(rng, 90, 0.2), _rigid(rng, 20, 0.5)
    H = np.eye(4)
    H[:3, :3] = Rotation.from_rotvec(np.radians([0.15, -0.1, 0.08])).as_matrix()
    obs = []
    for _k in range(15):
        F = _rigid(rng, 70, 0.3)
        p = np.array([rng.uniform(-0.4, 0.4), rng.uniform(-0.4, 0.4), 1.8])
        F[:3, 3] += p  # the base carried to p
        G = H.copy()
        G[:3, 3] = p - H[:3, :3] @ p
        true_F = G @ F
        obs.append(BoardObservation("v", F, invert(X) @ invert(true_F) @ W, base_position=p))
    start = solve_hand_eye(obs, HandEyeMethod.TSAI)
    assert pose_error(start.flange_T_camera, X)[0] > 1e-4  # biased
    r = refine_hand_eye(obs, start)
    dt, dr = pose_error(r.solution.flange_T_camera, X)
    assert dt < 1e-7 and dr < 1e-7
    assert np.allclose(r.base_rotation, Rotation.from_matrix(H[:3, :3]).as_rotvec(), atol=1e-8)
    res = view_residuals(corrected(obs, r), r.solution.flange_T_camera, r.solution.world_T_marker)
    assert max(x.translation for x in res) < 1e-7
    assert r.cost_after < 1e-12 < r.cost_before


def test_refinement_without_axis_travel_keeps_the_base():
    obs, X, _ = _exact(n=6, seed=2)
    obs = [BoardObservation(o.name, o.world_T_flange, o.camera_T_marker, base_position=np.zeros(3)) for o in obs]
    r = refine_hand_eye(obs, solve_hand_eye(obs))
    assert r.base_rotation is None
    assert pose_error(r.solution.flange_T_camera, X)[0] < 1e-9


def test_mean_pose_of_equal_poses():
    rng = np.random.default_rng(1)
    T = _rigid(rng, 60, 1.0)
    assert np.allclose(mean_pose([T, T, T]), T)


# --------------------------------------------------------------------- diversity
def _poses(views):
    return [v.frame_T_camera() for v in views]


def test_generated_views_are_diverse():
    d = pose_diversity(_poses(board_views(thesis_board(), BoardViewOptions(n=16))))
    assert d.ok, d.issues
    assert math.degrees(d.max_rotation) > 60


def test_one_ring_turns_about_one_axis():
    ring = [View((0.19, 0.12, 0.0), 0.45, math.radians(30), math.radians(30 * k), 0.0, Frame.MARKER)
            for k in range(12)]
    issues = dict(pose_diversity(_poses(ring)).issues)
    assert DiversityIssue.ONE_AXIS in issues and "not observable" in issues[DiversityIssue.ONE_AXIS]


def test_similar_and_few_views_are_warned():
    near = [View((0.19, 0.12, 0.0), 0.45, math.radians(20 + k), math.radians(3 * k), math.radians(2 * k),
                 Frame.MARKER) for k in range(4)]
    issues = dict(pose_diversity(_poses(near)).issues)
    assert {DiversityIssue.TOO_FEW_VIEWS, DiversityIssue.SIMILAR_ROTATIONS} <= set(issues)
    assert "4 usable views" in issues[DiversityIssue.TOO_FEW_VIEWS]


def test_degenerate_motion_is_named():
    """Every view at one orientation, or every rotation about one axis: no solver can find
    the calibration, and the diversity says why."""
    obs, _, _ = _exact(n=6)
    assert pose_diversity([o.world_T_flange for o in obs]).degenerate is None
    same = [obs[0].world_T_flange] * 6
    assert pose_diversity(same).degenerate.startswith("the robot poses rotate by at most 0.00° against each other "
                                                      "(at least 1° needed, 20° recommended)")
    turned = []
    for k in range(6):
        T = obs[0].world_T_flange.copy()
        T[:3, :3] = T[:3, :3] @ Rotation.from_rotvec([0, 0, np.radians(20 * k)]).as_matrix()
        T[:3, 3] += [0.01 * k, 0, 0]
        turned.append(T)
    why = pose_diversity(turned).degenerate
    assert why.startswith("every rotation between the views turns about one axis (axis spread ") and \
        "rotations up to 100.0°" in why, why


def test_a_solver_without_a_solution_is_one_line_and_prints_nothing(capfd):
    """Four views at one pose: OpenCV's Tsai solver logs "not enough informative motions" and
    returns the identity, Andreff's raises; both are one line naming OpenCV's reason, and
    nothing is printed."""
    obs, _, _ = _exact(n=6)
    small = [BoardObservation(f"v{k}", obs[0].world_T_flange, obs[0].camera_T_marker) for k in range(4)]
    with pytest.raises(SolverFailed) as info:
        solve_hand_eye(small, HandEyeMethod.TSAI)
    assert info.value.one_line().startswith("OpenCV's tsai solver found no solution for the 4 views (Hand-eye "
                                            "calibration failed! Not enough informative motions--include larger "
                                            "rotations.); add views turned about other axes")
    with pytest.raises(SolverFailed, match=r"andreff solver found no solution for the 4 views \(Rotation "
                                           r"normalization issue: determinant\(R\) is null\)"):
        solve_hand_eye(small, HandEyeMethod.ANDREFF)
    out, err = capfd.readouterr()
    assert out + err == ""


def test_view_options_are_checked():
    with pytest.raises(InputError, match="outside 1 ... 200"):
        BoardViewOptions(n=0)
    with pytest.raises(InputError, match="increasing range"):
        BoardViewOptions(radius=(0.6, 0.4))
