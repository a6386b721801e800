"""The shipped lab cells: a Franka Research 3 with a RealSense D405 (cells/fr3.yaml) and a
UR5e with a RealSense D435 (cells/ur5e.yaml), each on a lab table with the ChArUco board.

Checked against the vendors' published data (DH tables, limits, masses), not against the
description itself: forward kinematics against our own DH implementations, the home poses
(free, inside the soft limits, the board in view), and how many views around each cell's
object spot recon's IK reaches at the camera's scan distance.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml

from recon_cli.errors import ReconError
from recon_cli.geometry.view import View
from recon_cli.paths import ROBOT_DIR
from recon_cli.robot.cell import Cell
from recon_cli.robot.description import CellConfig
from recon_cli.robot.ik import IKOptions

PI = math.pi
# Franka's modified (Craig) DH table of the FR3 (frankaemika/docs control_parameters.rst):
# rows (a [m], d [m], alpha [rad]) of joints 1-7 and the flange (theta = 0)
FR3_DH = [(0.0, 0.333, 0.0), (0.0, 0.0, -PI / 2), (0.0, 0.316, PI / 2), (0.0825, 0.0, PI / 2),
          (-0.0825, 0.384, -PI / 2), (0.0, 0.0, PI / 2), (0.088, 0.0, PI / 2)]
FR3_FLANGE_D = 0.107
# UR's standard DH table of the UR5e (universal-robots.com, "DH parameters for calculations of
# kinematics and dynamics"): rows (a [m], d [m], alpha [rad]); masses [kg] and centres of mass
# [m] in DH frame i
UR5E_DH = [(0.0, 0.1625, PI / 2), (-0.425, 0.0, 0.0), (-0.3922, 0.0, 0.0), (0.0, 0.1333, PI / 2),
           (0.0, 0.0997, -PI / 2), (0.0, 0.0996, 0.0)]
UR5E_MASS = [3.761, 8.058, 2.846, 1.37, 1.3, 0.365]
UR5E_COM = [(0, -0.02561, 0.00193), (0.2125, 0, 0.11336), (0.15, 0.0, 0.0265), (0, -0.0018, 0.01634),
            (0, 0.0018, 0.01634), (0, 0, -0.001159)]
# FR3 joint space limits (Franka FCI documentation, control-parameters-joint-fr3.csv)
FR3_Q_MIN = [-2.7437, -1.7837, -2.9007, -3.0421, -2.8065, 0.5445, -3.0159]
FR3_Q_MAX = [2.7437, 1.7837, 2.9007, -0.1518, 2.8065, 4.5169, 3.0159]
FR3_DQ_MAX = [2.62, 2.62, 2.62, 2.62, 5.26, 4.18, 5.26]
FR3_TAU_MAX = [87, 87, 87, 87, 12, 12, 12]

THETAS = (20.0, 35.0, 50.0, 65.0)  # polar angles of the reachability views [deg]
AZIMUTHS = 12
FOCUS_HEIGHT = 0.08  # [m] the object centre above the object spot
#: share of the 48 views solved, measured 2026-11 (47/48 and 42/48; 46-47 and 42-44 over four
#: random streams); the floors are a few points below
MIN_SHARE = {"fr3": 0.90, "ur5e": 0.85}


def _rx(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]])


def _rz(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])


def _trans(x: float = 0.0, y: float = 0.0, z: float = 0.0) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = (x, y, z)
    return T


def fr3_dh_flange(q: np.ndarray) -> np.ndarray:
    """base_T_flange of the FR3 by Craig's convention: Rx(alpha) Tx(a) Rz(theta) Tz(d) per joint."""
    T = np.eye(4)
    for (a, d, alpha), theta in zip(FR3_DH, q, strict=True):
        T = T @ _rx(alpha) @ _trans(x=a) @ _rz(theta) @ _trans(z=d)
    return T @ _trans(z=FR3_FLANGE_D)


