"""The JSON files of scan stores and recordings (scan.json, session.json, ground_truth.json,
a recording's intrinsics.json and poses file) through their readers: FIFOs, oversized and
deeply nested files, NaN and Infinity, long integers and values outside their ranges are
refused with one line (a bad scan is skipped with its reason and the others registered),
within bounded time and memory; fuzzed files never give anything but the project's errors."""

from __future__ import annotations

import copy
import json
import math
import os
import re
import shutil
import threading
import time
import warnings
from pathlib import Path

import cv2
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from recon_cli.backends.hardware import replay
from recon_cli.backends.hardware.replay import ReplayConfig, open_camera, read_poses
from recon_cli.cli import main
from recon_cli.config import DEFAULTS, SceneConfig, SensorConfig
from recon_cli.errors import FileError, InputError, MetadataError, ReconError
from recon_cli.geometry.transforms import invert
from recon_cli.reconstruction import metadata
from recon_cli.reconstruction.crop import CropBox, box_pixels, crop_cloud
from recon_cli.reconstruction.metadata import load_json, parse_json, read_session
from recon_cli.reconstruction.pipeline import RegisterOptions, crop_box_marker, in_box_pixels, run_register
from recon_cli.reconstruction.scan_store import read_scan
from recon_cli.thesis import eq_4_1_views
from recon_cli.workflows.capture import CaptureOptions, run_capture
from tests.inputs.measure import run_cli

ROOT = Path(__file__).resolve().parents[2]
BAD = 1  # the scan spoiled in each case
FAST = RegisterOptions(local=False, mesh=False)
DEEP = "[" * 100_000 + "]" * 100_000
LONG_INT = "9" * 100_000


# ----------------------------------------------------------------------------- helpers
@pytest.fixture(scope="module")
def store(tmp_path_factory):
    """Three scans of the bottle (eq. 4.1 views 0, 2, 4) at 0.3 of the image size."""
    out = tmp_path_factory.mktemp("three")
    config = DEFAULTS.replace(scene=SceneConfig("bottle"), sensor=SensorConfig(resolution=0.3), seed=4)
    result = run_capture(CaptureOptions(views=tuple(eq_4_1_views()[0:6:2]), out=out, config=config))
    assert len(result.scans) == 3
    return out


@pytest.fixture()
def copy_(store, tmp_path):
    out = tmp_path / "s"
    shutil.copytree(store, out)
    return out


@pytest.fixture()
def recording(tmp_path):
    """A folder of images: color/, depth/ (16 bit, 5000 units per metre), intrinsics.json, pose.txt."""
    root = tmp_path / "rec"
    (root / "color").mkdir(parents=True)
    (root / "depth").mkdir()
    for k in range(3):
        cv2.imwrite(str(root / "color" / f"{k}.png"), np.full((6, 8, 3), (10 * k, 20, 30), np.uint8))
        cv2.imwrite(str(root / "depth" / f"{k}.png"), np.full((6, 8), 5000 * (k + 1), np.uint16))
    (root / "intrinsics.json").write_text(json.dumps({"fx": 7.0, "fy": 8.0, "cx": 3.5, "cy": 2.5}))
    (root / "pose.txt").write_text("0 0 0 0 0 0 1\n0.1 0 0 0 0 0 1\n0.2 0 0 0 0 0 1\n")
    return root


def _fifo(path: Path) -> None:
    if path.exists() or path.is_symlink():
        if path.is_dir():
            shutil.rmtree(path)
        else:
            path.unlink()
    os.mkfifo(path)


def _without_blocking(call, *fifos: Path, seconds: float = 20.0):
    """``call()``'s result or exception; fails (instead of hanging) when it blocks, and then
    opens the FIFOs' writing ends so the blocked reader returns."""
    box: dict = {}

    def run():
        try:
            box["value"] = call()
        except BaseException as exc:  # noqa: BLE001 (handed to the test)
            box["error"] = exc

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    thread.join(seconds)
    if thread.is_alive():
        for fifo in fifos:
            fd = os.open(fifo, os.O_WRONLY | os.O_NONBLOCK)
            os.close(fd)
        thread.join(5)
        pytest.fail(f"the reader blocked on {', '.join(map(str, fifos))}")
    if "error" in box:
        raise box["error"]
    return box.get("value")


def _one_line(exc: ReconError) -> str:
    line = exc.one_line()
    assert "\n" not in line and "set_int_max_str_digits" not in line and "Traceback" not in line
    return line


