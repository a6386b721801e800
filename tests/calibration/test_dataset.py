"""Hand-eye calibration from a data set made by anyone (recon calibrate handeye --dataset):
board images rendered with OpenCV from known poses, their robot poses written in the forms
people log them (libfranka's column-major O_T_EE in JSON, xyz + wxyz quaternion in YAML, a
CSV in mm and degrees, joint positions, an index file), each read to the same calibration,
both set-ups recovered, the same numbers on every run; the mistakes of a data set are one
line each and the usable views still calibrate."""

from __future__ import annotations

import csv
import json
import math
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from recon_cli.calibration.dataset import (
    AngleUnit,
    LengthUnit,
    MatrixOrder,
    PoseFormat,
    PoseMapping,
    QuaternionOrder,
    robot_pose,
)
from recon_cli.calibration.handeye import HandEyeMethod
from recon_cli.calibration.setups import Setup
from recon_cli.cli import main
from recon_cli.errors import InputError
from recon_cli.geometry.transforms import invert, pose_error
from recon_cli.perception.camera_model import Intrinsics
from recon_cli.perception.charuco import BoardSpec
from recon_cli.workflows.handeye_dataset import DatasetHandEyeOptions, run_handeye_dataset

BOARD = BoardSpec(5, 7, 0.04, 0.03, "DICT_6X6_250")  # 0.20 x 0.28 m
K = Intrinsics(960, 720, 900.0, 900.0, 479.5, 359.5)
INTRINSICS = (K.fx, K.fy, K.cx, K.cy)
PPM = 2500.0  # [px/m] of the printed board image the views are rendered from
N_VIEWS = 10


def _T(rotvec, t) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
    T[:3, 3] = t
    return T


#: the truth of both set-ups: eye-in-hand (flange_T_camera, base_T_board), eye-to-hand
#: (base_T_camera, flange_T_board)
FLANGE_T_CAMERA = _T([0.05, -0.08, 1.2], [0.04, -0.06, 0.11])
BASE_T_BOARD = _T([0.1, 3.0, 0.05], [0.62, 0.15, 0.02])
BASE_T_CAMERA = _T([-2.0, 0.3, 0.2], [0.4, 1.1, 0.6])
FLANGE_T_BOARD = _T([0.3, -0.2, 1.0], [0.02, 0.05, 0.09])


def _camera_T_marker(k: int) -> np.ndarray:
    """View k: the camera 0.42-0.55 m from a point near the board's centre, tilted 12-38°,
    turned about it and rolled about its viewing direction."""
    golden = math.pi * (3 - math.sqrt(5))
    centre = np.array([0.10, 0.14, 0.0]) + 0.02 * np.array([math.cos(3 * k), math.sin(5 * k), 0.0])
    tilt, azimuth = np.radians(12 + 26 * ((k * 0.618) % 1.0)), k * golden
    d = 0.42 + 0.13 * ((k * 0.382) % 1.0)
    p = centre + d * np.array([math.sin(tilt) * math.cos(azimuth), math.sin(tilt) * math.sin(azimuth),
                               math.cos(tilt)])
    z = (centre - p) / np.linalg.norm(centre - p)
    x = np.cross([0.0, 1.0, 0.0], z)
    x /= np.linalg.norm(x)
    R = np.column_stack([x, np.cross(z, x), z]) @ Rotation.from_rotvec([0, 0, np.radians(-30 + 60 * ((k * 0.7) % 1))]
                                                                       ).as_matrix()
    marker_T_camera = np.eye(4)
    marker_T_camera[:3, :3], marker_T_camera[:3, 3] = R, p
    return invert(marker_T_camera)


