"""Station capabilities: what a station declares (composed from its adapters' entries in the
registry) decides what a session writes and what commands do. A station of simulated parts
only is a simulation everywhere; a replay station is not, and has nothing to wait for; a
station that fails its check is refused before anything moves."""

from __future__ import annotations

import json
import time

import numpy as np
import pytest

from recon_cli.backends.adapters import CAMERA_ADAPTERS, ROBOT_ADAPTERS, station_capabilities
from recon_cli.backends.base import Backend, Capabilities, Station
from recon_cli.backends.hardware.station import AdapterStation
from recon_cli.backends.station_file import load_station
from recon_cli.cli import main
from recon_cli.geometry.view import View
from recon_cli.perception.camera_model import Intrinsics
from recon_cli.reconstruction.scan_store import Scan, ScanStore
from recon_cli.robot.cell import Cell
from recon_cli.robot.ik import IKOptions
from recon_cli.robot.poses import named_configuration

ALL_SIM = ("format: 1\nname: all sim\nrobot: {adapter: sim}\n"
           "camera:\n  adapter: sim\n  sim: {noise: false, resolution: 0.25}\n")

SCRIPT = """\
<?xml version="1.0"?>
<recon name="caps">
  <cell kind="gantry" backend="hardware"/>
  <object name="bottle"/>
  <wait seconds="30"/>
  <move focus="0 0 0.8" radius="0.6" theta="60" phi="0"/>
  <scan name="a"/>
</recon>
"""


def _replay_station(tmp_path, depth: float) -> tuple:
    """A station file of the simulated robot and a replay camera over a store of two 32 x 24
    scans whose depth is ``depth`` [m] (0: no depth at all)."""
    root = tmp_path / "recorded"
    store = ScanStore.create(root, {"backend": "hardware"})
    K = Intrinsics(32, 24, 30.0, 30.0, 15.5, 11.5)
    v, u = np.mgrid[0:24, 0:32]
    frames = []
    for k in range(2):
        d = np.where(u > 3, depth + 0.01 * k + 0.002 * u, 0.0) if depth > 0 else np.zeros((24, 32))
        color = np.stack([u * 8, v * 10, np.full_like(u, 40 * k)], axis=2).astype(np.uint8)
        store.write(Scan(k, color, d, K, {"j1": 0.0}, np.eye(4), {}), depth_scale=10000.0)
        frames.append(d)
    path = tmp_path / "replay.yaml"
    path.write_text(f"format: 1\nname: replay\nrobot: {{adapter: sim}}\ncamera:\n  adapter: replay\n"
                    f"  replay: {{source: {root}}}\n")
    return path, frames


def _run(tmp_path, station, capsys) -> tuple[int, str, dict | None, float]:
    script = tmp_path / "scan.xml"
    script.write_text(SCRIPT)
    out = tmp_path / "run"
    t0 = time.perf_counter()
    code = main(["run", str(script), "--out", str(out), "--station", str(station)])
    seconds = time.perf_counter() - t0
    err = capsys.readouterr().err
    report = out / "run_report.json"
    return code, err, json.loads(report.read_text()) if report.exists() else None, seconds


@pytest.mark.parametrize("robot, camera, expected", [
    ("sim", "sim", Capabilities(simulated=True, ground_truth=True, cover_board=True)),
    ("ads", "sim", Capabilities(simulated=False, cover_board=True, wall_clock=True)),
    ("sim", "replay", Capabilities(simulated=False)),
    ("sim", "genicam", Capabilities(simulated=False, wall_clock=True)),
    ("ads", "realsense", Capabilities(simulated=False, wall_clock=True)),
])
def test_station_capabilities_are_composed_from_the_registry(robot, camera, expected):
    caps = station_capabilities(ROBOT_ADAPTERS[robot], CAMERA_ADAPTERS[camera])
    assert caps == expected
    assert caps.backend is (Backend.SIM if robot == camera == "sim" else Backend.HARDWARE)
    assert caps.backend.value in ("sim", "hardware")  # the values session.json holds