def _edit(path: Path, change) -> None:
    """Rewrite a JSON file with ``change(doc)`` applied (NaN and Infinity written as Python writes them)."""
    doc = json.loads(path.read_text())
    change(doc)
    path.write_text(json.dumps(doc, indent=2))


def _set(*keys_value):
    *keys, value = keys_value

    def change(doc):
        node = doc
        for k in keys[:-1]:
            node = node[k]
        node[keys[-1]] = value

    return change


def _replace(path: Path, old: str, new: str) -> None:
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new, 1))


# ----------------------------------------------------------------------------- the reader itself
@pytest.mark.parametrize("text, message", [
    ('{"fx": NaN}', "x.json:1: scan.json holds NaN, which is not a finite number"),
    ('{"a": 1,\n "fx": -Infinity}', "x.json:2: scan.json holds -Infinity, which is not a finite number"),
    ('{"fx": 1e999}', "x.json:1: scan.json holds 1e999, which is too large for a number"),
    ('{"index": ' + LONG_INT + "}", "x.json:1: scan.json holds an integer of 100,000 digits, more than 30"),
    (DEEP, "x.json:1: scan.json nests lists and objects more than 32 levels deep"),
    ('{\n"a":' + '{"a":' * 40 + "1" + "}" * 41, "x.json:2: scan.json nests lists and objects more than 32 levels"),
    ('{"a": 1, "a": 2}', "scan.json has the key 'a' twice in one object"),
    ('{"name": "\\ud800"}', "scan.json holds text that is not Unicode (a lone surrogate \\ud800)"),
    ('{"a": [1, 2}', "x.json:1:12: scan.json is broken JSON"),
    ('{"a": "[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[["}', None),  # brackets in text are text
    ("[" * 32 + "]" * 32, None),
    ('{"big": 123456789012345678901234567890, "f": 1e308}', None),
])
def test_the_json_reader_refuses_with_file_and_line(text, message):
    if message is None:
        parse_json(text, Path("x.json"), "scan.json")
        return
    with pytest.raises(MetadataError) as info:
        parse_json(text, Path("x.json"), "scan.json")
    assert message in _one_line(info.value)


def test_a_fifo_is_refused_before_it_is_opened(tmp_path):
    fifo = tmp_path / "scan.json"
    os.mkfifo(fifo)  # no writer: opening it for reading would wait for one
    with pytest.raises(MetadataError, match=r"scan.json: scan.json is not a regular file \(a FIFO\)"):
        _without_blocking(lambda: load_json(fifo, "scan.json"), fifo)
    with pytest.raises(MetadataError, match=r"is not a regular file \(a folder\)"):
        load_json(tmp_path, "scan.json")
    (tmp_path / "zero.json").symlink_to("/dev/zero")
    with pytest.raises(MetadataError, match=r"is not a regular file \(a character device\)"):
        load_json(tmp_path / "zero.json", "scan.json")
    with pytest.raises(MetadataError, match="scan.json is missing"):
        load_json(tmp_path / "none.json", "scan.json")


def test_size_is_checked_before_the_file_is_read(tmp_path):
    big = tmp_path / "scan.json"
    with big.open("wb") as f:
        f.truncate(4 * 2**30)  # 4 GiB, sparse
    t0 = time.monotonic()
    with pytest.raises(MetadataError, match=r"scan.json has 4,294,967,296 bytes, more than the 1,000,000"):
        metadata.read_bytes(big, "scan.json")
    assert time.monotonic() - t0 < 1.0
    small = tmp_path / "report.json"
    small.write_text('{"a": "' + "x" * 1_500_000 + '"}')
    assert len(load_json(small, "report.json")["a"]) == 1_500_000  # reports: a larger limit
    with pytest.raises(MetadataError, match=r"scan.json has 1,500,0\d\d bytes, more than the 1,000,000 recon reads"):
        load_json(small, "scan.json", metadata.MAX_METADATA_BYTES)
    (tmp_path / "latin1.json").write_bytes(b'{"name": "\xe9"}')
    with pytest.raises(MetadataError, match=r"not UTF-8 text: byte 10"):
        load_json(tmp_path / "latin1.json", "scan.json")


# ----------------------------------------------------------------------------- bad scans: skipped
def _scan(folder: Path) -> Path:
    return folder / "scan.json"


