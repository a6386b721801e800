"""A hand-eye data set made carelessly or with hostile intent: every row of docs/inputs.md's
"Hand-eye data sets" table has its test here. Few usable views calibrate when the motion
determines the calibration and are refused in one line when it does not, before any solver
runs; nothing outside the data set folder is read; counts and sizes are bounded before they
are read; every number is finite and in range, named by its key path; no message shows what
a file holds, and nothing of OpenCV's is printed."""

from __future__ import annotations

import json
import re
import shutil
import struct
import zlib
from pathlib import Path
from types import SimpleNamespace

import cv2
import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from recon_cli.calibration import dataset as ds
from recon_cli.calibration.dataset import DatasetSpec, read_dataset, read_mapping
from recon_cli.cli import main
from recon_cli.errors import InputError, ReconError
from recon_cli.inputs import images as image_reader
from recon_cli.workflows.handeye_dataset import DatasetHandEyeOptions, run_handeye_dataset

from ..conftest import ROOT, SHARED_DATA
from .test_dataset import BOARD, FLANGE_T_CAMERA, INTRINSICS, _camera_T_marker, _eye_in_hand_flange, _render

REAL = SHARED_DATA / "handeye_real"
REAL_ARGS = ["--setup", "eye-to-hand", "--intrinsics", "1352.02747,1356.14287,789.67065,627.2995",
             "--board-spec", "5,7,0.036195,0.018256,DICT_6X6_250"]
needs_real = pytest.mark.skipif(not REAL.exists(), reason="../shared/data/handeye_real is not here")
SECRET = "secret_word_of_an_outside_file"
#: what OpenCV prints itself: its exceptions, its log lines, its source files
OPENCV_PRINTED = re.compile(r"OpenCV\(\d|\[ ?(ERROR|WARN|INFO)|cv2\.error|\.cpp:\d")


def _run(capfd, *argv) -> tuple[int, str]:
    """The command line's exit code and everything printed, by Python or by native code."""
    code = main([str(a) for a in argv])
    out, err = capfd.readouterr()
    text = out + err
    assert "Traceback" not in text and not OPENCV_PRINTED.search(text), text
    return code, text


def _real_views(folder: Path, views: list[int], poses: dict[int, int] | None = None) -> Path:
    """Views of the shared eye-to-hand set copied into ``folder`` (images/N.png, poses/N.yaml);
    ``poses`` gives view N the pose of another view."""
    (folder / "images").mkdir(parents=True)
    (folder / "poses").mkdir()
    for k in views:
        shutil.copy(REAL / "images" / f"{k}.png", folder / "images" / f"{k}.png")
        shutil.copy(REAL / "poses" / f"{(poses or {}).get(k, k)}.yaml", folder / "poses" / f"{k}.yaml")
    return folder


def _outside(tmp_path: Path) -> Path:
    """A folder of secrets beside the data set."""
    outside = tmp_path / "outside"
    outside.mkdir(exist_ok=True)
    (outside / "secret.yaml").write_text(f"{SECRET}: 1\n")
    (outside / "secret.txt").write_text(f"{SECRET}\n")
    cv2.imwrite(str(outside / "secret.png"), np.full((16, 16, 3), 200, np.uint8))
    return outside


def _rendered(folder: Path, n: int, flanges=None) -> Path:
    """n rendered board views (images/k.png) with the eye-in-hand flange pose of each as
    poses/k.json (a 4x4 matrix); ``flanges`` replaces the poses."""
    (folder / "images").mkdir(parents=True)
    (folder / "poses").mkdir()
    for k in range(n):
        C = _camera_T_marker(k)
        cv2.imwrite(str(folder / "images" / f"{k}.png"), _render(C))
        F = _eye_in_hand_flange(C) if flanges is None else flanges[k]
        (folder / "poses" / f"{k}.json").write_text(json.dumps({"matrix": F.tolist()}))
    return folder


def _options(folder: Path, out: Path, **kw) -> DatasetHandEyeOptions:
    return DatasetHandEyeOptions(folder, out, intrinsics=INTRINSICS, board=BOARD, **kw)


def _skipped(folder: Path, spec: DatasetSpec = DatasetSpec()) -> dict[str, str]:  # noqa: B008 (frozen)
    return {s.name: s.reason for s in read_dataset(folder, spec).skipped}


def _png_header(width: int, height: int) -> bytes:
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(b"\0" * 1000)) + chunk(b"IEND", b""))


