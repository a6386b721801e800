"""Hand-eye data sets as labs write them, read without an index file: a folder per view
(pose_NN/{image.png, data.json}, as Franka capture scripts write them) and images beside
their pose files (0001.png + 0001.json); the camera's intrinsics and distortion read from
each pose file by key; a 4x4 matrix's order told by its numbers (libfranka's column-major
O_T_EE, or the same key written row by row); a camera with distortion on the command line.
Each mistake is one line; a real Franka set (when present) is read as it is published."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from recon_cli.calibration import dataset as ds
from recon_cli.calibration.dataset import (
    CameraNumbers,
    DatasetSpec,
    MatrixOrder,
    PoseFormat,
    PoseMapping,
    camera_numbers,
    detect_format,
    matrix_order_of,
    parse_camera_numbers,
    read_dataset,
    read_mapping,
    robot_pose,
    view_camera,
)
from recon_cli.cli import main
from recon_cli.errors import InputError, ReconError
from recon_cli.geometry.transforms import pose_error
from recon_cli.workflows.handeye_dataset import DatasetHandEyeOptions, run_handeye_dataset

from .test_dataset import _T, BOARD, FLANGE_T_CAMERA, N_VIEWS, K, _camera_T_marker, _eye_in_hand_flange, _render

#: the camera matrix of the rendered views, as a pose file holds it
K3 = [[K.fx, 0.0, K.cx], [0.0, K.fy, K.cy], [0.0, 0.0, 1.0]]
#: a real Franka eye-in-hand set: github.com/kvasios/franka-handeye (MIT), data/captured-data at 0b9fe29
FRANKA = Path(os.environ.get("RECON_FRANKA_HANDEYE", "/work/shared_extra/franka-handeye-kvasios"))


@pytest.fixture(scope="module")
def rendered(tmp_path_factory) -> tuple[Path, list[np.ndarray]]:
    folder = tmp_path_factory.mktemp("rendered")
    poses = [_camera_T_marker(k) for k in range(N_VIEWS)]
    for k, C in enumerate(poses):
        cv2.imwrite(str(folder / f"{k}.png"), _render(C))
    return folder, poses


def _view_folders(rendered, folder: Path, pose: callable) -> Path:
    """pose_0 ... pose_9/{image.png, data.json, depth.png}: ``pose(k, base_T_flange)`` the JSON."""
    images, poses = rendered
    for k, C in enumerate(poses):
        sub = folder / f"pose_{k}"
        sub.mkdir(parents=True)
        shutil.copy(images / f"{k}.png", sub / "image.png")
        cv2.imwrite(str(sub / "depth.png"), np.zeros((8, 8), np.uint16))
        (sub / "data.json").write_text(json.dumps(pose(k, _eye_in_hand_flange(C))))
    return folder


def _franka(k: int, F: np.ndarray) -> dict:
    """What a Franka capture script writes: joints, O_T_EE (libfranka's column-major), the camera."""
    return {"joint_pose": [0.1 * k] * 7, "O_T_EE": F.T.ravel().tolist(), "camera_intrinsics": K3,
            "dist_coeffs": [0.0] * 5, "charuco_detected": True}


# ----------------------------------------------------------------------------- layouts
def test_a_folder_per_view_is_found_in_natural_order(rendered, tmp_path):
    data = _view_folders(rendered, tmp_path / "data", _franka)
    found = read_dataset(data)
    assert found.layout == f"a folder per view in {data}" and not found.skipped
    assert [v.name for v in found.views] == [f"pose_{k}/image.png" for k in range(N_VIEWS)]  # pose_2 before pose_10
    assert all(v.where.endswith("data.json") for v in found.views)
    assert found.hints.camera == CameraNumbers(K.fx, K.fy, K.cx, K.cy, (0.0,) * 5)


def test_a_folder_per_view_calibrates_without_index_camera_or_mapping(rendered, tmp_path):
    data = _view_folders(rendered, tmp_path / "data", _franka)
    r = run_handeye_dataset(DatasetHandEyeOptions(data, tmp_path / "out", board=BOARD))
    assert len(r.used) == N_VIEWS and not r.skipped
    assert r.sources["camera"] == "the pose files' intrinsics"
    assert r.mapping.pose_format is PoseFormat.MATRIX and r.mapping.matrix_order is MatrixOrder.COLUMN
    dt, dr = pose_error(r.solution.named()["flange_T_camera"], FLANGE_T_CAMERA)
    assert dt < 1e-3 and np.degrees(dr) < 0.1, (dt, np.degrees(dr))


def test_o_t_ee_written_row_by_row_is_read_as_such(rendered, tmp_path):
    """Some capture scripts write the O_T_EE key row by row (franky's Affine.matrix): the
    numbers say which, every view reads to the same calibration."""
    data = _view_folders(rendered, tmp_path / "data", lambda k, F: {**_franka(k, F), "O_T_EE": F.ravel().tolist()})
    r = run_handeye_dataset(DatasetHandEyeOptions(data, tmp_path / "out", board=BOARD))
    assert r.mapping.matrix_order is MatrixOrder.ROW and len(r.used) == N_VIEWS
    dt, dr = pose_error(r.solution.named()["flange_T_camera"], FLANGE_T_CAMERA)
    assert dt < 1e-3 and np.degrees(dr) < 0.1


def test_images_and_pose_files_side_by_side(rendered, tmp_path):
    """0001.png beside 0001.json, RealSense's intrinsics ({fx, fy, ppx, ppy, coeffs}) in each."""
    images, poses = rendered
    data = tmp_path / "data"
    data.mkdir()
    for k, C in enumerate(poses):
        shutil.copy(images / f"{k}.png", data / f"{k + 1:04d}.png")
        F = _eye_in_hand_flange(C)
        (data / f"{k + 1:04d}.json").write_text(json.dumps({
            "matrix": F.tolist(), "intrinsics": {"width": K.width, "height": K.height, "fx": K.fx, "fy": K.fy,
                                                 "ppx": K.cx, "ppy": K.cy, "model": "brown_conrady",
                                                 "coeffs": [0.0] * 5}}))
    found = read_dataset(data)
    assert len(found.views) == N_VIEWS and not found.skipped and found.hints.camera is not None
    assert found.views[0].name == "0001.png" and found.views[0].where.endswith("0001.json")
    r = run_handeye_dataset(DatasetHandEyeOptions(data, tmp_path / "out", board=BOARD))
    assert len(r.used) == N_VIEWS and r.mapping.matrix_order is MatrixOrder.ROW
    dt, dr = pose_error(r.solution.named()["flange_T_camera"], FLANGE_T_CAMERA)
    assert dt < 1e-3 and np.degrees(dr) < 0.1


def test_the_mapping_names_the_camera_keys(rendered, tmp_path):
    data = _view_folders(rendered, tmp_path / "data", lambda k, F: {
        "pose": {"T": F.T.ravel().tolist()}, "cam": {"M": K3, "dc": [0.01, -0.02, 0.0, 0.0, 0.003]}})
    mapping = tmp_path / "data" / "mapping.yaml"
    mapping.write_text("pose_format: matrix\nmatrix: pose.T\nmatrix_order: column\nintrinsics_key: cam.M\n"
                       "distortion_key: cam.dc\n")
    spec = read_mapping(mapping, data)
    assert (spec.intrinsics_key, spec.distortion_key) == ("cam.M", "cam.dc")
    found = read_dataset(data, spec)
    assert found.hints.camera == CameraNumbers(K.fx, K.fy, K.cx, K.cy, (0.01, -0.02, 0.0, 0.0, 0.003))
    assert all(v.camera == found.hints.camera for v in found.views)


# ----------------------------------------------------------------------------- the camera by key
@pytest.mark.parametrize(("record", "want"), [
    ({"K": K3, "D": [0.1, -0.2, 0.001, 0.002]}, (0.1, -0.2, 0.001, 0.002, 0.0)),
    ({"camera_matrix": sum(K3, []), "dist_coeffs": [[0.1, -0.2, 0.001, 0.002, 0.03]]},
     (0.1, -0.2, 0.001, 0.002, 0.03)),
    ({"intrinsics": {"fx": K.fx, "fy": K.fy, "cx": K.cx, "cy": K.cy, "distortion": [0.1, 0, 0, 0, 0]}},
     (0.1, 0.0, 0.0, 0.0, 0.0)),
    ({"intrinsics": {"fx": K.fx, "fy": K.fy, "ppx": K.cx, "ppy": K.cy, "coeffs": [0.1, 0, 0, 0, 0]}},
     (0.1, 0.0, 0.0, 0.0, 0.0)),
    ({"camera_intrinsics": [K.fx, K.fy, K.cx, K.cy], "distortion": [0.1, -0.2, 0, 0, 0, 0, 0, 0]},
     (0.1, -0.2, 0.0, 0.0, 0.0)),
    ({"camera_info": {"K": sum(K3, []), "D": [0.1, 0, 0, 0, 0]}}, (0.1, 0.0, 0.0, 0.0, 0.0)),
    ({"K": K3}, (0.0,) * 5),
], ids=["K-D", "flat-9-nested-dist", "dict", "realsense", "four-and-eight", "ros-camera-info", "no-distortion"])
def test_the_camera_of_a_pose_file_by_key(record, want):
    assert view_camera(record, "p.json") == CameraNumbers(K.fx, K.fy, K.cx, K.cy, want)


@pytest.mark.parametrize(("record", "keys", "message"), [
    ({"K": [[K.fx, 0, 0], [0, K.fy, 0], [K.cx, K.cy, 1]]}, {},
     "p.json: K is not a camera matrix [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] (it looks written column by column)"),
    ({"K": [1, 2, 3]}, {}, "p.json: K holds 3 numbers; intrinsics are a 3x3 camera matrix (9) or fx, fy, cx, cy (4)"),
    ({"K": "secret_text"}, {}, "p.json: K is a text, not intrinsics"),
    ({"intrinsics": {"fx": 1.0, "fy": 1.0}}, {}, "p.json: intrinsics lacks cx, cy"),
    ({"K": K3, "D": [0.1, 0, 0, 0, 0, 0.5, 0, 0]}, {}, "D holds 8 coefficients, the 6th or later not zero"),
    ({"K": K3, "D": [0.1, 0, 0]}, {}, "p.json: D holds 3 numbers; distortion coefficients are 4, 5, 8, 12 or 14"),
    ({"K": [[0.0, 0, 1], [0, 1, 1], [0, 0, 1]]}, {}, "p.json: K[0][0] = 0 px is outside [1, 100000] px"),
    ({"K": K3, "D": [float("nan")] * 5}, {}, "p.json: D[0] is not a finite number"),
    ({"K": K3}, {"intrinsics_key": "cam"}, "p.json: no key 'cam' (the intrinsics the mapping names; keys: K)"),
    ({"K": K3}, {"distortion_key": "dc"}, "p.json: no key 'dc' (the distortion the mapping names)"),
])
def test_a_camera_that_cannot_be_read_is_one_line(record, keys, message):
    got = view_camera(record, "p.json", **keys)
    assert isinstance(got, str) and message in got and "\n" not in got, got
    assert "secret_text" not in got


def test_a_view_whose_camera_cannot_be_read_is_skipped_the_others_calibrate(rendered, tmp_path):
    data = _view_folders(rendered, tmp_path / "data", lambda k, F: {
        **_franka(k, F), **({"camera_intrinsics": [1, 2, 3]} if k == 4 else {})})
    r = run_handeye_dataset(DatasetHandEyeOptions(data, tmp_path / "out", board=BOARD))
    assert [s.name for s in r.skipped] == ["pose_4/image.png"]
    assert "camera_intrinsics holds 3 numbers" in r.skipped[0].reason and len(r.used) == N_VIEWS - 1


# ----------------------------------------------------------------------------- the order of a matrix
def test_the_order_of_a_matrix_is_told_by_its_numbers():
    F = _T([0.1, -0.2, 0.3], [0.4, -0.1, 0.5])
    assert matrix_order_of(F.ravel(), "matrix") is MatrixOrder.ROW
    assert matrix_order_of(F.T.ravel(), "matrix") is MatrixOrder.COLUMN
    R = _T([0.1, -0.2, 0.3], [0, 0, 0])  # no translation: both read; the key decides
    assert matrix_order_of(R.T.ravel(), "O_T_EE") is MatrixOrder.COLUMN
    assert matrix_order_of(R.T.ravel(), "state.O_T_EE") is MatrixOrder.COLUMN
    assert matrix_order_of(R.ravel(), "pose") is MatrixOrder.ROW
    for values in (F.T.ravel(), F.ravel()):
        mapping = detect_format({"O_T_EE": values.tolist()}, PoseMapping(), "p.json")
        assert np.allclose(robot_pose({"O_T_EE": values.tolist()}, "p.json", mapping), F)
    assert detect_format({"O_T_EE": F.T.ravel().tolist()}, PoseMapping(), "p").matrix_order is MatrixOrder.COLUMN
    nested = detect_format({"time": 3.0, "robot_state": {"q": [0.0] * 7, "O_T_EE": F.T.ravel().tolist()}},
                           PoseMapping(), "p")
    assert nested.matrix == ("robot_state.O_T_EE",) and nested.matrix_order is MatrixOrder.COLUMN
    assert np.allclose(robot_pose({"robot_state": {"O_T_EE": F.T.ravel().tolist()}}, "p", nested), F)
    # an order the mapping states is kept, and a matrix in the other order refused in one line
    said = detect_format({"O_T_EE": F.ravel().tolist()}, PoseMapping(matrix_order=MatrixOrder.COLUMN), "p")
    assert said.matrix_order is MatrixOrder.COLUMN
    with pytest.raises(InputError, match="looks row-major while the mapping says column-major"):
        robot_pose({"O_T_EE": F.ravel().tolist()}, "p.json", said)
    with pytest.raises(InputError, match=r"p.json: the matrix's last row is not \[0, 0, 0, 1\], read row by row or "):
        robot_pose({"matrix": [1.0] * 16}, "p.json", PoseMapping(PoseFormat.MATRIX))


# ----------------------------------------------------------------------------- mistakes of a layout
def test_view_folders_that_cannot_be_used_are_one_line_each(rendered, tmp_path):
    data = _view_folders(rendered, tmp_path / "data", _franka)
    (data / "pose_1" / "image.png").rename(data / "pose_1" / "left.png")
    cv2.imwrite(str(data / "pose_1" / "right.png"), np.zeros((8, 8, 3), np.uint8))
    (data / "pose_2" / "data.json").unlink()
    (data / "pose_3" / "robot.yaml").write_text("x: 1\n")
    (data / "pose_3" / "extra.yaml").write_text("x: 1\n")
    (data / "pose_5" / "data.json").write_text("{not json")
    (data / "notes").mkdir()
    (data / "notes" / "notes.yaml").write_text("seen: 1\n")
    (data / "output").mkdir()
    (data / "output" / "result.txt").write_text("")
    (data / ".git").mkdir()
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "data.json").write_text(json.dumps({"secret_word": 1}))
    shutil.copy(data / "pose_6" / "image.png", outside / "image.png")
    os.symlink(outside, data / "pose_99")
    found = read_dataset(data)
    reasons = {s.name: s.reason for s in found.skipped}
    assert reasons["pose_1"].startswith(f"2 images in {data / 'pose_1'} (left.png, right.png); keep one")
    assert reasons["pose_2"] == f"no pose file (.yaml, .yml, .json) in {data / 'pose_2'}; add it or remove the folder"
    assert reasons["pose_3"].startswith(f"3 pose files in {data / 'pose_3'}")
    assert reasons["pose_5/image.png"].startswith(f"{data / 'pose_5' / 'data.json'}")
    assert reasons["notes"] == f"no image (.png, .jpg, .jpeg, .bmp, .tif, .tiff) in {data / 'notes'}"
    assert "output" not in reasons and ".git" not in reasons  # folders of neither images nor pose files
    assert reasons["pose_99"] == f"{data / 'pose_99'} is a link leading out of the data set folder; not read"
    assert all("\n" not in r and "secret_word" not in r for r in reasons.values())
    assert len(found.views) == N_VIEWS - 4


