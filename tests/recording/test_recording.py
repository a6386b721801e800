"""Recordings (--record, recon view): written headless, verified by rerun's own tools, read
back with rerun's reader, and what they must hold."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

rerun = pytest.importorskip("rerun", reason="recordings need the viz extra (pip install 'recon-scan[viz]')")

from recon_cli.cli import main  # noqa: E402
from recon_cli.paths import SCRIPTS_DIR  # noqa: E402
from recon_cli.recording.readback import summarize  # noqa: E402

MOVING_JOINTS = ("base_joint_1", "base_joint_2", *(f"arm_joint_{k}" for k in range(1, 8)))


def _verify(path: Path) -> None:
    """rerun's own check: the file loads and every chunk decodes (footers included)."""
    r = subprocess.run([sys.executable, "-m", "rerun", "rrd", "verify", str(path)], capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0, r.stdout + r.stderr


@pytest.fixture(scope="module")
def smoke_run(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("rec") / "smoke"
    assert main(["run", str(SCRIPTS_DIR / "smoke.xml"), "--out", str(out), "--record"]) == 0
    return out


def test_script_run_recording(smoke_run):
    path = smoke_run / "recording.rrd"
    _verify(path)
    s = summarize(path)
    report = json.loads((smoke_run / "run_report.json").read_text())
    moves = [c for c in report["commands"] if c["command"].startswith("move")]
    # the robot: every moving joint animated along the executed trajectories (25 Hz)
    assert set(s.joint_samples) >= set(MOVING_JOINTS)
    driven = sum(c["trajectory_s"] for c in moves)
    for name in MOVING_JOINTS:
        assert s.joint_samples[name] >= 25 * driven * 0.9
    assert s.time_range_s[1] >= driven
    assert s.moves == len(moves) == 4  # three views and home
    # N scans: N camera poses and N clouds; registration before/after, the mesh, distances
    assert s.scans == ["scan_0000", "scan_0001", "scan_0002"]
    assert s.camera_poses == 3 and s.clouds == 3 and s.registered == 3
    assert s.mesh and s.distances
    assert any(e.endswith("/camera/color/board/corners") for e in s.entities)  # board detections
    assert "/cell/recon_cell" in s.entities  # the cell from the URDF


def test_recording_readback_values(smoke_run):
    """The joints in the recording are those of the robot: when each scan was taken, every
    revolute joint's transform is the URDF joint's origin turned by the scan's reading."""
    import numpy as np
    from rerun.chunk import RrdReader
    from rerun.urdf import UrdfTree
    from scipy.spatial.transform import Rotation

    from recon_cli.reconstruction.scan_store import ScanStore
    from recon_cli.robot.description import expand_urdf

    samples: dict[str, list[tuple[int, list[float]]]] = {}
    scan_time: dict[int, int] = {}
    for chunk in RrdReader(smoke_run / "recording.rrd").stream():
        if chunk.is_static or "robot_time" not in chunk.timeline_names:
            continue
        batch = chunk.to_record_batch()
        times = batch.column("robot_time").cast("int64").to_pylist()
        if chunk.entity_path.startswith("/cell/joints/"):
            quats = batch.column("Transform3D:quaternion").to_pylist()
            samples.setdefault(chunk.entity_path.rsplit("/", 1)[1], []).extend(
                (t, q[0] if q and isinstance(q[0], list) else q) for t, q in zip(times, quats, strict=True))
        elif chunk.entity_path.startswith("/world/scans/") and chunk.entity_path.endswith("/camera"):
            scan_time[int(chunk.entity_path.split("/")[3].split("_")[1])] = times[0]
    urdf = smoke_run / "cell.urdf"
    urdf.write_text(expand_urdf())
    tree = UrdfTree.from_file_path(urdf)
    store = ScanStore(smoke_run / "scans")
    checked = 0
    for index in store.indices():
        scan = store.read(index)
        for name, value in scan.joints.items():
            joint = tree.get_joint_by_name(name)
            if joint.joint_type != "revolute":
                continue
            t, got = max((s for s in samples[name] if s[0] <= scan_time[index]), key=lambda s: s[0])
            expected = (Rotation.from_euler("xyz", joint.origin_rpy)
                        * Rotation.from_rotvec(np.asarray(joint.axis) * value)).as_quat()
            got = np.asarray(got, float)
            assert min(np.linalg.norm(got - expected), np.linalg.norm(got + expected)) < 1e-3, (index, name)
            checked += 1
    assert checked == 3 * 7


def test_autoscan_recording_has_iterations(tmp_path):
    out = tmp_path / "auto"
    assert main(["autoscan", "--n", "3", "--resolution", "0.2", "--object", "bottle", "--no-pictures",
                 "--out", str(out), "--record"]) == 0
    path = out / "recording.rrd"
    _verify(path)
    s = summarize(path)
    report = json.loads((out / "autoscan_report.json").read_text())
    assert s.camera_poses == s.clouds == report["scans"] == 3
    assert s.iterations == 2  # one ellipsoid per iteration after the initial scan
    assert {"/viewplan/views/completed", "/viewplan/views/active", "/viewplan/ellipsoid"} <= s.entities
    assert s.mesh and s.distances and s.registered == 3


def test_register_records_a_store(smoke_run, tmp_path):
    out = tmp_path / "reg"
    assert main(["register", str(smoke_run / "scans"), "--out", str(out), "--record"]) == 0
    s = summarize(out / "recording.rrd")
    assert s.camera_poses == s.clouds == s.registered == 3
    assert s.mesh and s.distances
    assert len(s.joint_samples) >= len(MOVING_JOINTS)  # the robot at each scan's joint readings


def test_view_without_display_says_how(smoke_run, capsys, monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    assert main(["view", str(smoke_run)]) == 0
    out = capsys.readouterr().out
    assert "recording.rrd: 3 scans, 4 moves" in out
    assert "no display here" in out and "--web" in out


def test_view_of_a_folder_without_recording(tmp_path, capsys):
    assert main(["view", str(tmp_path)]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "holds no recording" in err and "--record" in err


def test_record_without_rerun_is_one_line(tmp_path):
    """Without the extra, --record stops before anything runs, with the install hint."""
    out = tmp_path / "run"
    code = ("import sys; sys.modules['rerun'] = None\n"
            "from recon_cli.cli import main\n"
            f"sys.exit(main(['run', {str(SCRIPTS_DIR / 'smoke.xml')!r}, '--out', {str(out)!r}, '--record']))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                       env={**os.environ, "MUJOCO_GL": "egl"})
    assert r.returncode == 1
    assert r.stderr.strip().count("\n") == 0 and "pip install 'recon-scan[viz]'" in r.stderr
    assert not out.exists()