SCAN_CASES = {
    "FIFO scan.json": (lambda f: _fifo(_scan(f)), "scan.json is not a regular file (a FIFO)"),
    "FIFO ground_truth.json": (lambda f: _fifo(f / "ground_truth.json"),
                               "ground_truth.json is not a regular file (a FIFO)"),
    "folder as scan.json": (lambda f: (_scan(f).unlink(), _scan(f).mkdir()), "is not a regular file (a folder)"),
    "fx NaN": (lambda f: _edit(_scan(f), _set("intrinsics", "fx", math.nan)), "scan.json holds NaN"),
    "fx Infinity": (lambda f: _edit(_scan(f), _set("intrinsics", "fx", math.inf)), "scan.json holds Infinity"),
    "fx 1e300": (lambda f: _edit(_scan(f), _set("intrinsics", "fx", 1e300)),
                 "key 'intrinsics.fx': 1e+300 is greater than the maximum of 100000"),
    "fy 0.5": (lambda f: _edit(_scan(f), _set("intrinsics", "fy", 0.5)), "key 'intrinsics.fy'"),
    "cx -1e9": (lambda f: _edit(_scan(f), _set("intrinsics", "cx", -1e9)), "key 'intrinsics.cx'"),
    "pose NaN": (lambda f: _edit(_scan(f), lambda d: d["world_T_camera_fk"][0].__setitem__(3, math.nan)),
                 "scan.json holds NaN"),
    "pose 1e300": (lambda f: _edit(_scan(f), lambda d: d["world_T_camera_fk"][1].__setitem__(3, 1e300)),
                   "key 'world_T_camera_fk[1][3]'"),
    "pose scaled": (lambda f: _edit(_scan(f), lambda d: d.__setitem__(
        "world_T_camera_fk", (np.asarray(d["world_T_camera_fk"]) * 2).tolist())),
        "key 'world_T_camera_fk' is not a rigid transform"),
    "pose last row": (lambda f: _edit(_scan(f), lambda d: d["world_T_camera_fk"].__setitem__(3, [0, 0, 0, 0])),
                      "key 'world_T_camera_fk' is not a rigid transform"),
    "marker pose Infinity": (lambda f: _edit(_scan(f), _set("marker_T_camera", [[math.inf] * 4] * 4)),
                             "scan.json holds Infinity"),
    "depth_scale NaN": (lambda f: _edit(_scan(f), _set("depth_scale", math.nan)), "scan.json holds NaN"),
    "depth_scale 1e-300": (lambda f: _edit(_scan(f), _set("depth_scale", 1e-300)),
                           "key 'depth_scale': 1e-300 is less than the minimum of 0.001"),
    "joint NaN": (lambda f: _edit(_scan(f), _set("joints", "arm_joint_2", math.nan)), "scan.json holds NaN"),
    "joint 1e300": (lambda f: _edit(_scan(f), _set("joints", "arm_joint_2", 1e300)), "key 'joints.arm_joint_2'"),
    "distortion 1e300": (lambda f: _edit(_scan(f), _set("distortion", [1e300, 0, 0, 0])), "key 'distortion[0]'"),
    "deep nesting": (lambda f: _scan(f).write_text(DEEP), "nests lists and objects more than 32 levels deep"),
    "deep nesting in a kept key": (lambda f: _edit(_scan(f), _set("planned_view", json.loads("[" * 40 + "]" * 40))),
                                   "nests lists and objects more than 32 levels deep"),
    "100,000-digit index": (lambda f: _replace(_scan(f), f'"index": {BAD}', f'"index": {LONG_INT}'),
                            "holds an integer of 100,000 digits, more than 30"),
    "1e999": (lambda f: _replace(_scan(f), '"depth_scale": 20000.0', '"depth_scale": 1e999'),
              "holds 1e999, which is too large for a number"),
    "a key twice": (lambda f: _replace(_scan(f), '"depth_scale": 20000.0', '"depth_scale": 20000.0, "depth_scale": 1'),
                    "has the key 'depth_scale' twice"),
    "larger than 1 MB": (lambda f: _edit(_scan(f), _set("name", "x" * 1_100_000)),
                         "bytes, more than the 1,000,000 recon reads"),
    "ground_truth.json a list": (lambda f: (f / "ground_truth.json").write_text("[]"),
                                 "ground_truth.json holds no JSON object"),
    "ground_truth.json without its pose": (lambda f: (f / "ground_truth.json").write_text('{"joints": {}}'),
                                           "key 'world_T_camera' is not a 4 x 4 pose"),
    "ground_truth.json NaN": (lambda f: _edit(f / "ground_truth.json",
                                              lambda d: d["world_T_camera"][2].__setitem__(3, math.nan)),
                              "ground_truth.json holds NaN"),
}