# ----------------------------------------------------------------------------- usable views, motion, solvers
@needs_real
def test_three_usable_views_calibrate_and_the_methods_without_a_solution_are_named(tmp_path, capfd):
    """Views 2-5 of the shared eye-to-hand set (2.png shows 4 corners): the three others turn
    by 70-80° about different axes, so Tsai's solution is written; Andreff's and Li's linear
    solvers find none on three views and are reported, not raised."""
    data = _real_views(tmp_path / "data", [2, 3, 4, 5])
    code, text = _run(capfd, "calibrate", "handeye", "--dataset", data, *REAL_ARGS, "--accept", "--out",
                      tmp_path / "out")
    assert code == 0, text
    assert "images/2.png not used: board not found (4 corners, 8 needed)" in text
    assert "3 views, converged" in text
    assert "verdict: not trusted: the calibration without images/" in text  # 3 views: none can be held out
    assert "andreff     no solution (Rotation normalization issue: determinant(R) is null)" in text
    assert "li          no solution (Rotation normalization issue: determinant(R) is null)" in text
    report = json.loads((tmp_path / "out" / "handeye.json").read_text())
    assert report["views_used"] == 3 and set(report["methods_failed"]) == {"andreff", "li"}
    assert set(report["methods"]) == {"tsai", "park", "horaud", "daniilidis", "shah"}


@needs_real
def test_the_method_to_write_without_a_solution_is_refused_naming_the_others(tmp_path, capfd):
    data = _real_views(tmp_path / "data", [3, 4, 5])
    code, text = _run(capfd, "calibrate", "handeye", "--dataset", data, *REAL_ARGS, "--method", "andreff", "--out",
                      tmp_path / "out")
    assert code == 1 and len(text.strip().splitlines()) == 1, text
    assert "OpenCV's andreff solver found no solution for the 3 views (Rotation normalization issue: " \
           "determinant(R) is null); choose --method tsai (tsai, park, horaud, daniilidis, shah found a solution)" \
           in text
    assert not (tmp_path / "out" / "handeye.json").exists()


@needs_real
def test_six_views_at_one_robot_pose_are_refused_before_any_solver_runs(tmp_path, capfd):
    """Six real photos, all logged with view 0's flange pose: OpenCV's Tsai solver printed
    "not enough informative motions" and the others ended in a traceback."""
    data = _real_views(tmp_path / "data", [0, 1, 3, 4, 5, 6], poses=dict.fromkeys([0, 1, 3, 4, 5, 6], 0))
    code, text = _run(capfd, "calibrate", "handeye", "--dataset", data, *REAL_ARGS, "--out", tmp_path / "out")
    assert code == 1 and len(text.strip().splitlines()) == 1, text
    assert f"the 6 usable views of {data} cannot determine the hand-eye calibration: the robot poses rotate by at " \
           "most 0.00° against each other (at least 1° needed, 20° recommended)" in text
    assert not (tmp_path / "out" / "handeye.json").exists()


def test_rotations_about_one_axis_are_refused_before_any_image_is_decoded(tmp_path, capfd):
    """Six flange poses turned about one axis only: the refusal comes from the poses, so
    images that are not images at all are never read."""
    F0 = _eye_in_hand_flange(_camera_T_marker(0))
    turn = [np.eye(4) for _ in range(6)]
    for k, T in enumerate(turn):
        T[:3, :3] = Rotation.from_rotvec([0, 0, np.radians(25 * k)]).as_matrix()
    data = _rendered(tmp_path / "data", 6, [F0 @ T for T in turn])
    for k in range(6):
        (data / "images" / f"{k}.png").write_bytes(b"not an image")
    code, text = _run(capfd, "calibrate", "handeye", "--dataset", data, "--intrinsics", ",".join(map(str, INTRINSICS)),
                      "--board-spec", "5,7,0.04,0.03,DICT_6X6_250", "--out", tmp_path / "out")
    assert code == 1 and len(text.strip().splitlines()) == 1, text
    assert re.search(r"the 6 usable views of .* cannot determine the hand-eye calibration: every rotation between "
                     r"the views turns about one axis \(axis spread \S+, at least 0.0001 needed, 0.003 recommended; "
                     r"rotations up to 125.0°\): the translation along that axis is not observable", text), text
    assert "not a valid" not in text and "cannot be read as an image" not in text