def _render(camera_T_marker: np.ndarray) -> np.ndarray:
    """The board as the camera sees it (BGR), white around it."""
    printed = BOARD.image(PPM)
    h = printed.shape[0]
    board_px_to_marker = np.array([[1 / PPM, 0, 0.5 / PPM], [0, -1 / PPM, h / PPM - 0.5 / PPM], [0, 0, 1]])
    P = K.matrix() @ camera_T_marker[:3, [0, 1, 3]]
    image = cv2.warpPerspective(printed, P @ board_px_to_marker, (K.width, K.height), flags=cv2.INTER_AREA,
                                borderValue=255)
    image = cv2.GaussianBlur(image, (0, 0), 0.6)
    return cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)


@pytest.fixture(scope="module")
def views(tmp_path_factory) -> tuple[Path, list[np.ndarray]]:
    """The rendered images (images/0.png ...) and the camera_T_marker of each."""
    folder = tmp_path_factory.mktemp("rendered")
    poses = [_camera_T_marker(k) for k in range(N_VIEWS)]
    for k, C in enumerate(poses):
        cv2.imwrite(str(folder / f"{k}.png"), _render(C))
    return folder, poses


def _eye_in_hand_flange(C: np.ndarray) -> np.ndarray:
    return BASE_T_BOARD @ invert(C) @ invert(FLANGE_T_CAMERA)  # base_T_flange X C = base_T_board


def _eye_to_hand_flange(C: np.ndarray) -> np.ndarray:
    return BASE_T_CAMERA @ C @ invert(FLANGE_T_BOARD)  # base_T_flange Y = base_T_camera C


def _copy_images(rendered: Path, folder: Path, sub: str = "images") -> Path:
    (folder / sub).mkdir(parents=True, exist_ok=True)
    for k in range(N_VIEWS):
        shutil.copy(rendered / f"{k}.png", folder / sub / f"{k}.png")
    return folder


def _franka_json(rendered, poses, folder: Path) -> dict:
    """libfranka's O_T_EE: 16 numbers, column-major, one JSON file per image (no mapping)."""
    _copy_images(rendered, folder)
    (folder / "poses").mkdir()
    for k, C in enumerate(poses):
        F = _eye_in_hand_flange(C)
        (folder / "poses" / f"{k}.json").write_text(json.dumps({"O_T_EE": F.T.ravel().tolist(), "time": k}))
    return {}


def _wxyz_yaml(rendered, poses, folder: Path) -> dict:
    """xyz + wxyz quaternion under keys t and q, read by a mapping file."""
    _copy_images(rendered, folder)
    (folder / "poses").mkdir()
    for k, C in enumerate(poses):
        F = _eye_in_hand_flange(C)
        x, y, z, w = Rotation.from_matrix(F[:3, :3]).as_quat()
        (folder / "poses" / f"{k}.yaml").write_text(yaml.safe_dump({"t": F[:3, 3].tolist(), "q": [
            float(w), float(x), float(y), float(z)]}))
    mapping = folder / "mapping.yaml"
    mapping.write_text("pose_format: xyz-quat\nposition: t\nquaternion: q\nquaternion_order: wxyz\n")
    return {"mapping": mapping}