def test_view_folders_are_bounded_before_they_are_read(rendered, tmp_path, monkeypatch):
    data = _view_folders(rendered, tmp_path / "data", _franka)
    for k in range(ds.MAX_VIEW_ENTRIES):
        (data / "pose_7" / f"x{k}.txt").write_bytes(b"")
    found = read_dataset(data)
    assert {s.name: s.reason for s in found.skipped}["pose_7"] == (
        f"{data / 'pose_7'} holds more than {ds.MAX_VIEW_ENTRIES} entries; a view's folder holds its image and its "
        "pose file")
    monkeypatch.setattr(ds, "MAX_VIEWS", 5)
    with pytest.raises(InputError, match=rf"{data}: 10 folders, more than the 5 views recon reads"):
        read_dataset(data)


def test_a_folder_without_images_or_view_folders_is_one_line(tmp_path):
    (tmp_path / "data" / "a").mkdir(parents=True)
    (tmp_path / "data" / "a" / "pose.json").write_text("{}")
    with pytest.raises(ReconError, match="holds no images .*, nor folders of one image and one pose file each"):
        read_dataset(tmp_path / "data")


# ----------------------------------------------------------------------------- the command line
@pytest.mark.parametrize(("text", "want"), [
    ("900,900,479.5,359.5", (900.0, 900.0, 479.5, 359.5)),
    ("900,900,479.5,359.5,0.1,-0.2,0.001,0.002", (900.0, 900.0, 479.5, 359.5, 0.1, -0.2, 0.001, 0.002)),
    ("900, 900, 479.5, 359.5, 0.1, -0.2, 0.001, 0.002, 0.05", (900.0, 900.0, 479.5, 359.5, 0.1, -0.2, 0.001,
                                                                 0.002, 0.05)),
])
def test_intrinsics_with_distortion_on_the_command_line(text, want):
    assert parse_camera_numbers(text) == want
    cam = camera_numbers(want)
    assert (cam.fx, cam.fy, cam.cx, cam.cy) == want[:4] and cam.distortion == (tuple(want[4:]) + (0.0,) * 5)[:5]


