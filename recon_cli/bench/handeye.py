"""Hand-eye calibration with imperfect robot poses, in simulation (``recon bench handeye``).

On the FR3 cell (a RealSense D405 on the flange) the generated board views
(:mod:`recon_cli.calibration.views`) are reached by posture-keeping joint goals
(:mod:`recon_cli.calibration.goals`) once; then per seed:

- a true mount X (the cell's, moved by 5 mm / 1 deg in a random direction) and board W
  (the cell's, moved by 5 mm / 1 deg);
- ``views`` of the reachable views, drawn at random;
- the robot's error: joint zero offsets uniform within +-0.05 deg (the measured joints are the
  true ones minus them) and a pose error per view, 0.5 mm / 0.05 deg per axis (normal), on
  the flange's true pose;
- the board pose each view measures: the chessboard corners projected through the true chain
  with the D405's intrinsics (1280 x 720), 0.2 px of Gaussian noise per coordinate, then
  cv2.solvePnP (corners outside the image dropped).

Every OpenCV method of calibrateHandEye and recon's refinements with pose errors (from the
best closed-form solution by the chain residual, :mod:`recon_cli.calibration.robust`: on the
board poses, with the joint offsets where the views determine them, on the corners, and on
the corners with the joint offsets under their prior) solve the same views; the table gives
each method's median mount error against the true X over the seeds, and how well each
refinement's stated 1-sigma matches its actual error.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from recon_cli.calibration.camera_file import CameraCalibration
from recon_cli.calibration.goals import board_view_goals
from recon_cli.calibration.handeye import (
    BoardObservation,
    HandEyeMethod,
    HandEyeSolution,
    solve_hand_eye,
    view_residuals,
)
from recon_cli.calibration.robust import (
    PosePrior,
    _exp,
    estimate_joint_offsets,
    refine_corners_with_pose_errors,
    refine_with_pose_errors,
)
from recon_cli.calibration.setups import CornerView, Setup
from recon_cli.calibration.views import BoardViewOptions, board_views
from recon_cli.errors import ReconError
from recon_cli.geometry.transforms import invert, pose_error
from recon_cli.perception.camera_model import Intrinsics
from recon_cli.perception.charuco import cell_board
from recon_cli.perception.sensor import cell_sensor
from recon_cli.robot.cell import Cell
from recon_cli.robot.description import CellConfig, CellName
from recon_cli.robot.kinematics import Kinematics

#: OpenCV's AX = XB methods compared
CLOSED_FORM = (HandEyeMethod.TSAI, HandEyeMethod.PARK, HandEyeMethod.HORAUD, HandEyeMethod.ANDREFF,
               HandEyeMethod.DANIILIDIS)
REFINED = "recon"  # the row of refine_with_pose_errors
JOINTS = "recon+joints"  # the row of estimate_joint_offsets
CORNERS = "recon-corners"  # the row of refine_corners_with_pose_errors
CORNERS_JOINTS = "recon-corners+joints"  # the same with the joint positions (offsets with their prior)
RECON_ROWS = (REFINED, JOINTS, CORNERS, CORNERS_JOINTS)


@dataclass(frozen=True)
class RobotErrors:
    """The simulated errors (1-sigma per axis unless said otherwise) [m, rad, px]."""

    joint_offset: float = math.radians(0.05)  # largest joint zero offset (uniform within +-)
    pose_translation: float = 0.5e-3
    pose_rotation: float = math.radians(0.05)
    pixel_noise: float = 0.2
    mount_error: tuple[float, float] = (5e-3, math.radians(1.0))  # true X and W off the cell's


@dataclass(frozen=True)
class Views:
    """Joint positions of the reachable board views of a cell, the camera and the board."""

    joints: np.ndarray  # (m, n_joints) [rad]
    world_T_flange: np.ndarray  # (m, 4, 4) at those joints (the model)
    flange_T_camera: np.ndarray  # (4, 4) the cell's mount
    world_T_marker: np.ndarray  # (4, 4) the cell's board
    K: np.ndarray  # (3, 3)
    image_size: tuple[int, int]  # width, height [px]
    corners: np.ndarray  # (c, 3) the chessboard corners in the marker frame [m]
    kin: Kinematics | None = field(repr=False, compare=False, default=None)  # the cell's


def fr3_views(generated: int = 28) -> Views:
    """The FR3 cell's reachable board views (of ``generated`` generated ones)."""
    cell = Cell(CellConfig(kind=CellName.parse("fr3")))
    cell_file = cell.config.cell_file
    board, sensor = cell_board(cell_file), cell_sensor(cell_file)
    view_list = board_views(board, BoardViewOptions(n=generated).for_camera(board, sensor))
    goals = board_view_goals(cell, [cell.view_pose(v) for v in view_list], np.random.default_rng(0))
    Q = np.array([g.q for g in goals if g.q is not None])
    fid = cell.kin.frame_id(cell_file.flange_link)
    F = np.array([cell.kin.frame_pose(q, fid) for q in Q])
    X = invert(F[0]) @ cell.kin.world_T_camera(Q[0])
    K = sensor.intrinsics()
    s = board.square_length
    corners = np.array([(i * s, j * s, 0.0) for j in range(1, board.squares_y) for i in range(1, board.squares_x)])
    return Views(Q, F, X, cell.world_T_marker.copy(), K.matrix(), (K.width, K.height), corners, cell.kin)


