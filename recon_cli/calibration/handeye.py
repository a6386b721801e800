"""Hand-eye calibration: the camera's optical frame in the flange (``flange_T_camera``) and
the board in the robot's base frame (``world_T_marker``) from views of the ChArUco board.

Each view pairs the flange pose from forward kinematics of the measured joints
(``world_T_flange``; the "base" is the cell's world frame, the root of the gantry's linear
axes or of the ceiling mount) with the board pose seen by the camera (``camera_T_marker``).
For every view i the chain closes::

    world_T_flange[i] @ flange_T_camera @ camera_T_marker[i] = world_T_marker

OpenCV solves it two ways, every method selectable (:class:`HandEyeMethod`):

    calibrateHandEye            AX = XB over pairs of views: tsai, park, horaud, andreff,
                                daniilidis (world_T_marker is then the mean of the closed chains)
    calibrateRobotWorldHandEye  AX = ZB over single views: shah, li (both unknowns at once)

Both OpenCV functions are missing from the opencv-python 5.0 wheels; recon pins OpenCV 4.x
(pyproject.toml). The residual of a view is how far its closed chain lands from the common
``world_T_marker`` [m, rad]; :func:`pose_diversity` says whether the views rotate the camera
enough, about enough axes, for the problem to be well posed.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from enum import StrEnum

import numpy as np

from recon_cli.errors import InputError, UnknownNameError
from recon_cli.geometry.transforms import invert, rotation_angle
from recon_cli.inputs.images import native_output_captured

#: OpenCV needs 3 views; fewer than this many make a calibration we warn about
MIN_VIEWS = 3
RECOMMENDED_VIEWS = 10
#: [rad] the largest rotation between two views below which the views are "too similar"
MIN_ROTATION_SPREAD = np.radians(20.0)
#: the second-largest share of the motion axes' scatter below which all motions turn about one axis
MIN_AXIS_SPREAD = 0.003
#: [rad] the largest rotation between two views below which the motion is degenerate: every
#: view at nearly one orientation, no rotation axis to measure (refused before any solver runs)
DEGENERATE_ROTATION = np.radians(1.0)
#: the axis spread below which every motion turns about one axis (all within about 1 degree of
#: it): the translation along that axis is not observable (refused before any solver runs)
DEGENERATE_AXIS_SPREAD = 1e-4


class HandEyeMethod(StrEnum):
    """OpenCV's hand-eye solvers (``cv2.CALIB_HAND_EYE_*``, ``cv2.CALIB_ROBOT_WORLD_HAND_EYE_*``)."""

    TSAI = "tsai"  #: Tsai and Lenz 1989
    PARK = "park"  #: Park and Martin 1994
    HORAUD = "horaud"  #: Horaud and Dornaika 1995
    ANDREFF = "andreff"  #: Andreff, Horaud and Espiau 1999
    DANIILIDIS = "daniilidis"  #: Daniilidis 1999 (dual quaternions)
    SHAH = "shah"  #: Shah 2013, robot-world and hand-eye at once
    LI = "li"  #: Li, Wang and Wu 2010, robot-world and hand-eye at once

    @property
    def robot_world(self) -> bool:
        """True for the methods of calibrateRobotWorldHandEye (they estimate world_T_marker too)."""
        return self in (HandEyeMethod.SHAH, HandEyeMethod.LI)

    def opencv_flag(self) -> int:
        import cv2

        if self.robot_world:
            return int(getattr(cv2, f"CALIB_ROBOT_WORLD_HAND_EYE_{self.name}"))
        return int(getattr(cv2, f"CALIB_HAND_EYE_{self.name}"))

    @classmethod
    def parse(cls, name: str) -> HandEyeMethod:
        try:
            return cls(str(name).strip().lower())
        except ValueError:
            raise UnknownNameError("hand-eye method", name, [m.value for m in cls]) from None