def _csv_mm_deg(rendered, poses, folder: Path) -> dict:
    """One CSV in mm and degrees (roll-pitch-yaw), the units given as options."""
    _copy_images(rendered, folder)
    with open(folder / "robot_log.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["frame", "X_mm", "Y_mm", "Z_mm", "Rx_deg", "Ry_deg", "Rz_deg"])
        for k, C in enumerate(poses):
            F = _eye_in_hand_flange(C)
            yaw, pitch, roll = Rotation.from_matrix(F[:3, :3]).as_euler("ZYX", degrees=True)
            w.writerow([f"images/{k}.png", *(repr(float(v)) for v in F[:3, 3] * 1e3),
                        repr(float(roll)), repr(float(pitch)), repr(float(yaw))])
    mapping = folder / "mapping.yaml"
    mapping.write_text("image_column: frame\nposition: [X_mm, Y_mm, Z_mm]\nrpy: [Rx_deg, Ry_deg, Rz_deg]\n")
    return {"mapping": mapping, "pose_format": PoseFormat.XYZ_RPY, "length_unit": LengthUnit.MM,
            "angle_unit": AngleUnit.DEG}


FORMATS = {"franka_json": _franka_json, "wxyz_yaml": _wxyz_yaml, "csv_mm_deg": _csv_mm_deg}


def _calibrate(folder: Path, out: Path, **kw):
    return run_handeye_dataset(DatasetHandEyeOptions(folder, out, intrinsics=INTRINSICS, board=BOARD, **kw))


@pytest.fixture(scope="module")
def eye_in_hand(views, tmp_path_factory):
    """Each format's calibration (eye-in-hand)."""
    rendered, poses = views
    results = {}
    for name, write in FORMATS.items():
        folder = tmp_path_factory.mktemp(name)
        kw = write(rendered, poses, folder / "data")
        results[name] = _calibrate(folder / "data", folder / "out", **kw)
    return results


def test_every_format_reads_to_the_same_calibration(eye_in_hand):
    ref = eye_in_hand["franka_json"]
    assert ref.mapping.pose_format is PoseFormat.MATRIX and ref.mapping.matrix_order is MatrixOrder.COLUMN
    for name, r in eye_in_hand.items():
        assert len(r.used) == N_VIEWS and not r.skipped, (name, r.skipped)
        assert r.converged and r.setup is Setup.EYE_IN_HAND
        for got, want in ((r.solution.X, ref.solution.X), (r.solution.W, ref.solution.W)):
            dt, dr = pose_error(got, want)
            assert dt < 1e-6 and dr < 1e-6, (name, dt, dr)


def test_eye_in_hand_recovers_the_truth(eye_in_hand):
    r = eye_in_hand["franka_json"]
    dt, dr = pose_error(r.solution.named()["flange_T_camera"], FLANGE_T_CAMERA)
    assert dt < 1e-3 and np.degrees(dr) < 0.1, (dt, np.degrees(dr))
    dt, dr = pose_error(r.solution.named()["base_T_board"], BASE_T_BOARD)
    assert dt < 1e-3 and np.degrees(dr) < 0.1, (dt, np.degrees(dr))
    assert r.reprojection_rms < 0.5 and r.chain_rms[0] < 1e-3 and not r.outliers
    assert set(r.methods) == set(HandEyeMethod)
    for m in r.methods.values():  # every OpenCV method close to the written one
        assert m.vs_written[0] < 2e-3 and np.degrees(m.vs_written[1]) < 0.2
    written = {p.name for p in r.folder.iterdir()}
    assert written == {"handeye.json", "hand_eye.yaml", "handeye_residuals.png"}
    report = json.loads((r.folder / "handeye.json").read_text())
    assert report["setup"] == "eye-in-hand" and len(report["views"]) == N_VIEWS
    assert report["refinement"]["converged"] is True


def test_the_same_numbers_on_every_run(eye_in_hand, tmp_path):
    first = eye_in_hand["wxyz_yaml"]
    again = _calibrate(first.dataset, tmp_path / "again", mapping=first.dataset / "mapping.yaml")
    a = json.loads((first.folder / "handeye.json").read_text())
    b = json.loads((again.folder / "handeye.json").read_text())
    a.pop("seconds"), b.pop("seconds")
    assert a == b


def test_eye_to_hand_from_an_index_file(views, tmp_path):
    """The camera fixed, the board on the flange: an index of {image, pose} pairs (xyz +
    xyzw quaternion, as ros-industrial's cal_data.yaml) with its intrinsics and board."""
    rendered, poses = views
    data = _copy_images(rendered, tmp_path / "data")
    (data / "poses").mkdir()
    entries = []
    for k, C in enumerate(poses):
        F = _eye_to_hand_flange(C)
        x, y, z, w = Rotation.from_matrix(F[:3, :3]).as_quat()
        (data / "poses" / f"{k}.yaml").write_text(yaml.safe_dump({
            "x": float(F[0, 3]), "y": float(F[1, 3]), "z": float(F[2, 3]),
            "qx": float(x), "qy": float(y), "qz": float(z), "qw": float(w)}))
        entries.append({"image": f"images/{k}.png", "pose": f"poses/{k}.yaml"})
    (data / "cal_data.yaml").write_text(yaml.safe_dump({
        "data": entries, "static_camera": True, "intrinsics": dict(zip(("fx", "fy", "cx", "cy"), INTRINSICS,
                                                                       strict=True)),
        "target_finder": {"type": "CharucoGridTargetFinder", "rows": 7, "cols": 5, "chessboard_dim": 0.04,
                          "aruco_marker_dim": 0.03, "dictionary": 10}}))
    r = run_handeye_dataset(DatasetHandEyeOptions(data, tmp_path / "out"))
    assert r.setup is Setup.EYE_TO_HAND and r.board == BOARD and len(r.used) == N_VIEWS
    assert r.sources["camera"] == "the index file's intrinsics"
    # the index file's camera has no distortion, and the renders have none: a camera
    # calibrated from the other photos does not explain each photo better, and is not used
    check = r.camera_check
    assert check is not None and check.views == N_VIEWS and not check.calibrate and r.camera_fit is None
    named = r.solution.named()
    for key, truth in (("base_T_camera", BASE_T_CAMERA), ("flange_T_board", FLANGE_T_BOARD)):
        dt, dr = pose_error(named[key], truth)
        assert dt < 1e-3 and np.degrees(dr) < 0.1, (key, dt, np.degrees(dr))
    assert r.pnp_mean[0] < 1e-3 and r.converged
    assert not (r.folder / "hand_eye.yaml").exists()  # a station's hand_eye is eye-in-hand


def test_joint_positions_through_a_cell(views, tmp_path):
    """Joint positions in degrees, the flange by forward kinematics of the FR3 cell."""
    from recon_cli.robot.description import CellConfig, CellName, expand_urdf
    from recon_cli.robot.kinematics import Kinematics

    cell = CellConfig(kind=CellName.parse("fr3"))
    kin = Kinematics(expand_urdf(cell), cell.cell_file)
    rng = np.random.default_rng(7)
    q0 = kin.neutral()
    lo, hi = kin.limits.lower, kin.limits.upper
    data = tmp_path / "data"
    (data / "poses").mkdir(parents=True)
    (data / "images").mkdir()
    # the camera on the flange, the board placed where the first configuration sees it
    F0 = kin.frame_pose(np.clip(q0, lo, hi), kin.cell.flange_link)
    W = F0 @ FLANGE_T_CAMERA @ _camera_T_marker(0)
    k = 0
    while k < 6:
        q = np.clip(q0 + rng.uniform(-0.25, 0.25, size=len(q0)), lo, hi)
        C = invert(FLANGE_T_CAMERA) @ invert(kin.frame_pose(q, kin.cell.flange_link)) @ W
        corners = (C[:3, :3] @ np.array([[0, 0, 0], [0.2, 0, 0], [0, 0.28, 0], [0.2, 0.28, 0]]).T).T + C[:3, 3]
        uv = corners[:, :2] / corners[:, 2:] * 900 + [479.5, 359.5]
        if np.all(corners[:, 2] > 0.2) and np.all((uv > 20) & (uv < [940, 700])):
            cv2.imwrite(str(data / "images" / f"{k}.png"), _render(C))
            (data / "poses" / f"{k}.yaml").write_text(yaml.safe_dump({"joints": np.degrees(q).tolist()}))
            k += 1
    # the views turn by less than the 17° per pair that OpenCV's Tsai needs (it finds no solution)
    r = _calibrate(data, tmp_path / "out", cell=cell, angle_unit=AngleUnit.DEG, method=HandEyeMethod.PARK)
    assert r.mapping.pose_format is PoseFormat.JOINTS and len(r.used) == 6
    assert "Not enough informative motions" in r.method_failures[HandEyeMethod.TSAI]
    dt, dr = pose_error(r.solution.named()["flange_T_camera"], FLANGE_T_CAMERA)
    assert dt < 2e-3 and np.degrees(dr) < 0.2, (dt, np.degrees(dr))


# ----------------------------------------------------------------------------- one pose
@pytest.mark.parametrize(("record", "mapping"), [
    ({"x": 0.1, "y": 0.2, "z": 0.3, "qx": 0.0, "qy": 0.0, "qz": math.sin(0.25), "qw": math.cos(0.25)},
     PoseMapping(PoseFormat.XYZ_QUAT)),
    ({"p": [100, 200, 300], "q": [math.cos(0.25), 0, 0, math.sin(0.25)]},
     PoseMapping(PoseFormat.XYZ_QUAT, position=("p",), quaternion=("q",), quaternion_order=QuaternionOrder.WXYZ,
                 length_unit=LengthUnit.MM)),
    ({"x": 0.1, "y": 0.2, "z": 0.3, "roll": 0, "pitch": 0, "yaw": math.degrees(0.5)},
     PoseMapping(PoseFormat.XYZ_RPY, angle_unit=AngleUnit.DEG)),
    ({"m": [[math.cos(0.5), -math.sin(0.5), 0, 0.1], [math.sin(0.5), math.cos(0.5), 0, 0.2], [0, 0, 1, 0.3],
            [0, 0, 0, 1]]}, PoseMapping(PoseFormat.MATRIX, matrix=("m",))),
    ({"O_T_EE": [math.cos(0.5), math.sin(0.5), 0, 0, -math.sin(0.5), math.cos(0.5), 0, 0, 0, 0, 1, 0, 0.1, 0.2, 0.3,
                 1]}, PoseMapping(PoseFormat.MATRIX, matrix=("O_T_EE",), matrix_order=MatrixOrder.COLUMN)),
    ({"pose": {"position": {"x": 0.1, "y": 0.2, "z": 0.3}, "orientation": {"x": 0, "y": 0, "z": math.sin(0.25),
                                                                          "w": math.cos(0.25)}}},
     PoseMapping(PoseFormat.XYZ_QUAT, position=("pose.position.x", "pose.position.y", "pose.position.z"),
                 quaternion=("pose.orientation.x", "pose.orientation.y", "pose.orientation.z", "pose.orientation.w"))),
], ids=["xyzw", "mm-wxyz-lists", "rpy-deg", "matrix-rows", "franka-columns", "nested-ros"])
def test_each_form_of_a_pose(record, mapping):
    want = _T([0, 0, 0.5], [0.1, 0.2, 0.3])
    assert np.allclose(robot_pose(record, "p.yaml", mapping), want, atol=1e-12)


@pytest.mark.parametrize(("record", "mapping", "message"), [
    ({"x": 0, "y": 0, "z": 0, "qx": 0, "qy": 0, "qz": 0, "qw": 1.02}, PoseMapping(PoseFormat.XYZ_QUAT),
     "p.yaml: the quaternion's norm is 1.02, off 1 by 0.02 (more than 0.001); this view is not used"),
    ({"x": 612.0, "y": 20.0, "z": 410.0, "qx": 0, "qy": 0, "qz": 0, "qw": 1}, PoseMapping(PoseFormat.XYZ_QUAT),
     "looks like millimetres while the mapping says metres; set length_unit: mm"),
    ({"x": 0, "y": 0, "z": 0, "roll": 180, "pitch": 0, "yaw": 90}, PoseMapping(PoseFormat.XYZ_RPY),
     "looks like degrees while the mapping says radians; set angle_unit: deg"),
    ({"O_T_EE": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0.1, 0.2, 0.3, 1]},
     PoseMapping(PoseFormat.MATRIX, matrix=("O_T_EE",), matrix_order=MatrixOrder.ROW),
     "looks column-major while the mapping says row-major; set matrix_order: column"),
    ({"x": 0, "y": 0, "z": 0, "qx": 0, "qy": 0, "qw": 1}, PoseMapping(PoseFormat.XYZ_QUAT),
     "p.yaml: no key 'qz' (the quaternion; keys: x, y, z, qx, qy, qw)"),
])
def test_a_wrong_pose_is_one_line_naming_the_file(record, mapping, message):
    with pytest.raises(InputError) as info:
        robot_pose(record, "p.yaml", mapping)
    assert message in info.value.one_line() and "\n" not in info.value.one_line()


