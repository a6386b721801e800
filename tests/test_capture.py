"""`recon capture`: one planned, executed move and one scan whose points lie on the object."""

from __future__ import annotations

import json

import numpy as np
import open3d as o3d
import pytest

from recon_cli.cli import main
from recon_cli.config import DEFAULTS, SceneConfig
from recon_cli.geometry.transforms import pose_error, transform_points
from recon_cli.geometry.view import View
from recon_cli.perception.sensor import motioncam_3d_m
from recon_cli.reconstruction.scan_store import ScanStore
from recon_cli.workflows.capture import CaptureOptions, run_capture

from .conftest import SHARED_DATA


@pytest.fixture(scope="module")
def drill_capture(tmp_path_factory):
    name = "drill" if (SHARED_DATA / "ycb").exists() else "bottle"
    out = tmp_path_factory.mktemp("capture")
    view = View.from_degrees((0, 0, 0.78), 0.6, 70, 0)
    return run_capture(CaptureOptions(views=(view,), out=out, config=DEFAULTS.replace(scene=SceneConfig(name), seed=1)))


def test_scan_points_lie_on_the_object(drill_capture):
    res = drill_capture
    scan = ScanStore(res.folder).read(0)
    T_true = np.asarray(scan.ground_truth["world_T_camera"])
    pts = transform_points(T_true, scan.points_camera())
    lo, hi = res.scene_object.world_aabb()
    near = np.all((pts > lo - 0.005) & (pts < hi + 0.005), axis=1) & (pts[:, 2] > lo[2] + 0.002)
    assert near.sum() > 20000
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(res.scene_object.mesh_world()))
    d = scene.compute_distance(o3d.core.Tensor(pts[near].astype(np.float32))).numpy()
    z = (np.linalg.inv(T_true) @ np.c_[pts[near], np.ones(near.sum())].T)[2]
    sigma = motioncam_3d_m().sigma(np.median(z))
    assert np.median(d) < sigma  # below the noise level at that range


def test_scan_record(drill_capture):
    scan = ScanStore(drill_capture.folder).read(0)
    assert scan.intrinsics.width == 1600 and scan.intrinsics.height == 1200
    move = scan.meta["move"]
    assert move["settled"] and move["camera_position_error_m"] < 1e-4
    # the recorded FK pose is the one of the measured joints; the truth differs only by tracking
    dp, dr = pose_error(scan.world_T_camera_fk, np.asarray(scan.ground_truth["world_T_camera"]))
    assert dp < 1e-9 and dr < 1e-9  # same URDF: FK of the measured joints is the true pose
    goal = np.asarray(scan.meta["planned_view"]["world_T_camera_goal"])
    dp, dr = pose_error(scan.world_T_camera_fk, goal)
    assert dp < 1e-4 and np.degrees(dr) < 1e-2
    assert (drill_capture.folder / "ground_truth").is_dir()
    assert json.loads((drill_capture.folder / "session.json").read_text())["backend"] == "sim"
    report = json.loads(drill_capture.report.read_text())
    assert (report["status"], report["views"], report["scans"], report["failures"]) == ("done", 1, 1, [])
    assert drill_capture.page == drill_capture.folder / "report.html" and drill_capture.page.is_file()


def test_capture_cli_errors(capsys, tmp_path):
    blocker = tmp_path / "f"
    blocker.write_text("")
    for argv, needle in [
        (["capture", "--object", str(tmp_path / "nothing.stl")], "does not exist"),
        (["capture", "--object", "spaceship"], "Invalid value for '--object': 'spaceship' is not one of wood_block,"),
        (["capture", "--out", str(blocker / "x")], "not writable"),
        (["capture", "--scale", "-2", "--object", "bottle"], "Invalid value for '--scale'"),
    ]:
        code = main(argv)
        _, err = capsys.readouterr()
        lines = [x for x in err.splitlines() if x.strip() and "leak" not in x]
        usage = "--scale" in argv or "spaceship" in argv  # not a value the option takes: a usage error
        assert code == (2 if usage else 1), argv
        assert len(lines) == 1 and lines[0].startswith("error: ") and needle in lines[0], err