def test_fewer_than_three_usable_views_name_every_view_skipped_and_why(tmp_path):
    data = _rendered(tmp_path / "data", 5)
    for k in (1, 2, 4):
        (data / "poses" / f"{k}.json").unlink()
    with pytest.raises(InputError) as info:
        run_handeye_dataset(_options(data, tmp_path / "out"))
    text = info.value.one_line()
    assert text.startswith(f"2 of the 5 views of {data} are usable; hand-eye calibration needs 3 or more (skipped: "
                           f"images/1.png: no pose file {data / 'poses' / '1'}.yaml"), text
    assert "images/2.png: no pose file" in text and "images/4.png: no pose file" in text


def test_a_calibration_from_rendered_views_still_calibrates(tmp_path):
    r = run_handeye_dataset(_options(_rendered(tmp_path / "data", 6), tmp_path / "out"))
    assert len(r.used) == 6 and not r.method_failures and r.converged
    assert np.allclose(r.solution.X, FLANGE_T_CAMERA, atol=2e-3)


# ----------------------------------------------------------------------------- paths
@needs_real
def test_paths_leaving_the_folder_are_skipped_unread_and_three_views_remain(tmp_path, capfd):
    """An index naming '../../' and absolute image and pose paths, and links leading out:
    each view skipped before anything is read; the three left calibrate."""
    outside = _outside(tmp_path)
    data = _real_views(tmp_path / "data", [3, 4, 5])
    shutil.copy(REAL / "images" / "6.png", outside / "6.png")
    (data / "images" / "link.png").symlink_to(outside / "6.png")
    (data / "poses" / "link.yaml").symlink_to(outside / "secret.yaml")
    entries = [  # the good pairs last: a view skipped for its pose may be listed again
        {"image": "../../outside/6.png", "pose": "poses/3.yaml"},
        {"image": str(outside / "6.png"), "pose": "poses/4.yaml"},
        {"image": "images/5.png/../../../outside/6.png", "pose": "poses/5.yaml"},
        {"image": "images/link.png", "pose": "poses/3.yaml"},
        {"image": "images/3.png", "pose": "poses/link.yaml"},
        {"image": "images/4.png", "pose": str(outside / "secret.yaml")},
        {"image": "images/5.png", "pose": "~/secret.yaml"}] + [
        {"image": f"images/{k}.png", "pose": f"poses/{k}.yaml"} for k in (3, 4, 5)]
    (data / "index.yaml").write_text(yaml.safe_dump({"data": entries}))
    code, text = _run(capfd, "calibrate", "handeye", "--dataset", data, *REAL_ARGS, "--accept", "--out",
                      tmp_path / "out")
    assert code == 0 and "3 views, converged" in text, text
    assert SECRET not in text
    assert "'../../outside/6.png' leaves the data set folder" in text
    assert f"'{outside / '6.png'}' leaves the data set folder" in text
    assert "'images/5.png/../../../outside/6.png' leaves the data set folder" in text
    assert f"{data / 'images' / 'link.png'} leads out of the data set folder (a link); not read" in text
    assert f"{data / 'poses' / 'link.yaml'} leads out of the data set folder (a link); not read" in text
    assert "'~/secret.yaml' leaves the data set folder" in text


def test_a_mapping_naming_a_system_file_as_its_board_shows_none_of_it(tmp_path, capfd):
    data = _rendered(tmp_path / "data", 3)
    outside = _outside(tmp_path)
    (data / "board_link.yaml").symlink_to(outside / "secret.yaml")
    (data / "notes.yaml").write_text(f"{SECRET}\n")
    for board, message in (("/etc/passwd", "board: '/etc/passwd' leaves the data set folder"),
                           ("../outside/secret.yaml", "board: '../outside/secret.yaml' leaves the data set folder"),
                           ("board_link.yaml", f"{data / 'board_link.yaml'} leads out of the data set folder (a link); "
                                               "not read"),
                           ("notes.yaml", f"{data / 'notes.yaml'}: the board file holds a text, not a mapping")):
        (data / "mapping.yaml").write_text(f"board: {board}\n")
        code, text = _run(capfd, "calibrate", "handeye", "--dataset", data, "--mapping", data / "mapping.yaml",
                          "--intrinsics", "900,900,480,360", "--out", tmp_path / "out")
        assert code == 1 and message in text and len(text.strip().splitlines()) == 1, text
        assert SECRET not in text and "root:" not in text