def test_registry_names_are_the_station_file_choices(tmp_path):
    assert tuple(ROBOT_ADAPTERS) == ("ads", "franka", "sim")
    assert tuple(CAMERA_ADAPTERS) == ("sim", "genicam", "realsense", "replay")
    path = tmp_path / "s.yaml"
    path.write_text("format: 1\nrobot: {adapter: sim}\ncamera: {adapter: sim}\n")
    station = load_station(path)
    assert type(station.robot).__name__ == "SimRobotConfig" and station.camera.resolution == 1.0
    assert station.capabilities.backend is Backend.SIM


def test_sim_station_declares_its_capabilities_and_covers_the_board():
    from recon_cli.backends.sim.scene import BOARD_PRINT_NAME, mujoco
    from recon_cli.backends.sim.station import SimStation
    from recon_cli.robot.description import CellConfig

    cell = Cell(CellConfig())
    home = named_configuration(cell.config.kind, "home", cell.joint_names)
    with SimStation(cell, None, home, np.random.default_rng(0), noise=False, resolution=0.1) as station:
        assert isinstance(station, Station) and station.backend is Backend.SIM
        assert station.capabilities == Capabilities(simulated=True, ground_truth=True, cover_board=True,
                                                    realism=True)
        model = station.scene.model
        gid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, BOARD_PRINT_NAME)
        printed = int(model.geom_matid[gid])
        station.cover_board(True)
        assert model.geom_matid[gid] == -1 and np.allclose(model.geom_rgba[gid], [0.6, 0.6, 0.6, 1.0])
        station.cover_board(False)
        assert model.geom_matid[gid] == printed >= 0


def test_all_sim_station_knows_the_truth_and_covers_the_board(tmp_path):
    path = tmp_path / "allsim.yaml"
    path.write_text(ALL_SIM)
    sf = load_station(path)
    cell = Cell(sf.cell)
    home = named_configuration(cell.config.kind, "home", cell.joint_names)
    board = cell.world_T_marker[:3, 3] + np.array([0.15, 0.1, 0.0])  # inside the printed board
    q = cell.solve_view(View(tuple(board), 0.6, 0.0, 0.0), np.random.default_rng(0),
                        options=IKOptions(max_solutions=1)).solutions[0].q
    with AdapterStation(sf, cell, None, home, np.random.default_rng(0)) as station:
        assert station.capabilities.ground_truth and station.backend is Backend.SIM
        station.robot.reset(q)  # looking down at the board
        shown = station.camera.capture().color.astype(float)
        truth = station.ground_truth()
        assert np.allclose(truth["world_T_camera"], cell.kin.world_T_camera(q), atol=1e-6)
        assert np.allclose(list(truth["joints"].values()), q)
        station.cover_board(True)
        covered = station.camera.capture().color.astype(float)
        station.cover_board(False)
        again = station.camera.capture().color.astype(float)
    assert np.abs(covered - shown).mean() > 5.0  # the printed board is gone ...
    assert np.array_equal(again, shown)  # ... and back


def test_replay_station_has_no_truth_and_cannot_cover_the_board(tmp_path):
    path, _ = _replay_station(tmp_path, 0.6)
    sf = load_station(path)
    cell = Cell(sf.cell)
    home = named_configuration(cell.config.kind, "home", cell.joint_names)
    with AdapterStation(sf, cell, None, home, np.random.default_rng(0)) as station:
        assert station.backend is Backend.HARDWARE and station.ground_truth() is None
        with pytest.raises(NotImplementedError, match="cannot cover the board"):
            station.cover_board(True)