def ur5e_dh_frames(q: np.ndarray) -> list[np.ndarray]:
    """base_T_i (DH frames 1..6) of the UR5e, standard DH: Rz(theta) Tz(d) Tx(a) Rx(alpha)."""
    T, frames = np.eye(4), []
    for (a, d, alpha), theta in zip(UR5E_DH, q, strict=True):
        T = T @ _rz(theta) @ _trans(z=d) @ _trans(x=a) @ _rx(alpha)
        frames.append(T)
    return frames


@pytest.fixture(scope="module")
def cells() -> dict[str, Cell]:
    return {kind: Cell(CellConfig(kind=kind)) for kind in ("fr3", "ur5e")}


def _random_q(cell: Cell, rng: np.random.Generator) -> np.ndarray:
    return rng.uniform(cell.limits.lower, cell.limits.upper)


def _sensor(cell: Cell) -> dict:
    with open(cell.config.cell_file.sensor_file, encoding="utf-8") as f:
        return yaml.safe_load(f)


def _board(cell: Cell) -> dict:
    with open(cell.config.cell_file.board_file, encoding="utf-8") as f:
        return yaml.safe_load(f)


# ----------------------------------------------------------------------------- kinematics
def test_fr3_forward_kinematics_is_franka_dh(cells: dict[str, Cell]) -> None:
    cell = cells["fr3"]
    cf = cell.config.cell_file
    assert cell.joint_names == tuple(f"fr3_joint{i}" for i in range(1, 8))
    assert (cf.base_link, cf.flange_link) == ("fr3_link0", "fr3_link8")
    rng = np.random.default_rng(1)
    world_T_base = cell.kin.frame_pose(cell.kin.neutral(), cf.base_link)
    for _ in range(20):
        q = _random_q(cell, rng)
        expected = world_T_base @ fr3_dh_flange(q)
        np.testing.assert_allclose(cell.kin.frame_pose(q, cf.flange_link), expected, rtol=0, atol=1e-9)


def test_ur5e_forward_kinematics_is_ur_dh(cells: dict[str, Cell]) -> None:
    cell = cells["ur5e"]
    cf = cell.config.cell_file
    assert len(cell.joint_names) == 6 and cell.joint_names[0] == "ur5e_shoulder_pan_joint"
    rng = np.random.default_rng(2)
    world_T_base = cell.kin.frame_pose(cell.kin.neutral(), cf.base_link)
    for _ in range(20):
        q = _random_q(cell, rng)
        expected = world_T_base @ ur5e_dh_frames(q)[-1]
        np.testing.assert_allclose(cell.kin.frame_pose(q, cf.flange_link), expected, rtol=0, atol=1e-9)


def test_ur5e_masses_and_centres_of_mass_are_urs(cells: dict[str, Cell]) -> None:
    """Each link's URDF mass and centre of mass, seen from our DH frame i, are UR's table values."""
    from lxml import etree

    cell = cells["ur5e"]
    root = etree.fromstring(cell.urdf.encode())
    q = _random_q(cell, np.random.default_rng(3))
    world_T_base = cell.kin.frame_pose(q, cell.config.cell_file.base_link)
    links = ["shoulder", "upper_arm", "forearm", "wrist_1", "wrist_2", "wrist_3"]
    for link, frame, mass, com in zip(links, ur5e_dh_frames(q), UR5E_MASS, UR5E_COM, strict=True):
        inertial = root.find(f"link[@name='ur5e_{link}_link']/inertial")
        assert float(inertial.find("mass").get("value")) == pytest.approx(mass)
        link_com = [float(v) for v in inertial.find("origin").get("xyz").split()]
        world_com = cell.kin.frame_pose(q, f"ur5e_{link}_link") @ np.append(link_com, 1.0)
        dh_com = np.linalg.inv(world_T_base @ frame) @ world_com
        np.testing.assert_allclose(dh_com[:3], com, atol=1e-9)