def test_files_given_on_the_command_line_may_not_be_links_out_of_their_folder(tmp_path, capfd):
    data = _rendered(tmp_path / "data", 3)
    _outside(tmp_path)
    (tmp_path / "outside" / "cal_data.yaml").write_text(yaml.safe_dump({"data": [{"image": "x.png", "pose": "y"}]}))
    (data / "mapping.yaml").symlink_to(tmp_path / "outside" / "secret.yaml")
    (data / "cal_data.yaml").symlink_to(tmp_path / "outside" / "cal_data.yaml")
    code, text = _run(capfd, "calibrate", "handeye", "--dataset", data, "--mapping", data / "mapping.yaml",
                      "--intrinsics", "900,900,480,360", "--out", tmp_path / "out")
    assert code == 1 and "the mapping file is a link leading out of its folder; not read" in text, text
    code, text = _run(capfd, "calibrate", "handeye", "--dataset", data / "cal_data.yaml", "--intrinsics",
                      "900,900,480,360", "--out", tmp_path / "out")
    assert code == 1 and f"{data / 'cal_data.yaml'} leads out of its folder (a link); not read" in text, text
    assert SECRET not in text


# ----------------------------------------------------------------------------- counts and sizes
def test_views_are_counted_before_any_pose_or_image_is_read(tmp_path):
    data = tmp_path / "data"
    data.mkdir()
    n = ds.MAX_VIEWS + 1
    (data / "cal_data.yaml").write_text(yaml.safe_dump({"data": [{"image": f"{k}.png", "pose": f"{k}.yaml"}
                                                                for k in range(n)]}))
    with pytest.raises(InputError, match=r"cal_data.yaml: 1,001 pairs, more than 1,000; use at most 1,000 views"):
        read_dataset(data)
    (data / "cal_data.yaml").unlink()
    (data / "images").mkdir()
    for k in range(n):
        (data / "images" / f"{k}.png").write_bytes(b"")
    with pytest.raises(InputError, match=r"images: 1,001 images, more than 1,000"):
        read_dataset(data)
    with open(data / "log.csv", "w") as f:
        f.write("image,x,y,z,qx,qy,qz,qw\n" + "".join(f"images/{k}.png,0,0,0,0,0,0,1\n" for k in range(n)))
    with pytest.raises(InputError, match=r"log.csv: more than 1,000 rows"):
        read_dataset(data / "log.csv")


def test_a_folder_of_too_many_entries_is_refused_before_they_are_looked_at(tmp_path, monkeypatch):
    data = tmp_path / "data"
    (data / "images").mkdir(parents=True)
    for k in range(12):
        (data / "images" / f"x{k}.txt").write_bytes(b"")
    monkeypatch.setattr(ds, "MAX_FOLDER_ENTRIES", 10)
    with pytest.raises(InputError, match=r"images holds more than 10 entries"):
        read_dataset(data)


def test_pose_files_are_bounded_each_and_together(tmp_path, monkeypatch):
    data = _rendered(tmp_path / "data", 4)
    big = {"matrix": np.eye(4).tolist(), "log": "x" * ds.MAX_POSE_BYTES}
    (data / "poses" / "1.json").write_text(json.dumps(big))
    (data / "poses" / "2.json").unlink()
    (data / "poses" / "2.yaml").write_text("".join(f"k{i}: {i}\n" for i in range(ds.MAX_POSE_VALUES)))
    skipped = _skipped(data)
    assert re.search(r"1.json: pose file has [\d,]+ bytes, more than the 65,536 recon reads", skipped["images/1.png"])
    assert "2.yaml:" in skipped["images/2.png"] and "more than 2,000 values" in skipped["images/2.png"]
    monkeypatch.setattr(ds, "MAX_POSES_BYTES", 1000)
    with pytest.raises(InputError, match=r"the pose files hold more than 1,000 bytes together"):
        read_dataset(data)


def test_a_csv_file_is_bounded_in_columns_and_names(tmp_path):
    data = tmp_path / "data"
    data.mkdir()
    (data / "log.csv").write_text("image," + ",".join(f"c{i}" for i in range(ds.MAX_CSV_COLUMNS)) + "\n")
    with pytest.raises(InputError, match=r"log.csv:1: 1,001 columns, more than 1,000"):
        read_dataset(data / "log.csv")
    (data / "log.csv").write_text("image,x\n" + "a" * (ds.MAX_NAME + 1) + ",1\n")
    skipped = _skipped(data / "log.csv")
    assert skipped == {"row 2": f"{data / 'log.csv'}:2: the image is not a file name (4,097 characters); write a "
                                "path of at most 4,096 characters inside the data set folder"}