@pytest.mark.parametrize("case", list(SCAN_CASES))
def test_a_bad_scan_is_skipped_with_its_reason(case, copy_, tmp_path):
    spoil, reason = SCAN_CASES[case]
    folder = copy_ / f"scan_{BAD:04d}"
    spoil(folder)
    fifos = [p for p in (folder / "scan.json", folder / "ground_truth.json") if p.exists() and p.is_fifo()]
    with pytest.raises(MetadataError) as info:
        _without_blocking(lambda: read_scan(folder), *fifos)
    assert reason in _one_line(info.value) and str(folder) in info.value.one_line()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = _without_blocking(lambda: run_register(copy_, tmp_path / "r", FAST), *fifos, seconds=120)
    assert not [w for w in caught if "overflow" in str(w.message) or "invalid value" in str(w.message)]
    assert len(result.scans) == 3 and len(result.used) == 2
    assert reason in result.scans[BAD].skipped and f"scan_{BAD:04d}" in result.scans[BAD].skipped
    assert (tmp_path / "r" / "cloud.ply").exists()


def test_the_scans_as_written_are_read(store):
    for k in range(3):
        scan = read_scan(store / f"scan_{k:04d}")
        assert scan.index == k and scan.ground_truth is not None


# ----------------------------------------------------------------------------- bad session.json: one line
SESSION_CASES = {
    "FIFO": (lambda s: _fifo(s), "session.json is not a regular file (a FIFO)"),
    "world_T_marker NaN": (lambda s: _edit(s, lambda d: d["world_T_marker"][0].__setitem__(3, math.nan)),
                           "session.json holds NaN"),
    "world_T_marker not rigid": (lambda s: _edit(s, lambda d: d["world_T_marker"][0].__setitem__(0, 3.0)),
                                 "key 'world_T_marker' is not a rigid transform"),
    "crop_box.size NaN": (lambda s: _edit(s, lambda d: d["crop_box"]["size"].__setitem__(0, math.nan)),
                          "session.json holds NaN"),
    "crop_box.size 1e300": (lambda s: _edit(s, lambda d: d["crop_box"]["size"].__setitem__(0, 1e300)),
                            "key 'crop_box.size[0]'"),
    "crop_box.center Infinity": (lambda s: _edit(s, lambda d: d["crop_box"]["center"].__setitem__(2, -math.inf)),
                                 "session.json holds -Infinity"),
    "table_lift 7": (lambda s: _edit(s, _set("cell", "table_lift", 7)), "key 'cell.table_lift'"),
    "deep nesting": (lambda s: s.write_text(DEEP), "nests lists and objects more than 32 levels deep"),
    "100,000-digit seed": (lambda s: _replace(s, '"seed": 4', f'"seed": {LONG_INT}'),
                           "holds an integer of 100,000 digits"),
}


@pytest.mark.parametrize("case", list(SESSION_CASES))
def test_a_bad_session_json_is_one_line(case, copy_, tmp_path, capsys):
    spoil, reason = SESSION_CASES[case]
    path = copy_ / "session.json"
    spoil(path)
    fifos = [path] if path.is_fifo() else []
    with pytest.raises(MetadataError) as info:
        _without_blocking(lambda: read_session(copy_), *fifos)
    assert reason in _one_line(info.value) and str(path) in info.value.one_line()
    with pytest.raises(MetadataError, match=re.escape(reason)):
        _without_blocking(lambda: run_register(copy_, tmp_path / "r", FAST), *fifos)
    assert _without_blocking(lambda: main(["register", str(copy_), "--out", str(tmp_path / "r")]), *fifos) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and reason in err and "Traceback" not in err
    assert not (tmp_path / "r").exists()


