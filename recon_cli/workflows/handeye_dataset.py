"""``recon calibrate handeye --dataset DIR``: hand-eye calibration from a data set made by
anyone (board images and the robot pose of each; recon_cli.calibration.dataset), eye-in-hand
or eye-to-hand (recon_cli.calibration.setups).

Writes into the run folder::

    <out>/handeye.json            the calibration, the verdict, every candidate's held-out
                                  errors (per view and summarised), every view (reprojection,
                                  chain residual, agreement with its own board pose, outlier),
                                  the mapping and the sources of board and camera
    <out>/hand_eye.yaml           eye-in-hand: flange_T_camera as a station file's hand_eye block,
                                  and its joint_offsets line when the calibration written has the
                                  joints' zero offsets (only when the verdict is "trusted", or
                                  with accept)
    <out>/handeye_residuals.png   per view: reprojection RMS, chain residual [mm], [deg], and the
                                  held-out error of the written candidate [mm], [deg]

The candidates are every OpenCV method, the reprojection refinement and the refinement with
flange pose errors (recon_cli.calibration.robust), both from the closed-form method with the
smallest held-out error (or from ``method`` when given), and with the joint positions logged
beside the poses and a cell that explains them, the mount with the joints' zero offsets (its
views' poses then the cell's forward kinematics of the corrected joints); the one written has the smallest
held-out error (recon_cli.calibration.holdout), not the smallest in-sample residual. The
verdict (recon_cli.calibration.verdict) is computed on it; a calibration that is not trusted
raises :class:`~recon_cli.calibration.verdict.NotTrusted` after the report is written,
unless ``accept``.

Nothing is written when fewer than 3 views are usable, or when their robot poses cannot
determine the calibration (every view at nearly one orientation, or every rotation between
them about one axis): both are checked on the robot poses before any image is decoded, and
again on the usable views before any solver runs. An OpenCV method that finds no solution is
reported as such; when it is the method to write, the calibration is refused.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from recon_cli.calibration.camera_file import load_camera_file
from recon_cli.calibration.dataset import (
    AngleUnit,
    CameraNumbers,
    CameraSource,
    DatasetSpec,
    DatasetView,
    LengthUnit,
    MatrixOrder,
    PoseFormat,
    PoseMapping,
    QuaternionOrder,
    camera_numbers,
    dataset_views,
    detect_format,
    read_dataset,
    read_mapping,
)
from recon_cli.calibration.handeye import (
    MIN_VIEWS,
    BoardObservation,
    Diversity,
    HandEyeMethod,
    HandEyeSolution,
    SolverFailed,
    ViewResidual,
    pose_diversity,
    solve_hand_eye,
)
from recon_cli.calibration.holdout import LEVER, HeldOut, best, leave_one_out, preferred
from recon_cli.calibration.intrinsics import (
    BoardView,
    DistortionModel,
    IntrinsicsResult,
    SkippedImage,
    calibrate_intrinsics,
)
from recon_cli.calibration.logged_joints import JOINT_KEYS, JointChain, match_chain, record_joints
from recon_cli.calibration.robust import JointOffsets, PosePrior, estimate_joint_offsets, refine_with_pose_errors
from recon_cli.calibration.setups import (
    CornerView,
    Refinement,
    Setup,
    SetupSolution,
    chain_observations,
    chain_residuals,
    outlier_views,
    pnp_agreement,
    refine,
    reprojection_errors,
    rms,
    solve,
)
from recon_cli.calibration.station_update import hand_eye_block
from recon_cli.calibration.verdict import NotTrusted, Verdict, check_observations, detection_precision, judge
from recon_cli.config import CellConfig
from recon_cli.console import write_json
from recon_cli.errors import InputError, ReconError
from recon_cli.geometry.transforms import invert, pose_error
from recon_cli.inputs.images import read_color
from recon_cli.outputs import atomic_write, atomic_write_text
from recon_cli.perception.boards import Board, board_dict, opencv_frame_fields
from recon_cli.perception.camera_model import Intrinsics
from recon_cli.perception.charuco import cell_board
from recon_cli.robot.description import expand_urdf
from recon_cli.robot.kinematics import Kinematics

Progress = Callable[[str, int, int], None]


@dataclass(frozen=True)
class DatasetHandEyeOptions:
    """What ``recon calibrate handeye --dataset`` does.

    dataset: the data set folder (or its index or CSV file)
    mapping: a mapping file (schemas/handeye_dataset.schema.json); the options below override it
    setup: None: the mapping's, else the index file's (static_camera), else eye-in-hand
    camera_file / intrinsics (fx, fy, cx, cy [px]): the camera; None: the mapping's or the index file's
    board: None: the mapping's, else the index file's, else the cell's
    cell: the cell whose kinematics turn joint positions into flange poses
    drop_outliers: calibrate again without the views flagged as outliers
    method: None: the candidate with the smallest held-out error; a method: it, or its
        refinement when that predicts held-out views better (refine)
    accept: write hand_eye.yaml and return normally also when the verdict is "not trusted"
    camera_from_views: calibrate the camera (intrinsics, k1 k2 p1 p2) from the same photos
        first, the given intrinsics as the start (True), never (False); None: when no camera is
        given, or when the given camera has no distortion and a camera calibrated from the
        other photos explains each photo clearly better than it (:func:`camera_held_out`)
    """

    dataset: Path
    out: Path
    mapping: Path | None = None
    setup: Setup | None = None
    method: HandEyeMethod | None = None
    refine: bool = True
    camera_file: Path | None = None
    intrinsics: tuple[float, ...] | None = None  # fx, fy, cx, cy
    board: Board | None = None
    cell: CellConfig = field(default_factory=CellConfig)
    pose_format: PoseFormat | None = None
    length_unit: LengthUnit | None = None
    angle_unit: AngleUnit | None = None
    quaternion_order: QuaternionOrder | None = None
    matrix_order: MatrixOrder | None = None
    drop_outliers: bool = False
    min_corners: int = 8
    accept: bool = False
    camera_from_views: bool | None = None  # None: when no camera is given, or it is held out as worse


@dataclass(frozen=True)
class ViewReport:
    """One usable view under the written calibration: its corners' reprojection RMS [px],
    chain residual (translation [m], rotation [rad]), its own board pose against the
    calibration's (translation [m], rotation [rad]); whether it took part."""

    name: str
    corners: int
    pnp_rms: float
    reprojection_rms: float
    chain: ViewResidual
    pnp_difference: tuple[float, float]
    used: bool
    outlier: str | None
    pose_source: str


