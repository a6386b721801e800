"""The two hand-eye set-ups as one chain, refined by the board corners' reprojection error.

Eye-in-hand (the camera on the flange)::

    base_T_flange[i] @ flange_T_camera @ camera_T_board[i] = base_T_board

Eye-to-hand (the camera fixed, the board on the flange)::

    base_T_flange[i] @ flange_T_board = base_T_camera @ camera_T_board[i]
    <=> inv(base_T_flange[i]) @ base_T_camera @ camera_T_board[i] = flange_T_board

Both have the form ``G[i] @ X @ camera_T_board[i] = W`` that OpenCV's solvers take
(:mod:`recon_cli.calibration.handeye`): G is the robot pose (eye-in-hand) or its inverse
(eye-to-hand), X the camera's pose in the frame it is fixed to, W the board's. So the same
solvers serve both, with the robot poses inverted for eye-to-hand (as OpenCV's documentation
says for calibrateHandEye). Every pose here is (4, 4) [m].

The refinement minimizes what was measured, the board corners in the images: each view's
corners projected through ``camera_T_board[i] = inv(X) @ inv(G[i]) @ W`` (the camera's
intrinsics and distortion) against where they were detected, over X and W, by
Levenberg-Marquardt (scipy's least_squares) from an OpenCV solution. Its result is the
same on every run (no randomness; the views in a fixed order).

The consistency of a calibration is where the fixed part lands in the base frame, view by
view: the board for eye-in-hand (``base_T_flange[i] @ X @ camera_T_board[i]``), the camera
for eye-to-hand (``base_T_flange[i] @ W @ inv(camera_T_board[i])``), against the
calibration's; a view far off the others (:func:`outlier_views`) is flagged.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

import numpy as np

from recon_cli.calibration.camera_file import CameraCalibration
from recon_cli.calibration.handeye import BoardObservation, HandEyeMethod, ViewResidual, solve_hand_eye
from recon_cli.errors import InputError, UnknownNameError
from recon_cli.geometry.transforms import invert, pose_error

#: a view is an outlier when its chain residual is more than this many times the median ...
OUTLIER_FACTOR = 3.0
#: ... and more than these floors [m, rad] (exact data has tiny residuals, none an outlier)
OUTLIER_FLOOR = (0.001, np.radians(0.1))
#: a chain residual above these bounds [m, rad] is an outlier whatever the median
OUTLIER_BOUND = (0.05, np.radians(5.0))


class Setup(StrEnum):
    """Where the camera is: on the flange (eye-in-hand) or fixed, looking at a board the
    robot carries (eye-to-hand)."""

    EYE_IN_HAND = "eye-in-hand"
    EYE_TO_HAND = "eye-to-hand"

    @classmethod
    def parse(cls, name: str) -> Setup:
        try:
            return cls(str(name).strip().lower().replace("_", "-"))
        except ValueError:
            raise UnknownNameError("set-up", name, [s.value for s in cls]) from None

    @property
    def unknowns(self) -> tuple[str, str]:
        """The names of X (the camera in its frame) and W (the board in its frame)."""
        if self is Setup.EYE_IN_HAND:
            return "flange_T_camera", "base_T_board"
        return "base_T_camera", "flange_T_board"

    @property
    def fixed(self) -> str:
        """What stays put in the base frame while the robot moves: what the consistency measures."""
        return "board" if self is Setup.EYE_IN_HAND else "camera"

    def chain_pose(self, base_T_flange: np.ndarray) -> np.ndarray:
        """G of the chain ``G @ X @ camera_T_board = W``: the robot pose or its inverse."""
        return base_T_flange if self is Setup.EYE_IN_HAND else invert(base_T_flange)


@dataclass(frozen=True)
class CornerView:
    """One usable view: the robot pose, the board's corners in the image and on the board,
    and the board pose of the image alone (solvePnP).

    object_points: (N, 3) the corners in the board's frame (recon's marker frame) [m]
    image_points: (N, 2) where they were detected [px]
    pnp_rms: RMS reprojection error of the image's own board pose [px]
    """

    name: str
    base_T_flange: np.ndarray
    camera_T_board: np.ndarray
    object_points: np.ndarray
    image_points: np.ndarray
    camera: CameraCalibration
    pnp_rms: float
    pose_source: str = ""

    @property
    def corners(self) -> int:
        return len(self.object_points)


@dataclass(frozen=True)
class SetupSolution:
    """X and W of a set-up (see the module docstring), and how they were found."""

    setup: Setup
    method: HandEyeMethod
    X: np.ndarray  # flange_T_camera (eye-in-hand) or base_T_camera (eye-to-hand)
    W: np.ndarray  # base_T_board (eye-in-hand) or flange_T_board (eye-to-hand)
    refined: bool = False

    def named(self) -> dict[str, np.ndarray]:
        x, w = self.setup.unknowns
        return {x: self.X, w: self.W}

    def camera_T_board(self, base_T_flange: np.ndarray) -> np.ndarray:
        """The board in the camera in a view with this robot pose, as the calibration says."""
        return invert(self.X) @ invert(self.setup.chain_pose(base_T_flange)) @ self.W


def chain_observations(views: list[CornerView], setup: Setup) -> list[BoardObservation]:
    """The views as OpenCV's solvers take them (robot poses inverted for eye-to-hand)."""
    return [BoardObservation(v.name, setup.chain_pose(v.base_T_flange), v.camera_T_board, v.corners, v.pnp_rms)
            for v in views]