def test_limits_are_the_published_ones(cells: dict[str, Cell]) -> None:
    fr3 = cells["fr3"].limits
    np.testing.assert_allclose(fr3.lower, FR3_Q_MIN, atol=1e-6)
    np.testing.assert_allclose(fr3.upper, FR3_Q_MAX, atol=1e-6)
    np.testing.assert_allclose(fr3.velocity, FR3_DQ_MAX, atol=1e-5)
    np.testing.assert_allclose(fr3.acceleration, 10.0, atol=1e-5)
    np.testing.assert_allclose(fr3.effort, FR3_TAU_MAX)
    np.testing.assert_allclose(fr3.upper - fr3.soft_upper, math.radians(5.0))
    assert np.all(fr3.upper[3] < 0) and np.all(fr3.lower[5] > 0)  # joint 4 negative, joint 6 positive
    ur = cells["ur5e"].limits
    np.testing.assert_allclose(ur.velocity, math.radians(180.0))
    np.testing.assert_allclose(ur.effort, [150, 150, 150, 28, 28, 28])
    np.testing.assert_allclose(ur.upper, PI)
    np.testing.assert_allclose(ur.lower, -PI)


# ----------------------------------------------------------------------------- the cell around
@pytest.mark.parametrize("kind", ["fr3", "ur5e"])
def test_home_is_free_and_inside_the_soft_limits(cells: dict[str, Cell], kind: str) -> None:
    cell = cells[kind]
    q = cell.config.cell_file.pose("home", cell.joint_names)
    assert cell.limits.within_soft(q)
    assert cell.collision.check(q).pairs == ()
    assert not cell.collision.in_collision(q)
    clearance = cell.collision.distance(q)
    assert clearance.environment > 0.05  # [m] beyond the safety distance
    assert clearance.self_ > 0.0


@pytest.mark.parametrize("kind", ["fr3", "ur5e"])
def test_camera_at_home_sees_the_whole_board(cells: dict[str, Cell], kind: str) -> None:
    """Every corner of the printed area in front of the camera, within the sensor's range,
    inside its image (pinhole model of the sensor file: square pixels, centred)."""
    cell = cells[kind]
    sensor, board = _sensor(cell), _board(cell)
    q = cell.config.cell_file.pose("home", cell.joint_names)
    camera_T_marker = np.linalg.inv(cell.kin.world_T_camera(q)) @ cell.world_T_marker
    sx, sy = board["squares_x"] * board["square_length"], board["squares_y"] * board["square_length"]
    corners = np.array([[x, y, 0.0, 1.0] for x in (0.0, sx) for y in (0.0, sy)]).T
    p = camera_T_marker @ corners
    assert np.all(p[2] > sensor["z_min"]) and np.all(p[2] < sensor["z_max"])
    f = sensor["width"] / 2.0 / math.tan(math.radians(sensor["hfov_deg"]) / 2.0)
    u = f * p[0] / p[2] + sensor["width"] / 2.0
    v = f * p[1] / p[2] + sensor["height"] / 2.0
    assert np.all((u > 0) & (u < sensor["width"]) & (v > 0) & (v < sensor["height"]))


@pytest.mark.parametrize("kind", ["fr3", "ur5e"])
def test_object_spot_is_the_board_centre_on_the_table(cells: dict[str, Cell], kind: str) -> None:
    cell = cells[kind]
    board = _board(cell)
    centre = cell.world_T_marker @ np.array([board["squares_x"] * board["square_length"] / 2.0,
                                             board["squares_y"] * board["square_length"] / 2.0, 0.0, 1.0])
    np.testing.assert_allclose(cell.config.cell_file.object_position, centre[:3], atol=1e-9)
    assert cell.table_surface_z == pytest.approx(0.75)
    assert cell.world_T_marker[2, 3] == pytest.approx(0.753)  # on the 3 mm board


@pytest.mark.parametrize("kind", ["fr3", "ur5e"])
def test_sensor_file_has_the_camera_keys_and_a_scan_distance_in_range(cells: dict[str, Cell], kind: str) -> None:
    sensor = _sensor(cells[kind])
    with open(ROBOT_DIR / "camera.yaml", encoding="utf-8") as f:
        thesis = yaml.safe_load(f)
    assert set(sensor) == set(thesis) | {"scan_distance"}
    assert sensor["z_min"] < sensor["scan_distance"] < sensor["z_max"]
    assert sensor["noise_z_ref"] == pytest.approx(sensor["scan_distance"])