def test_a_nearly_unit_quaternion_is_normalised():
    s = 1.0 + 4e-4
    T = robot_pose({"x": 0, "y": 0, "z": 0, "qx": 0, "qy": 0, "qz": 0, "qw": s}, "p", PoseMapping(PoseFormat.XYZ_QUAT))
    assert np.allclose(T, np.eye(4))


# ----------------------------------------------------------------------------- mistakes
def test_the_usable_views_still_calibrate(views, tmp_path):
    """An image without the board, a missing pose file, a quaternion off by 2 %: each skipped
    with one line naming its file; the other views calibrate. (A pose in millimetres among
    poses in metres refuses the whole set: tests/calibration/test_verdict.py.)"""
    rendered, poses = views
    data = _copy_images(rendered, tmp_path / "data")
    (data / "poses").mkdir()
    for k, C in enumerate(poses):
        F = _eye_in_hand_flange(C)
        x, y, z, w = Rotation.from_matrix(F[:3, :3]).as_quat()
        t = F[:3, 3]
        q = np.array([x, y, z, w]) * (1.02 if k == 2 else 1.0004 if k == 4 else 1.0)
        if k != 1:
            (data / "poses" / f"{k}.yaml").write_text(yaml.safe_dump(dict(zip(
                ("x", "y", "z", "qx", "qy", "qz", "qw"), map(float, [*t, *q]), strict=True))))
    cv2.imwrite(str(data / "images" / "0.png"), np.full((K.height, K.width, 3), 255, np.uint8))
    r = _calibrate(data, tmp_path / "out")
    reasons = {s.name: s.reason for s in r.skipped}
    assert set(reasons) == {"images/0.png", "images/1.png", "images/2.png"}
    assert "board not found (0 corners, 8 needed)" in reasons["images/0.png"]
    assert f"no pose file {data / 'poses' / '1'}.yaml (or .yml, .json)" in reasons["images/1.png"]
    assert f"{data / 'poses' / '2.yaml'}: the quaternion's norm is 1.02, off 1 by 0.02" in reasons["images/2.png"]
    assert len(r.used) == N_VIEWS - 3 and "images/4.png" in {v.name for v in r.used}
    dt, dr = pose_error(r.solution.named()["flange_T_camera"], FLANGE_T_CAMERA)
    assert dt < 1e-3 and np.degrees(dr) < 0.1