# ----------------------------------------------------------------------------- recordings
REPLAY_CASES = {
    "FIFO pose.txt": (lambda r: _fifo(r / "pose.txt"), "pose.txt: poses file is not a regular file (a FIFO)"),
    "FIFO intrinsics.json": (lambda r: _fifo(r / "intrinsics.json"),
                             "intrinsics.json: intrinsics.json is not a regular file (a FIFO)"),
    "pose NaN": (lambda r: (r / "pose.txt").write_text("nan 0 0 0 0 0 1\n0 0 0 0 0 0 1\n0 0 0 0 0 0 1\n"),
                 "pose.txt:1: nan 0 0 0 0 0 1 holds NaN or infinity"),
    "pose inf in a quaternion": (lambda r: (r / "pose.txt").write_text("0 0 0 0 0 0 1\n0 0 0 0 0 inf 1\n"),
                                 "pose.txt:2: 0 0 0 0 0 inf 1 holds NaN or infinity"),
    "pose 1e300": (lambda r: (r / "pose.txt").write_text("1e300 0 0 0 0 0 1\n0 0 0 0 0 0 1\n0 0 0 0 0 0 1\n"),
                   "pose.txt:1: translation (1e+300, 0, 0) m is outside [-1000, 1000] m"),
    "pose 2 km": (lambda r: (r / "pose.txt").write_text("0 0 0 0 0 0 1\n0 2000 0 0 0 0 1\n0 0 0 0 0 0 1\n"),
                  "pose.txt:2: translation (0, 2000, 0) m is outside"),
    "pose zero quaternion": (lambda r: (r / "pose.txt").write_text("0 0 0 0 0 0 0\n"),
                             "pose.txt:1: quaternion of norm 0.0000"),
    "pose matrix scaled": (lambda r: (r / "pose.txt").write_text("2 0 0 0 0 2 0 0 0 0 2 0\n" * 3),
                           "pose.txt:1: the matrix is not a rigid transform"),
    "pose matrix last row": (lambda r: (r / "pose.txt").write_text("1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 0\n" * 3),
                             "pose.txt:1: the matrix is not a rigid transform"),
    "poses file of 17 MiB": (lambda r: (r / "pose.txt").open("wb").truncate(17 * 2**20),
                             "poses file has 17,825,792 bytes, more than the 16,777,216"),
    "intrinsics deep nesting": (lambda r: (r / "intrinsics.json").write_text(DEEP),
                                "intrinsics.json:1: intrinsics.json nests lists and objects more than 32 levels"),
    "intrinsics Infinity": (lambda r: (r / "intrinsics.json").write_text(
        '{"fx": Infinity, "fy": 8, "cx": 3.5, "cy": 2.5}'), "intrinsics.json holds Infinity"),
    "intrinsics fx 1e300": (lambda r: (r / "intrinsics.json").write_text(
        '{"fx": 1e300, "fy": 8, "cx": 3.5, "cy": 2.5}'), "intrinsics.json.fx = 1e+300 px is outside [1, 100000] px"),
    "intrinsics cy -1e6": (lambda r: (r / "intrinsics.json").write_text(
        '{"fx": 7, "fy": 8, "cx": 3.5, "cy": -1e6}'), "intrinsics.json.cy = -1e+06 px is outside"),
    "intrinsics 100,000 digits": (lambda r: (r / "intrinsics.json").write_text(
        '{"fx": ' + LONG_INT + ', "fy": 8, "cx": 3.5, "cy": 2.5}'), "holds an integer of 100,000 digits"),
    "intrinsics a list": (lambda r: (r / "intrinsics.json").write_text("[7, 8, 3.5, 2.5]"),
                          "is not a mapping of fx, fy, cx, cy"),
}


@pytest.mark.parametrize("case", list(REPLAY_CASES))
def test_a_bad_recording_is_refused_with_one_line(case, recording):
    spoil, reason = REPLAY_CASES[case]
    spoil(recording)
    fifos = [p for p in (recording / "pose.txt", recording / "intrinsics.json") if p.exists() and p.is_fifo()]
    with pytest.raises((FileError, InputError)) as info:
        _without_blocking(lambda: open_camera(ReplayConfig(str(recording), depth_scale=5000.0)), *fifos)
    assert reason in _one_line(info.value)


def test_the_recording_as_written_plays(recording):
    with open_camera(ReplayConfig(str(recording), depth_scale=5000.0)) as cam:
        assert cam.describe()["frames"] == 3 and cam.describe()["poses"]
    (recording / "pose.txt").write_text("1 0 0 0.5 0 1 0 0 0 0 1 0\n" * 3)  # a 3 x 4 matrix
    assert read_poses(recording / "pose.txt")[0][0, 3] == 0.5


def test_intrinsics_given_on_the_command_line_are_checked(recording, tmp_path, capsys):
    (recording / "intrinsics.json").unlink()
    code = main(["replay", str(recording), "--intrinsics", "1e300,8,3.5,2.5", "--out", str(tmp_path / "r")])
    err = capsys.readouterr().err
    assert code == 1 and err.count("\n") == 1 and "--intrinsics fx = 1e+300 px is outside [1, 100000] px" in err
    assert not (tmp_path / "r").exists()