@dataclass(frozen=True)
class MethodReport:
    """An OpenCV method's own solution on the views used: chain residual RMS [m, rad],
    reprojection RMS [px], and its difference from the written solution in X [m, rad]."""

    solution: SetupSolution
    chain_rms: tuple[float, float]
    reprojection_rms: float
    vs_written: tuple[float, float]


@dataclass(frozen=True)
class Candidate:
    """A calibration judged on held-out views: its solution on every view used and its
    leave-one-view-out errors (recon_cli.calibration.holdout)."""

    name: str
    solution: SetupSolution
    held_out: HeldOut


@dataclass(frozen=True)
class DatasetHandEyeResult:
    folder: Path
    dataset: Path
    layout: str
    setup: Setup
    solution: SetupSolution  # written
    refinement: Refinement | None
    views: list[ViewReport]
    methods: dict[HandEyeMethod, MethodReport]
    diversity: Diversity
    skipped: list[SkippedImage]
    mapping: PoseMapping
    board: Board
    sources: dict[str, str]  # where the set-up, board and camera came from
    seconds: float
    method_failures: dict[HandEyeMethod, str] = field(default_factory=dict)  # OpenCV methods without a solution
    candidates: list[Candidate] = field(default_factory=list)  # every candidate, by held-out error
    chosen: str = ""  # the candidate written
    verdict: Verdict | None = None
    mount_std: tuple[float, float] | None = None  # [mm, deg] of the pose-error refinement, when it ran

    @property
    def written(self) -> Candidate:
        return next(c for c in self.candidates if c.name == self.chosen)

    @property
    def used(self) -> list[ViewReport]:
        return [v for v in self.views if v.used]

    @property
    def dropped(self) -> list[str]:
        return [v.name for v in self.views if not v.used]

    @property
    def outliers(self) -> dict[str, str]:
        return {v.name: v.outlier for v in self.views if v.outlier is not None}

    written_converged: bool = True  # the written candidate's solver stopped on its tolerances
    camera_fit: IntrinsicsResult | None = None  # the camera calibrated from the same photos
    camera_check: CameraCheck | None = None  # the given camera against one calibrated from the photos
    joint_offsets: dict | None = None  # the joint zero offsets' candidate (offsets [deg], std, used), when it ran

    @property
    def converged(self) -> bool:
        """The written candidate's refinement stopped on its tolerances (a closed form: True)."""
        return self.written_converged

    @property
    def reprojection_rms(self) -> float:
        """RMS over every corner of the views used [px] (the distance in the image)."""
        used = self.used
        return float(np.sqrt(sum(v.reprojection_rms**2 * v.corners for v in used) / max(sum(v.corners for v in used),
                                                                                          1)))

    @property
    def cost_per_residual(self) -> float:
        """ros-industrial/industrial_calibration's reported error: sqrt(Ceres' final cost
        (half the sum of squares) per scalar residual (two per corner)) = RMS / 2 [px]."""
        return self.reprojection_rms / 2.0

    @property
    def chain_rms(self) -> tuple[float, float]:
        t = np.array([v.chain.translation for v in self.used])
        r = np.array([v.chain.rotation for v in self.used])
        return float(np.sqrt(np.mean(t**2))), float(np.sqrt(np.mean(r**2)))

    @property
    def chain_max(self) -> tuple[float, float]:
        return max(v.chain.translation for v in self.used), max(v.chain.rotation for v in self.used)

    @property
    def pnp_mean(self) -> tuple[float, float]:
        """Mean over the views used of the calibration's camera_T_board against each image's
        own (solvePnP) [m, rad]: industrial_calibration's check."""
        used = self.used
        return (float(np.mean([v.pnp_difference[0] for v in used])),
                float(np.mean([v.pnp_difference[1] for v in used])))

    def to_dict(self) -> dict:
        t, r = self.chain_rms
        tm, rm = self.chain_max
        pt, pr = self.pnp_mean
        return {
            "setup": self.setup.value, "method": self.solution.method.value, "refined": self.solution.refined,
            "candidate": self.chosen, "verdict": None if self.verdict is None else self.verdict.to_dict(),
            "selection": f"smallest held-out score (RMS over the views of sqrt(t^2 + ({LEVER:g} m x r)^2), t and r "
                         "the board pose predicted by the calibration of the other views against the image's own); "
                         "the refinement that models the robot's errors instead when its score is within one "
                         "standard error of the smallest",
            "held_out": [c.held_out.to_dict() for c in self.candidates],
            "mount_std_mm_deg": None if self.mount_std is None else list(self.mount_std),
            "camera_from_views": None if self.camera_fit is None else self.camera_fit.to_dict(),
            "camera_check": None if self.camera_check is None else self.camera_check.to_dict(),
            "joint_offsets": self.joint_offsets,
            "dataset": str(self.dataset), "layout": self.layout, "sources": self.sources,
            **{name: T for name, T in self.solution.named().items()},
            "views_used": len(self.used), "dropped": self.dropped,
            "refinement": None if self.refinement is None else {
                "converged": self.refinement.converged, "message": self.refinement.message,
                "evaluations": self.refinement.evaluations, "rms_before_px": self.refinement.rms_before,
                "rms_after_px": self.refinement.rms_after},
            "reprojection": {"rms_px": self.reprojection_rms, "cost_per_residual_px": self.cost_per_residual},
            "consistency": {"fixed": self.setup.fixed, "translation_rms_m": t, "rotation_rms_rad": r,
                            "translation_max_m": tm, "rotation_max_rad": rm},
            "pnp_agreement": {"translation_mean_m": pt, "rotation_mean_rad": pr},
            "views": [{"name": v.name, "used": v.used, "corners": v.corners, "pose": v.pose_source,
                       "pnp_rms_px": v.pnp_rms, "reprojection_rms_px": v.reprojection_rms,
                       "chain_translation_m": v.chain.translation, "chain_rotation_rad": v.chain.rotation,
                       "pnp_translation_m": v.pnp_difference[0], "pnp_rotation_rad": v.pnp_difference[1],
                       "outlier": v.outlier} for v in self.views],
            "methods": {m.value: {**{name: T for name, T in s.solution.named().items()},
                                  "chain_rms_m_rad": list(s.chain_rms), "reprojection_rms_px": s.reprojection_rms,
                                  "vs_written_m_rad": list(s.vs_written)} for m, s in self.methods.items()},
            "methods_failed": {m.value: why for m, why in self.method_failures.items()},
            "diversity": self.diversity.to_dict(),
            "skipped": [{"name": s.name, "reason": s.reason} for s in self.skipped],
            "mapping": self.mapping.to_dict(), "board": board_dict(self.board),
            **opencv_frame_fields(self.board, self.solution.W, f"{self.setup.unknowns[1]}_opencv"),
            "seconds": self.seconds,
        }