def solve(views: list[CornerView], setup: Setup, method: HandEyeMethod) -> SetupSolution:
    """One OpenCV method's solution of the set-up."""
    s = solve_hand_eye(chain_observations(views, setup), method)
    return SetupSolution(setup, method, s.flange_T_camera, s.world_T_marker)


# --------------------------------------------------------------------- reprojection
def _project(view: CornerView, camera_T_board: np.ndarray) -> np.ndarray:
    """(N, 2) the view's board corners projected through ``camera_T_board`` [px]."""
    import cv2

    rvec = cv2.Rodrigues(np.ascontiguousarray(camera_T_board[:3, :3]))[0]
    K = view.camera.intrinsics.matrix()
    uv, _ = cv2.projectPoints(view.object_points.reshape(-1, 1, 3), rvec, camera_T_board[:3, 3].reshape(3, 1),
                              K, view.camera.distortion_array)
    return uv.reshape(-1, 2)


def reprojection_errors(views: list[CornerView], solution: SetupSolution) -> list[np.ndarray]:
    """Per view: (N,) distances [px] between the detected corners and the corners projected
    through the calibration's chain."""
    return [np.linalg.norm(_project(v, solution.camera_T_board(v.base_T_flange)) - v.image_points, axis=1)
            for v in views]


def rms(errors: list[np.ndarray] | np.ndarray) -> float:
    """RMS over all corners of distances [px]."""
    e = np.concatenate(errors) if isinstance(errors, list) else np.asarray(errors)
    return float(np.sqrt(np.mean(e**2))) if e.size else 0.0


def _twist(x: np.ndarray) -> np.ndarray:
    """Rigid transform of (translation [m], rotation vector [rad])."""
    from scipy.spatial.transform import Rotation

    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(x[3:]).as_matrix()
    T[:3, 3] = x[:3]
    return T


@dataclass(frozen=True)
class Refinement:
    """The refined solution; converged: scipy's least_squares stopped on its tolerances
    (not on its evaluation limit); rms before and after [px]; evaluations of the residuals."""

    solution: SetupSolution
    converged: bool
    rms_before: float
    rms_after: float
    evaluations: int
    message: str