# ----------------------------------------------------------------------------- guards behind the readers
def test_box_pixels_of_a_non_finite_projection_is_none():
    from recon_cli.perception.camera_model import Intrinsics

    box = CropBox(np.eye(4), (0.1, 0.1, 0.1))
    camera_T_frame = np.eye(4)
    camera_T_frame[2, 3] = 1.0
    K = Intrinsics(64, 48, 50.0, 50.0, 31.5, 23.5)
    assert box_pixels(box, camera_T_frame, K) is not None
    assert box_pixels(box, camera_T_frame, Intrinsics(64, 48, math.nan, 50.0, 31.5, 23.5)) is None
    assert box_pixels(box, camera_T_frame, Intrinsics(64, 48, math.inf, 50.0, 31.5, 23.5)) is None
    far = camera_T_frame.copy()
    far[0, 3] = 1e300
    u0, _, u1, _ = box_pixels(box, far, K)
    assert u0 == u1 == 64  # far right of the image: an empty rectangle


def test_fuse_refuses_points_too_far_apart_for_its_voxel_grid():
    import open3d as o3d

    from recon_cli.reconstruction.surface import SurfaceOptions, fuse

    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.array([[0.0, 0, 0], [1e7, 0, 0]])))
    with pytest.raises(InputError, match=r"the scans' points span 1e\+07 m, too far for a voxel grid of 0.001 m"):
        fuse([cloud], SurfaceOptions(voxel=0.001), [np.zeros(3)])
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.array([[0.0, 0, 0], [np.nan, 0, 0]])))
    with pytest.raises(InputError, match="NaN or infinite coordinates"):
        fuse([cloud], SurfaceOptions(voxel=0.001), [np.zeros(3)])


# ----------------------------------------------------------------------------- schemas and docs
def _number_rows(name: str):
    """(key, range text) of every number of schemas/NAME.schema.json (as docs/inputs.md writes them)."""
    schema = json.loads((ROOT / "schemas" / f"{name}.schema.json").read_text())

    def fmt(x):
        return str(x) if isinstance(x, int) else f"{x:g}"

    def walk(node, key):
        if "$ref" in node:
            yield from walk(schema["$defs"][node["$ref"].rsplit("/", 1)[1]], key)
            return
        for alt in node.get("anyOf", []) + node.get("oneOf", []):
            yield from walk(alt, key)
        if node.get("type") in ("number", "integer"):
            lo = node.get("minimum", node.get("exclusiveMinimum"))
            hi = node.get("maximum", node.get("exclusiveMaximum"))
            assert lo is not None and hi is not None, f"{name} {key} is not bounded"
            text = f"{'(' if 'exclusiveMinimum' in node else '['}{fmt(lo)}, {fmt(hi)}]"
            yield key, f"{text} {node.get('unit', '')}".rstrip()
        for k, v in node.get("properties", {}).items():
            yield from walk(v, f"{key}.{k}" if key else k)
        if isinstance(node.get("additionalProperties"), dict):
            yield from walk(node["additionalProperties"], f"{key}.NAME")
        if isinstance(node.get("items"), dict):
            yield from walk(node["items"], f"{key}[]")

    return list(walk(schema, ""))


def test_every_number_of_the_store_schemas_is_bounded_and_documented():
    import jsonschema

    text = (ROOT / "docs" / "inputs.md").read_text()
    section = text[text.index("## JSON files of scan stores and recordings"):text.index("## Paths a file may name")]
    for name in ("scan", "session"):
        schema = json.loads((ROOT / "schemas" / f"{name}.schema.json").read_text())
        jsonschema.validators.validator_for(schema).check_schema(schema)
        for key, rng in _number_rows(name):
            if key != "format":
                assert f"| {name}.json | `{key}` | {rng} |" in section, f"docs/inputs.md lacks {name}.json {key} {rng}"
    for value in (f"{metadata.MAX_METADATA_BYTES:,} bytes", f"{metadata.MAX_JSON_BYTES:,} bytes",
                  f"{replay.MAX_POSES_BYTES:,} bytes", f"{metadata.MAX_DEPTH} levels",
                  f"{metadata.MAX_INT_DIGITS} digits", f"[-{replay.MAX_TRANSLATION:g}, {replay.MAX_TRANSLATION:g}] m",
                  f"{metadata.RIGID_TOLERANCE:g}"):
        assert value in section, f"docs/inputs.md does not state {value}"


# ----------------------------------------------------------------------------- through the CLI, measured
def _measured(run, code: int):
    assert run.code == code, (run.out, run.err)
    assert "Traceback" not in run.err and "Warning" not in run.err
    assert run.seconds < 20 and run.peak_gb < 1.0, (run.seconds, run.peak_gb)