def test_all_sim_station_file_is_a_simulation_everywhere(tmp_path, capsys):
    station = tmp_path / "allsim.yaml"
    station.write_text(ALL_SIM)
    assert main(["station", "check", str(station)]) == 0
    assert "robot sim, camera sim, cell gantry, backend sim" in capsys.readouterr().out
    code, err, report, seconds = _run(tmp_path, station, capsys)
    assert code == 0, err
    scans = tmp_path / "run" / "scans"
    assert json.loads((scans / "session.json").read_text())["backend"] == "sim"
    assert report["backend"] == "sim" and report["status"] == "done"
    assert "backend: sim" in (tmp_path / "run" / "config.yaml").read_text()
    assert (scans / "ground_truth" / "bottle.ply").stat().st_size > 10_000  # the exact mesh, for evaluation
    scan = ScanStore(scans).read(0)
    assert scan.ground_truth["object"] == "bottle"
    assert np.allclose(scan.ground_truth["world_T_camera"], scan.world_T_camera_fk, atol=1e-4)
    wait = next(c for c in report["commands"] if c["command"].startswith("wait"))
    assert "no wall-clock wait" in wait["message"] and seconds < 30


def test_replay_station_run_is_hardware_and_starts_at_the_first_frame(tmp_path, capsys):
    """The station check before the run grabs a frame through its own connection: the run's
    first scan is still the recording's first frame. Nothing physical: no wall-clock wait."""
    station, frames = _replay_station(tmp_path, 0.6)
    code, err, report, seconds = _run(tmp_path, station, capsys)
    assert code == 0, err
    scans = tmp_path / "run" / "scans"
    assert json.loads((scans / "session.json").read_text())["backend"] == "hardware"
    assert report["backend"] == "hardware" and not (scans / "ground_truth").exists()
    scan = ScanStore(scans).read(0)
    assert scan.ground_truth is None
    assert np.allclose(scan.depth, frames[0], atol=1e-4)
    wait = next(c for c in report["commands"] if c["command"].startswith("wait"))
    assert "no wall-clock wait" in wait["message"] and seconds < 30


def test_run_refuses_a_station_whose_check_fails_before_anything_moves(tmp_path, capsys):
    station, _ = _replay_station(tmp_path, 0.0)
    code, err, report, _ = _run(tmp_path, station, capsys)
    assert code == 1 and err.count("\n") == 1 and "Traceback" not in err
    assert f"station {station}: the camera's frame has no depth; nothing was moved" in err
    assert not (tmp_path / "run" / "scans" / "session.json").exists()
    assert main(["station", "check", str(station)]) == 1  # the same check, the same refusal
    assert "the camera's frame has no depth" in capsys.readouterr().err


def test_autoscan_measures_accuracy_only_where_the_truth_is_known(tmp_path):
    """The same small autoscan on a station of simulated parts (ground truth: coverage and
    signed distances) and with a camera replaying those scans (no ground truth: none)."""
    from recon_cli.config import DEFAULTS, SceneConfig, SensorConfig, ViewPlanConfig
    from recon_cli.workflows.autoscan import Autoscan, AutoscanOptions

    config = DEFAULTS.replace(scene=SceneConfig("bottle"), seed=1, sensor=SensorConfig(resolution=0.25),
                              viewplan=ViewPlanConfig(n=3))
    station = tmp_path / "allsim.yaml"
    station.write_text(ALL_SIM)
    sim = Autoscan(AutoscanOptions(tmp_path / "a", config, mesh=False, pictures=False, page=False,
                                   station=station)).run()
    assert sim.scans == 3 and sim.coverage > 0.3 and abs(sim.accuracy.mean_mm) < 1.0
    assert json.loads((tmp_path / "a" / "session.json").read_text())["backend"] == "sim"
    replay = tmp_path / "replay.yaml"
    replay.write_text(f"format: 1\nrobot: {{adapter: sim}}\ncamera:\n  adapter: replay\n"
                      f"  replay: {{source: {tmp_path / 'a'}}}\n")
    recorded = Autoscan(AutoscanOptions(tmp_path / "b", config, mesh=False, pictures=False, page=False,
                                        station=replay)).run()
    assert recorded.scans == 3 and recorded.cloud.exists()
    assert recorded.coverage is None and recorded.accuracy is None
    assert json.loads((tmp_path / "b" / "session.json").read_text())["backend"] == "hardware"
