"""``recon calibrate``: board views, camera calibration and hand-eye calibration.

A calibration run writes into its own folder::

    <out>/scans/                  the board views (a scan store), when recorded by this run
    <out>/handeye.json            flange_T_camera, world_T_marker, residuals per view, every method,
                                  pose diversity, warnings (and, in simulation, the error against
                                  the truth)
    <out>/hand_eye.yaml           the station file's hand_eye block
    <out>/handeye_residuals.png   per-view residuals
    <out>/intrinsics.yaml         camera calibration (recon_cli.calibration.camera_file)
    <out>/intrinsics.json         its statistics, per view
    <out>/intrinsics_reprojection.png
    <out>/realism.yaml            (--realism) a realism profile whose assumed camera is the calibration

With a station file, the hand-eye result is written into it (``hand_eye``), so every later
run with ``--station`` plans and computes forward kinematics with it.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from enum import StrEnum
from pathlib import Path, PurePath

import numpy as np

from recon_cli.acquisition import view_record
from recon_cli.backends.base import Backend
from recon_cli.backends.station_file import load_station
from recon_cli.calibration.camera_file import load_camera_file, write_calibrated_profile, write_camera_file
from recon_cli.calibration.goals import board_view_goals
from recon_cli.calibration.handeye import (
    Diversity,
    HandEyeMethod,
    HandEyeSolution,
    SolverFailed,
    ViewResidual,
    pose_diversity,
    solve_hand_eye,
    view_residuals,
)
from recon_cli.calibration.holdout import LEVER, HeldOut, best, leave_one_out, predicted_board, preferred
from recon_cli.calibration.intrinsics import (
    DistortionModel,
    IntrinsicsResult,
    SkippedImage,
    calibrate_intrinsics,
    find_boards,
    plot_reprojection,
)
from recon_cli.calibration.observations import scan_observations
from recon_cli.calibration.refine import corrected, refine_hand_eye
from recon_cli.calibration.robust import PosePrior, refine_with_pose_errors
from recon_cli.calibration.station_update import hand_eye_block, write_station_hand_eye
from recon_cli.calibration.verdict import NotTrusted, Verdict, check_observations, judge
from recon_cli.calibration.views import BoardViewOptions, board_views
from recon_cli.config import DEFAULTS, Config
from recon_cli.console import write_json
from recon_cli.errors import FileError, InputError, ReconError
from recon_cli.geometry.transforms import invert, pose_error
from recon_cli.inputs.images import read_color
from recon_cli.inputs.jsonfile import load_json
from recon_cli.outputs import atomic_write, atomic_write_text
from recon_cli.perception.boards import Board, board_dict, board_text, frame_text, opencv_frame_fields
from recon_cli.perception.charuco import BoardSpec, cell_board, recorded_board
from recon_cli.perception.sensor import cell_sensor
from recon_cli.reconstruction.metadata import read_session
from recon_cli.robot.description import CellName, expand_urdf
from recon_cli.robot.kinematics import Kinematics
from recon_cli.session import Mode, SessionSpec, open_session

Progress = Callable[[str, int, int], None]
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")


# --------------------------------------------------------------------- board views
@dataclass(frozen=True)
class BoardViewsResult:
    folder: Path  # the scan store
    views: int  # asked for
    scans: int  # written
    failures: list[tuple[int, str]]  # 1-based view, why it was skipped
    seconds: float


def record_board_views(out: Path, config: Config = DEFAULTS, views: BoardViewOptions = BoardViewOptions(),  # noqa: B008
                       station: Path | None = None, board: BoardSpec | None = None,
                       progress: Progress | None = None) -> BoardViewsResult:
    """Move through the generated board views (nothing on the table but the board) and
    write one scan per reachable view into the scan store ``out``."""

    t0 = time.perf_counter()
    n = views.n
    failures, scans = [], 0
    spec = SessionSpec(Path(out), config, Mode.CALIBRATION, station=station, board_only=True,
                       run={"command": "calibrate", "views": n})
    with open_session(spec) as session:
        cell, acq = session.cell, session.acquisition
        assert acq is not None  # open_session opens the acquisition
        cell_file = cell.config.cell_file  # the station file's cell, when there is one
        board = board or cell_board(cell_file)
        view_list = board_views(board, views.for_camera(board, cell_sensor(cell_file)))
        poses = [cell.view_pose(v) for v in view_list]
        goals = board_view_goals(cell, poses, session.rng)  # keeping the arm's posture
        for k, (view, T, goal) in enumerate(zip(view_list, poses, goals, strict=True), start=1):
            try:
                if goal.q is None:
                    failures.append((k, goal.reason))
                    continue
                move = acq.move_to_joints(goal.q, what=f"board view {k}")
                acq.scan(view_record(view, T), move, name=f"board view {k}")
                scans += 1
            except ReconError as exc:  # unplannable: report, go on
                failures.append((k, exc.one_line()))
            finally:
                if progress:
                    progress("board views", k, n)
    return BoardViewsResult(Path(out), n, scans, failures, time.perf_counter() - t0)


# --------------------------------------------------------------------- hand-eye
class HandEyeStatus(StrEnum):
    OK = "ok"  #: written (when there is a station file to write into)
    WARNINGS = "warnings"  #: poorly posed (too few or too similar views): not written without --force-write


@dataclass(frozen=True)
class HandEyeOptions:
    """What ``recon calibrate handeye`` does.

    out: the run folder
    scans: a scan store of board views (any workflow's); None: record the generated views
    method: the solver whose result is written (every method is computed and compared)
    refine: refine it together with the base error (recon_cli.calibration.refine)
    camera: a calibrated camera (intrinsics.yaml); None: the scans' own intrinsics
    station: station file: adapters and cell of the recording, and where the result goes
    write: put the result into the station file (when there is one)
    force: write even when the views are poorly posed
    accept: write into the station file also when the verdict is "not trusted"
    method: None: the candidate with the smallest held-out error (OpenCV's methods, the
        refinements from the best of them); a method: it or its refinement, whichever
        predicts held-out views better
    """

    out: Path
    config: Config = DEFAULTS
    scans: Path | None = None
    views: BoardViewOptions = field(default_factory=BoardViewOptions)
    method: HandEyeMethod | None = None
    refine: bool = True
    camera: Path | None = None
    station: Path | None = None
    write: bool = True
    force: bool = False
    board: Board | None = None
    accept: bool = False


@dataclass(frozen=True)
class HandEyeResult:
    """A hand-eye calibration. Poses (4, 4) [m]; errors (translation [m], rotation [rad])."""

    folder: Path
    scans: Path
    status: HandEyeStatus
    solution: HandEyeSolution  # what is written: the method's, refined unless --no-refine
    residuals: list[ViewResidual]
    refined: bool  # the method's solution refined with the base error
    base_rotation: np.ndarray | None  # (3,) rotation vector [rad] of the base error the refinement found
    methods: dict[HandEyeMethod, HandEyeSolution]
    diversity: Diversity
    skipped: list[SkippedImage]
    model_flange_T_camera: np.ndarray  # what the model had before
    model_world_T_marker: np.ndarray
    truth_flange_T_camera: np.ndarray | None  # simulation only
    recorded: BoardViewsResult | None
    station_written: Path | None
    seconds: float
    station_backup: Path | None = None  # the station file as it was (beside the file a link points to)
    method_failures: dict[HandEyeMethod, str] = field(default_factory=dict)  # OpenCV methods without a solution
    candidates: list[tuple[str, HeldOut]] = field(default_factory=list)  # every candidate's held-out errors
    chosen: str = ""  # the candidate written
    verdict: Verdict | None = None

    @property
    def views(self) -> int:
        return len(self.residuals)

    @property
    def change(self) -> tuple[float, float]:
        """The calibrated flange_T_camera against the model's."""
        return pose_error(self.solution.flange_T_camera, self.model_flange_T_camera)

    @property
    def truth_error(self) -> tuple[float, float] | None:
        if self.truth_flange_T_camera is None:
            return None
        return pose_error(self.solution.flange_T_camera, self.truth_flange_T_camera)

    def method_spread(self) -> dict[str, tuple[float, float]]:
        """Every method's flange_T_camera against the chosen one's."""
        return {m.value: pose_error(s.flange_T_camera, self.solution.flange_T_camera) for m, s in self.methods.items()}

    def to_dict(self) -> dict:
        t, r = np.array([x.translation for x in self.residuals]), np.array([x.rotation for x in self.residuals])
        truth = self.truth_error
        return {
            "status": self.status.value, "method": self.solution.method.value, "scans": str(self.scans),
            "candidate": self.chosen, "verdict": None if self.verdict is None else self.verdict.to_dict(),
            "selection": f"smallest held-out score (RMS over the views of sqrt(t^2 + ({LEVER:g} m x r)^2)); the "
                         "refinement that models the robot's errors instead when its score is within one standard "
                         "error of the smallest",
            "held_out": [h.to_dict() for _, h in self.candidates],
            "refined": self.refined, "views_used": self.views,
            "flange_T_camera": self.solution.flange_T_camera, "world_T_marker": self.solution.world_T_marker,
            "base_rotation_rad": self.base_rotation,
            "residuals": {"translation_rms_m": float(np.sqrt(np.mean(t**2))), "translation_max_m": float(t.max()),
                          "rotation_rms_rad": float(np.sqrt(np.mean(r**2))), "rotation_max_rad": float(r.max()),
                          "views": [{"name": x.name, "translation_m": x.translation, "rotation_rad": x.rotation}
                                    for x in self.residuals]},
            "methods": {m.value: {"flange_T_camera": s.flange_T_camera, "world_T_marker": s.world_T_marker,
                                  "vs_chosen_m_rad": list(self.method_spread()[m.value])}
                        for m, s in self.methods.items()},
            "methods_failed": {m.value: why for m, why in self.method_failures.items()},
            "diversity": self.diversity.to_dict(),
            "skipped": [{"name": s.name, "reason": s.reason} for s in self.skipped],
            "model": {"flange_T_camera": self.model_flange_T_camera, "world_T_marker": self.model_world_T_marker,
                      "change_m_rad": list(self.change),
                      "world_T_marker_change_m_rad": list(pose_error(self.solution.world_T_marker,
                                                                     self.model_world_T_marker))},
            "truth": None if truth is None else {"flange_T_camera": self.truth_flange_T_camera,
                                                 "error_m_rad": list(truth)},
            "station_written": None if self.station_written is None else str(self.station_written),
            "seconds": self.seconds,
        }


def _model_kinematics(scans: Path, station_file, config: Config):
    """The model the scans' joints are read with: the station file's cell, else the cell
    recorded in session.json, else the configuration's."""


    if station_file is not None:
        cell = station_file.cell
    else:
        info = read_session(scans)
        cell = config.cell
        if info.cell_kind is not None:
            cell = replace(cell, kind=CellName.parse(info.cell_kind),
                           table_lift=info.table_lift if info.table_lift is not None else cell.table_lift)
    return Kinematics(expand_urdf(cell), cell.cell_file)


def _truth_flange_T_camera(scans: Path, model: np.ndarray) -> np.ndarray | None:
    """Simulation only: the true camera mount (ground_truth/realism.json; without a realism
    profile the simulated camera is where the model says)."""


    info = read_session(scans)
    if info.backend != Backend.SIM:
        return None
    record = Path(scans) / "ground_truth" / "realism.json"
    if record.exists():

        data = load_json(record, "ground_truth/realism.json")
        kin = (data.get("kinematics") if isinstance(data, dict) else None) or {}
        if kin.get("flange_T_camera") is not None:
            return np.asarray(kin["flange_T_camera"], dtype=float)
    return model


def run_handeye(opt: HandEyeOptions, progress: Progress | None = None) -> HandEyeResult:
    """Record board views (unless given), calibrate, report, write (see the module docstring)."""

    t0 = time.perf_counter()
    out = Path(opt.out)
    out.mkdir(parents=True, exist_ok=True)
    board = opt.board or cell_board(opt.config.cell.cell_file)
    camera = load_camera_file(opt.camera) if opt.camera is not None else None
    station_file = None
    if opt.station is not None:

        station_file = load_station(opt.station)
    recorded = None
    scans = opt.scans
    if scans is None:
        if not isinstance(board, BoardSpec):
            raise InputError(f"the simulation shows a ChArUco board, not the {board_text(board)} of --board-spec",
                             hint="calibrate views of that board recorded on a cell with --scan-store or --dataset")
        scans = out / "scans"
        recorded = record_board_views(scans, opt.config, opt.views, opt.station, board, progress)
    kin = _model_kinematics(scans, station_file, opt.config)
    q0 = kin.neutral()
    model_X = invert(kin.frame_pose(q0, kin.cell.flange_link)) @ kin.world_T_camera(q0)
    found = scan_observations(scans, board, kin, camera)
    obs = found.observations
    diversity = pose_diversity([o.world_T_flange for o in obs])
    if len(obs) < 3:
        why = [f"{s.name}: {s.reason}" for s in found.skipped[:3]]
        if recorded is not None and recorded.failures:
            why = [f"{recorded.scans} of {recorded.views} views reached"] + [
                f"view {k}: {reason}" for k, reason in recorded.failures[:2]]
        raise InputError(f"the board was found in {len(obs)} of the scans in {scans}; hand-eye calibration needs 3 "
                         f"or more" + (f" ({'; '.join(why)})" if why else ""),
                         hint="record views the robot reaches with the whole board in sight (your own script's "
                              "scans with --scan-store; docs/calibration.md)")
    check_observations(obs, diversity, str(scans))  # before any solver runs
    methods: dict[HandEyeMethod, HandEyeSolution] = {}
    failures: dict[HandEyeMethod, str] = {}
    for m in HandEyeMethod:
        try:
            methods[m] = solve_hand_eye(obs, m)
        except SolverFailed as exc:
            failures[m] = exc.reason
            if m is opt.method:  # no solution from the method asked for: refused
                refusal = exc
    if opt.method in failures:
        solved = ", ".join(m.value for m in methods)
        raise InputError(refusal.message, hint=(f"choose --method {next(iter(methods)).value} ({solved} found a "
                                                "solution), or record views" if methods else "record views")
                         + " turned by 20° or more about other axes")
    candidates, chosen, refined = _judged_candidates(obs, methods, opt.method, opt.refine, progress)
    solution, base_rotation, chain = chosen[1], None, obs
    if refined is not None and chosen[0].endswith("+ base error"):
        base_rotation, chain = refined.base_rotation, corrected(obs, refined)
    residuals = view_residuals(chain, solution.flange_T_camera, solution.world_T_marker)
    status = HandEyeStatus.OK if diversity.ok else HandEyeStatus.WARNINGS
    truth = _truth_flange_T_camera(scans, model_X)
    held = dict(candidates)[chosen[0]]
    verdict = judge(obs, solution, held, diversity, eye_in_hand=True, model_mount=model_X)
    comment = (f"recon calibrate handeye, {time.strftime('%Y-%m-%d %H:%M')}, {chosen[0]}, {len(obs)} views, "
               f"held-out error {held.rms[0] * 1e3:.3f} mm RMS, "
               f"{'trusted' if verdict.trusted else 'NOT trusted (accepted)'}")
    written = backup = None
    if verdict.trusted or opt.accept:
        atomic_write_text(out / "hand_eye.yaml", hand_eye_block(solution.flange_T_camera, comment))
        if opt.station is not None and opt.write and (status is HandEyeStatus.OK or opt.force):
            backup = write_station_hand_eye(opt.station, solution.flange_T_camera, comment)
            written = Path(opt.station)
    result = HandEyeResult(out, Path(scans), status, solution, residuals, chosen[0] != solution.method.value,
                           base_rotation, methods, diversity, found.skipped, model_X, kin.world_T_marker(), truth,
                           recorded, written, time.perf_counter() - t0, backup, failures, candidates, chosen[0],
                           verdict)
    write_json(out / "handeye.json", {**result.to_dict(), **opencv_frame_fields(board, solution.world_T_marker)})
    atomic_write(out / "handeye_residuals.png", lambda tmp: plot_handeye_residuals(result, tmp))
    if not verdict.trusted and not opt.accept:
        raise NotTrusted(verdict, hint=f"nothing written but the report {out / 'handeye.json'}; --accept writes it "
                                       "anyway (docs/calibration.md)")
    return result


def _judged_candidates(obs: list, methods: dict[HandEyeMethod, HandEyeSolution], start: HandEyeMethod | None,
                       refine_too: bool, progress: Progress | None = None):
    """Every OpenCV method's held-out errors and, with ``refine_too``, those of the
    refinement with the base error (recon_cli.calibration.refine) and of the refinement with
    flange pose errors (recon_cli.calibration.robust), both from ``start`` (None: the
    closed-form method with the smallest held-out score). Returns [(name, HeldOut)] by score,
    (name, solution) of the candidate written, and the base-error refinement on every view."""
    held: dict[str, HeldOut] = {}
    solutions: dict[str, HandEyeSolution] = {}
    total, done = len(methods) + (2 if refine_too else 0), 0
    def closed_form(m: HandEyeMethod):
        return lambda o: solve_hand_eye(o, m)

    for m, s in methods.items():
        held[m.value] = leave_one_out(obs, closed_form(m), m.value)
        solutions[m.value] = s
        done += 1
        if progress:
            progress("held-out views", done, total)
    first = start or HandEyeMethod(best(list(held.values())).candidate)
    pool = [m.value for m in methods if start is None or m is start]
    refined = None
    if refine_too:
        def base_error(o):
            return refine_hand_eye(o, solve_hand_eye(o, first))

        def through_base(r, o) -> np.ndarray:
            return predicted_board(r.solution, corrected([o], r)[0].world_T_flange)

        refined = refine_hand_eye(obs, methods[first])
        name = f"{first.value} + base error"
        held[name], solutions[name] = leave_one_out(obs, base_error, name, through_base), refined.solution
        robust = refine_with_pose_errors(obs, methods[first])
        prior = PosePrior(detection_translation=robust.detection_std[0], detection_rotation=robust.detection_std[1])
        rname = f"{first.value} + pose errors"
        held[rname] = leave_one_out(obs, lambda o: refine_with_pose_errors(o, solve_hand_eye(o, first),
                                                                           prior).solution, rname)
        solutions[rname] = robust.solution
        pool += [name, rname]
        if progress:
            progress("held-out views", total, total)
    # the flange pose errors model the robot's errors: written when held-out views cannot tell
    # them from the smallest score
    chosen = preferred([held[n] for n in pool], [f"{first.value} + pose errors"]).candidate
    ranked = sorted(held.items(), key=lambda item: item[1].score)
    return ranked, (chosen, solutions[chosen]), refined


def plot_handeye_residuals(result: HandEyeResult, path: Path) -> None:
    """Per-view residuals of the closed chain: translation [mm] and rotation [deg]."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = [r.name.replace("scan_", "") for r in result.residuals]
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(max(6.0, 0.35 * len(names) + 2), 5), sharex=True)
    a1.bar(range(len(names)), [r.translation * 1e3 for r in result.residuals], color="tab:blue")
    a1.set_ylabel("translation [mm]")
    a2.bar(range(len(names)), [np.degrees(r.rotation) for r in result.residuals], color="tab:orange")
    a2.set_ylabel("rotation [deg]")
    a2.set_xticks(range(len(names)))
    a2.set_xticklabels(names, rotation=60, ha="right", fontsize=7)
    a2.set_xlabel("view (scan)")
    dt, dr = result.change
    label = result.solution.method.value + (" refined" if result.refined else "")
    fig.suptitle(f"hand-eye ({label}, {result.views} views): closed-chain residual per view; "
                 f"change against the model {dt * 1e3:.2f} mm / {np.degrees(dr):.3f}°", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# --------------------------------------------------------------------- intrinsics
@dataclass(frozen=True)
class IntrinsicsOptions:
    """What ``recon calibrate intrinsics`` does.

    source: a folder of images or a scan store (its scans' colour images)
    pattern: which files of an image folder (glob)
    model: the distortion model fitted
    profile: a realism profile (name or file) to copy with the calibration as its assumed
        camera (``<out>/realism.yaml``: simulated sessions then use the calibration)
    """

    source: Path
    out: Path
    board: Board | None = None
    pattern: str = "*"
    model: DistortionModel = DistortionModel.FULL
    min_corners: int = 8
    profile: str | None = None


def check_pattern(pattern: str) -> str:
    """``--pattern``: a glob relative to the image folder that cannot climb out of it."""
    parts = PurePath(pattern).parts
    if not pattern.strip() or PurePath(pattern).is_absolute() or pattern.startswith("~") or ".." in parts:
        raise InputError(f"--pattern {pattern!r} leaves the image folder",
                         hint="give a glob relative to the folder, without '..', e.g. 'img_*.png' or 'left/*.png'")
    return pattern


def _outside(path: Path, root: Path) -> str | None:
    """Why ``path`` (in the folder ``root``, already resolved) is not read: a link, or a link
    on its way, that leads out of ``root`` or does not resolve; None when it stays inside."""
    try:
        target = path.resolve(strict=True)
    except (OSError, RuntimeError):
        return "a link that does not resolve"
    if not target.is_relative_to(root):
        return "a link leading out of the folder"
    return None


def board_images(source: Path, pattern: str = "*", skipped: list | None = None) -> list[tuple[str, np.ndarray]]:
    """RGB images of a folder (files matching ``pattern``, a glob inside it) or of a scan
    store's scans. Files that are links leading out of the folder are not read: they go into
    ``skipped`` (SkippedImage) with the reason."""
    import cv2

    source = Path(source)
    if not source.is_dir():
        raise FileError(f"{source} is not a folder", hint="pass a folder of board images or a scan store")
    check_pattern(pattern)
    root = source.resolve()
    scan_dirs = sorted(p for p in source.glob("scan_*") if (p / "color.png").exists())
    try:
        files = [p / "color.png" for p in scan_dirs] if scan_dirs else sorted(
            p for p in source.glob(pattern) if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES)
    except (ValueError, NotImplementedError, IndexError):  # a glob pathlib does not take ("a**", ".")
        raise InputError(f"--pattern {pattern!r} is not a glob of file names",
                         hint="'**' only as a whole path component, e.g. 'img_*.png', 'left/*.png' or "
                              "'**/*.png'") from None
    names = [f.parent.name if scan_dirs else str(f.relative_to(source)) for f in files]
    kept, away = [], []
    for f, name in zip(files, names, strict=True):
        reason = _outside(f, root)
        if reason is None:
            kept.append((f, name))
        else:
            away.append(SkippedImage(name, f"not read: {reason}"))
    if skipped is not None:
        skipped.extend(away)
    if not kept:
        what = f"{source} holds no images" + (f" matching {pattern!r}" if pattern != "*" else "")
        if away:
            what += f" inside it ({len(away)} {'is a link' if len(away) == 1 else 'are links'} leading out of it)"
        raise FileError(what, hint=f"images ({', '.join(IMAGE_SUFFIXES)}) or scan_NNNN/color.png")
    images = []
    for f, name in kept:
        bgr = read_color(f, "calibration image", hint="remove it or narrow --pattern")
        images.append((name, cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)))
    return images


@dataclass(frozen=True)
class IntrinsicsRun:
    result: IntrinsicsResult
    camera_file: Path
    report: Path
    figure: Path
    images: int
    seconds: float
    profile: Path | None = None  # the realism profile with the calibrated camera


def run_intrinsics(opt: IntrinsicsOptions) -> IntrinsicsRun:
    """Find the board in every image, calibrate, write intrinsics.yaml, its report and figure."""

    t0 = time.perf_counter()
    out = Path(opt.out)
    out.mkdir(parents=True, exist_ok=True)
    # the board of the scan store's session, when the source is one (else the thesis' board)
    store = Path(opt.source) / "session.json"
    board = opt.board or recorded_board(read_session(Path(opt.source)).board if store.is_file() else None)
    away: list[SkippedImage] = []
    images = board_images(opt.source, opt.pattern, away)
    views, skipped = find_boards(images, board, opt.min_corners)
    skipped = away + skipped
    result = calibrate_intrinsics(views, opt.model, skipped)
    stats = {"source": str(opt.source), "rms_px": result.rms, "views": len(result.views),
             "corners": result.corners, "model": result.model.value, "std": result.std,
             "created": time.strftime("%Y-%m-%d %H:%M:%S")}
    camera_file = write_camera_file(out / "intrinsics.yaml", result.camera, stats,
                                    comment="recon calibrate intrinsics: the camera's intrinsics [px] and OpenCV "
                                            "distortion;\nuse with recon calibrate handeye --camera-file, or as a "
                                            "realism profile's camera.assumed")
    report = out / "intrinsics.json"
    write_json(report, {**result.to_dict(), "source": str(opt.source), "board": board_dict(board),
                        "board_frame": frame_text(board),
                        "images": len(images)})
    figure = atomic_write(out / "intrinsics_reprojection.png", lambda tmp: plot_reprojection(result, tmp))
    profile = None
    if opt.profile is not None:

        profile = write_calibrated_profile(opt.profile, result.camera, out / "realism.yaml")
    return IntrinsicsRun(result, camera_file, report, figure, len(images), time.perf_counter() - t0, profile)
