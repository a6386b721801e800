"""Station files and `recon run --station` end to end: the robot over ADS (pyads' test
server with the stand-in PLC program) and the simulated sensor rendered at the joints the
PLC measures; a PLC fault in the middle of a run stops it and keeps the completed scans."""

from __future__ import annotations

import json
import os
import signal
import textwrap
import threading
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pyads", reason="the ADS adapter needs pyads (pip install 'recon-scan[ads]')")

from recon_cli.backends.station_file import load_station  # noqa: E402
from recon_cli.cli import main  # noqa: E402
from recon_cli.errors import InputError  # noqa: E402
from recon_cli.robot.cell import Cell  # noqa: E402
from recon_cli.robot.description import CellConfig  # noqa: E402
from recon_cli.robot.poses import named_configuration  # noqa: E402

from .plc_standin import NC_FOLLOWING_ERROR, PLCStandIn  # noqa: E402

STATION = """\
format: 1
name: stand-in cell
cell: {kind: gantry, safety_distance: 0.03}
robot:
  adapter: ads
  ads: {ams_net_id: 127.0.0.1.1.1, ip: 127.0.0.1, port: 851, poll: 0.005, timeout: 1.0, watchdog: 2.0,
        time_margin: 2.0, settle_timeout: 1.0}
camera:
  adapter: sim
  sim: {noise: true, resolution: 0.25}
"""

SCRIPT = """\
<?xml version="1.0"?>
<recon name="station" on_failure="skip">
  <cell kind="gantry" backend="hardware"/>
  <object name="bottle"/>
  <move focus="0 0 0.8" radius="0.6" theta="60" phi="0"/>
  <scan name="a"/>
  <move focus="0 0 0.8" radius="0.6" theta="60" phi="120"/>
  <scan name="b"/>
  <move focus="0 0 0.8" radius="0.6" theta="45" phi="240"/>
  <scan name="c"/>
  <register/>
  <reconstruct voxel="0.002" depth="7"/>
  <export mesh="mesh.ply"/>
</recon>
"""


@pytest.fixture()
def plc():
    cell = Cell(CellConfig())
    start = named_configuration(cell.config.kind, "home", cell.joint_names)
    stand_in = PLCStandIn(len(cell.joint_names), start, speedup=10.0).start()
    yield stand_in
    stand_in.close()
    assert stand_in.crash is None, stand_in.crash


def _when(condition, action, timeout: float = 120.0) -> threading.Thread:
    """Run ``action`` (in a thread) as soon as ``condition()`` holds."""

    def watch():
        deadline = time.monotonic() + timeout
        while not condition():
            if time.monotonic() > deadline:
                return
            time.sleep(0.002)
        action()

    thread = threading.Thread(target=watch, daemon=True)
    thread.start()
    return thread


@pytest.fixture()
def files(tmp_path):
    (tmp_path / "cell.yaml").write_text(STATION)
    (tmp_path / "scan.xml").write_text(SCRIPT)
    return tmp_path / "cell.yaml", tmp_path / "scan.xml"


def test_station_check(plc, files, capsys):
    station, _ = files
    assert main(["station", "check", str(station)]) == 0
    out = capsys.readouterr().out
    assert "robot ads, camera sim" in out and "base_joint_1 -1.0000 m" in out
    assert "frame: 400 x 300 px" in out and "station ok" in out


def test_run_with_station_end_to_end(plc, files, tmp_path, capsys):
    station, script = files
    out = tmp_path / "run"
    code = main(["run", str(script), "--out", str(out), "--station", str(station)])
    text = capsys.readouterr()
    assert code == 0, text.out + text.err + str(plc.crash)
    assert plc.started == 3  # three moves through the PLC
    scans = sorted((out / "scans").glob("scan_*/scan.json"))
    assert [json.loads(s.read_text())["name"] for s in scans] == ["a", "b", "c"]
    session = json.loads((out / "scans" / "session.json").read_text())
    assert session["backend"] == "hardware" and not (out / "scans" / "ground_truth").exists()
    assert (out / "mesh.ply").stat().st_size > 10_000
    report = json.loads((out / "run_report.json").read_text())
    assert report["status"] == "done" and report["backend"] == "hardware", report
    # the last scan was taken where the PLC says the robot is
    assert np.allclose(plc.measured, np.array(list(json.loads(scans[-1].read_text())["joints"].values())),
                       atol=1e-3)


