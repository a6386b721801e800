"""The replay camera over a scan store, a folder of images and the real RGB-D sequence of
../shared/data/rgbd_real; the replay session: the recording imported as a scan store,
registered from the recorded poses (``recon register --no-board``) and the fused cloud's
overlap residual between consecutive frames."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from recon_cli.backends.base import CameraBackend
from recon_cli.backends.hardware.replay import (
    ReplayConfig,
    import_recording,
    open_camera,
    read_poses,
)
from recon_cli.errors import CameraFault, FileError, InputError
from recon_cli.perception.camera_model import Intrinsics
from recon_cli.reconstruction.scan_store import Scan, ScanStore

from ..conftest import SHARED_DATA

SLAMBOOK = SHARED_DATA / "rgbd_real" / "slambook2" / "ch5_rgbd"
#: slambook2 ch5 (joinMap.cpp): fx 518, fy 519, cx 325.5, cy 253.5; depth in mm
SLAMBOOK_INTRINSICS = {"fx": 518.0, "fy": 519.0, "cx": 325.5, "cy": 253.5}
needs_slambook = pytest.mark.skipif(not SLAMBOOK.exists(), reason="../shared/data/rgbd_real/slambook2 is not here")


def _pose(x: float, yaw: float) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(np.array([0.0, yaw, 0.0]))[0]
    T[:3, 3] = (x, 0.0, 0.0)
    return T


@pytest.fixture()
def store(tmp_path):
    """A scan store of three small scans (a tilted plane, a colour ramp, one with distortion)."""
    root = tmp_path / "store"
    s = ScanStore.create(root, {"backend": "sim"})
    K = Intrinsics(32, 24, 30.0, 30.0, 15.5, 11.5)
    v, u = np.mgrid[0:24, 0:32]
    for k in range(3):
        depth = 0.5 + 0.01 * k + 0.002 * u
        depth[0, 0] = 0.0
        color = np.stack([u * 8, v * 10, np.full_like(u, 40 * k)], axis=2).astype(np.uint8)
        s.write(Scan(k, color, depth, K, {"j1": 0.1 * k}, _pose(0.1 * k, 0.2 * k), {"name": f"view {k}"},
                     distortion=(0.01, 0.0, 0.0, 0.0, 0.0) if k == 2 else None), depth_scale=10000.0)
    return root


def test_replay_plays_a_scan_store_in_order_then_fails_with_one_line(store):
    cam = open_camera(ReplayConfig.from_mapping({"source": str(store)}, "cell.yaml: camera.replay"))
    assert isinstance(cam, CameraBackend)
    assert cam.describe()["frames"] == 3 and cam.describe()["poses"]
    for k in range(3):
        frame = cam.capture()
        assert frame.depth.shape == (24, 32) and frame.color.shape == (24, 32, 3)
        assert frame.depth[0, 0] == 0.0 and frame.depth[5, 7] == pytest.approx(0.5 + 0.01 * k + 0.014, abs=1e-4)
        assert frame.color[5, 7, 2] == 40 * k and frame.intrinsics.fx == 30.0
        assert frame.distortion == ((0.01, 0.0, 0.0, 0.0, 0.0) if k == 2 else None)
        assert cam.last.name == f"scan_{k:04d}" and np.allclose(cam.last.world_T_camera, _pose(0.1 * k, 0.2 * k))
    with pytest.raises(CameraFault) as info:
        cam.capture()
    assert info.value.one_line() == (f"the replay of {store} has no frame left (all 3 played); plan at most 3 "
                                     "scans, or set cell.yaml: camera.replay.loop: true")
    cam.close()
    with pytest.raises(CameraFault, match="closed"):
        cam.capture()


def test_replay_loop_starts_again(store):
    with open_camera(ReplayConfig(str(store), loop=True)) as cam:
        names = [(cam.capture(), cam.last.name)[1] for _ in range(4)]
    assert names == ["scan_0000", "scan_0001", "scan_0002", "scan_0000"]


@pytest.fixture()
def images(tmp_path):
    """A folder of images: color/ and depth/ (TUM: 16 bit, 5000 units per metre) in natural
    order 1, 2, 10; intrinsics.json; TUM groundtruth-style poses (timestamp first)."""
    root = tmp_path / "rec"
    (root / "color").mkdir(parents=True)
    (root / "depth").mkdir()
    for k, name in enumerate(("1", "2", "10")):
        cv2.imwrite(str(root / "color" / f"{name}.png"), np.full((6, 8, 3), (10 * k, 20, 30), np.uint8))  # BGR
        cv2.imwrite(str(root / "depth" / f"{name}.png"), np.full((6, 8), 5000 * (k + 1), np.uint16))
    (root / "intrinsics.json").write_text(json.dumps({"fx": 7.0, "fy": 8.0, "cx": 3.5, "cy": 2.5, "width": 8}))
    (root / "poses.txt").write_text("# timestamp tx ty tz qx qy qz qw\n"
                                    "0.1 0 0 0 0 0 0 1\n0.2 1 0 0 0 0 0.7071068 0.7071068\n0.3 2 0 0 0 0 0 1\n")
    return root


def test_replay_folder_of_images_pairs_files_in_natural_order(images):
    with open_camera(ReplayConfig(str(images), depth_scale=5000.0)) as cam:
        frames = [(cam.capture(), cam.last) for _ in range(3)]
    assert [f.name for _, f in frames] == ["1", "2", "10"]
    for k, (frame, rec) in enumerate(frames):
        assert np.all(frame.depth == k + 1.0)  # 5000 (k + 1) units / 5000
        assert tuple(frame.color[0, 0]) == (30, 20, 10 * k)  # RGB
        assert frame.intrinsics == Intrinsics(8, 6, 7.0, 8.0, 3.5, 2.5)
        assert rec.world_T_camera[0, 3] == k
    assert np.allclose(frames[1][1].world_T_camera[:3, :3], [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-6)


def test_replay_recording_errors_name_file_and_line(images, tmp_path):
    (images / "poses.txt").write_text("0 0 0 0 0 0 1\n0 0 0 0 0 0 2\n0 0 0 0 0 0 1\n")
    with pytest.raises(FileError, match=r"poses.txt:2: quaternion of norm 2.0000"):
        open_camera(ReplayConfig(str(images)))
    (images / "poses.txt").write_text("0 0 0 0 0 0 1\n")
    with pytest.raises(FileError, match="poses.txt: 1 poses for 3 frames"):
        open_camera(ReplayConfig(str(images)))
    (images / "poses.txt").unlink()
    (images / "intrinsics.json").unlink()
    with pytest.raises(InputError, match="has no intrinsics; give camera.replay.intrinsics"):
        open_camera(ReplayConfig(str(images)))
    (images / "color" / "3.png").write_bytes(b"")
    with pytest.raises(FileError, match="4 colour images but 3 depth images"):
        open_camera(ReplayConfig(str(images), intrinsics=(1.0, 1.0, 0.0, 0.0)))
    with pytest.raises(FileError, match="is not a folder"):
        open_camera(ReplayConfig(str(tmp_path / "nowhere")))
    with pytest.raises(FileError, match=r":1: 5 numbers"):
        (tmp_path / "p.txt").write_text("1 2 3 4 5\n")
        read_poses(tmp_path / "p.txt")


def test_replay_config_is_checked_key_by_key():
    with pytest.raises(InputError, match="camera.replay.source is missing"):
        ReplayConfig.from_mapping({})
    with pytest.raises(InputError, match=r"camera.replay.fps is not a known key; known keys: color, depth, "
                                         r"depth_scale, distortion, intrinsics, kind, loop, poses, source"):
        ReplayConfig.from_mapping({"source": "x", "fps": 3})
    with pytest.raises(InputError, match="kind is not one of auto, store, images"):
        ReplayConfig.from_mapping({"source": "x", "kind": "video"})
    with pytest.raises(InputError, match="loop is not true or false"):
        ReplayConfig.from_mapping({"source": "x", "loop": "yes"})
    cfg = ReplayConfig.from_mapping({"source": "x", "intrinsics": SLAMBOOK_INTRINSICS, "depth_scale": 5000})
    assert cfg.intrinsics == (518.0, 519.0, 325.5, 253.5) and cfg.depth_scale == 5000.0


def test_station_file_with_a_replay_camera(tmp_path, store):
    from recon_cli.backends.station_file import load_station

    path = tmp_path / "cell.yaml"
    path.write_text(f"format: 1\nrobot: {{adapter: sim}}\ncamera:\n  adapter: replay\n"
                    f"  replay: {{source: {store}, loop: true}}\n")
    station = load_station(path)
    assert station.camera == ReplayConfig(str(store), loop=True)
    path.write_text("format: 1\nrobot: {adapter: sim}\ncamera:\n  adapter: replay\n  replay: {source: x, fsp: 3}\n")
    with pytest.raises(InputError, match=r"cell.yaml:5: camera.replay.fsp is not a known key"):
        load_station(path)


# --------------------------------------------------------------------- the real RGB-D sequence
def _slambook() -> ReplayConfig:
    return ReplayConfig.from_mapping({"source": str(SLAMBOOK), "intrinsics": SLAMBOOK_INTRINSICS})


@needs_slambook
def test_replay_of_the_real_rgbd_sequence():
    with open_camera(_slambook()) as cam:
        frames = [(cam.capture(), cam.last) for _ in range(5)]
        with pytest.raises(CameraFault, match="all 5 played"):
            cam.capture()
    for k, (frame, rec) in enumerate(frames):
        assert rec.name == str(k + 1) and frame.color.shape == (480, 640, 3) and frame.depth.shape == (480, 640)
        valid = frame.depth > 0
        assert 0.6 < valid.mean() < 0.8  # Kinect-style holes
        assert 0.7 < frame.depth[valid].min() and frame.depth.max() < 10.0  # [m] from mm
    first = frames[0][1].world_T_camera  # pose.txt line 1, world_T_camera
    assert np.allclose(first[:3, 3], (-0.228993, 0.00645704, 0.0287837))


@needs_slambook
@pytest.mark.slow
def test_imported_recording_goes_through_recon_register(tmp_path):
    from recon_cli.cli import main
    from recon_cli.reconstruction.metadata import read_session

    imported = import_recording(_slambook(), tmp_path / "store")
    assert len(imported.scans) == 5
    session = read_session(tmp_path / "store")  # checked against schemas/session.schema.json
    assert session.backend == "hardware" and np.allclose(session.world_T_marker, np.eye(4))
    assert session.crop_box is not None and all(3.0 < s < 9.0 for s in session.crop_box.size)
    scan = ScanStore(tmp_path / "store").read(0)
    assert scan.joints == {} and scan.marker_T_camera is None
    assert np.allclose(scan.world_T_camera_fk, read_poses(SLAMBOOK / "pose.txt")[0])
    with pytest.raises(FileError, match="already holds scans"):
        import_recording(_slambook(), tmp_path / "store")
    out = tmp_path / "reg"
    code = main(["register", str(tmp_path / "store"), "--no-board", "--global-only", "--voxel", "0.02", "--depth",
                 "6", "--out", str(out)])
    assert code == 0
    report = json.loads((out / "report.json").read_text())
    assert report["scans_registered"] == 5 and report["pose_sources"]["kinematics"] == 5
    assert (out / "cloud.ply").stat().st_size > 100_000


@needs_slambook
@pytest.mark.slow
def test_replay_session_registers_and_reports_the_overlap_residual(tmp_path):
    """The recorded poses already agree to about a centimetre (median point-to-plane distance
    between consecutive frames; an inverted pose convention would give metres); the pose
    graph brings them closer still."""
    from recon_cli.workflows.replay import ReplayOptions, run_replay

    result = run_replay(ReplayOptions(_slambook(), tmp_path / "session", voxel=0.04))
    before, after = result.summary["before"], result.summary["after"]
    assert before["pairs"] == after["pairs"] == 4 and before["overlap"] > 0.3
    assert before["median_m"] < 0.02
    assert after["median_m"] < 0.8 * before["median_m"] and after["rms_m"] < before["rms_m"]
    assert result.picture.stat().st_size > 10_000
    data = json.loads(result.report.read_text())
    assert data["after"]["summary"]["median_m"] == after["median_m"] and len(data["corrections"]) == 5
    assert (tmp_path / "session" / "reconstruction" / "cloud.ply").exists()


@needs_slambook
def test_recon_replay_command(tmp_path, capsys):
    from recon_cli.cli import main

    code = main(["replay", str(SLAMBOOK), "--intrinsics", "518,519,325.5,253.5", "--voxel", "0.04",
                 "--out", str(tmp_path / "r")])
    out = capsys.readouterr().out
    assert code == 0, out
    assert "5 frames imported" in out and "overlap residual after registration" in out
    assert (tmp_path / "r" / "cloud.png").stat().st_size > 1000 and (tmp_path / "r" / "consistency.json").exists()