def _camera(opt: DatasetHandEyeOptions, spec: DatasetSpec, hint: CameraNumbers | None,
            hint_source: str) -> tuple[CameraSource, str]:
    if opt.camera_file is not None:
        return load_camera_file(opt.camera_file), f"--camera-file {opt.camera_file}"
    if opt.intrinsics is not None:
        camera = camera_numbers(opt.intrinsics, "--intrinsics")
        return camera, ("--intrinsics" if any(camera.distortion) or len(opt.intrinsics) > 4
                        else "--intrinsics (no distortion)")
    if spec.camera is not None:
        return spec.camera, f"the mapping {spec.source}"
    if hint is not None:
        return hint, hint_source
    raise InputError("the camera's intrinsics are not known for the data set",
                     hint="pass --camera-file FILE (recon calibrate intrinsics writes one) or --intrinsics "
                          "fx,fy,cx,cy, or give camera: in the mapping file")


#: views a camera calibration from the hand-eye photos needs
MIN_CAMERA_VIEWS = 8


def guessed_camera(image: Path) -> CameraNumbers:
    """A start for the board poses of a camera calibrated from the views: the focal length
    the image's larger side [px], the principal point in the image's centre."""
    h, w = read_color(image).shape[:2]
    f = float(max(w, h))
    return CameraNumbers(f, f, (w - 1) / 2.0, (h - 1) / 2.0)


#: [rad] the joint zero offsets estimated from logged joints stay within +- this
OFFSET_BOUND = float(np.radians(0.5))
#: a camera calibrated from the photos replaces a given one without distortion when its
#: held-out reprojection RMS is below this share of the given camera's
CAMERA_GAIN = 0.8


@dataclass(frozen=True)
class CameraCheck:
    """The given camera against one calibrated from the photos, on photos each calibration did
    not see: the RMS over the views of each view's own board-pose reprojection RMS [px] with the
    given camera, and with the camera calibrated from the other views (leave-one-view-out)."""

    given_px: float
    held_out_px: float
    views: int

    @property
    def calibrate(self) -> bool:
        """Whether the camera calibrated from the photos explains unseen photos clearly better."""
        return self.held_out_px < CAMERA_GAIN * self.given_px

    def to_dict(self) -> dict:
        return {"given_rms_px": self.given_px, "held_out_rms_px": self.held_out_px, "views": self.views,
                "calibrated_from_views": self.calibrate,
                "rule": f"calibrate from the views when the held-out RMS is below {CAMERA_GAIN:g} x the given camera's"}


def _board_views(views: list[CornerView]) -> list[BoardView]:
    K0 = views[0].camera.intrinsics
    return [BoardView(v.name, (K0.width, K0.height), np.arange(v.corners), v.object_points, v.image_points, 0)
            for v in views]