@pytest.mark.parametrize("kind", ["fr3", "ur5e"])
def test_base_and_camera_pose_settings_reach_the_description(cells: dict[str, Cell], kind: str) -> None:
    """recon's base pose (realism) and hand-eye settings are the xacro's base_* / camera_* arguments."""
    from recon_cli.robot.description import expand_urdf
    from recon_cli.robot.kinematics import Kinematics

    cell = cells[kind]
    cf = cell.config.cell_file
    q = cf.pose("home", cell.joint_names)
    flange_T_camera = np.linalg.inv(cell.kin.frame_pose(q, cf.flange_link)) @ cell.kin.world_T_camera(q)
    moved = flange_T_camera @ _trans(0.001, -0.002, 0.003) @ _rz(0.01)
    mount_T_base = np.linalg.inv(cell.kin.frame_pose(q, "table")) @ cell.kin.frame_pose(q, cf.base_link)
    shifted = _trans(0.01, 0.0, 0.0) @ mount_T_base
    config = CellConfig(kind=kind, flange_T_camera=tuple(moved.ravel()), mount_T_base=tuple(shifted.ravel()))
    kin = Kinematics(expand_urdf(config), config.cell_file)
    np.testing.assert_allclose(np.linalg.inv(kin.frame_pose(q, cf.flange_link)) @ kin.world_T_camera(q), moved,
                               atol=1e-9)
    np.testing.assert_allclose(kin.frame_pose(q, cf.base_link)[:3, 3] - cell.kin.frame_pose(q, cf.base_link)[:3, 3],
                               [0.01, 0.0, 0.0], atol=1e-9)


# ----------------------------------------------------------------------------- reachability
def _reach(cell: Cell) -> tuple[float, float]:
    """Share of the views around the object spot solved by cell.solve_view and the median IK
    time [s] of the solved ones (seeded with home, as a scan starts there)."""
    cf = cell.config.cell_file
    r = _sensor(cell)["scan_distance"]
    focus = np.asarray(cf.object_position) + (0.0, 0.0, FOCUS_HEIGHT)
    home = cf.pose("home", cell.joint_names)
    rng = np.random.default_rng(0)
    solved, seconds = 0, []
    for theta in THETAS:
        for k in range(AZIMUTHS):
            view = View.from_degrees(focus, r, theta, 360.0 * k / AZIMUTHS)
            try:
                result = cell.solve_view(view, rng, seed=home, options=IKOptions(max_solutions=1))
            except ReconError:
                continue
            assert cell.limits.within_soft(result.solutions[0].q)
            solved += 1
            seconds.append(result.seconds)
    return solved / (len(THETAS) * AZIMUTHS), float(np.median(seconds))


@pytest.mark.parametrize("kind", ["fr3", "ur5e"])
def test_views_around_the_object_spot_are_reachable(cells: dict[str, Cell], kind: str) -> None:
    share, median = _reach(cells[kind])
    print(f"{kind}: {share:.1%} of {len(THETAS) * AZIMUTHS} views solved, median IK {median * 1e3:.2f} ms")
    assert share >= MIN_SHARE[kind]


def test_ik_survives_the_ur5e_wrist_singularity(cells: dict[str, Cell]) -> None:
    """A descent toward an unreachable view that slides into wrist 2 = 0 (a rank-5 Jacobian)
    with its damping decayed to nothing: once np.linalg.LinAlgError, now an unconverged result."""
    cell = cells["ur5e"]
    focus = np.asarray(cell.config.cell_file.object_position) + (0.0, 0.0, FOCUS_HEIGHT)
    goal = cell.view_pose(View.from_degrees(focus, 0.38, 50.0, 210.0))
    q, converged, _, _ = cell.ik.descend(goal, np.array([2.03, 1.83, 0.57, -1.87, 2.5, 2.4]), IKOptions())
    assert np.all(np.isfinite(q)) and not converged


# ----------------------------------------------------------------------------- simulation
@pytest.mark.parametrize("kind", ["fr3", "ur5e"])
def test_mujoco_scene_compiles(cells: dict[str, Cell], kind: str) -> None:
    from recon_cli.backends.sim.scene import build_scene

    scene = build_scene(CellConfig(kind=kind))
    assert scene.joint_names == cells[kind].joint_names
    assert scene.model.nu == len(scene.joint_names)