@dataclass(frozen=True)
class BoardObservation:
    """One view of the board. Poses (4, 4) [m]; ``name`` says which scan or image."""

    name: str
    world_T_flange: np.ndarray  # forward kinematics of the measured joints (the model's)
    camera_T_marker: np.ndarray  # the board seen by the camera (ChArUco corners, solvePnP)
    corners: int = 0  # chessboard corners the board pose used
    reprojection_px: float = 0.0  # RMS reprojection error of the board pose [px]
    base_position: np.ndarray | None = None  # (3,) the robot base (arm_link_0) in the world, moved by linear axes


@dataclass(frozen=True)
class HandEyeSolution:
    """flange_T_camera and world_T_marker (4, 4) [m] of one method."""

    method: HandEyeMethod
    flange_T_camera: np.ndarray
    world_T_marker: np.ndarray


@dataclass(frozen=True)
class ViewResidual:
    """How far view ``name``'s closed chain lands from the common world_T_marker."""

    name: str
    translation: float  # [m]
    rotation: float  # [rad]


# --------------------------------------------------------------------- solving
def _split(Ts) -> tuple[list[np.ndarray], list[np.ndarray]]:
    return ([np.ascontiguousarray(T[:3, :3], dtype=np.float64) for T in Ts],
            [np.ascontiguousarray(T[:3, 3].reshape(3, 1), dtype=np.float64) for T in Ts])


def _join(R, t) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = np.asarray(R, dtype=np.float64)
    T[:3, 3] = np.asarray(t, dtype=np.float64).reshape(3)
    return T


def mean_pose(poses) -> np.ndarray:
    """Chordal mean of rigid transforms: the rotation nearest to the mean rotation matrix,
    the mean translation."""
    Ts = np.asarray(poses, dtype=np.float64)
    U, _, Vt = np.linalg.svd(Ts[:, :3, :3].mean(axis=0))
    R = U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt
    return _join(R, Ts[:, :3, 3].mean(axis=0))


def solve_hand_eye(observations: list[BoardObservation], method: HandEyeMethod = HandEyeMethod.TSAI
                   ) -> HandEyeSolution:
    """flange_T_camera and world_T_marker from the views with one of OpenCV's methods."""
    import cv2

    method = HandEyeMethod(method)
    if len(observations) < MIN_VIEWS:
        raise InputError(f"hand-eye calibration needs at least {MIN_VIEWS} views of the board, "
                         f"{len(observations)} given",
                         hint=f"record {RECOMMENDED_VIEWS} or more views with the board fully in sight")
    missing = [name for name, ok in (("calibrateHandEye", hasattr(cv2, "calibrateHandEye")),
                                     ("calibrateRobotWorldHandEye", hasattr(cv2, "calibrateRobotWorldHandEye")))
               if not ok]
    if missing:
        raise InputError(f"this OpenCV {cv2.__version__} lacks {' and '.join(missing)}",
                         hint="install opencv-python-headless>=4.10,<5 (pyproject.toml says why)")
    world_T_flange = [o.world_T_flange for o in observations]
    camera_T_marker = [o.camera_T_marker for o in observations]
    logging = cv2.utils.logging
    level = logging.getLogLevel()
    X: np.ndarray | None = None
    W: np.ndarray | None = None
    # OpenCV logs a failed Tsai solve (and returns a result): its log is read, not printed
    with native_output_captured((1, 2), opencv=False) as printed:
        logging.setLogLevel(logging.LOG_LEVEL_ERROR)
        try:
            if method.robot_world:
                R_w2c, t_w2c = _split(camera_T_marker)  # "world" of OpenCV = the board
                R_b2g, t_b2g = _split([invert(T) for T in world_T_flange])  # "base" = our world frame
                R_b2w, t_b2w, R_g2c, t_g2c = cv2.calibrateRobotWorldHandEye(R_w2c, t_w2c, R_b2g, t_b2g,
                                                                             method=method.opencv_flag())
                X, W = invert(_join(R_g2c, t_g2c)), invert(_join(R_b2w, t_b2w))
            else:
                R_g2b, t_g2b = _split(world_T_flange)
                R_t2c, t_t2c = _split(camera_T_marker)
                R_c2g, t_c2g = cv2.calibrateHandEye(R_g2b, t_g2b, R_t2c, t_t2c, method=method.opencv_flag())
                X, W = _join(R_c2g, t_c2g), None
            failure = None
        except cv2.error as exc:
            failure = _opencv_reason(str(exc))
        finally:
            logging.setLogLevel(level)
    if failure is None and printed and "failed" in printed[0]:
        failure = _opencv_reason(printed[0])
    if failure is None and not _is_rigid(X):
        failure = "its result is not a rotation and a translation"
    if failure is None and X is not None and W is None:
        W = mean_pose([A @ X @ B for A, B in zip(world_T_flange, camera_T_marker, strict=True)])
    if failure is None and (W is None or not _is_rigid(W)):
        failure = "its result is not a rotation and a translation"
    if failure is not None or X is None or W is None:
        raise SolverFailed(method, len(observations), failure or "no result")
    return HandEyeSolution(method, X, W)