def _board_pose(v: CornerView, K: np.ndarray, dist: np.ndarray) -> tuple[np.ndarray, float]:
    """The view's board pose with the camera (K, dist), from its current one, and its
    reprojection RMS [px]."""
    import cv2

    rvec = cv2.Rodrigues(np.ascontiguousarray(v.camera_T_board[:3, :3]))[0]
    tvec = v.camera_T_board[:3, 3].reshape(3, 1).copy()
    _, rvec, tvec = cv2.solvePnP(v.object_points, v.image_points, K, dist, rvec=rvec, tvec=tvec,
                                 useExtrinsicGuess=True, flags=cv2.SOLVEPNP_ITERATIVE)
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(rvec)[0]
    T[:3, 3] = np.asarray(tvec).reshape(3)
    uv, _ = cv2.projectPoints(v.object_points.reshape(-1, 1, 3), rvec, tvec, K, dist)
    return T, float(np.sqrt(np.mean(np.sum((uv.reshape(-1, 2) - v.image_points) ** 2, axis=1))))


def camera_held_out(views: list[CornerView]) -> CameraCheck:
    """The views' given camera against the camera (intrinsics, k1 k2 p1 p2) calibrated from
    the other views, the given intrinsics as the start, on each view in turn."""
    given = np.array([v.pnp_rms for v in views])
    board_views = _board_views(views)
    initial = views[0].camera.intrinsics
    held = []
    for i, v in enumerate(views):
        fit = calibrate_intrinsics(board_views[:i] + board_views[i + 1:], DistortionModel.K1K2P, initial=initial)
        held.append(_board_pose(v, fit.camera.intrinsics.matrix(), fit.camera.distortion_array)[1])
    return CameraCheck(float(np.sqrt(np.mean(given ** 2))), float(np.sqrt(np.mean(np.square(held)))), len(views))


def camera_from_views(views: list[CornerView], initial: Intrinsics | None) -> tuple[list[CornerView], IntrinsicsResult]:
    """Intrinsics and distortion (k1, k2, p1, p2) from the views' corners (cv2.calibrateCamera
    by recon_cli.calibration.intrinsics, ``initial`` as the start, else OpenCV's own), then
    every view's board pose again (solvePnP with the calibrated camera, from its pose)."""
    if len(views) < MIN_CAMERA_VIEWS:
        raise InputError(f"calibrating the camera from the photos needs {MIN_CAMERA_VIEWS} or more views of the "
                         f"board, {len(views)} are usable", hint="give the camera (--camera-file or --intrinsics), "
                                                                 "or add views")
    fit = calibrate_intrinsics(_board_views(views), DistortionModel.K1K2P, initial=initial)
    K, dist = fit.camera.intrinsics.matrix(), fit.camera.distortion_array
    out = []
    for v in views:
        T, rms_px = _board_pose(v, K, dist)
        out.append(dataclasses.replace(v, camera=fit.camera, camera_T_board=T, pnp_rms=rms_px))
    return out, fit


def _views_report(views: list[CornerView], solution: SetupSolution, used: set[str],
                  outliers: dict[str, str]) -> list[ViewReport]:
    errors = reprojection_errors(views, solution)
    chain = chain_residuals(views, solution)
    pnp = pnp_agreement(views, solution)
    return [ViewReport(v.name, v.corners, v.pnp_rms, rms(e), c, p, v.name in used, outliers.get(v.name), v.pose_source)
            for v, e, c, p in zip(views, errors, chain, pnp, strict=True)]


def _method_report(views: list[CornerView], s: SetupSolution, written: SetupSolution) -> MethodReport:
    chain = chain_residuals(views, s)
    t = float(np.sqrt(np.mean([c.translation**2 for c in chain])))
    r = float(np.sqrt(np.mean([c.rotation**2 for c in chain])))
    return MethodReport(s, (t, r), rms(reprojection_errors(views, s)), pose_error(s.X, written.X))


def _skipped_text(skipped: list[SkippedImage], shown: int = 5) -> str:
    """ (skipped: name: reason; ...; and N more)"""
    if not skipped:
        return ""
    more = f"; and {len(skipped) - shown} more" if len(skipped) > shown else ""
    return " (skipped: " + "; ".join(f"{s.name}: {s.reason}" for s in skipped[:shown]) + more + ")"


#: the reader's words for a pose in another unit than the mapping says (recon_cli.calibration.dataset)
UNIT_MISMATCH = ("it looks like millimetres", "it looks like degrees")


def check_units(skipped: list[SkippedImage], usable: int) -> None:
    """Refuse a data set whose poses mix units: some views skipped because their pose looks
    like millimetres (or degrees) while others read as metres (radians). Calibrating the
    rest would hide a logging mistake that likely affects every view."""
    mixed = [s for s in skipped if any(m in s.reason for m in UNIT_MISMATCH)]
    if mixed and usable:
        raise InputError(f"the poses mix units: {len(mixed)} views look like another unit than the mapping says "
                         f"({mixed[0].name}: {mixed[0].reason}), {usable} read as it says",
                         hint="log every pose in one unit, or give --length-unit/--angle-unit for all of them")