def test_an_index_is_bounded_like_every_yaml_file(tmp_path):
    data = tmp_path / "data"
    data.mkdir()
    (data / "cal_data.yaml").write_text("data:\n" + "#" * ds.MAX_INDEX_BYTES + "\n")
    with pytest.raises(ReconError, match=r"more than a index file may hold \(1,000,000\)"):
        read_dataset(data / "cal_data.yaml")


@needs_real
def test_an_image_claiming_60000_x_60000_pixels_is_refused_from_its_header(tmp_path, capfd):
    """Refused from its header (no decoder sees it); the three other views calibrate (this
    ended in a traceback from OpenCV's solvers)."""
    data = _real_views(tmp_path / "data", [3, 4, 5, 6])
    (data / "images" / "6.png").write_bytes(_png_header(60000, 60000))
    code, text = _run(capfd, "calibrate", "handeye", "--dataset", data, *REAL_ARGS, "--accept", "--out",
                      tmp_path / "out")
    assert code == 0 and "3 views, converged" in text, text
    assert f"images/6.png not used: {data / 'images' / '6.png'}: board image declares 60000 x 60000 pixels (3600 " \
           f"megapixels), more than the {image_reader.MAX_IMAGE_PIXELS / 1e6:g} megapixels recon reads" in text


# ----------------------------------------------------------------------------- numbers
def test_a_number_that_is_not_finite_is_named_by_its_key_path(tmp_path):
    data = _rendered(tmp_path / "data", 5)
    (data / "poses" / "0.json").write_text('{"O_T_EE": [1, 0, 0, 0, 0, NaN, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]}')
    (data / "poses" / "1.json").write_text('{"O_T_EE": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 1e999, 1]}')
    (data / "poses" / "2.json").unlink()
    (data / "poses" / "2.yaml").write_text("x: 0.1\ny: .nan\nz: 0.3\nqx: 0\nqy: 0\nqz: 0\nqw: 1\n")
    (data / "poses" / "3.json").unlink()
    (data / "poses" / "3.yaml").write_text("pose:\n  position: [0.1, 0.2, -.inf]\n")
    skipped = _skipped(data)
    assert skipped["images/0.png"].startswith(f"{data / 'poses' / '0.json'}:1: O_T_EE[5] is not a finite number")
    assert skipped["images/1.png"].startswith(f"{data / 'poses' / '1.json'}:1: O_T_EE[14] is not a finite number")
    assert skipped["images/2.png"].startswith(f"{data / 'poses' / '2.yaml'}:2: y is not a finite number")
    assert skipped["images/3.png"].startswith(f"{data / 'poses' / '3.yaml'}:2: pose.position[2] is not a finite "
                                              "number")