def test_an_outlier_is_flagged_and_dropped_on_request(views, tmp_path):
    rendered, poses = views
    data = _copy_images(rendered, tmp_path / "data")
    (data / "poses").mkdir()
    for k, C in enumerate(poses):
        F = _eye_in_hand_flange(C)
        if k == 5:  # a robot that had not settled: 2 cm and 2° off
            F = F @ _T([0, np.radians(2.0), 0], [0.02, 0, 0])
        (data / "poses" / f"{k}.json").write_text(json.dumps({"matrix": F.tolist()}))
    kept = _calibrate(data, tmp_path / "kept", accept=True)
    assert list(kept.outliers) == ["images/5.png"] and len(kept.used) == N_VIEWS
    assert kept.verdict is not None and not kept.verdict.trusted  # the outlier kept: not trusted
    dropped = _calibrate(data, tmp_path / "dropped", drop_outliers=True)
    assert dropped.dropped == ["images/5.png"] and len(dropped.used) == N_VIEWS - 1
    assert dropped.chain_rms[0] < kept.chain_rms[0]
    dt, dr = pose_error(dropped.solution.named()["flange_T_camera"], FLANGE_T_CAMERA)
    assert dt < 1e-3 and np.degrees(dr) < 0.1
    assert dropped.verdict is not None and dropped.verdict.trusted