def check_solvable(base_T_flange: list[np.ndarray], views: int, skipped: list[SkippedImage], setup: Setup,
                   dataset: Path) -> None:
    """Refuse, before any solver runs, a data set whose usable robot poses cannot determine
    the calibration: fewer than MIN_VIEWS, or degenerate motion (every view at nearly one
    orientation, every rotation between them about one axis). One line: the usable views,
    what is needed, the views skipped and why."""
    n = len(base_T_flange)
    if n < MIN_VIEWS:
        raise InputError(f"{n} of the {views} views of {dataset} are usable; hand-eye calibration needs {MIN_VIEWS} "
                         f"or more{_skipped_text(skipped)}",
                         hint="fix what the reasons say (docs/calibration.md, Calibrating from your own data)")
    reason = pose_diversity([setup.chain_pose(T) for T in base_T_flange]).degenerate
    if reason is not None:
        raise InputError(f"the {n} usable views of {dataset} cannot determine the hand-eye calibration: {reason}"
                         f"{_skipped_text(skipped)}",
                         hint="add views with the flange turned about two or more different axes, by 20° or more "
                              "(docs/calibration.md)")


def solve_methods(views: list[CornerView], setup: Setup, chosen: HandEyeMethod | None
                  ) -> tuple[dict[HandEyeMethod, SetupSolution], dict[HandEyeMethod, str]]:
    """Every OpenCV method's solution, and the methods that find none with OpenCV's reason;
    when the chosen one finds none, one line naming those that did."""
    solutions: dict[HandEyeMethod, SetupSolution] = {}
    failures: dict[HandEyeMethod, str] = {}
    for m in HandEyeMethod:
        try:
            solutions[m] = solve(views, setup, m)
        except SolverFailed as exc:
            failures[m] = exc.reason
            if m is chosen:
                refusal = exc
    if chosen in failures:
        others = ", ".join(m.value for m in solutions)
        raise InputError(refusal.message, hint=(f"choose --method {next(iter(solutions)).value} ({others} found a "
                                                "solution), or add views" if solutions else "add views")
                         + " turned by 20° or more about other axes")
    return solutions, failures