@pytest.mark.parametrize(("record", "mapping", "message"), [
    ({"O_T_EE": [1, 0, 0, 0, 0, 1e6, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]},
     ds.PoseMapping(ds.PoseFormat.MATRIX, matrix=("O_T_EE",), matrix_order=ds.MatrixOrder.COLUMN),
     "pose_03.json: O_T_EE[5] = 1e+06 is outside [-10, 10] (no number of a pose matrix in m is larger)"),
    ({"m": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 20000], [0, 0, 0, 1]]},
     ds.PoseMapping(ds.PoseFormat.MATRIX, matrix=("m",), length_unit=ds.LengthUnit.MM),
     "pose_03.json: m[11] = 2e+04 is outside [-10000, 10000] (no number of a pose matrix in mm is larger)"),
    ({"x": 612.0, "y": 0, "z": 0, "qx": 0, "qy": 0, "qz": 0, "qw": 1}, ds.PoseMapping(ds.PoseFormat.XYZ_QUAT),
     "pose_03.json: the translation is 612 m from the base (x = 612 m), more than 10 m"),
    ({"x": 0, "y": 0, "z": 0, "roll": 0, "pitch": 7.0, "yaw": 0}, ds.PoseMapping(ds.PoseFormat.XYZ_RPY),
     "pose_03.json: pitch = 7 is more than 2 pi: it looks like degrees while the mapping says radians"),
    ({"x": 0, "y": 0, "z": 0, "roll": 0, "pitch": 0, "yaw": -400},
     ds.PoseMapping(ds.PoseFormat.XYZ_RPY, angle_unit=ds.AngleUnit.DEG),
     "pose_03.json: yaw = -400 deg is outside [-360, 360] deg"),
    ({"x": 0, "y": 0, "z": 0, "qx": 0.5, "qy": 0, "qz": 0, "qw": 1}, ds.PoseMapping(ds.PoseFormat.XYZ_QUAT),
     "pose_03.json: the quaternion's norm is 1.11803"),
    ({"matrix": [[1, 0, 0, 0], [0, 1, 0.1, 0], [0, 0, 1, 0], [0, 0, 0, 1]]}, ds.PoseMapping(ds.PoseFormat.MATRIX),
     "pose_03.json: the matrix's rotation part is not a rotation"),
    ({"x": "0.1 m", "y": 0, "z": 0, "qx": 0, "qy": 0, "qz": 0, "qw": 1}, ds.PoseMapping(ds.PoseFormat.XYZ_QUAT),
     "pose_03.json: x is a text, not a number"),
    ({"t": [0, 0, [1]], "q": [0, 0, 0, 1]}, ds.PoseMapping(ds.PoseFormat.XYZ_QUAT, position=("t",), quaternion=("q",)),
     "pose_03.json: the translation is 1 m"),
    ({"t": [0, 0, {"a": 1}], "q": [0, 0, 0, 1]},
     ds.PoseMapping(ds.PoseFormat.XYZ_QUAT, position=("t",), quaternion=("q",)),
     "pose_03.json: t[2] is a mapping, not a number"),
    ({"joints": list(range(65))}, ds.PoseMapping(ds.PoseFormat.JOINTS),
     "pose_03.json: joints holds 65 numbers, the joint positions takes at most 64"),
], ids=["matrix-m", "matrix-mm", "translation", "angle-rad", "angle-deg", "quaternion", "rotation", "text", "nested",
        "mapping", "joints"])
def test_numbers_out_of_range_are_named_by_their_key_path(record, mapping, message):
    if message.endswith("the translation is 1 m"):  # nested lists are read row by row: in range, taken
        assert np.allclose(ds.robot_pose(record, "poses/pose_03.json", mapping)[:3, 3], [0, 0, 1])
        return
    kin = SimpleNamespace(joint_names=[f"j{i}" for i in range(7)])  # the count is refused before it is used
    with pytest.raises(InputError) as info:
        ds.robot_pose(record, "poses/pose_03.json", mapping, kin)
    assert info.value.one_line().startswith("poses/" + message), info.value.one_line()


@pytest.mark.parametrize(("intrinsics", "message"), [
    ({"fx": 0, "fy": 900, "cx": 480, "cy": 360}, "intrinsics.fx = 0 px is outside [1, 100000] px"),
    ({"fx": 900, "fy": 1e9, "cx": 480, "cy": 360}, "intrinsics.fy = 1e+09 px is outside [1, 100000] px"),
    ({"fx": 900, "fy": 900, "cx": -2e5, "cy": 360}, "intrinsics.cx = -200000 px is outside [-100000, 100000] px"),
    ({"fx": 900, "fy": 900, "cx": 480, "cy": "x"}, "intrinsics.cy is a text, not a number"),
    ({"fx": 900, "fy": 900, "cx": 480, "cy": 360, "distortion": [0] * 8},
     "intrinsics.distortion is a list of 8, not a list of at most 5 numbers"),
    ({"fx": 900, "fy": 900, "cx": 480, "cy": 360, "distortion": [0, 500]},
     "intrinsics.distortion[1] = 500 is outside [-100, 100]"),
])
def test_an_index_files_intrinsics_are_ranged(tmp_path, intrinsics, message):
    data = tmp_path / "data"
    data.mkdir()
    (data / "cal_data.yaml").write_text(yaml.safe_dump({"data": [{"image": "0.png", "pose": "0.yaml"}],
                                                        "intrinsics": intrinsics}))
    with pytest.raises(InputError) as info:
        read_dataset(data)
    assert re.match(rf"{re.escape(str(data / 'cal_data.yaml'))}:\d+: {re.escape(message)}", info.value.one_line())