def test_plc_fault_mid_run_stops_and_keeps_scans(plc, files, tmp_path, capsys):
    station, script = files
    plc.faults.fault_at, plc.faults.motion = 0.5, 2
    out = tmp_path / "run"
    code = main(["run", str(script), "--out", str(out), "--station", str(station)])
    err = capsys.readouterr().err
    assert code == 4 and err.count("\n") == 1 and "Traceback" not in err
    assert f"the PLC reports fault {NC_FOLLOWING_ERROR}" in err and "the robot was stopped" in err
    assert len(list((out / "scans").glob("scan_*/scan.json"))) == 1  # the scan before the fault is kept
    report = json.loads((out / "run_report.json").read_text())
    assert report["status"] == "aborted" and "PLC reports fault" in report["aborted"]
    assert plc.get("stop", "B")[0] == 1


def test_station_file_names_a_cell_file_beside_it(tmp_path, capsys):
    """`cell: {kind: FILE.yaml}`: a cell file relative to the station file; a mistake in that
    file is its own one line with file:line."""
    from recon_cli.paths import CELLS_DIR

    text = (CELLS_DIR / "gantry.yaml").read_text().replace("../robot/", "")  # found in recon's robot/
    (tmp_path / "cells").mkdir()
    (tmp_path / "cells" / "lab.yaml").write_text(text.replace("name: gantry", "name: lab gantry"))
    path = tmp_path / "station.yaml"
    path.write_text(STATION.replace("cell: {kind: gantry, safety_distance: 0.03}", "cell: {kind: cells/lab.yaml}"))
    station = load_station(path)
    assert station.cell.name == "lab gantry" and station.cell.safety_distance == 0.03
    assert station.cell.cell_file.planning_joints == CellConfig().cell_file.planning_joints
    (tmp_path / "cells" / "lab.yaml").write_text(text.replace("flange: arm_link_7", "flange: arm_link_77"))
    assert main(["station", "check", str(path)]) == 1
    err = capsys.readouterr().err
    assert err.startswith(f"error: {tmp_path / 'cells' / 'lab.yaml'}:") and err.count("\n") == 1, err
    assert "arm_link_77" in err