def refine(views: list[CornerView], start: SetupSolution, max_evaluations: int = 2000) -> Refinement:
    """X and W minimizing the corners' reprojection error over all views, from ``start``."""
    from scipy.optimize import least_squares

    G_inv = [invert(start.setup.chain_pose(v.base_T_flange)) for v in views]
    X0, W0 = start.X, start.W

    def residuals(x: np.ndarray) -> np.ndarray:
        X_inv = invert(X0 @ _twist(x[:6]))
        W = W0 @ _twist(x[6:])
        return np.concatenate([(_project(v, X_inv @ Gi @ W) - v.image_points).ravel()
                               for v, Gi in zip(views, G_inv, strict=True)])

    x0 = np.zeros(12)
    r0 = residuals(x0)
    if not np.all(np.isfinite(r0)):
        raise InputError(f"the {start.method.value} solution projects some board corners to no finite point, so it "
                         "cannot be refined", hint="calibrate with --no-refine, or with another --method")
    fit = least_squares(residuals, x0, method="lm", x_scale=np.full(12, 0.01), xtol=1e-12, ftol=1e-12, gtol=1e-12,
                        max_nfev=max_evaluations)
    solution = SetupSolution(start.setup, start.method, X0 @ _twist(fit.x[:6]), W0 @ _twist(fit.x[6:]),
                             refined=True)
    n = max(len(r0) // 2, 1)
    return Refinement(solution, bool(fit.status > 0), float(np.sqrt(np.sum(r0**2) / n)),
                      float(np.sqrt(np.sum(fit.fun**2) / n)), int(fit.nfev), str(fit.message))


# --------------------------------------------------------------------- consistency
def landed(views: list[CornerView], solution: SetupSolution) -> list[np.ndarray]:
    """Per view: where the fixed part lands in the base frame through the view's chain, the
    board (eye-in-hand: base_T_board[i]) or the camera (eye-to-hand: base_T_camera[i])."""
    if solution.setup is Setup.EYE_IN_HAND:
        return [v.base_T_flange @ solution.X @ v.camera_T_board for v in views]
    return [v.base_T_flange @ solution.W @ invert(v.camera_T_board) for v in views]


def fixed_pose(solution: SetupSolution) -> np.ndarray:
    """The calibration's pose of the fixed part in the base frame (base_T_board or base_T_camera)."""
    return solution.W if solution.setup is Setup.EYE_IN_HAND else solution.X


def chain_residuals(views: list[CornerView], solution: SetupSolution) -> list[ViewResidual]:
    """Per view: how far its closed chain puts the fixed part from the calibration's
    (translation [m], rotation [rad])."""
    ref = fixed_pose(solution)
    return [ViewResidual(v.name, *pose_error(T, ref)) for v, T in zip(views, landed(views, solution), strict=True)]


def pnp_agreement(views: list[CornerView], solution: SetupSolution) -> list[tuple[float, float]]:
    """Per view: the calibration's camera_T_board against the image's own (solvePnP) pose
    (translation [m], rotation [rad]), the check of ros-industrial/industrial_calibration."""
    return [pose_error(solution.camera_T_board(v.base_T_flange), v.camera_T_board) for v in views]


def outlier_views(residuals: list[ViewResidual], factor: float = OUTLIER_FACTOR) -> dict[str, str]:
    """The views whose chain residual is more than ``factor`` times the median (and above
    OUTLIER_FLOOR), or above OUTLIER_BOUND, with the reason."""
    if not residuals:
        return {}
    t = np.array([r.translation for r in residuals])
    a = np.array([r.rotation for r in residuals])
    med_t, med_a = float(np.median(t)), float(np.median(a))
    out = {}
    for r in residuals:
        why = []
        if r.translation > OUTLIER_BOUND[0] or (r.translation > factor * med_t and r.translation > OUTLIER_FLOOR[0]):
            why.append(f"{r.translation * 1e3:.1f} mm (median {med_t * 1e3:.1f})")
        if r.rotation > OUTLIER_BOUND[1] or (r.rotation > factor * med_a and r.rotation > OUTLIER_FLOOR[1]):
            why.append(f"{np.degrees(r.rotation):.2f}° (median {np.degrees(med_a):.2f})")
        if why:
            out[r.name] = "chain residual " + ", ".join(why)
    return out