def run_handeye_dataset(opt: DatasetHandEyeOptions, progress: Progress | None = None) -> DatasetHandEyeResult:
    """Read the data set, calibrate, report, write (see the module docstring)."""
    t0 = time.perf_counter()
    spec = read_mapping(opt.mapping, opt.dataset) if opt.mapping is not None else DatasetSpec()
    mapping = spec.mapping.overridden(pose_format=opt.pose_format, length_unit=opt.length_unit,
                                      angle_unit=opt.angle_unit, quaternion_order=opt.quaternion_order,
                                      matrix_order=opt.matrix_order)
    dataset = read_dataset(opt.dataset, spec)
    hints = dataset.hints
    sources = {}
    setup = opt.setup or spec.setup or hints.setup or Setup.EYE_IN_HAND
    sources["setup"] = ("--setup" if opt.setup else "the mapping" if spec.setup else
                        "the index file (static_camera)" if hints.setup else "the default")
    if opt.board is not None:
        board, sources["board"] = opt.board, "--board-spec"
    elif spec.board is not None:
        board, sources["board"] = spec.board, f"the mapping {spec.source}"
    elif hints.board is not None:
        board, sources["board"] = hints.board, "the index file's target_finder"
    else:
        board = cell_board(opt.cell.cell_file)
        sources["board"] = f"the cell {opt.cell.cell_file.name}'s ({opt.cell.cell_file.board_file})"
    no_camera = opt.camera_file is None and opt.intrinsics is None and spec.camera is None and hints.camera is None
    guessed = no_camera and opt.camera_from_views is not False and bool(dataset.views)
    camera: CameraSource
    if guessed:
        camera, sources["camera"] = guessed_camera(dataset.views[0].image), "calibrated from the views"
    else:
        camera, sources["camera"] = _camera(opt, spec, hints.camera, hints.camera_source)
    if mapping.pose_format is None and dataset.views:
        try:
            mapping = detect_format(dataset.views[0].record, mapping, dataset.views[0].where)
        except ReconError:
            pass  # every view says why
    kin = None
    if mapping.pose_format is PoseFormat.JOINTS:
        kin = Kinematics(expand_urdf(opt.cell), opt.cell.cell_file)
        sources["kinematics"] = f"the cell {opt.cell.cell_file.name}, flange {opt.cell.cell_file.flange_link}"
    total = len(dataset.views) + len(dataset.skipped)

    def poses_read(poses: list[np.ndarray], skipped: list[SkippedImage]) -> None:
        check_solvable(poses, total, skipped, setup, opt.dataset)

    found = dataset_views(dataset, mapping, board, camera, kin, opt.min_corners, progress, poses_read)
    views = found.views
    check_units(found.skipped, len(views))
    check_solvable([v.base_T_flange for v in views], total, found.skipped, setup, opt.dataset)
    camera_fit = None
    camera_check = None
    if (opt.camera_from_views is None and not guessed and len(views) >= MIN_CAMERA_VIEWS
            and not np.any(views[0].camera.distortion_array)):
        camera_check = camera_held_out(views)
    if guessed or opt.camera_from_views or (camera_check is not None and camera_check.calibrate):
        given = sources["camera"]
        views, camera_fit = camera_from_views(views, None if guessed else views[0].camera.intrinsics)
        sources["camera"] = (f"calibrated from the {len(views)} views" if guessed else
                             f"calibrated from the {len(views)} views, starting from {given}")
        if camera_check is not None:
            sources["camera"] += (f" (it has no distortion; held out, {camera_check.held_out_px:.2f} px against "
                                  f"{camera_check.given_px:.2f} px)")
    observations = chain_observations(views, setup)
    check_observations(observations, pose_diversity([o.world_T_flange for o in observations]), str(opt.dataset))
    # outliers by the closed chains of OpenCV's solution: the refinement would spread one bad
    # view's error over all of them
    methods, failures = solve_methods(views, setup, opt.method)
    reference = opt.method or (HandEyeMethod.TSAI if HandEyeMethod.TSAI in methods else next(iter(methods)))
    outliers = outlier_views(chain_residuals(views, methods[reference]))
    kept = views
    if opt.drop_outliers and outliers:
        kept = [v for v in views if v.name not in outliers]
        if len(kept) < MIN_VIEWS:
            raise InputError(f"dropping the {len(outliers)} outlier views leaves {len(kept)} of {len(views)}; "
                             f"hand-eye calibration needs {MIN_VIEWS} or more",
                             hint="calibrate without --drop-outliers, or add views")
        reason = pose_diversity([setup.chain_pose(v.base_T_flange) for v in kept]).degenerate
        if reason is not None:
            raise InputError(f"dropping the {len(outliers)} outlier views leaves {len(kept)} views that cannot "
                             f"determine the hand-eye calibration: {reason}",
                             hint="calibrate without --drop-outliers, or add views")
        methods, failures = solve_methods(kept, setup, opt.method)
    kept_observations = chain_observations(kept, setup)
    logged = _logged_joints(dataset.views, kept, opt.cell, kin, sources) \
        if opt.refine and setup is Setup.EYE_IN_HAND else None
    judged = judge_candidates(kept, setup, methods, opt.method, opt.refine, progress, logged)
    chosen = judged.chosen
    solution = chosen.solution
    used = {v.name for v in kept}
    method_reports = {m: _method_report(kept, s, solution) for m, s in methods.items()}
    if judged.offsets is not None:  # the calibration written sees the robot with its joints corrected
        assert logged is not None
        chain, q, d = logged.chain, logged.q, judged.offsets
        corrected = {v.name: dataclasses.replace(v, base_T_flange=chain.logged(q[v.name] + d)) for v in kept}
        kept = [corrected[v.name] for v in kept]
        views = [corrected.get(v.name, v) for v in views]
        kept_observations = chain_observations(kept, setup)
    reports = _views_report(views, solution, used, outliers)
    diversity = pose_diversity([setup.chain_pose(v.base_T_flange) for v in kept])
    verdict = judge(kept_observations, HandEyeSolution(solution.method, solution.X, solution.W), chosen.held_out,
                    diversity, eye_in_hand=setup is Setup.EYE_IN_HAND, precision=detection_precision(kept))
    result = DatasetHandEyeResult(Path(opt.out), Path(opt.dataset), dataset.layout, setup, solution,
                                  judged.refinement, reports, method_reports, diversity, found.skipped, found.mapping,
                                  board, sources, time.perf_counter() - t0, failures, judged.candidates, chosen.name,
                                  verdict, judged.mount_std, judged.converged[chosen.name], camera_fit,
                                  camera_check, judged.joint_offsets)
    out = Path(opt.out)
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "handeye.json", result.to_dict())
    if setup is Setup.EYE_IN_HAND and (verdict.trusted or opt.accept):
        comment = (f"recon calibrate handeye --dataset, {time.strftime('%Y-%m-%d %H:%M')}, {chosen.name}, "
                   f"{len(kept)} views, held-out error {chosen.held_out.rms[0] * 1e3:.2f} mm RMS, "
                   f"{'trusted' if verdict.trusted else 'NOT trusted (accepted)'}")
        mount, line = solution.X, ""
        if judged.offsets is not None and judged.joint_offsets is not None and logged is not None:
            # the station's hand_eye is on the cell's flange, where the joints' offsets were found
            mount = logged.chain.right @ solution.X
            comment += f", on the cell's flange {opt.cell.cell_file.flange_link}"
            line = joint_offsets_line(judged.joint_offsets["station_values"])
        atomic_write_text(out / "hand_eye.yaml", hand_eye_block(mount, comment) + line)
    atomic_write(out / "handeye_residuals.png", lambda tmp: plot_dataset_residuals(result, tmp))
    if not verdict.trusted and not opt.accept:
        raise NotTrusted(verdict, hint=f"nothing written but the report {out / 'handeye.json'}; --accept writes it "
                                       "anyway (docs/calibration.md)")
    return result


def _logged_joints(records: list[DatasetView], views: list[CornerView], cell: CellConfig, kin: Kinematics | None,
                   sources: dict[str, str]) -> LoggedJoints | None:
    """The joint positions the pose files hold beside the poses, with the cell's kinematics
    matched to the poses; None (and in ``sources["joints"]`` why) when there are none or the
    cell does not explain the poses."""
    by_name = {r.name: r.record for r in records}
    first = by_name.get(views[0].name) if views else None
    if not isinstance(first, dict) or not any(isinstance(first.get(k), list) for k in JOINT_KEYS):
        return None
    if kin is None:
        kin = Kinematics(expand_urdf(cell), cell.cell_file)
    read = {v.name: record_joints(by_name.get(v.name), kin.nq) for v in views}
    q = {name: value for name, value in read.items() if value is not None}
    if len(q) < len(views):
        missing = next(name for name in read if name not in q)
        held = next((len(first[k]) for k in JOINT_KEYS if isinstance(first.get(k), list)), 0)
        sources["joints"] = (f"not used: {len(views) - len(q)} of {len(views)} views have no {kin.nq} joint "
                             f"positions for the cell {cell.cell_file.name} (e.g. {missing}; the first holds "
                             f"{held}); pass the --cell the poses were logged with")
        return None
    chain = match_chain(kin, [q[v.name] for v in views], [v.base_T_flange for v in views])
    if isinstance(chain, str):
        sources["joints"] = f"not used: {chain}; pass the --cell the poses were logged with"
        return None
    sources["joints"] = (f"the pose files' joint positions, the cell {cell.cell_file.name}'s kinematics "
                         f"(flange {cell.cell_file.flange_link}) matched to the logged poses")
    return LoggedJoints(chain, q)