def _run(capsys, *argv) -> tuple[int, str]:
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out + err


def test_fewer_than_three_views_is_one_line_and_nothing_is_written(views, tmp_path, capsys):
    rendered, poses = views
    data = _copy_images(rendered, tmp_path / "data")
    (data / "poses").mkdir()
    for k in range(2):
        (data / "poses" / f"{k}.json").write_text(json.dumps({"matrix": _eye_in_hand_flange(poses[k]).tolist()}))
    out = tmp_path / "out"
    code, text = _run(capsys, "calibrate", "handeye", "--dataset", data, "--intrinsics", ",".join(map(str, INTRINSICS)),
                      "--board-spec", "5,7,0.04,0.03,DICT_6X6_250", "--out", out)
    assert code == 1 and len(text.strip().splitlines()) == 1, text
    assert "2 of the 10 views" in text and "needs 3 or more" in text and "no pose file" in text
    assert not out.exists() or not any(out.iterdir())


def test_the_command_line(eye_in_hand, tmp_path, capsys):
    r = eye_in_hand["csv_mm_deg"]
    code, text = _run(capsys, "calibrate", "handeye", "--dataset", r.dataset, "--mapping", r.dataset / "mapping.yaml",
                      "--pose-format", "xyz-rpy", "--length-unit", "mm", "--angle-unit", "deg", "--intrinsics",
                      ",".join(map(str, INTRINSICS)), "--board-spec", "5,7,0.04,0.03,DICT_6X6_250", "--out",
                      tmp_path / "cli")
    assert code == 0, text
    assert "10 views, converged" in text and f"flange_T_camera ({r.chosen})" in text and "verdict: trusted" in text
    report = json.loads((tmp_path / "cli" / "handeye.json").read_text())
    assert np.allclose(report["flange_T_camera"], r.solution.X, atol=1e-9)