def test_the_command_line_passes_every_number_of_the_camera(tmp_path, monkeypatch):
    from recon_cli.cli import calibrate

    seen = {}

    def fake(opts, progress=None):
        seen["intrinsics"] = opts.intrinsics
        raise InputError("stop here", hint="a test")

    monkeypatch.setattr(calibrate, "run_handeye_dataset", fake)
    code = main(["calibrate", "handeye", "--dataset", str(tmp_path), "--intrinsics",
                 "900,900,479.5,359.5,0.1,-0.2,0.001,0.002", "--out", str(tmp_path / "o")])
    assert code == 1 and seen["intrinsics"] == (900.0, 900.0, 479.5, 359.5, 0.1, -0.2, 0.001, 0.002)


@pytest.mark.parametrize(("value", "message"), [
    ("1,2,3", "--intrinsics: 3 numbers, 4, 8 or 9 expected"),
    ("900,900,480,360,0.1,0.2,0.3", "--intrinsics: 7 numbers, 4, 8 or 9 expected"),
    ("900,900,480,360,0.1,0.2,0.3,500", "--intrinsics p2 = 500 is outside [-100, 100]"),
    ("900,900,secret_text,360", "--intrinsics: cx is not a number"),
    ("900,900,480,nan", "--intrinsics: cy is not a finite number"),
])
def test_intrinsics_mistakes_are_one_line(tmp_path, capsys, value, message):
    code = main(["calibrate", "handeye", "--dataset", str(tmp_path), "--intrinsics", value, "--out",
                 str(tmp_path / "o")])
    out, err = capsys.readouterr()
    text = out + err
    assert code == 1 and message in text and len(text.strip().splitlines()) == 1, text
    assert "secret_text" not in text and "Traceback" not in text