@dataclass(frozen=True)
class JudgedCandidates:
    """Every candidate with its held-out errors, the one with the smallest held-out score,
    the reprojection refinement on every view (when it ran), whether each candidate's
    solver converged, and the pose-error refinement's mount std [mm, deg]."""

    candidates: list[Candidate]
    chosen: Candidate
    refinement: Refinement | None
    converged: dict[str, bool]
    mount_std: tuple[float, float] | None
    joint_offsets: dict | None = None  # the joint offsets' candidate: the offsets [deg], their std, which joints
    offsets: np.ndarray | None = None  # its offsets [rad, m per joint] when it is the candidate chosen


@dataclass(frozen=True)
class LoggedJoints:
    """The joint positions logged beside the views' poses (by view name) and the cell's
    kinematics matched to those poses (:mod:`recon_cli.calibration.logged_joints`)."""

    chain: JointChain
    q: dict[str, np.ndarray]


def judge_candidates(views: list[CornerView], setup: Setup, methods: dict[HandEyeMethod, SetupSolution],
                     start: HandEyeMethod | None, refine_too: bool, progress: Progress | None = None,
                     joints: LoggedJoints | None = None) -> JudgedCandidates:
    """Leave-one-view-out errors of every OpenCV method that solved the views and, with
    ``refine_too``, of the reprojection refinement and the refinement with flange pose errors
    from ``start`` (None: the closed-form method with the smallest held-out score), and with
    ``joints`` (a camera on the flange) of the joint zero offsets estimated with the mount
    (:func:`_joint_offsets_candidate`: written with the offsets, which a station file's
    ``joint_offsets`` adds to the joints its robot reports). With ``start`` given, the
    candidate written is ``start`` or one of its refinements; else any."""
    observations = chain_observations(views, setup)
    by_name = {v.name: v for v in views}
    with_joints = refine_too and joints is not None and setup is Setup.EYE_IN_HAND
    total = len(methods) + (2 if refine_too else 0) + (1 if with_joints else 0)
    done = 0

    def step() -> None:
        nonlocal done
        done += 1
        if progress is not None:
            progress("held-out views", done, total)

    def closed_form(m: HandEyeMethod):
        return lambda o: solve_hand_eye(o, m)

    candidates = []
    for m, s in methods.items():
        candidates.append(Candidate(m.value, s, leave_one_out(observations, closed_form(m), m.value)))
        step()
    converged = {c.name: True for c in candidates}
    first = start or HandEyeMethod(best([c.held_out for c in candidates]).candidate)
    pool = [c for c in candidates if start is None or c.name == start.value]
    refinement, mount_std = None, None
    if refine_too:
        def reprojection(o: list[BoardObservation]) -> HandEyeSolution:
            vs = [by_name[x.name] for x in o]
            r = refine(vs, solve(vs, setup, first)).solution
            return HandEyeSolution(first, r.X, r.W)

        refinement = refine(views, methods[first])
        name = f"{first.value} + reprojection"
        pool.append(Candidate(name, refinement.solution, leave_one_out(observations, reprojection, name)))
        converged[name] = refinement.converged
        step()
        s0 = methods[first]
        robust = refine_with_pose_errors(observations, HandEyeSolution(first, s0.X, s0.W))
        # the folds keep the board poses' std found on every view (its estimate is the costly part)
        prior = PosePrior(detection_translation=robust.detection_std[0], detection_rotation=robust.detection_std[1])

        def pose_errors(o: list[BoardObservation]) -> HandEyeSolution:
            return refine_with_pose_errors(o, solve_hand_eye(o, first), prior).solution

        name = f"{first.value} + pose errors"
        pool.append(Candidate(name, SetupSolution(setup, first, robust.solution.flange_T_camera,
                                                  robust.solution.world_T_marker, refined=True),
                              leave_one_out(observations, pose_errors, name)))
        converged[name] = robust.converged
        mount_std = robust.std_mm_deg
        step()
        candidates += pool[-2:]
    offsets, found = None, None
    if with_joints:
        assert joints is not None
        # its mount holds with the offsets added to the measured joints: written with them
        candidate, offsets, found, converged[f"{first.value} + joint offsets"] = _joint_offsets_candidate(
            observations, setup, first, joints)
        candidates.append(candidate)
        pool.append(candidate)
        step()
    # the joint offsets and the flange pose errors model the robot's errors: written when
    # held-out views cannot tell them from the smallest score
    chosen_held = preferred([c.held_out for c in pool], [f"{first.value} + joint offsets",
                                                        f"{first.value} + pose errors"])
    chosen = next(c for c in pool if c.held_out is chosen_held)
    candidates.sort(key=lambda c: c.held_out.score)
    written = offsets is not None and chosen.name == offsets["candidate"]
    if offsets is not None:
        offsets["written"] = written
        if not written:
            offsets["why_not_written"] = f"{chosen.name} predicts held-out views better"
    return JudgedCandidates(candidates, chosen, refinement, converged, mount_std, offsets,
                            found if written else None)


