"""`recon register` / `recon evaluate` on a small simulated session (6 views of eq. 4.1 at a
half the image size, the board covered in one view), and its error handling."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from recon_cli.cli import main
from recon_cli.config import DEFAULTS, SceneConfig, SensorConfig
from recon_cli.errors import FileError, InputError
from recon_cli.perception.sensor import motioncam_3d_m
from recon_cli.reconstruction.assessment import run_evaluate
from recon_cli.reconstruction.pipeline import RegisterOptions, run_register
from recon_cli.thesis import eq_4_1_views
from recon_cli.workflows.capture import CaptureOptions, run_capture

from ..conftest import SHARED_DATA

COVERED = 3  # 1-based view with a sheet over the board


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    name = "drill" if (SHARED_DATA / "ycb").exists() else "bottle"
    out = tmp_path_factory.mktemp("eq41")
    views = tuple(eq_4_1_views()[0:12:2])  # theta 70 deg, every 60 deg
    config = DEFAULTS.replace(scene=SceneConfig(name), sensor=SensorConfig(resolution=0.5), seed=2)
    run_capture(CaptureOptions(views=views, out=out, config=config, cover_board=frozenset({COVERED})))
    return out, name


@pytest.fixture(scope="module")
def registered(session, tmp_path_factory):
    folder, _ = session
    return run_register(folder, tmp_path_factory.mktemp("rec"), RegisterOptions())


def test_pose_sources_and_fallback(registered):
    sources = [r.pose.source.value for r in registered.scans]
    assert sources[COVERED - 1] == "kinematics"
    assert "board not found" in registered.scans[COVERED - 1].pose.reason
    assert sources.count("charuco") == len(sources) - 1
    report = json.loads(registered.report.read_text())
    assert report["pose_sources"] == {"charuco": 5, "kinematics": 1}
    for r in registered.scans:
        if r.charuco_error is not None:  # 800 x 600 px here; full size: recon bench registration
            assert r.charuco_error[0] < 1e-3 and np.degrees(r.charuco_error[1]) < 0.1


def test_pose_graph_structure(registered):
    m = registered.multiway
    odometry = [e for e in m.edges if e.kind == "odometry"]
    assert len(odometry) == len(registered.used) - 1  # a spanning tree
    nodes = {e.source for e in odometry} | {e.target for e in odometry}
    assert nodes == set(range(len(registered.used)))
    # the tree maximizes the correspondence counts: no loop closure beats the weakest tree
    # edge on the path it closes (cheap check: the strongest overlap is in the tree)
    best = max(m.edges, key=lambda e: e.correspondences)
    assert best.kind == "odometry"
    # the pose graph keeps the poses at least as accurate as the board (ICP that slides along
    # a symmetric object, the built-in bottle, is rejected)
    errors = [r.pose_errors() for r in registered.used]
    assert np.mean([e["final"][0] for e in errors]) <= np.mean([e["global"][0] for e in errors]) + 0.1e-3
    assert np.mean([e["final"][1] for e in errors]) <= np.mean([e["global"][1] for e in errors]) + np.radians(0.01)


def test_outputs_are_accurate(registered, session):
    folder, name = session
    for path in (registered.cloud, registered.cloud_global, registered.mesh, registered.report):
        assert path.exists() and path.stat().st_size > 0
    sigma = motioncam_3d_m().sigma(0.6)
    ev = run_evaluate(registered.cloud, folder / "ground_truth" / f"{name}.ply", 0.001, folder,
                      samples=50_000, out=registered.folder)
    e = ev.evaluation
    assert abs(e.mean) < sigma and e.std < 2 * sigma  # the target: std <= 2 x noise
    assert e.coverage_visible > 0.9  # 6 views at half the image size
    assert ev.histogram.exists()


def test_register_cli(session, tmp_path, capsys):
    folder, _ = session
    code = main(["register", str(folder), "--out", str(tmp_path / "r"), "--global-only", "--depth", "7"])
    out = capsys.readouterr().out
    assert code == 0, out
    assert "kinematics" in out and (tmp_path / "r" / "mesh.ply").exists()


def test_no_colour_means_kinematics(session, tmp_path):
    folder, _ = session
    copy = tmp_path / "s"
    shutil.copytree(folder, copy)
    for png in copy.glob("scan_*/color.png"):
        png.unlink()
    result = run_register(copy, tmp_path / "r", RegisterOptions(local=False, mesh=False))
    assert all(r.pose.source.value == "kinematics" for r in result.scans)
    assert all(r.pose.reason == "scan has no colour image" for r in result.scans)


def test_poorly_reprojecting_board_poses_give_way_to_kinematics(session):
    """A board pose reprojecting worse than the limit is replaced by the kinematic pose (with
    the reason); without a world_T_marker it is the only pose and is kept."""
    from recon_cli.perception.charuco import thesis_board
    from recon_cli.reconstruction.global_registration import global_pose
    from recon_cli.reconstruction.scan_store import ScanStore

    folder, _ = session
    store = ScanStore(folder)
    world_T_marker = np.asarray(store.session().world_T_marker)
    scan = store.read(0)
    good = global_pose(scan, thesis_board(), world_T_marker)
    assert good.source.value == "charuco" and good.reprojection_px < 1.0
    strict = global_pose(scan, thesis_board(), world_T_marker, max_reprojection_px=0.5 * good.reprojection_px)
    assert strict.source.value == "kinematics" and "rejected" in strict.reason
    alone = global_pose(scan, thesis_board(), None, max_reprojection_px=0.5 * good.reprojection_px)
    assert alone.source.value == "charuco"


def test_board_never_found_and_no_joint_data(session, tmp_path):
    folder, _ = session
    copy = tmp_path / "s"
    shutil.copytree(folder, copy)
    for png in copy.glob("scan_*/color.png"):
        png.unlink()
    info = json.loads((copy / "session.json").read_text())
    del info["world_T_marker"]
    info["crop_box"]["frame"] = "marker"
    (copy / "session.json").write_text(json.dumps(info))
    with pytest.raises(InputError, match="none of the 6 scans .* can be used"):
        run_register(copy, tmp_path / "r", RegisterOptions())


def test_errors(session, tmp_path, capsys):
    folder, _ = session
    (tmp_path / "empty").mkdir()
    with pytest.raises(FileError, match="holds no scans"):
        run_register(tmp_path / "empty", tmp_path / "r")
    with pytest.raises(FileError, match="is not a folder"):
        run_register(tmp_path / "missing", tmp_path / "r")
    # a crop box beside the object: zero points after cropping, nothing written
    assert main(["register", str(folder), "--crop-box", "0.5,0.5,0.8,0.1,0.1,0.1", "--out", str(tmp_path / "r")]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "points inside the crop box" in err
    assert not (tmp_path / "r").exists()
    assert main(["evaluate", str(tmp_path / "nothing.ply"), "--reference", str(tmp_path / "x.ply")]) == 1
    assert "does not exist" in capsys.readouterr().err


def test_a_memo_of_the_poses_and_clouds_gives_the_same_cloud_without_reading_the_images(session, registered, tmp_path,
                                                                                          monkeypatch):
    """What a run made of its scans already (CloudMemo: each scan's board pose and cloud, as
    an autoscan makes them) is reused: the registration gives the very same cloud, and reads
    the images of no scan but the one whose pose waits for the board's correction."""
    from recon_cli.perception.charuco import recorded_board
    from recon_cli.reconstruction import scan_store
    from recon_cli.reconstruction.pipeline import CloudMemo, crop_box_marker, scan_points

    folder, _ = session
    options = RegisterOptions()
    store = scan_store.ScanStore(folder)
    info = store.session()
    box, board = crop_box_marker(options, info), recorded_board(info.board)
    memo = CloudMemo()
    for _, scan_folder in store.scan_folders():
        scan = scan_store.read_scan(scan_folder)
        pose = memo.pose(scan_folder.name, scan, board, info.world_T_marker, options)
        memo.put(scan_folder.name, pose.marker_T_camera, box, scan_points(scan, pose, box))
    read = scan_store._read_image
    images: list[str] = []

    def counted(path, *args, **kwargs):
        images.append(path.parent.name)
        return read(path, *args, **kwargs)

    monkeypatch.setattr(scan_store, "_read_image", counted)
    again = run_register(folder, tmp_path / "memo", options, memo=memo)
    assert again.cloud.read_bytes() == registered.cloud.read_bytes()
    assert set(images) == {f"scan_{COVERED - 1:04d}"}, images


def test_the_fused_cloud_is_reused_for_a_surface_that_fuses_alike(registered):
    """A <reconstruct/> with the registration's fusion options (its Poisson options aside)
    takes the fused cloud at hand, the very points of cloud.ply; other fusion options fuse
    the scans anew."""
    from dataclasses import replace

    from recon_cli.reconstruction.surface import fuse

    surface = registered.surface
    again = fuse(registered.clouds, surface, registered.cameras)
    kept = registered.fused_with(replace(surface, poisson_depth=7, density_quantile=0.05))
    assert kept is not registered.fused
    assert np.array_equal(np.asarray(kept.points), np.asarray(again.points))
    assert np.array_equal(np.asarray(kept.normals), np.asarray(again.normals))
    coarse = registered.fused_with(replace(surface, voxel=0.002))
    assert len(coarse.points) < 0.5 * len(again.points)