# ----------------------------------------------------------------------------- a real set
needs_franka = pytest.mark.skipif(not (FRANKA / "pose_00" / "data.json").exists(),
                                  reason=f"the Franka eye-in-hand set is not at {FRANKA} (docs/benchmarks.md)")


@needs_franka
def test_a_real_franka_set_is_read_as_published(tmp_path):
    """12 views of a 5 x 7 ChArUco board from a wrist RealSense on a Franka: a folder per view,
    O_T_EE written row by row, the camera matrix and distortion in each view's JSON."""
    found = read_dataset(FRANKA, DatasetSpec())
    assert len(found.views) == 12 and not found.skipped
    assert found.hints.camera is not None and found.hints.camera.fx == pytest.approx(634.58, abs=0.01)
    assert any(found.hints.camera.distortion)
    board = ds.BoardSpec(5, 7, 0.034, 0.028, "DICT_6X6_250")
    r = run_handeye_dataset(DatasetHandEyeOptions(FRANKA, tmp_path / "out", board=board, refine=False))
    assert r.mapping.matrix_order is MatrixOrder.ROW and len(r.used) == 12
    dt, _ = pose_error(r.solution.X, r.methods[r.solution.method].solution.X)
    assert dt < 1e-9
    assert np.linalg.norm(r.solution.X[:3, 3]) < 0.15  # a wrist camera, a few centimetres from the flange


