"""``recon calibrate handeye``, ``recon calibrate intrinsics``: the camera and its mount from
views of the ChArUco board."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from recon_cli.calibration.dataset import (
    AngleUnit,
    LengthUnit,
    MatrixOrder,
    PoseFormat,
    QuaternionOrder,
    parse_camera_numbers,
)
from recon_cli.calibration.handeye import HandEyeMethod
from recon_cli.calibration.holdout import HeldOut
from recon_cli.calibration.intrinsics import DistortionModel
from recon_cli.calibration.setups import Setup
from recon_cli.calibration.views import BoardViewOptions
from recon_cli.cli.app import app
from recon_cli.cli.options import (
    CellOpt,
    D,
    ForceOpt,
    RealismOpt,
    ResolutionOpt,
    SafetyOpt,
    SeedOpt,
    cell_config,
    output_folder,
    realism_option,
    realism_profile,
)
from recon_cli.config import SensorConfig
from recon_cli.console import console, progress_bar, styled
from recon_cli.errors import InputError
from recon_cli.perception.boards import Board, board_text
from recon_cli.perception.boards import parse_board as parse_board_text
from recon_cli.workflows.calibrate import HandEyeOptions, IntrinsicsOptions, check_pattern, run_handeye, run_intrinsics
from recon_cli.workflows.handeye_dataset import DatasetHandEyeOptions, DatasetHandEyeResult, run_handeye_dataset

calibrate_app = typer.Typer(help="Calibration from views of the ChArUco board: camera intrinsics and distortion, "
                                 "the hand-eye transform.", no_args_is_help=True, rich_markup_mode=None)
app.add_typer(calibrate_app, name="calibrate")

BoardOpt = Annotated[str | None, typer.Option(
    "--board-spec",
    help="Another board than the cell's (robot/board.yaml): charuco:COLSxROWS,SQUARE,MARKER,DICTIONARY[,legacy] "
         "(squares; legacy: printed by OpenCV before 4.6), chessboard:COLSxROWS,SQUARE (inner corners, one count "
         "even and one odd), circles:COLSxROWS,SPACING (asymmetric grid: circles per row x rows, an odd number "
         "of rows; OpenCV's spacing s: rows s apart, circles of a row 2 s), lengths in metres, e.g. "
         "charuco:5x7,0.04,0.02,DICT_6X6_250, chessboard:9x6,0.025, circles:4x11,0.02; the ChArUco form "
         "5,7,0.04,0.02,DICT_6X6_250 too (docs/calibration.md, Boards).")]


def _metavar(enum) -> str:
    """<a|b|c>: the choices of an option that may be left out (None: the mapping's)."""
    return "<" + "|".join(m.value for m in enum) + ">"


def parse_board(text: str | None) -> Board | None:
    """The board of ``--board-spec`` (None: the cell's board); a malformed one is a one-line error
    (recon_cli.perception.boards.parse_board)."""
    return None if text is None else parse_board_text(text, "--board-spec")


@calibrate_app.command("handeye")
def handeye(
    scans: Annotated[Path | None, typer.Option("--scan-store", help="Scan store of board views to calibrate from "
                                                                    "(any workflow's, e.g. a script run's "
                                                                    "<out>/scans); default: record the generated "
                                                                    "views first.")] = None,
    out: Annotated[Path | None, typer.Option("--out", "-o", help="Output folder (default runs/handeye-<time>).")]
    = None,
    views: Annotated[int, typer.Option("--board-views", min=3, max=200, help="Generated board views to record "
                                                                             "(tilted up to 48 deg, rolled up to "
                                                                             "35 deg, around the board).")] = 20,
    method: Annotated[HandEyeMethod | None, typer.Option(
        metavar=_metavar(HandEyeMethod),
        help="OpenCV solver to write (refined when that predicts held-out views better): tsai, park, horaud, "
             "andreff, daniilidis (calibrateHandEye) or shah, li (calibrateRobotWorldHandEye); default: the "
             "candidate with the smallest held-out error. All are computed and judged on held-out views.")] = None,
    refine: Annotated[bool, typer.Option("--refine/--no-refine", help="Refine the solution: together with the "
                                                                      "robot base's error (recorded views, "
                                                                      "--scan-store), by the board corners' "
                                                                      "reprojection error (--dataset); "
                                                                      "docs/calibration.md.")]
    = True,
    intrinsics: Annotated[Path | None, typer.Option("--camera-file", help="Calibrated camera (intrinsics.yaml of "
                                                                           "recon calibrate intrinsics); default: "
                                                                           "the scans' own intrinsics.")] = None,
    dataset: Annotated[Path | None, typer.Option("--dataset", help="Calibrate from a data set made by anyone: a "
                                                                   "folder of board images and the robot pose of "
                                                                   "each (pose files by stem, one CSV file, or an "
                                                                   "index file like cal_data.yaml), or that index "
                                                                   "or CSV file (docs/calibration.md).")] = None,
    mapping: Annotated[Path | None, typer.Option("--mapping", help="With --dataset: a mapping FILE.yaml saying "
                                                                   "where the images and poses are, which key "
                                                                   "holds what and the units; the options below "
                                                                   "override it.")] = None,
    setup: Annotated[Setup | None, typer.Option("--setup", metavar=_metavar(Setup),
                                                help="With --dataset: eye-in-hand (the camera on the flange: "
                                                     "flange_T_camera, base_T_board) or eye-to-hand (the camera "
                                                     "fixed, the board on the flange: base_T_camera, "
                                                     "flange_T_board); default: the mapping's, the index file's "
                                                     "static_camera, else eye-in-hand.")] = None,
    pinhole: Annotated[str | None, typer.Option("--intrinsics", help="With --dataset: the camera of the images "
                                                                     "as they are: fx,fy,cx,cy [px], or "
                                                                     "fx,fy,cx,cy,k1,k2,p1,p2[,k3] with OpenCV's "
                                                                     "distortion (else --camera-file, the "
                                                                     "mapping's, the index file's or the pose "
                                                                     "files' own).")] = None,
    pose_format: Annotated[PoseFormat | None, typer.Option("--pose-format", metavar=_metavar(PoseFormat),
                                                           help="With --dataset: what a pose is: xyz + quaternion, "
                                                                "xyz + roll-pitch-yaw, a 4x4 matrix or joint "
                                                                "positions (forward kinematics of --cell); default: "
                                                                "the mapping's, else told by the keys.")] = None,
    length_unit: Annotated[LengthUnit | None, typer.Option("--length-unit", metavar=_metavar(LengthUnit),
                                                           help="With --dataset: the poses' lengths (default m).")]
    = None,
    angle_unit: Annotated[AngleUnit | None, typer.Option("--angle-unit", metavar=_metavar(AngleUnit),
                                                         help="With --dataset: the poses' angles (default rad).")]
    = None,
    quaternion_order: Annotated[QuaternionOrder | None, typer.Option(
        "--quaternion-order", metavar=_metavar(QuaternionOrder),
        help="With --dataset: the order of a quaternion's numbers (default xyzw).")] = None,
    matrix_order: Annotated[MatrixOrder | None, typer.Option(
        "--matrix-order", metavar=_metavar(MatrixOrder),
        help="With --dataset: a 4x4 matrix's 16 numbers row by row or column by column (libfranka's O_T_EE; "
             "default row).")] = None,
    drop_outliers: Annotated[bool, typer.Option("--drop-outliers", help="With --dataset: calibrate again without "
                                                                        "the views flagged as outliers (chain "
                                                                        "residual over 3 times the median, or over "
                                                                        "50 mm or 5 deg).")] = False,
    station: Annotated[Path | None, typer.Option(help="Station file: record with its adapters and cell, and write "
                                                      "the result into its hand_eye (old file kept as .bak).")]
    = None,
    write: Annotated[bool, typer.Option("--write/--no-write", help="Write the result into the station file.")]
    = True,
    force_write: Annotated[bool, typer.Option("--force-write", help="Write into the station file even when the "
                                                                    "views are poorly posed (warnings).")] = False,
    camera_from_views: Annotated[bool | None, typer.Option(
        "--camera-from-views/--no-camera-from-views",
        help="With --dataset: calibrate the camera (intrinsics, distortion k1 k2 p1 p2) from the same photos "
             "first, the given intrinsics as the start, and report its reprojection; default: when no camera is "
             "given, or the given one has no distortion and a camera calibrated from the other photos explains "
             "each photo better (held out; 8 or more views needed).")] = None,
    accept: Annotated[bool, typer.Option("--accept", help="Write the result (station file, hand_eye.yaml) and exit "
                                                          "0 also when the verdict is 'not trusted' (otherwise "
                                                          "exit code 5, only the report written).")] = False,
    board: BoardOpt = None,
    resolution: ResolutionOpt = D.sensor.resolution,
    noise: Annotated[bool, typer.Option("--noise/--no-noise", help="Sensor noise of the simulation.")]
    = D.sensor.noise,
    cell: CellOpt = D.cell.kind,
    safety: SafetyOpt = None,
    seed: SeedOpt = D.seed,
    realism: RealismOpt = D.realism.name,
    force: ForceOpt = False,
) -> None:
    """Hand-eye calibration: flange_T_camera (and the board in the world) from board views, or either set-up from
    a data set of board images and robot poses (--dataset)."""


    config = D.replace(cell=cell_config(cell, safety),
                       sensor=SensorConfig(noise, resolution), seed=seed, realism=realism_profile(realism))
    spec = parse_board(board)
    if dataset is not None:
        if scans is not None or station is not None:
            raise InputError("--dataset is calibrated on its own, without --scan-store or --station",
                             hint="give one source of board views")
        numbers = parse_camera_numbers(pinhole, "--intrinsics") if pinhole is not None else None
        folder = output_folder(out, "calibrate handeye", default="handeye", force=force,
                               inputs=(dataset, mapping, intrinsics)).path
        opts = DatasetHandEyeOptions(dataset, folder, mapping, setup, method, refine, intrinsics, numbers, spec,
                                     config.cell, pose_format, length_unit, angle_unit, quaternion_order,
                                     matrix_order, drop_outliers, accept=accept,
                                     camera_from_views=camera_from_views)
        with progress_bar() as update:
            _print_dataset(run_handeye_dataset(opts, update))
        return
    dataset_only = {"--mapping": mapping, "--setup": setup, "--intrinsics": pinhole, "--pose-format": pose_format,
                    "--length-unit": length_unit, "--angle-unit": angle_unit, "--quaternion-order": quaternion_order,
                    "--matrix-order": matrix_order, "--drop-outliers": drop_outliers or None,
                    "--camera-from-views": camera_from_views}
    given = [name for name, value in dataset_only.items() if value is not None]
    if given:
        raise InputError(f"{', '.join(given)} {'is' if len(given) == 1 else 'are'} read with --dataset only",
                         hint="pass --dataset DIR, or leave them out")
    folder = output_folder(out, "calibrate handeye", default="handeye", force=force,
                           inputs=(scans, intrinsics, station, Path(realism))).path
    options = HandEyeOptions(folder, config, scans, BoardViewOptions(n=views), method, refine,
                             intrinsics, station, write, force_write, spec, accept)
    with progress_bar() as update:
        r = run_handeye(options, update)
    if r.recorded is not None:
        console.print(f"recorded {r.recorded.scans} of {r.recorded.views} board views in {r.recorded.seconds:.1f} s "
                      f"({r.scans})")
        for k, why in r.recorded.failures:
            console.print(styled(f"view {k} skipped:", "yellow", f" {why}"))
    for s in r.skipped:
        console.print(styled(f"{s.name} not used:", "yellow", f" {s.reason}"))
    if intrinsics is None:
        console.print("board poses seen with the scans' own intrinsics (uncalibrated: calibrate the camera with "
                      "recon calibrate intrinsics and pass --camera-file)")
    t = np.array([x.translation for x in r.residuals]) * 1e3
    a = np.degrees([x.rotation for x in r.residuals])
    console.print(f"{r.views} views; closed-chain residual per view: RMS {np.sqrt(np.mean(t**2)):.3f} mm "
                  f"(max {t.max():.3f}), {np.sqrt(np.mean(a**2)):.4f}° (max {a.max():.4f})")
    console.print("method      vs written [mm]  [deg]")
    for name, (dt, dr) in r.method_spread().items():
        console.print(f"{name:11s} {dt * 1e3:14.3f}  {np.degrees(dr):.4f}")
    for m, why in r.method_failures.items():
        console.print(f"{m.value:11s} no solution ({why})")
    print_held_out([_Judged(name, held) for name, held in r.candidates], r.chosen)
    X = r.solution.flange_T_camera
    dt, dr = r.change
    label = r.chosen or r.solution.method.value
    console.print(f"flange_T_camera ({label}), {dt * 1e3:.2f} mm / {np.degrees(dr):.3f}° from the model's:")
    for row in X[:3]:
        console.print("  [" + ", ".join(f"{v: .6f}" for v in row) + "]")
    if r.base_rotation is not None:
        console.print(f"robot base rotation against the model (and the arm's constant sag): "
                      f"{np.degrees(np.linalg.norm(r.base_rotation)):.3f}°")
    if r.truth_error is not None:
        e = r.truth_error
        console.print(f"simulation: {e[0] * 1e3:.3f} mm / {np.degrees(e[1]):.4f}° from the true camera mount")
    for _, message in r.diversity.issues:
        console.print(styled("warning:", "yellow", f" {message}"))
    if r.verdict is not None:
        console.print(styled("verdict:", "green" if r.verdict.trusted else "red", f" {r.verdict.line()}"))
    if r.station_written is not None:
        console.print(f"written into {r.station_written} (hand_eye; the old file is {r.station_backup})")
    elif station is not None and write:
        console.print(styled("not written", "yellow", f" into {station}: the views are poorly posed (see the "
                                                      "warnings); record more views or pass --force-write"))
    console.print(f"report: {r.folder / 'handeye.json'}\nhand_eye block: {r.folder / 'hand_eye.yaml'}\n"
                  f"figure: {r.folder / 'handeye_residuals.png'}")


@dataclass(frozen=True)
class _Judged:
    name: str
    held_out: HeldOut


def print_held_out(candidates, chosen: str) -> None:
    """Every candidate's leave-one-view-out error (the board pose of a view predicted by the
    calibration of the others against the image's own), smallest score first."""
    console.print("held-out views (each predicted by the calibration of the others): candidate, score [mm], "
                  "median, RMS, max [mm / deg]")
    for c in candidates:
        h = c.held_out
        mark = "  <- written" if c.name == chosen else ""
        if not h.complete:
            console.print(f"{c.name:26s} no calibration without {', '.join(h.failed[:2])}{mark}")
            continue
        (mt, mr), (qt, qr), (xt, xr) = h.median, h.rms, h.max
        console.print(f"{c.name:26s} {h.score * 1e3:7.2f}  {mt * 1e3:7.2f} / {np.degrees(mr):5.2f}  "
                      f"{qt * 1e3:7.2f} / {np.degrees(qr):5.2f}  {xt * 1e3:7.2f} / {np.degrees(xr):5.2f}{mark}")


def _print_dataset(r: DatasetHandEyeResult) -> None:
    """The terminal summary of a calibration from a data set."""
    console.print(f"data set: {r.layout}; set-up {r.setup.value} ({r.sources['setup']}); board "
                  f"{board_text(r.board)} ({r.sources['board']}); camera: {r.sources['camera']}")
    console.print("poses read as " + ", ".join(f"{k}: {v}" for k, v in r.mapping.to_dict().items()))
    for s in r.skipped:
        console.print(styled(f"{s.name} not used:", "yellow", f" {s.reason}"))
    if r.camera_fit is not None:
        K, fit = r.camera_fit.camera.intrinsics, r.camera_fit
        console.print(f"camera from the {len(fit.views)} views: reprojection RMS {fit.rms:.3f} px; fx {K.fx:.2f}, "
                      f"fy {K.fy:.2f}, cx {K.cx:.2f}, cy {K.cy:.2f} px; k1, k2, p1, p2 "
                      + ", ".join(f"{v:.5g}" for v in fit.camera.distortion[:4]))
    for name, why in r.outliers.items():
        what = "left out" if name in r.dropped else "kept (--drop-outliers leaves it out)"
        console.print(styled(f"{name} outlier:", "yellow", f" {why}; {what}"))
    fixed = r.setup.fixed
    console.print(f"view                      corners  PnP [px]  reproj [px]  {fixed} in base [mm]  [deg]  "
                  "vs own PnP [mm]  [deg]")
    for v in r.views:
        mark = "" if v.used else "  (left out)"
        console.print(f"{v.name[:25]:25s} {v.corners:7d} {v.pnp_rms:9.2f} {v.reprojection_rms:12.2f} "
                      f"{v.chain.translation * 1e3:18.2f} {np.degrees(v.chain.rotation):6.3f} "
                      f"{v.pnp_difference[0] * 1e3:16.2f} {np.degrees(v.pnp_difference[1]):6.3f}{mark}")
    t, a = r.chain_rms
    tm, am = r.chain_max
    pt, pa = r.pnp_mean
    converged = "" if r.refinement is None else ", converged" if r.converged else ", NOT converged"
    console.print(f"{len(r.used)} views{converged}; reprojection RMS {r.reprojection_rms:.3f} px "
                  f"(industrial_calibration's cost per residual {r.cost_per_residual:.3f} px)")
    console.print(f"consistency ({fixed} in the base frame over the views): RMS {t * 1e3:.2f} mm (max "
                  f"{tm * 1e3:.2f}), {np.degrees(a):.3f}° (max {np.degrees(am):.3f}); against each image's own board "
                  f"pose: mean {pt * 1e3:.2f} mm, {np.degrees(pa):.3f}°")
    console.print(f"method      {fixed} RMS [mm]  [deg]  reproj [px]  vs written [mm]  [deg]")
    for m, row in r.methods.items():
        console.print(f"{m.value:11s} {row.chain_rms[0] * 1e3:14.2f} {np.degrees(row.chain_rms[1]):6.3f} "
                      f"{row.reprojection_rms:12.2f} {row.vs_written[0] * 1e3:16.2f} "
                      f"{np.degrees(row.vs_written[1]):6.3f}")
    for m, why in r.method_failures.items():
        console.print(f"{m.value:11s} no solution ({why})")
    print_held_out(r.candidates, r.chosen)
    if r.mount_std is not None:
        console.print(f"mount uncertainty (refinement with pose errors, 1-sigma): {r.mount_std[0]:.2f} mm, "
                      f"{r.mount_std[1]:.3f}°")
    if r.joint_offsets is not None:
        j = r.joint_offsets
        values = ", ".join(f"{n} {v:+.3f}" for n, v, seen in zip(j["joints"], j["station_values"], j["observable"],
                                                                strict=True) if seen)
        how = ("written: put its joint_offsets line into the station file with the hand_eye block" if j["written"]
               else f"not written: {j['why_not_written']}")
        console.print(f"joints' zero offsets ({j['candidate']}; [deg], [mm] of a prismatic joint): "
                      f"{values or 'none the views determine'}; {how}")
    for name, T in r.solution.named().items():
        console.print(f"{name} ({r.chosen}):")
        for row in T[:3]:
            console.print("  [" + ", ".join(f"{v: .6f}" for v in row) + "]")
    for _, message in r.diversity.issues:
        console.print(styled("warning:", "yellow", f" {message}"))
    if r.verdict is not None:
        console.print(styled("verdict:", "green" if r.verdict.trusted else "red", f" {r.verdict.line()}"))
    yaml_written = r.setup is Setup.EYE_IN_HAND and (r.folder / "hand_eye.yaml").exists()
    names = ["handeye.json"] + (["hand_eye.yaml"] if yaml_written else []) + ["handeye_residuals.png"]
    console.print("written: " + ", ".join(str(r.folder / n) for n in names))


@calibrate_app.command("intrinsics")
def intrinsics(
    source: Annotated[Path, typer.Argument(help="Folder of board images, or a scan store (its colour images).")],
    out: Annotated[Path | None, typer.Option("--out", "-o", help="Output folder (default runs/intrinsics-<time>).")]
    = None,
    pattern: Annotated[str, typer.Option(help="Which files of an image folder (a glob inside it: relative, no "
                                              "'..'), e.g. 'img_*.jpg'.")] = "*",
    model: Annotated[DistortionModel, typer.Option(help="Distortion coefficients to fit: k1k2p1p2k3 (OpenCV's "
                                                        "default), k1k2p1p2, k1k2 or none.")] = DistortionModel.FULL,
    board: BoardOpt = None,
    min_corners: Annotated[int, typer.Option(min=4, max=10_000, help="Board corners an image needs to take "
                                                                      "part.")] = 8,
    profile: Annotated[str | None, realism_option("Realism profile (ideal, thesis, lab or FILE.yaml) to copy into "
                                                  "<out>/realism.yaml with the calibration as its assumed camera "
                                                  "(simulated sessions then use it: --realism that file).")] = None,
    force: ForceOpt = False,
) -> None:
    """Camera calibration (intrinsics and lens distortion) from images of the ChArUco board."""


    check_pattern(pattern)
    spec = parse_board(board)
    folder = output_folder(out, "calibrate intrinsics", default="intrinsics", force=force,
                           inputs=(source, None if profile is None else Path(profile))).path
    run = run_intrinsics(IntrinsicsOptions(Path(source), folder, spec, pattern, model, min_corners,
                                           profile))
    r = run.result
    K = r.camera.intrinsics
    for s in r.skipped:
        console.print(styled(f"{s.name} not used:", "yellow", f" {s.reason}"))
    console.print(f"{len(r.views)} of {run.images} images, {r.corners} corners; reprojection RMS {r.rms:.3f} px")
    console.print("view                          RMS [px]  max [px]  corners")
    for v in r.views:
        console.print(f"{v.name[:28]:28s} {v.rms:9.3f} {v.max:9.3f}  {len(v.residuals):7d}")
    std = r.std
    console.print(f"{K.width} x {K.height}: fx {K.fx:.3f} ± {std.get('fx', np.nan):.3f}, fy {K.fy:.3f} ± "
                  f"{std.get('fy', np.nan):.3f}, cx {K.cx:.3f} ± {std.get('cx', np.nan):.3f}, cy {K.cy:.3f} ± "
                  f"{std.get('cy', np.nan):.3f} px")
    console.print("distortion k1, k2, p1, p2, k3: " + ", ".join(f"{v:.6g}" for v in r.camera.distortion))
    console.print(f"camera file: {run.camera_file}\nreport: {run.report}\nfigure: {run.figure}")
    if run.profile is not None:
        console.print(f"realism profile with this camera as the assumed one: {run.profile}")
