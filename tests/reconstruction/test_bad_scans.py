"""A scan store with bad scans: each bad scan is skipped with its reason (in the result, the
report and on the console) and the others are registered; broken session metadata is one
line naming the file and the line or key. Five views of eq. 4.1 at a quarter image size."""

from __future__ import annotations

import json
import shutil

import cv2
import numpy as np
import pytest

from recon_cli.cli import main
from recon_cli.config import DEFAULTS, SceneConfig, SensorConfig
from recon_cli.errors import InputError, MetadataError
from recon_cli.reconstruction.metadata import read_session
from recon_cli.reconstruction.pipeline import RegisterOptions, run_register
from recon_cli.reconstruction.scan_store import read_scan
from recon_cli.thesis import eq_4_1_views
from recon_cli.workflows.capture import CaptureOptions, run_capture

BAD = 2  # the scan that is spoiled in each case
FAST = RegisterOptions(local=False, mesh=False)


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    out = tmp_path_factory.mktemp("five")
    views = tuple(eq_4_1_views()[0:10:2])
    config = DEFAULTS.replace(scene=SceneConfig("bottle"), sensor=SensorConfig(resolution=0.3), seed=4)
    result = run_capture(CaptureOptions(views=views, out=out, config=config))
    assert len(result.scans) == 5
    return out


def _json(path):
    return json.loads(path.read_text())


def _truncate(folder):
    data = (folder / "depth.png").read_bytes()
    (folder / "depth.png").write_bytes(data[: len(data) // 2])


def _missing_depth(folder):
    (folder / "depth.png").unlink()


def _broken_json(folder):
    text = (folder / "scan.json").read_text()
    (folder / "scan.json").write_text(text[: len(text) // 3])


def _list_json(folder):
    (folder / "scan.json").write_text("[1, 2, 3]\n")


def _missing_key(folder):
    d = _json(folder / "scan.json")
    del d["depth_scale"]
    (folder / "scan.json").write_text(json.dumps(d))


def _wrong_type(folder):
    d = _json(folder / "scan.json")
    d["intrinsics"]["fx"] = "five hundred"
    (folder / "scan.json").write_text(json.dumps(d))


def _bad_pose(folder):
    d = _json(folder / "scan.json")
    d["world_T_camera_fk"] = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]
    (folder / "scan.json").write_text(json.dumps(d))


def _colour_size(folder):
    bgr = cv2.imread(str(folder / "color.png"))
    cv2.imwrite(str(folder / "color.png"), cv2.resize(bgr, (bgr.shape[1] // 2, bgr.shape[0] // 2)))


def _depth_8bit(folder):
    depth = cv2.imread(str(folder / "depth.png"), cv2.IMREAD_UNCHANGED)
    cv2.imwrite(str(folder / "depth.png"), (depth // 256).astype(np.uint8))


def _no_scan_json(folder):
    (folder / "scan.json").unlink()


CASES = {
    "truncated depth.png": (_truncate, "depth.png: depth image cannot be decoded"),
    "missing depth.png": (_missing_depth, "depth.png: depth image is missing"),
    "broken scan.json": (_broken_json, "scan.json:"),
    "scan.json is a list": (_list_json, "scan.json holds a list, not a JSON object"),
    "scan.json lacks a key": (_missing_key, "'depth_scale' is a required property"),
    "string for a number": (_wrong_type, "key 'intrinsics.fx'"),
    "pose not 4 x 4": (_bad_pose, "key 'world_T_camera_fk"),
    "colour size differs": (_colour_size, "colour image is"),
    "8-bit depth": (_depth_8bit, "not 16-bit grey"),
    "folder without scan.json": (_no_scan_json, "scan folder without scan.json"),
}


@pytest.mark.parametrize("case", list(CASES))
def test_one_bad_scan_of_five_is_skipped(case, store, tmp_path):
    spoil, reason = CASES[case]
    copy = tmp_path / "s"
    shutil.copytree(store, copy)
    spoil(copy / f"scan_{BAD:04d}")
    with pytest.raises(MetadataError, match="|".join(map(str, [reason.replace("(", r"\(")]))):
        read_scan(copy / f"scan_{BAD:04d}")
    result = run_register(copy, tmp_path / "r", FAST)
    assert len(result.scans) == 5 and len(result.used) == 4
    bad = result.scans[BAD]
    assert bad.skipped and reason in bad.skipped and f"scan_{BAD:04d}" in bad.skipped
    report = _json(result.report)
    assert report["scans_registered"] == 4 and report["scans_skipped"] == 1
    assert reason in report["scans"][BAD]["skipped"] and report["scans"][BAD]["folder"] == f"scan_{BAD:04d}"
    assert (tmp_path / "r" / "cloud.ply").exists()


def test_cli_names_the_skipped_scan(store, tmp_path, capsys):
    copy = tmp_path / "s"
    shutil.copytree(store, copy)
    _truncate(copy / f"scan_{BAD:04d}")
    code = main(["register", str(copy), "--out", str(tmp_path / "r"), "--depth", "6"])
    out = capsys.readouterr().out
    assert code == 0, out
    assert "4 of 5 scans registered (1 skipped)" in out
    assert f"scan_{BAD:04d} skipped:" in out and "cannot be decoded" in out
    assert (tmp_path / "r" / "mesh.ply").exists()


def test_every_scan_bad_fails_with_the_reasons(store, tmp_path, capsys):
    copy = tmp_path / "s"
    shutil.copytree(store, copy)
    for folder in copy.glob("scan_*"):
        _list_json(folder)
    assert main(["register", str(copy), "--out", str(tmp_path / "r")]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "none of the 5 scans" in err and "holds a list" in err
    assert not (tmp_path / "r").exists()
    with pytest.raises(InputError, match="none of the 5 scans"):
        run_register(copy, tmp_path / "r", FAST)


@pytest.mark.parametrize("content, expected", [
    ('{"format": 1, "backend": "sim",\n "cell": {"kind": "gantry",}\n}',
     r"session.json:2:\d+: session.json is broken JSON"),
    ('["not", "a", "session"]', "session.json holds a list, not a JSON object"),
    ('{"format": 1, "crop_box": {"center": [0, 0, 0.8], "size": "big"}}', "key 'crop_box.size'"),
    ('{"format": 1, "world_T_marker": [[1, 0], [0, 1]]}', r"key 'world_T_marker\[0\]' has 2 items, at least 4"),
    ('{"format": 7}', "session.json has format 7, this recon reads format 1 and older"),
])
def test_corrupt_session_json_is_one_line(content, expected, store, tmp_path, capsys):
    copy = tmp_path / "s"
    shutil.copytree(store, copy)
    (copy / "session.json").write_text(content)
    with pytest.raises(MetadataError, match=expected):
        read_session(copy)
    assert main(["register", str(copy), "--out", str(tmp_path / "r")]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert str(copy / "session.json") in err and "session.json" in err
    assert not (tmp_path / "r").exists()