@needs_franka
def test_a_real_franka_sets_joints_give_a_calibration_better_than_opencv_on_held_out_views(tmp_path):
    """The same set with the FR3 cell: the pose files' joint positions are matched to the logged
    O_T_EE (the cell's kinematics and the Franka Hand's end effector), the joints' zero offsets
    are estimated with the mount, and that calibration predicts held-out views better than
    every OpenCV method and puts the board's origin in the base more consistently than
    OpenCV's Tsai (docs/benchmarks.md, "Eye-in-hand: a Franka with a wrist RealSense"). It is
    the calibration written, with the offsets as a station file's joint_offsets line (a station
    adds them to the joints its robot reports), and its report sees the corrected robot."""
    from recon_cli.calibration.handeye import HandEyeMethod
    from recon_cli.calibration.logged_joints import record_joints
    from recon_cli.robot.description import CellConfig, CellName, expand_urdf
    from recon_cli.robot.kinematics import Kinematics

    board = ds.BoardSpec(5, 7, 0.034, 0.028, "DICT_6X6_250")
    cell = CellConfig(kind=CellName.parse("fr3"))
    r = run_handeye_dataset(DatasetHandEyeOptions(FRANKA, tmp_path / "out", board=board, cell=cell))
    assert r.sources["joints"].startswith("the pose files' joint positions, the cell fr3's kinematics")
    joint = r.joint_offsets
    assert joint is not None and joint["candidate"] == "tsai + joint offsets" and joint["written"]
    held = {c.name: c.held_out for c in r.candidates}
    assert r.chosen == joint["candidate"]
    assert held[joint["candidate"]].rms[0] < 0.5 * held["tsai"].rms[0]  # measured 1.48 mm against 3.76 mm
    assert all(held[joint["candidate"]].score < held[m.value].score for m in r.methods)
    assert r.verdict is not None and r.verdict.trusted
    # the report's consistency is the corrected robot's: measured 1.03 mm RMS against Tsai's 3.32 mm
    assert r.chain_rms[0] < 0.5 * r.methods[HandEyeMethod.TSAI].chain_rms[0]
    # the board's origin in the base through each view's chain, each calibration with its robot
    found = read_dataset(FRANKA, DatasetSpec())
    mapping = ds.detect_format(found.views[0].record, ds.PoseMapping(), found.views[0].where)
    views = ds.dataset_views(found, mapping, board, found.hints.camera).views
    kin = Kinematics(expand_urdf(cell), cell.cell_file)
    q = {v.name: record_joints(v.record, 7) for v in found.views}
    offsets = np.radians(joint["offsets_deg"])
    ee = np.linalg.inv(kin.frame_pose(q[views[0].name], "fr3_link8")) @ kin.frame_pose(q[views[0].name], "fr3_link0") \
        @ views[0].base_T_flange

    def spread(flanges, X):
        p = np.array([(F @ X @ v.camera_T_board)[:3, 3] for F, v in zip(flanges, views, strict=True)])
        return float(np.mean(np.linalg.norm(p - p.mean(axis=0), axis=1)))

    logged = [v.base_T_flange for v in views]
    corrected = [np.linalg.inv(kin.frame_pose(q[v.name] + offsets, "fr3_link0"))
                 @ kin.frame_pose(q[v.name] + offsets, "fr3_link8") @ ee for v in views]
    tsai = r.methods[HandEyeMethod.TSAI].solution.X
    assert spread(corrected, joint["flange_T_camera"]) < spread(logged, tsai)  # measured 0.89 mm against 2.69 mm
    # hand_eye.yaml is the station file's two entries, and a station file with them loads
    text = (tmp_path / "out" / "hand_eye.yaml").read_text()
    assert "\njoint_offsets: [0, 0, -0.5, 0, 0.5, -0.4" in text
    station = tmp_path / "station.yaml"
    station.write_text("format: 1\ncell: {kind: fr3}\nrobot: {adapter: franka, franka: {ip: 127.0.0.1}}\n"
                       "camera: {adapter: sim}\n" + text)
    from recon_cli.backends.station_file import load_station

    loaded = load_station(station)
    assert loaded.joint_offsets == tuple(joint["station_values"])
    # on the cell's flange (fr3_link8), not the Franka Hand's end effector the poses name
    mount = np.reshape(loaded.cell.flange_T_camera, (4, 4))
    assert cell.cell_file.flange_link == "fr3_link8" and np.allclose(mount[:3], (ee @ r.solution.X)[:3], atol=1e-6)