@pytest.mark.parametrize(("change", "message"), [
    ({"rows": 1000}, "target_finder.rows = 1000 is outside [2, 100]"),
    ({"cols": 2.5}, "target_finder.cols = 2.5 is not a whole number"),
    ({"chessboard_dim": 0}, "target_finder.chessboard_dim = 0 m is outside [0.001, 1] m"),
    ({"aruco_marker_dim": 0.05}, "target_finder.aruco_marker_dim is not smaller than chessboard_dim"),
    ({"dictionary": 99}, "target_finder.dictionary is not an ArUco dictionary"),
    ({"static_camera": "yes"}, "static_camera is a text, not true or false"),
])
def test_an_index_files_board_is_ranged(tmp_path, change, message):
    data = tmp_path / "data"
    data.mkdir()
    finder = {"type": "CharucoGridTargetFinder", "rows": 7, "cols": 5, "chessboard_dim": 0.04,
              "aruco_marker_dim": 0.03, "dictionary": 10}
    doc = {"data": [{"image": "0.png", "pose": "0.yaml"}], "target_finder": finder}
    if "static_camera" in change:
        doc.update(change)
    else:
        finder.update(change)
    (data / "cal_data.yaml").write_text(yaml.safe_dump(doc))
    with pytest.raises(InputError) as info:
        read_dataset(data)
    assert re.match(rf"{re.escape(str(data / 'cal_data.yaml'))}:\d+: {re.escape(message)}", info.value.one_line())


def test_intrinsics_on_the_command_line_are_ranged(tmp_path, capfd):
    data = _rendered(tmp_path / "data", 3)
    code, text = _run(capfd, "calibrate", "handeye", "--dataset", data, "--intrinsics", "900,0,480,360",
                      "--out", tmp_path / "out")
    assert code == 1 and "--intrinsics fy = 0 px is outside [1, 100000] px" in text, text


# ----------------------------------------------------------------------------- content
def test_no_refusal_shows_what_a_file_holds(tmp_path):
    """Texts where numbers or mappings belong, a whole file of text: each refusal names the
    file and the key, never the value."""
    data = _rendered(tmp_path / "data", 4)
    (data / "poses" / "0.json").write_text(json.dumps({"matrix": SECRET}))
    (data / "poses" / "1.json").write_text(json.dumps(SECRET))
    (data / "poses" / "2.json").write_text(json.dumps({"matrix": [[SECRET] * 4] * 4}))
    (data / "mapping.yaml").write_text(f"{SECRET} of the mapping\n")
    found = ds.dataset_views(read_dataset(data), ds.PoseMapping(ds.PoseFormat.MATRIX), BOARD,
                             ds.CameraNumbers(*INTRINSICS))
    reasons = " ".join(s.reason for s in found.skipped)
    assert "2.json: matrix[0] is a text, not a number" in reasons, reasons
    assert SECRET not in reasons, reasons
    with pytest.raises(InputError) as info:
        read_mapping(data / "mapping.yaml", data)
    assert SECRET not in info.value.one_line() and "the mapping file holds a text" in info.value.one_line()


def test_the_limits_are_what_the_docs_say():
    text = (ROOT / "docs" / "inputs.md").read_text()
    section = text[text.index("## Hand-eye data sets"):text.index("## Paths a file may name")]
    for value in (f"{ds.MAX_VIEWS:,}", f"{ds.MAX_FOLDER_ENTRIES:,}", f"{ds.MAX_POSE_BYTES:,} bytes",
                  f"{ds.MAX_POSE_VALUES:,} values", f"{ds.MAX_POSES_BYTES:,} bytes", f"{ds.MAX_INDEX_BYTES:,} bytes",
                  f"{ds.MAX_CSV_BYTES:,} bytes", f"{ds.MAX_CSV_COLUMNS:,} columns", f"{ds.MAX_NAME:,} characters",
                  "[1, 100000] px", "[-100000, 100000] px", "[-100, 100]", "at least 1°", "0.0001"):
        assert value in section, f"docs/inputs.md's hand-eye section does not state {value}"
    from recon_cli.calibration.handeye import DEGENERATE_AXIS_SPREAD, DEGENERATE_ROTATION, MIN_VIEWS

    assert (np.degrees(DEGENERATE_ROTATION), DEGENERATE_AXIS_SPREAD, MIN_VIEWS) == (1.0, 1e-4, 3)
    assert ds.FOCAL_RANGE == (1.0, 100_000.0) and ds.DISTORTION_RANGE == (-100.0, 100.0)