@pytest.mark.parametrize("case", ["FIFO", "deep nesting"])
def test_register_refuses_a_hostile_session_json_in_bounded_time_and_memory(case, copy_, tmp_path):
    spoil, reason = SESSION_CASES[case]
    spoil(copy_ / "session.json")
    run = run_cli(["register", str(copy_), "--out", str(tmp_path / "r")], tmp_path)
    _measured(run, 1)
    assert run.err.count("\n") == 1 and reason in run.err
    assert not (tmp_path / "r").exists()


@pytest.mark.parametrize("case", ["FIFO scan.json", "deep nesting", "100,000-digit index", "fx NaN",
                                  "depth_scale 1e-300"])
def test_register_skips_a_hostile_scan_json_in_bounded_time_and_memory(case, copy_, tmp_path):
    spoil, reason = SCAN_CASES[case]
    spoil(copy_ / f"scan_{BAD:04d}")
    run = run_cli(["register", str(copy_), "--out", str(tmp_path / "r"), "--global-only", "--depth", "6"], tmp_path)
    _measured(run, 0)
    assert "2 of 3 scans registered (1 skipped)" in run.out
    skipped = [line for line in run.out.splitlines() if line.startswith(f"scan_{BAD:04d} skipped:")]
    assert len(skipped) == 1 and reason in skipped[0], run.out
    assert run.err == ""


@pytest.mark.parametrize("case", ["FIFO pose.txt", "FIFO intrinsics.json", "intrinsics deep nesting", "pose NaN",
                                  "pose 1e300", "intrinsics fx 1e300"])
def test_replay_refuses_a_hostile_recording_in_bounded_time_and_memory(case, recording, tmp_path):
    spoil, reason = REPLAY_CASES[case]
    spoil(recording)
    run = run_cli(["replay", str(recording), "--depth-scale", "5000", "--out", str(tmp_path / "r")], tmp_path)
    _measured(run, 1)
    assert run.err.count("\n") == 1 and reason in run.err
    assert not (tmp_path / "r").exists()