# ----------------------------------------------------------------------------- the documented one-line mappings
#: docs/calibration.md, "Calibrating from your own data": each real layout's mapping in one line
ONE_LINE = {
    "kvasios": "{pose_format: matrix, matrix: O_T_EE, matrix_order: row, intrinsics_key: camera_intrinsics, "
               "distortion_key: dist_coeffs, board: {squares_x: 5, squares_y: 7, square_length: 0.034, "
               "marker_length: 0.028, dictionary: DICT_6X6_250}}",
    "libfranka": "{pose_format: matrix, matrix: O_T_EE, matrix_order: column, intrinsics_key: K, distortion_key: D}",
    "industrial_calibration": "{index: cal_data.yaml, setup: eye-to-hand, pose_format: xyz-quat, "
                              "quaternion_order: xyzw}",
}


def test_the_documented_one_line_mappings_are_in_the_docs():
    text = (Path(__file__).resolve().parents[2] / "docs" / "calibration.md").read_text()
    for line in ONE_LINE.values():
        assert f"`{line}`" in text, line


@pytest.mark.parametrize(("name", "pose"), [
    ("kvasios", lambda k, F: {"joint_pose": [0.0] * 7, "O_T_EE": F.ravel().tolist(), "camera_intrinsics": K3,
                              "dist_coeffs": [0.0] * 5}),
    ("libfranka", lambda k, F: {"q": [0.0] * 7, "O_T_EE": F.T.ravel().tolist(), "K": K3, "D": [0.0] * 5}),
])
def test_a_one_line_mapping_reads_its_layout(rendered, tmp_path, name, pose):
    data = _view_folders(rendered, tmp_path / "data", pose)
    mapping = tmp_path / "mapping.yaml"
    mapping.write_text(ONE_LINE[name] + "\n")
    r = run_handeye_dataset(DatasetHandEyeOptions(data, tmp_path / "out", mapping=mapping, board=BOARD))
    assert len(r.used) == N_VIEWS and not r.skipped
    dt, dr = pose_error(r.solution.named()["flange_T_camera"], FLANGE_T_CAMERA)
    assert dt < 1e-3 and np.degrees(dr) < 0.1