@pytest.mark.parametrize(("extra", "message"), [
    (["--setup", "eye-to-hand"], "--setup is read with --dataset only"),
    (["--dataset", "{tmp}", "--scan-store", "{tmp}"], "--dataset is calibrated on its own"),
    (["--dataset", "{tmp}/none", "--intrinsics", "1,1,1,1"], "data set {tmp}/none does not exist"),
    (["--dataset", "{tmp}", "--intrinsics", "1,2"], "--intrinsics: 2 numbers, 4, 8 or 9 expected"),
    (["--dataset", "{tmp}"], "the camera's intrinsics are not known for the data set"),
    (["--dataset", "{tmp}", "--setup", "eye-on-base"], "Invalid value for '--setup': 'eye-on-base' is not one of"),
])
def test_command_line_mistakes_are_one_line(tmp_path, capsys, extra, message):
    cv2.imwrite(str(tmp_path / "0.png"), np.full((48, 64, 3), 255, np.uint8))
    code, text = _run(capsys, "calibrate", "handeye", *[a.format(tmp=tmp_path) for a in extra], "--out",
                      tmp_path / "o")
    assert code in (1, 2) and message.format(tmp=tmp_path) in text, text
    assert len(text.strip().splitlines()) == 1


def test_a_mapping_file_is_checked(tmp_path, capsys):
    (tmp_path / "images").mkdir()
    mapping = tmp_path / "mapping.yaml"
    mapping.write_text("pose_format: xyz-quat\nquaternion_order: zyxw\n")
    code, text = _run(capsys, "calibrate", "handeye", "--dataset", tmp_path, "--mapping", mapping, "--intrinsics",
                      "900,900,480,360", "--out", tmp_path / "o")
    assert code == 1 and f"{mapping}:2: quaternion_order" in text and "is not one of xyzw, wxyz" in text, text