# ----------------------------------------------------------------------------- fuzz
_fuzz = settings(max_examples=200, deadline=None,
                 suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
_scalars = st.one_of(st.none(), st.booleans(), st.integers(-10**40, 10**40), st.floats(allow_nan=True),
                     st.sampled_from([0, 1, -1, 0.5, 1e-300, 1e300, 65535, 65536, 1e5, 2**64]), st.text(max_size=12))


def _keys(name: str) -> list[str]:
    names: set[str] = set()

    def walk(node):
        if isinstance(node, dict):
            names.update(node.get("properties", {}))
            for v in node.values():
                walk(v)
        elif isinstance(node, list):
            for v in node:
                walk(v)

    walk(json.loads((ROOT / "schemas" / f"{name}.schema.json").read_text()))
    return sorted(names) + ["bogus", "arm_joint_1", "world_T_camera"]


def _documents(name: str):
    keys = st.sampled_from(_keys(name))
    return st.recursive(_scalars, lambda inner: st.one_of(st.lists(inner, max_size=5),
                                                          st.dictionaries(keys, inner, max_size=8)), max_leaves=40)


def _paths(node, prefix=()):
    yield prefix
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _paths(v, (*prefix, k))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _paths(v, (*prefix, i))


_ODD = st.sampled_from([math.nan, math.inf, -math.inf, 1e300, -1e300, 1e-300, 0, -1, 10**25, 2**64, 0.5])


@st.composite
def _mutated(draw, valid: dict, name: str):
    """``valid`` with 1 to 3 values replaced or keys removed; mostly where the schema describes
    the file (intrinsics, poses, joints, boxes), a number often by an odd one."""
    doc = copy.deepcopy(valid)
    described = set(json.loads((ROOT / "schemas" / f"{name}.schema.json").read_text())["properties"])
    for _ in range(draw(st.integers(1, 3))):
        paths = [p for p in _paths(doc) if p]
        inside = [p for p in paths if p[0] in described]
        path = draw(st.sampled_from(inside if inside and draw(st.integers(0, 3)) else paths))
        parent = doc
        for part in path[:-1]:
            parent = parent[part]
        value = parent[path[-1]]
        if isinstance(value, int | float) and not isinstance(value, bool) and draw(st.booleans()):
            parent[path[-1]] = draw(_ODD)
        elif isinstance(parent, dict) and draw(st.integers(0, 3)) == 0:
            del parent[path[-1]]
        else:
            parent[path[-1]] = draw(st.one_of(_scalars, st.lists(_scalars, max_size=5),
                                              st.dictionaries(st.sampled_from(_keys(name)), _scalars, max_size=3),
                                              st.just(np.eye(4).tolist()), st.just([[math.nan] * 4] * 4)))
    return doc


@st.composite
def _edited_text(draw, text: str):
    """``text`` with a few characters replaced, inserted or removed (JSON's special ones likely)."""
    chars = st.sampled_from(list('[]{}",:\\-0123456789.eENaInfity \n') + ["NaN", "Infinity", "1e999", "9" * 40,
                                                                         "\\ud800", "[" * 40])
    for _ in range(draw(st.integers(1, 4))):
        at = draw(st.integers(0, len(text)))
        what = draw(st.sampled_from(["insert", "replace", "delete"]))
        piece = draw(chars) if what != "delete" else ""
        end = at if what == "insert" else min(len(text), at + draw(st.integers(1, 8)))
        text = text[:at] + piece + text[end:]
    return text


def _use_scan(folder: Path) -> None:
    """Read a scan; when it is read, what registration does first with it must work too."""
    scan = read_scan(folder)
    world_T_box = np.eye(4)
    world_T_box[2, 3] = 0.78
    box = CropBox(world_T_box, (0.2, 0.2, 0.3))  # around the bottle, in the world frame
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        cut = in_box_pixels(scan, box, scan.world_T_camera_fk)
        crop_cloud(cut.to_open3d_cloud(scan.world_T_camera_fk), box)
        scan.points_world_fk()


@pytest.fixture(scope="module")
def fuzz_scan(store, tmp_path_factory):
    """One scan folder (a copy) whose scan.json the fuzz tests overwrite, and its valid scan.json."""
    folder = tmp_path_factory.mktemp("fuzz") / "scan_0000"
    shutil.copytree(store / "scan_0000", folder)
    return folder, (folder / "scan.json").read_text()


def _try_scan(folder: Path, text: str) -> None:
    (folder / "scan.json").write_text(text, encoding="utf-8", errors="surrogatepass")
    try:
        _use_scan(folder)
    except MetadataError as exc:
        _one_line(exc)


def _try_session(folder: Path, text: str, scan_folder: Path) -> None:
    (folder / "session.json").write_text(text, encoding="utf-8", errors="surrogatepass")
    try:
        info = read_session(folder)
    except MetadataError as exc:
        _one_line(exc)
        return
    try:
        box = crop_box_marker(FAST, info)
    except InputError as exc:
        _one_line(exc)
        return
    scan = read_scan(scan_folder)
    world_T_marker = np.eye(4) if info.world_T_marker is None else info.world_T_marker
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        box_pixels(box, invert(scan.world_T_camera_fk) @ world_T_marker, scan.intrinsics)


@_fuzz
@given(text=st.one_of(st.text(max_size=200), st.binary(max_size=200).map(lambda b: b.decode("latin-1"))))
def test_fuzz_the_reader_with_random_text(text):
    try:
        parse_json(text, Path("x.json"), "scan.json")
    except MetadataError as exc:
        _one_line(exc)


@_fuzz
@given(data=st.data())
def test_fuzz_random_scan_json_documents(fuzz_scan, data):
    folder, _ = fuzz_scan
    _try_scan(folder, json.dumps(data.draw(_documents("scan"))))


@_fuzz
@given(data=st.data())
def test_fuzz_mutated_scan_json(fuzz_scan, data):
    folder, valid = fuzz_scan
    _try_scan(folder, json.dumps(data.draw(_mutated(json.loads(valid), "scan")), indent=1))


@_fuzz
@given(data=st.data())
def test_fuzz_edited_scan_json_text(fuzz_scan, data):
    folder, valid = fuzz_scan
    _try_scan(folder, data.draw(_edited_text(valid)))


@pytest.fixture(scope="module")
def fuzz_store(store, tmp_path_factory):
    root = tmp_path_factory.mktemp("fuzz_store")
    shutil.copy(store / "session.json", root / "session.json")
    return root, (root / "session.json").read_text(), store / "scan_0000"


@_fuzz
@given(data=st.data())
def test_fuzz_random_session_json_documents(fuzz_store, data):
    root, _, scan_folder = fuzz_store
    _try_session(root, json.dumps(data.draw(_documents("session"))), scan_folder)


@_fuzz
@given(data=st.data())
def test_fuzz_mutated_session_json(fuzz_store, data):
    root, valid, scan_folder = fuzz_store
    _try_session(root, json.dumps(data.draw(_mutated(json.loads(valid), "session")), indent=1), scan_folder)


@_fuzz
@given(data=st.data())
def test_fuzz_edited_session_json_text(fuzz_store, data):
    root, valid, scan_folder = fuzz_store
    _try_session(root, data.draw(_edited_text(valid)), scan_folder)