class SolverFailed(InputError):
    """One of OpenCV's solvers found no solution for the views; ``reason``: OpenCV's words
    (without its source location)."""

    def __init__(self, method: HandEyeMethod, views: int, reason: str) -> None:
        self.method = method
        self.reason = reason
        super().__init__(f"OpenCV's {method.value} solver found no solution for the {views} views ({reason})",
                         hint="add views turned about other axes, or choose another --method")


def _opencv_reason(text: str) -> str:
    """What OpenCV said, without its source location: "Rotation normalization issue: ..." of
    "OpenCV(4.x) /path/file.cpp:549: error: (-7:...) Rotation normalization issue: ... in
    function 'f'", or the text of its log line."""
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    line = lines[-1] if lines else "no reason given"
    line = re.sub(r"^.*?error: \([^)]*\)\s*", "", line)
    line = re.sub(r"^\[[^]]*\]\s*global \S+ \S+\s*", "", line)  # "[ERROR:0@1.9] global file.cpp:335 function"
    line = re.sub(r"\s*in function '[^']*'$", "", line)
    return line[:160]


def _is_rigid(T: np.ndarray | None) -> bool:
    """A finite 4x4 transform whose rotation part is a rotation (within 1e-6)."""
    if T is None or T.shape != (4, 4) or not np.all(np.isfinite(T)):
        return False
    R = T[:3, :3]
    return bool(np.max(np.abs(R.T @ R - np.eye(3))) < 1e-6 and np.linalg.det(R) > 0)


def view_residuals(observations: list[BoardObservation], flange_T_camera: np.ndarray,
                   world_T_marker: np.ndarray) -> list[ViewResidual]:
    """Per view: the closed chain world_T_flange @ flange_T_camera @ camera_T_marker against
    world_T_marker (translation [m], rotation [rad])."""
    inv = invert(world_T_marker)
    out = []
    for o in observations:
        E = inv @ o.world_T_flange @ flange_T_camera @ o.camera_T_marker
        out.append(ViewResidual(o.name, float(np.linalg.norm(E[:3, 3])), rotation_angle(E[:3, :3])))
    return out


# --------------------------------------------------------------------- pose diversity
class DiversityIssue(StrEnum):
    TOO_FEW_VIEWS = "too_few_views"
    SIMILAR_ROTATIONS = "similar_rotations"
    ONE_AXIS = "one_rotation_axis"


