"""A hand-eye result written into a station file: only the hand_eye block changes, the file
stays valid, and the cell description (so the kinematics) then carries the calibrated mount."""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from recon_cli.backends.station_file import load_station
from recon_cli.calibration.station_update import hand_eye_block, replace_hand_eye, write_station_hand_eye
from recon_cli.errors import InputError
from recon_cli.geometry.transforms import invert, pose_error
from recon_cli.robot.cell import Cell
from recon_cli.robot.description import CellConfig

STATION = """\
format: 1
name: test cell   # a comment that must survive
cell: {kind: gantry, safety_distance: 0.03}
hand_eye:                   # the old calibration
  - [1, 0, 0, 0.1]
  - [0, 1, 0, 0.0]

  - [0, 0, 1, 0.0]
  - [0, 0, 0, 1]

robot:
  adapter: sim
camera:
  adapter: sim
  sim: {noise: false, resolution: 0.25}
"""


def _calibrated() -> np.ndarray:
    """The description's mount moved by 5 mm and 1 deg."""
    cell = Cell(CellConfig())
    q0 = cell.kin.neutral()
    X = invert(cell.kin.frame_pose(q0, "arm_link_7")) @ cell.kin.world_T_camera(q0)
    E = np.eye(4)
    E[:3, :3] = Rotation.from_rotvec(np.radians([0.6, -0.5, 0.6])).as_matrix()
    E[:3, 3] = [0.003, -0.004, 0.0]
    return X @ E


def test_only_the_block_is_replaced():
    new = replace_hand_eye(STATION, hand_eye_block(np.eye(4), "new"))
    assert "a comment that must survive" in new and "the old calibration" not in new
    assert new.count("hand_eye:") == 1 and "\nrobot:\n  adapter: sim" in new
    assert "  - [0, 0, 0, 1]\n\nrobot:" in new  # the blank line before the next key stays
    without = STATION.replace(STATION[STATION.index("hand_eye:"):STATION.index("robot:")], "")
    assert replace_hand_eye(without, hand_eye_block(np.eye(4))).rstrip().endswith("- [0, 0, 0, 1]")
    flow = "format: 1\nhand_eye: [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]\nrobot: {adapter: sim}\n"
    data = yaml.safe_load(replace_hand_eye(flow, hand_eye_block(2 * np.eye(4))))
    assert data["hand_eye"][0] == [2, 0, 0, 0] and data["robot"] == {"adapter": "sim"}


def test_written_hand_eye_feeds_the_kinematics(tmp_path):
    path = tmp_path / "cell.yaml"
    path.write_text(STATION)
    X = _calibrated()
    backup = write_station_hand_eye(path, X, "recon calibrate handeye, test")
    assert backup.read_text() == STATION
    station = load_station(path)
    assert np.allclose(np.reshape(station.cell.flange_T_camera, (4, 4)), X, atol=1e-9)
    cell = Cell(station.cell)
    for q in (cell.kin.neutral(), cell.limits.sample_soft(np.random.default_rng(0))):
        flange_T_camera = invert(cell.kin.frame_pose(q, "arm_link_7")) @ cell.kin.world_T_camera(q)
        dt, dr = pose_error(flange_T_camera, X)
        assert dt < 1e-8 and dr < 1e-8
    assert "name: test cell   # a comment that must survive" in path.read_text()


def test_a_bad_transform_leaves_the_file_alone(tmp_path):
    path = tmp_path / "cell.yaml"
    path.write_text(STATION)
    bad = np.eye(4)
    bad[0, 0] = 2.0
    with pytest.raises(InputError, match="not a rigid 4 x 4 transform"):
        write_station_hand_eye(path, bad)
    assert path.read_text() == STATION and not (tmp_path / "cell.yaml.bak").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cell.yaml"]