@pytest.mark.parametrize("text, message", [
    ("format: 1\nrobot: {adapter: ads}\n", "no camera section"),
    ("format: 1\nrobot: {adapter: kuka}\ncamera: {adapter: sim}\n",
     "robot.adapter is not one of ads, franka, sim"),
    ("format: 1\nrobot: {adapter: sim}\ncamera: {adapter: sim}\nspeed: 3\n", "speed is not a known key"),
    ("format: 1\nrobot: {adapter: ads, ads: {poll: -1}}\ncamera: {adapter: sim}\n", "robot.ads.poll = -1 s is outside"),
    ("format: 1\nrobot: [adapter\n", r"station.yaml:3: not valid YAML \(did not find expected ',' or ']'"),
    ("format: 1\nhand_eye: [[1, 0], [0, 1]]\nrobot: {adapter: sim}\ncamera: {adapter: sim}\n",
     "hand_eye has 2 items, 4 expected"),
    ("format: 1\nhand_eye: [[2, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]\nrobot: {adapter: sim}\n"
     "camera: {adapter: sim}\n", "not a rigid 4 x 4 transform"),
    ("format: 1\njoint_offsets: [0, 0, 2, 0, 0, 0, 0, 0, 0]\nrobot: {adapter: ads}\ncamera: {adapter: sim}\n",
     r"station.yaml:2: joint_offsets\[2\] = 2 deg \(or mm\) is outside \[-1, 1\]"),
    ("format: 1\njoint_offsets: [0, 0.5, 0]\nrobot: {adapter: ads}\ncamera: {adapter: sim}\n",
     r"station.yaml:2: joint_offsets has 3 numbers; the cell has 9 joints \(base_joint_1, "),
    ("format: 1\njoint_offsets: [0, 0, 0, 0, 0, 0, 0, 0, 0.5]\nrobot: {adapter: sim}\ncamera: {adapter: sim}\n",
     "joint_offsets correct the joints a real robot reports; the sim robot adapter is a simulation"),
])
def test_station_file_errors_are_one_line(text, message, tmp_path, capsys):
    path = tmp_path / "station.yaml"
    path.write_text(textwrap.dedent(text))
    with pytest.raises(InputError, match=message):
        load_station(path)
    assert main(["station", "check", str(path)]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err


def test_hardware_without_station_says_what_to_do(files, tmp_path, capsys):
    _, script = files
    assert main(["run", str(script), "--out", str(tmp_path / "r")]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "scan.xml:3: the hardware backend needs a station file" in err
    assert "--station" in err and not (tmp_path / "r").exists()


def test_station_check_ads_and_software_gentl_camera(plc, tmp_path, monkeypatch, capsys):
    """`recon station check` against both stand-ins: the ADS robot (pyads test server) and the
    genicam package's software GenTL producer."""
    pytest.importorskip("harvesters", reason="the GenICam adapter needs harvesters (recon-scan[genicam])")
    from .test_cameras import _producer

    cti = _producer()
    if cti is None:
        pytest.skip("the genicam package's software producer is not installed")
    monkeypatch.setenv("GENICAM_GENTL64_PATH", str(Path(cti).parent))
    path = tmp_path / "cell.yaml"
    path.write_text(STATION.split("camera:")[0] + 'camera:\n  adapter: genicam\n  genicam: {serial: "2", timeout: 5}\n')
    assert main(["station", "check", str(path)]) == 0
    out = capsys.readouterr().out
    assert "robot ads, camera genicam" in out and "base_joint_1 -1.0000 m" in out
    assert "frame: 400 x 400 px" in out and "station ok" in out


def test_robot_that_never_settles_ends_the_run_before_its_scan(plc, files, tmp_path, capsys):
    """The second move ends 0.01 rad off its goal: no scan there, the robot stopped, exit 4,
    the first scan kept."""
    station, script = files
    plc.faults.settle_offset, plc.faults.motion = 0.01, 2
    out = tmp_path / "run"
    code = main(["run", str(script), "--out", str(out), "--station", str(station)])
    err = capsys.readouterr().err
    assert code == 4 and err.count("\n") == 1 and "Traceback" not in err, err
    assert "the robot did not settle at the goal within 1 s (final error arm_joint_7 0.01 rad" in err
    assert "no scan was taken; the robot was stopped (confirmed by the PLC after" in err
    assert [json.loads(s.read_text())["name"] for s in (out / "scans").glob("scan_*/scan.json")] == ["a"]
    report = json.loads((out / "run_report.json").read_text())
    assert report["status"] == "aborted" and "did not settle" in report["aborted"]
    assert plc.get("stop", "B")[0] == 1 and plc.started == 2


def test_drive_that_keeps_swinging_ends_the_run_with_a_settle_fault(plc, files, tmp_path, capsys):
    """At the end of the second move the last axis swings around its goal (10 x the settle
    tolerance, passing through it twice a period) for longer than the settle timeout: the run
    ends with the settle fault before that scan (exit 4), the robot stopped, the first scan
    kept, the report aborted."""
    station, script = files
    plc.faults.oscillate, plc.faults.motion = (0.002, 10.0), 2
    out = tmp_path / "run"
    code = main(["run", str(script), "--out", str(out), "--station", str(station)])
    err = capsys.readouterr().err
    assert code == 4 and err.count("\n") == 1 and "Traceback" not in err, err
    assert "the robot did not settle at the goal within 1 s (" in err and "no scan was taken" in err, err
    assert [json.loads(s.read_text())["name"] for s in (out / "scans").glob("scan_*/scan.json")] == ["a"], err
    report = json.loads((out / "run_report.json").read_text())
    assert report["status"] == "aborted" and "did not settle" in report["aborted"]
    assert plc.get("stop", "B")[0] == 1 and plc.started == 2


def test_connection_loss_mid_run_says_what_happened(plc, files, tmp_path, capsys):
    """The network goes away during the second move and stays away: one line that says the
    stop could not be confirmed (and nothing about a stopped robot); the PLC's watchdog stops
    the axes within `watchdog` (2 s, + a poll and two PLC cycles, in robot time / speedup)."""
    station, script = files
    _when(lambda: plc.started == 2, plc.drop_connection)
    out = tmp_path / "run"
    code = main(["run", str(script), "--out", str(out), "--station", str(station)])
    err = capsys.readouterr().err
    assert code == 4 and err.count("\n") == 1 and "Traceback" not in err, err
    assert "lost the connection to the PLC" in err and "robot was stopped" not in err
    assert "the stop could not be confirmed within 2 s; the PLC watchdog stops the axes after 2 s without a " \
           "heartbeat" in err
    assert len(list((out / "scans").glob("scan_*/scan.json"))) == 1
    dropped, _ = plc.event("dropped")
    assert plc.last_motion() - dropped <= (2.0 + 0.005 + 0.004) * plc.speedup


def test_sigterm_mid_move_stops_the_robot_and_keeps_scans(plc, files, tmp_path, capsys):
    """SIGTERM during the second move: the robot is stopped before the run ends (exit 143),
    the first scan is kept and the report says what was interrupted; the axes stop within
    0.1 s (x speedup in robot time) of the signal."""
    station, script = files

    def terminate():
        time.sleep(0.05)
        plc.mark("signal")
        os.kill(os.getpid(), signal.SIGTERM)

    _when(lambda: plc.started == 2, terminate)
    out = tmp_path / "run"
    code = main(["run", str(script), "--out", str(out), "--station", str(station)])
    err = capsys.readouterr().err
    assert code == 143 and err.count("\n") == 1 and "interrupted by SIGTERM" in err, err
    assert plc.event("stopped by stop") is not None and plc.event("done") is not None  # move 1 done
    sent, _ = plc.event("signal")
    assert 0 <= plc.last_motion() - sent <= 0.1 * plc.speedup and plc.started == 2
    assert len(list((out / "scans").glob("scan_*/scan.json"))) == 1
    report = json.loads((out / "run_report.json").read_text())
    assert "SIGTERM" in report["aborted"]


def test_station_check_refuses_a_nan_measurement(plc, files, capsys):
    station, _ = files
    plc.faults.garbage_at, plc.faults.measured_axis, plc.faults.measured_value = 0.0, 2, float("nan")
    time.sleep(0.02)
    assert main(["station", "check", str(station)]) == 4
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert "the PLC reports the measured position of arm_joint_1 (axis 2) as nan, not a finite number" in err
    assert plc.get("stop", "B")[0] == 1


def test_run_checks_the_station_before_the_first_move(files, tmp_path, capsys):
    """`recon run --station` runs the check of `recon station check` first: a robot standing
    outside its soft limits (inside the hard ones) is refused with one line, and the PLC has
    not been asked to move."""
    station, script = files
    cell = Cell(CellConfig())
    start = named_configuration(cell.config.kind, "home", cell.joint_names).copy()
    j = cell.joint_names.index("arm_joint_2")
    start[j] = cell.kin.limits.soft_upper[j] + 0.05
    assert start[j] < cell.kin.limits.upper[j]
    stand_in = PLCStandIn(len(cell.joint_names), start, speedup=10.0).start()
    try:
        out = tmp_path / "run"
        code = main(["run", str(script), "--out", str(out), "--station", str(station)])
        err = capsys.readouterr().err
        assert code == 1 and err.count("\n") == 1 and "Traceback" not in err, err
        assert f"station {station}: the measured joints arm_joint_2 are outside their soft limits; nothing was " \
               "moved" in err
        assert stand_in.started == 0 and not (out / "scans" / "session.json").exists()
    finally:
        stand_in.close()
    assert stand_in.crash is None, stand_in.crash


def test_run_refuses_a_station_it_cannot_reach(files, tmp_path, capsys):
    """No PLC listening: the check before the run cannot connect; one line, exit 1 (as
    `recon station check`), nothing written into the scan store."""
    station, script = files
    out = tmp_path / "run"
    code = main(["run", str(script), "--out", str(out), "--station", str(station)])
    err = capsys.readouterr().err
    assert code == 1 and err.count("\n") == 1 and "cannot reach the PLC" in err, err
    assert not (out / "scans" / "session.json").exists()