def _joint_offsets_candidate(observations: list[BoardObservation], setup: Setup, first: HandEyeMethod,
                             joints: LoggedJoints) -> tuple[Candidate, dict, np.ndarray, bool]:
    """The mount with the joints' zero offsets (recon_cli.calibration.robust.estimate_joint_offsets
    from ``first``'s closed form), judged on held-out views predicted through the offsets of
    the other views; the offsets for the report (``station_values``: as a station file's
    ``joint_offsets`` gives them, [deg] or [mm]); the offsets [rad or m]; whether the solver
    converged."""
    chain, q = joints.chain, joints.q

    def solve_with_offsets(o: list[BoardObservation]) -> JointOffsets:
        world = [BoardObservation(x.name, chain.world_T_flange(q[x.name]), x.camera_T_marker) for x in o]
        return estimate_joint_offsets([q[x.name] for x in o], [x.camera_T_marker for x in o], chain.kin,
                                      solve_hand_eye(world, first), PosePrior(), bound=OFFSET_BOUND)

    def predict(found: JointOffsets, o: BoardObservation) -> np.ndarray:
        return (invert(found.solution.flange_T_camera) @ invert(chain.world_T_flange(q[o.name] + found.offsets))
                @ found.solution.world_T_marker)

    found = solve_with_offsets(observations)
    name = f"{first.value} + joint offsets"
    X = invert(chain.right) @ found.solution.flange_T_camera  # in the flange frame the poses name
    W = chain.left @ found.solution.world_T_marker  # in the base the poses are logged in
    held = leave_one_out(observations, solve_with_offsets, name, predict)
    names = chain.kin.joint_names
    # an offset held at the bound has no std of its own (the data would move it further)
    at_bound = np.abs(found.offsets) >= OFFSET_BOUND * (1 - 1e-9)
    report = {"joints": list(names), "offsets_deg": [float(np.degrees(v)) for v in found.offsets],
              "std_deg": [float(np.degrees(v)) if np.isfinite(v) and v < OFFSET_BOUND and not b else None
                          for v, b in zip(found.std, at_bound, strict=True)],
              "observable": [bool(v) for v in found.observable], "at_bound": [bool(b) for b in at_bound],
              "bound_deg": float(np.degrees(OFFSET_BOUND)), "candidate": name, "written": False,
              "station_values": station_offsets(found.offsets, chain.kin.limits.prismatic),
              "flange_T_camera": X, "base_T_board": W}
    converged = found.refinement.converged if found.refinement is not None else True
    return Candidate(name, SetupSolution(setup, first, X, W, refined=True), held), report, found.offsets, converged


def station_offsets(offsets: np.ndarray, prismatic: np.ndarray) -> list[float]:
    """Joint offsets [rad, m] as a station file's ``joint_offsets`` gives them: [deg] of a
    revolute joint, [mm] of a prismatic one."""
    return [round(float(v * 1000.0 if p else np.degrees(v)), 4) for v, p in zip(offsets, prismatic, strict=True)]


def joint_offsets_line(values: list[float]) -> str:
    """The ``joint_offsets:`` line of a station file."""
    return "joint_offsets: [" + ", ".join(f"{v:g}" for v in values) + "]   # [deg] ([mm] of a prismatic joint)\n"


def plot_dataset_residuals(result: DatasetHandEyeResult, path: Path) -> None:
    """Per view: reprojection RMS [px], chain residual [mm] and [deg]; outliers red, views
    left out hatched."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    views = result.views
    x = range(len(views))
    colours = ["tab:red" if v.outlier else "tab:blue" for v in views]
    hatches = ["" if v.used else "//" for v in views]
    held = {h.name: h for h in result.written.held_out.views} if result.candidates else {}
    nan = float("nan")
    fig, axes = plt.subplots(5, 1, figsize=(max(6.0, 0.35 * len(views) + 2), 9.5), sharex=True)
    panels = [([v.reprojection_rms for v in views], "reprojection RMS [px]"),
              ([v.chain.translation * 1e3 for v in views], f"{result.setup.fixed} in base [mm]"),
              ([np.degrees(v.chain.rotation) for v in views], f"{result.setup.fixed} in base [deg]"),
              ([held[v.name].translation * 1e3 if v.name in held else nan for v in views], "held-out [mm]"),
              ([np.degrees(held[v.name].rotation) if v.name in held else nan for v in views], "held-out [deg]")]
    for ax, (values, label) in zip(axes, panels, strict=True):
        bars = ax.bar(x, values, color=colours, edgecolor="black", linewidth=0.3)
        for bar, hatch in zip(bars, hatches, strict=True):
            bar.set_hatch(hatch)
        ax.set_ylabel(label, fontsize=8)
    axes[-1].set_xticks(list(x))
    axes[-1].set_xticklabels([v.name for v in views], rotation=60, ha="right", fontsize=7)
    axes[-1].set_xlabel("view (red: outlier; hatched: left out)")
    t, r = result.chain_rms
    label = result.chosen or result.solution.method.value
    fig.suptitle(f"hand-eye {result.setup.value} ({label}, {len(result.used)} views)\nreprojection RMS "
                 f"{result.reprojection_rms:.2f} px; {result.setup.fixed} in the base frame: RMS {t * 1e3:.2f} mm / "
                 f"{np.degrees(r):.3f}°", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