def _random_twist(rng: np.random.Generator, translation: float, rotation: float) -> np.ndarray:
    """A twist of the given size in a random direction."""
    a, b = rng.normal(size=3), rng.normal(size=3)
    return np.concatenate([a / np.linalg.norm(a) * translation, b / np.linalg.norm(b) * rotation])


def measured_corners(camera_T_marker: np.ndarray, views: Views, pixel_noise: float,
                     rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The board pose solvePnP finds from the corners projected with ``pixel_noise`` [px] of
    noise, with the corners it used: (camera_T_marker, object points (N, 3) [m], image points
    (N, 2) [px]); None when fewer than 12 corners are in the image."""
    import cv2

    P = views.corners @ camera_T_marker[:3, :3].T + camera_T_marker[:3, 3]
    uv = P @ views.K.T
    uv = uv[:, :2] / uv[:, 2:3]
    w, h = views.image_size
    inside = (P[:, 2] > 0.05) & (uv[:, 0] >= 0) & (uv[:, 0] < w) & (uv[:, 1] >= 0) & (uv[:, 1] < h)
    if inside.sum() < 12:
        return None
    img = uv[inside] + rng.normal(scale=pixel_noise, size=(int(inside.sum()), 2))
    rvec0, _ = cv2.Rodrigues(camera_T_marker[:3, :3])
    ok, rvec, tvec = cv2.solvePnP(views.corners[inside], img, views.K, None, rvec=rvec0.copy(),
                                  tvec=camera_T_marker[:3, 3].reshape(3, 1).copy(), useExtrinsicGuess=True,
                                  flags=cv2.SOLVEPNP_ITERATIVE)
    if not ok:
        return None
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(rvec)[0]
    T[:3, 3] = tvec.ravel()
    return T, views.corners[inside].copy(), img


def measured_board_pose(camera_T_marker: np.ndarray, views: Views, pixel_noise: float,
                        rng: np.random.Generator) -> np.ndarray | None:
    """The board pose of :func:`measured_corners` alone."""
    found = measured_corners(camera_T_marker, views, pixel_noise, rng)
    return None if found is None else found[0]


@dataclass(frozen=True)
class SimulatedSet:
    """One seed's views and its truth."""

    observations: list[BoardObservation]
    joints: np.ndarray  # (n, n_joints) measured [rad]
    flange_T_camera: np.ndarray  # the truth
    world_T_marker: np.ndarray
    joint_offsets: np.ndarray  # (n_joints,) true offsets [rad]: true joints = measured + offsets
    corner_views: list[CornerView] = field(default_factory=list)  # the same views with their corners
    true_camera_T_marker: list[np.ndarray] = field(default_factory=list)  # each view's board pose, no detection error



def simulate(views: Views, n: int, rng: np.random.Generator, errors: RobotErrors = RobotErrors(),  # noqa: B008
             pick: np.ndarray | None = None) -> SimulatedSet:
    """``n`` views (drawn from ``views`` unless ``pick`` says which) with the robot's and the
    detection's errors (module docstring)."""
    kin = views.kin
    assert kin is not None, "views without the cell's kinematics"
    fid = kin.frame_id(kin.cell.flange_link)
    X = views.flange_T_camera @ _exp(_random_twist(rng, *errors.mount_error))
    W = views.world_T_marker @ _exp(_random_twist(rng, *errors.mount_error))
    nj = views.joints.shape[1]
    offsets = np.asarray(rng.uniform(-errors.joint_offset, errors.joint_offset, size=nj), dtype=float)
    order = pick if pick is not None else rng.permutation(len(views.joints))
    camera = CameraCalibration(Intrinsics(views.image_size[0], views.image_size[1], views.K[0, 0], views.K[1, 1],
                                          views.K[0, 2], views.K[1, 2]))
    obs, joints, corner_views, truth = [], [], [], []
    for k in order:
        q_true = views.joints[k]
        noise = np.concatenate([rng.normal(scale=errors.pose_translation, size=3),
                                rng.normal(scale=errors.pose_rotation, size=3)])
        F_true = kin.frame_pose(q_true, fid) @ _exp(noise)
        B_true = invert(F_true @ X) @ W
        found = measured_corners(B_true, views, errors.pixel_noise, rng)
        if found is None:
            continue
        B, object_points, image_points = found
        q_meas = q_true - offsets
        F_meas = kin.frame_pose(q_meas, fid)
        obs.append(BoardObservation(f"view {k + 1}", F_meas, B))
        corner_views.append(CornerView(f"view {k + 1}", F_meas, B, object_points, image_points, camera,
                                       _pnp_rms(B, object_points, image_points, views.K)))
        joints.append(q_meas)
        truth.append(B_true)
        if len(obs) == n:
            break
    return SimulatedSet(obs, np.array(joints), X, W, offsets, corner_views, truth)


def _pnp_rms(camera_T_marker: np.ndarray, object_points: np.ndarray, image_points: np.ndarray,
             K: np.ndarray) -> float:
    """RMS reprojection error [px] of the corners through their own board pose."""
    P = object_points @ camera_T_marker[:3, :3].T + camera_T_marker[:3, 3]
    uv = P @ K.T
    d = uv[:, :2] / uv[:, 2:3] - image_points
    return float(np.sqrt(np.mean(np.sum(d * d, axis=1))))


def best_closed_form(observations: list[BoardObservation]) -> tuple[dict[HandEyeMethod, HandEyeSolution],
                                                                      HandEyeSolution]:
    """Every closed-form method's solution and the one with the smallest RMS chain residual
    (translation [m] + rotation [rad] x 0.5 m)."""
    solutions: dict[HandEyeMethod, HandEyeSolution] = {}
    for m in CLOSED_FORM:
        try:
            solutions[m] = solve_hand_eye(observations, m)
        except ReconError:
            continue

    def score(s: HandEyeSolution) -> float:
        r = view_residuals(observations, s.flange_T_camera, s.world_T_marker)
        return float(np.sqrt(np.mean([v.translation ** 2 + (0.5 * v.rotation) ** 2 for v in r])))

    return solutions, min(solutions.values(), key=score)


@dataclass(frozen=True)
class StudyRow:
    """One method over the seeds: median and 90th percentile of the mount error."""

    method: str
    median_mm: float
    median_deg: float
    p90_mm: float
    p90_deg: float


@dataclass(frozen=True)
class HandEyeStudy:
    """The study's table and what it measured per seed (errors [mm, deg])."""

    seeds: int
    views: int
    rows: list[StudyRow]
    errors: dict[str, np.ndarray]  # method -> (seeds, 2) [mm, deg]
    stated_mm_deg: np.ndarray  # (seeds, 2) the refinement's std_mm_deg
    ratio: tuple[float, float]  # recon's (refine_with_pose_errors) median over the best OpenCV method's (mm, deg)
    best_opencv: tuple[str, str]  # the best method by mm and by deg
    seconds: float
    refine_seconds: float  # mean per refinement
    ratios: dict[str, tuple[float, float]] = field(default_factory=dict)  # every recon row's ratio (mm, deg)
    stated: dict[str, np.ndarray] = field(default_factory=dict)  # recon row -> (seeds, 2) its std_mm_deg

    def table(self) -> str:
        lines = [f"{'method':<20} {'median mm':>10} {'median deg':>11} {'p90 mm':>8} {'p90 deg':>8}"]
        for r in self.rows:
            lines.append(f"{r.method:<20} {r.median_mm:>10.3f} {r.median_deg:>11.4f} {r.p90_mm:>8.3f} "
                         f"{r.p90_deg:>8.4f}")
        for name, ratio in (self.ratios or {REFINED: self.ratio}).items():
            lines.append(f"ratio {name} / best OpenCV: {ratio[0]:.2f} (mm, best {self.best_opencv[0]}), "
                         f"{ratio[1]:.2f} (deg, best {self.best_opencv[1]})")
        for name, values in (self.stated or {REFINED: self.stated_mm_deg}).items():
            stated = np.median(values, axis=0)
            spread = self.spread(name)
            lines.append(f"{name} stated 1-sigma (median): {stated[0]:.3f} mm / {stated[1]:.4f} deg; "
                         f"observed RMS error: {spread[0]:.3f} mm / {spread[1]:.4f} deg")
        return "\n".join(lines)

    def spread(self, method: str = REFINED) -> tuple[float, float]:
        """RMS of a recon row's mount error over the seeds [mm, deg] (what a 1-sigma should match)."""
        e = self.errors[method]
        return float(np.sqrt(np.mean(e[:, 0] ** 2))), float(np.sqrt(np.mean(e[:, 1] ** 2)))

    def to_dict(self) -> dict:
        return {"seeds": self.seeds, "views": self.views, "ratio": list(self.ratio),
                "best_opencv": list(self.best_opencv), "seconds": self.seconds,
                "refine_seconds": self.refine_seconds,
                "rows": [r.__dict__ for r in self.rows],
                "stated_mm_deg": self.stated_mm_deg.tolist(),
                "ratios": {k: list(v) for k, v in self.ratios.items()},
                "stated": {k: v.tolist() for k, v in self.stated.items()},
                "errors_mm_deg": {k: v.tolist() for k, v in self.errors.items()}}


def handeye_study(seeds: int = 20, views: int = 16, errors: RobotErrors = RobotErrors(),  # noqa: B008
                  cell_views: Views | None = None, first_seed: int = 0, prior: PosePrior | None = None,
                  loss: str = "linear", joints: bool = True, corners: bool = True) -> HandEyeStudy:
    """The study of the module docstring over seeds ``first_seed`` ... ``first_seed + seeds - 1``.
    ``cell_views``: the FR3 views (:func:`fr3_views`) when already made; ``prior``: the
    refinement's (default: the simulated pose errors, the detection std from the data);
    ``joints``: also estimate the joint zero offsets (row ``recon+joints``); ``corners``: also
    the corner-level refinement (rows ``recon-corners``, ``recon-corners+joints``, the latter
    when ``joints``)."""
    t0 = time.perf_counter()
    cell_views = cell_views or fr3_views()
    prior = prior or PosePrior(errors.pose_translation, errors.pose_rotation)
    names = [m.value for m in CLOSED_FORM] + [REFINED] + ([JOINTS] if joints else []) + \
        ([CORNERS] if corners else []) + ([CORNERS_JOINTS] if corners and joints else [])
    errs: dict[str, list[tuple[float, float]]] = {k: [] for k in names}
    stated: dict[str, list[tuple[float, float]]] = {k: [] for k in names if k in (REFINED, CORNERS, CORNERS_JOINTS)}
    t_refine = 0.0
    for seed in range(first_seed, first_seed + seeds):
        rng = np.random.default_rng(seed)
        sim = simulate(cell_views, views, rng, errors)
        solutions, best = best_closed_form(sim.observations)
        for m in CLOSED_FORM:
            s = solutions.get(m)
            e = pose_error(s.flange_T_camera, sim.flange_T_camera) if s is not None else (np.nan, np.nan)
            errs[m.value].append((e[0] * 1e3, math.degrees(e[1])))
        t1 = time.perf_counter()
        refined = refine_with_pose_errors(sim.observations, best, prior, loss=loss)
        t_refine += time.perf_counter() - t1
        e = pose_error(refined.solution.flange_T_camera, sim.flange_T_camera)
        errs[REFINED].append((e[0] * 1e3, math.degrees(e[1])))
        stated[REFINED].append(refined.std_mm_deg)
        if corners:
            runs = [(CORNERS, None)] + ([(CORNERS_JOINTS, sim.joints)] if joints else [])
            for name, q in runs:
                r = refine_corners_with_pose_errors(sim.corner_views, Setup.EYE_IN_HAND, best, prior, joints=q,
                                                    kin=cell_views.kin)
                e = pose_error(r.solution.flange_T_camera, sim.flange_T_camera)
                errs[name].append((e[0] * 1e3, math.degrees(e[1])))
                stated[name].append(r.std_mm_deg)
        if joints:
            assert cell_views.kin is not None
            found = estimate_joint_offsets(list(sim.joints), [o.camera_T_marker for o in sim.observations],
                                           cell_views.kin, best, prior)
            e = pose_error(found.solution.flange_T_camera, sim.flange_T_camera)
            errs[JOINTS].append((e[0] * 1e3, math.degrees(e[1])))
    arrays = {k: np.array(v) for k, v in errs.items()}
    rows = [StudyRow(k, *np.nanmedian(a, axis=0), *np.nanpercentile(a, 90, axis=0)) for k, a in arrays.items()]
    opencv = [r for r in rows if r.method not in RECON_ROWS]
    best_mm = min(opencv, key=lambda r: r.median_mm)
    best_deg = min(opencv, key=lambda r: r.median_deg)
    ratios = {r.method: (r.median_mm / best_mm.median_mm, r.median_deg / best_deg.median_deg)
              for r in rows if r.method in RECON_ROWS}
    return HandEyeStudy(seeds, views, rows, arrays, np.array(stated[REFINED]), ratios[REFINED],
                        (best_mm.method, best_deg.method), time.perf_counter() - t0, t_refine / max(seeds, 1),
                        ratios, {k: np.array(v) for k, v in stated.items()})