@dataclass(frozen=True)
class Diversity:
    """How well the views pose the problem.

    views: number of views
    max_rotation: the largest rotation between two flange poses [rad]
    median_rotation: the median over all pairs [rad]
    axis_spread: second-largest eigenvalue share of the motions' rotation axes (weighted by
        the sine of their angles): 0 when every motion turns about one axis, up to 1/3 when
        the axes cover all directions (Tsai and Lenz need two non-parallel axes)
    issues: what to warn about, each with its message
    """

    views: int
    max_rotation: float
    median_rotation: float
    axis_spread: float
    issues: tuple[tuple[DiversityIssue, str], ...]

    @property
    def ok(self) -> bool:
        return not self.issues

    @property
    def degenerate(self) -> str | None:
        """Why no solver can find the hand-eye transform from these views (every view at
        nearly one orientation, or every rotation between them about one axis), or None."""
        if self.views >= 2 and self.max_rotation < DEGENERATE_ROTATION:
            return (f"the robot poses rotate by at most {np.degrees(self.max_rotation):.2f}° against each other "
                    f"(at least {np.degrees(DEGENERATE_ROTATION):.0f}° needed, "
                    f"{np.degrees(MIN_ROTATION_SPREAD):.0f}° recommended): the views are taken at nearly one "
                    "orientation")
        if self.views >= 3 and self.axis_spread < DEGENERATE_AXIS_SPREAD:
            return (f"every rotation between the views turns about one axis (axis spread {self.axis_spread:.2g}, "
                    f"at least {DEGENERATE_AXIS_SPREAD:g} needed, {MIN_AXIS_SPREAD:g} recommended; rotations up "
                    f"to {np.degrees(self.max_rotation):.1f}°): the translation along that axis is not observable")
        return None

    def to_dict(self) -> dict:
        return {"views": self.views, "max_rotation_deg": float(np.degrees(self.max_rotation)),
                "median_rotation_deg": float(np.degrees(self.median_rotation)), "axis_spread": self.axis_spread,
                "issues": [{"issue": i.value, "message": m} for i, m in self.issues]}


def pose_diversity(world_T_flange, recommended: int = RECOMMENDED_VIEWS) -> Diversity:
    """Rotation diversity of the flange poses of a calibration (see :class:`Diversity`)."""
    from scipy.spatial.transform import Rotation

    Ts = np.asarray(world_T_flange, dtype=np.float64).reshape(-1, 4, 4)
    n = len(Ts)
    Rs = Ts[:, :3, :3]
    rows: list[np.ndarray] = []
    scatter = np.zeros((3, 3))
    for i in range(n - 1):  # every pair (i, j > i), one view's pairs at a time
        rv = Rotation.from_matrix(np.einsum("ba,jbc->jac", Rs[i], Rs[i + 1:])).as_rotvec()
        a = np.linalg.norm(rv, axis=1)
        rows.append(a)
        moved = a > 1e-9
        axes = (rv[moved] / a[moved, None]) @ Rs[i].T  # in world axes, comparable across pairs
        scatter += np.einsum("k,ka,kb->ab", np.sin(np.minimum(a[moved], np.pi / 2)), axes, axes)
    angles = np.concatenate(rows) if rows else np.zeros(0)
    ev = np.sort(np.linalg.eigvalsh(scatter))[::-1] if np.trace(scatter) > 0 else np.zeros(3)
    spread = float(ev[1] / ev.sum()) if ev.sum() > 0 else 0.0
    max_rot = float(angles.max()) if angles.size else 0.0
    issues = []
    if n < recommended:
        issues.append((DiversityIssue.TOO_FEW_VIEWS,
                       f"{n} usable views (at least {recommended} recommended; {MIN_VIEWS} is OpenCV's minimum)"))
    if n >= 2 and max_rot < MIN_ROTATION_SPREAD:
        issues.append((DiversityIssue.SIMILAR_ROTATIONS,
                       f"the views rotate the camera by at most {np.degrees(max_rot):.1f}° against each other "
                       f"(want >= {np.degrees(MIN_ROTATION_SPREAD):.0f}°): tilt and roll the camera more"))
    if n >= 3 and spread < MIN_AXIS_SPREAD:
        issues.append((DiversityIssue.ONE_AXIS,
                       f"the rotations between views turn about nearly one axis (axis spread {spread:.3f} < "
                       f"{MIN_AXIS_SPREAD}): translation along it is not observable; add views tilted about "
                       "another axis or rolled about the viewing direction"))
    return Diversity(n, max_rot, float(np.median(angles)) if angles.size else 0.0, spread, tuple(issues))