@pytest.mark.parametrize(("name", "folder"), [
    ("industrial_calibration", Path(__file__).resolve().parents[2].parent / "shared" / "data" / "handeye_real"),
    ("kvasios", FRANKA),
])
def test_a_one_line_mapping_reads_a_real_set(tmp_path, name, folder):
    if not folder.is_dir():
        pytest.skip(f"{folder} is not here")
    mapping = tmp_path / "mapping.yaml"
    mapping.write_text(ONE_LINE[name] + "\n")
    spec = read_mapping(mapping, folder)
    found = read_dataset(folder, spec)
    assert len(found.views) in (12, 16) and found.hints.camera is not None
    poses = [robot_pose(v.record, v.where, spec.mapping) for v in found.views]
    assert all(abs(np.linalg.det(T[:3, :3]) - 1) < 1e-6 and np.linalg.norm(T[:3, 3]) < 2 for T in poses)


# ----------------------------------------------------------------------------- fuzzed view folders
_scalar = (st.none() | st.booleans() | st.integers(-10**30, 10**30) | st.floats()
           | st.sampled_from(["secret_text", "", "K", "O_T_EE", "0"]))
_camera_value = st.recursive(_scalar, lambda c: st.lists(c, max_size=10) | st.dictionaries(
    st.sampled_from(["fx", "fy", "cx", "cy", "ppx", "ppy", "coeffs", "distortion", "K", "D"]), c, max_size=6),
    max_leaves=20)
_record = st.dictionaries(st.sampled_from(["K", "D", "camera_matrix", "dist_coeffs", "intrinsics", "camera_intrinsics",
                                           "coeffs", "O_T_EE", "matrix", "camera_info"]), _camera_value, max_size=5)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                  HealthCheck.function_scoped_fixture])
@given(records=st.lists(_record | _scalar, min_size=1, max_size=4), keys=st.sampled_from([
    {}, {"intrinsics_key": "K"}, {"distortion_key": "D"}, {"intrinsics_key": "camera_info.K"}]))
def test_fuzzed_view_folders_are_read_or_refused_in_one_line(tmp_path_factory, records, keys):
    data = tmp_path_factory.mktemp("fuzz")
    for k, record in enumerate(records):
        sub = data / f"pose_{k}"
        sub.mkdir()
        (sub / "image.png").write_bytes(b"")
        (sub / "data.json").write_text(json.dumps(record))
    try:
        found = read_dataset(data, DatasetSpec(**keys))
    except ReconError as exc:
        assert "\n" not in exc.one_line() and "secret_text" not in exc.one_line()
        return
    for v in found.views:
        assert v.camera is None or isinstance(v.camera, CameraNumbers) or (
            "\n" not in v.camera and "secret_text" not in v.camera), v.camera
        if isinstance(v.camera, CameraNumbers):
            assert len(v.camera.distortion) == 5 and all(np.isfinite([v.camera.fx, v.camera.fy, v.camera.cx,
                                                                      v.camera.cy, *v.camera.distortion]))
        try:
            robot_pose(v.record, v.where, detect_format(v.record, PoseMapping(), v.where))
        except ReconError as exc:
            assert "\n" not in exc.one_line() and "secret_text" not in exc.one_line()


# ----------------------------------------------------------------------------- a camera file at the top
@pytest.mark.parametrize(("name", "text", "distortion"), [
    ("intrinsics.yaml", f"fx: {K.fx}\nfy: {K.fy}\ncx: {K.cx}\ncy: {K.cy}\ndistortion: [0.01, 0, 0, 0]\n",
     (0.01, 0.0, 0.0, 0.0, 0.0)),
    ("camera_info.yaml", "image_width: 960\nimage_height: 720\ncamera_name: d415\n"
                         f"camera_matrix: {{rows: 3, cols: 3, data: [{K.fx}, 0, {K.cx}, 0, {K.fy}, {K.cy}, 0, 0, 1]}}\n"
                         "distortion_model: plumb_bob\n"
                         "distortion_coefficients: {rows: 1, cols: 5, data: [0.01, 0, 0, 0, 0]}\n",
     (0.01, 0.0, 0.0, 0.0, 0.0)),
    ("camera.json", json.dumps({"K": K3}), (0.0,) * 5),
], ids=["flat-yaml", "ros-camera-info", "json-K"])
def test_a_camera_file_at_the_top_of_the_data_set(rendered, tmp_path, name, text, distortion):
    data = _view_folders(rendered, tmp_path / "data", lambda k, F: {"O_T_EE": F.T.ravel().tolist()})
    (data / name).write_text(text)
    found = read_dataset(data)
    assert found.hints.camera == CameraNumbers(K.fx, K.fy, K.cx, K.cy, distortion)
    assert found.hints.camera_source == "the camera file at the top of the data set"
    assert len(found.views) == N_VIEWS and not found.skipped


def test_the_pose_files_camera_comes_before_a_camera_file(rendered, tmp_path):
    data = _view_folders(rendered, tmp_path / "data", _franka)
    (data / "intrinsics.yaml").write_text("fx: 100\nfy: 100\ncx: 50\ncy: 50\n")
    assert read_dataset(data).hints.camera.fx == K.fx


def test_a_camera_file_that_cannot_be_read_is_one_line(rendered, tmp_path):
    data = _view_folders(rendered, tmp_path / "data", lambda k, F: {"O_T_EE": F.T.ravel().tolist()})
    (data / "camera_info.yaml").write_text("camera_matrix: {rows: 3, cols: 3, data: [1, 2, 3]}\n")
    with pytest.raises(InputError) as info:
        read_dataset(data)
    line = info.value.one_line()
    assert f"{data / 'camera_info.yaml'}: camera_matrix.data holds 3 numbers" in line and "\n" not in line
    assert "fix the camera file, or move it out of the data set folder" in line
