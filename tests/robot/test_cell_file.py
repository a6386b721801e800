"""Cell files: the shipped cells give the thesis' description unchanged, and a cell file with
a mistake is refused with one line naming file:line and what to do."""

from __future__ import annotations

import contextlib
import io
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from recon_cli.errors import InputError
from recon_cli.paths import CELLS_DIR, ROBOT_DIR
from recon_cli.robot.cell import Cell
from recon_cli.robot.cell_file import load_cell, shipped_cells
from recon_cli.robot.description import CellConfig, CellName, expand_urdf

#: the thesis' hand-eye transform, the optical frame in the flange frame (docs/cell.md)
HAND_EYE = (0.01, 0.02, 0.03)


def _xacro(args: dict[str, str]) -> str:
    """robot/cell.urdf.xacro expanded directly with the given arguments."""
    import xacro

    with contextlib.redirect_stderr(io.StringIO()):
        return xacro.process_file(str(ROBOT_DIR / "cell.urdf.xacro"), mappings=args).toprettyxml(indent="  ")


def _body(urdf: str) -> str:
    """The URDF's elements, attributes and text, without comments and layout whitespace."""
    from lxml import etree

    root = etree.fromstring(urdf.encode(), etree.XMLParser(remove_blank_text=True, remove_comments=True))
    return etree.tostring(root, pretty_print=True, encoding="unicode")


def test_the_shipped_cells_are_the_thesis_cells_first():
    assert shipped_cells()[:2] == ("gantry", "ceiling")
    assert CellName.parse("9DOF") == "gantry" and CellName.parse("7dof") == "ceiling"


@pytest.mark.parametrize("kind", ["gantry", "ceiling"])
def test_shipped_cell_files_give_the_same_urdf(kind):
    plain = {"cell": kind, "sd": "0.03", "table_lift": "0.0", "ceiling_x": "0.0", "ceiling_y": "0.0"}
    assert _body(expand_urdf(CellConfig(kind=kind))) == _body(_xacro(plain))
    # settings through the cell file's argument names: lift, safety, hand-eye and base pose
    T = np.eye(4)
    T[:3, 3] = HAND_EYE
    given = CellConfig(kind=kind, safety_distance=0.05, table_lift=0.1, flange_T_camera=tuple(T.ravel()),
                       mount_T_base=tuple(T.ravel()))
    rpy = " ".join(repr(float(v)) for v in Rotation.from_matrix(np.eye(3)).as_euler("xyz"))
    # the optical frame in the camera bracket, 0.0723 m above the flange (robot/parts/camera.xacro)
    args = {**plain, "sd": "0.05", "table_lift": "0.1", "camera_xyz": f"0.01 0.02 {0.03 - 0.0723!r}",
            "camera_rpy": rpy, "base_xyz": "0.01 0.02 0.03", "base_rpy": rpy}
    assert _body(expand_urdf(given)) == _body(_xacro(args))


def test_shipped_cell_files_give_the_same_model():
    g = Cell(CellConfig(kind="gantry"))
    assert g.joint_names == ("base_joint_1", "base_joint_2", *(f"arm_joint_{i}" for i in range(1, 8)))
    assert np.allclose(g.limits.soft_upper[2:], np.radians([160, 110, 160, 110, 160, 110, 165]), atol=1e-12)
    assert np.allclose(g.limits.acceleration[2:], np.radians([85, 85, 100, 75, 130, 135, 135]), atol=1e-12)
    assert list(g.limits.prismatic) == [True, True] + [False] * 7
    home = load_cell("gantry").pose("home", g.joint_names)
    assert np.array_equal(home, [-1.0, 0, 0, 0, 0, 0, 0, 0, 0])
    c = Cell(CellConfig(kind="ceiling"))
    assert c.joint_names == tuple(f"arm_joint_{i}" for i in range(1, 8)) and not c.limits.prismatic.any()
    # the camera frame hangs on the flange at the thesis' hand-eye pose, in both cells
    for cell in (g, c):
        q = cell.kin.neutral()
        flange_T_camera = np.linalg.inv(cell.kin.frame_pose(q, "arm_link_7")) @ cell.kin.world_T_camera(q)
        assert np.allclose(flange_T_camera[:3, 3], (-0.0288531, -0.1731820, 0.0608131 + 0.0723), atol=1e-9)


# ----------------------------------------------------------------------------- mistakes
def _cell(tmp_path: Path, edit) -> Path:
    """cells/gantry.yaml, edited, beside a copy of robot/ (its paths made relative to that copy)."""
    import shutil

    shutil.copytree(ROBOT_DIR, tmp_path / "robot", ignore=shutil.ignore_patterns("realism"))
    text = edit((CELLS_DIR / "gantry.yaml").read_text()).replace("../robot/", "robot/")
    path = tmp_path / "mine.yaml"
    path.write_text(text)
    return path


def _line(path: Path, needle: str) -> int:
    return next(i for i, line in enumerate(path.read_text().splitlines(), 1) if needle in line)


@pytest.mark.parametrize("edit, needle, message, hint", [
    (lambda t: t.replace("base: arm_link_0", "base: arm_link_0\nbogus: 1"), "bogus: 1",
     "bogus is not a known key", "known keys"),
    (lambda t: t.replace("flange: arm_link_7", "flange: arm_link_9"), "flange: arm_link_9",
     "flange arm_link_9 is not a link of cell.urdf.xacro", "its links: world, frame_link"),
    (lambda t: t.replace("arm_joint_6, arm_joint_7]", "arm_joint_8, arm_joint_7]"), "arm_joint_8,",
     "planning joint arm_joint_8 is not a joint of cell.urdf.xacro", "its movable joints: base_joint_1"),
    (lambda t: t.replace("file: ../robot/cell.urdf.xacro", "file: ../robot/nope.urdf.xacro"), "nope.urdf.xacro",
     "description.file: the robot description robot/nope.urdf.xacro does not exist", "relative to the cell file"),
    (lambda t: t.replace("limits: ../robot/limits.yaml", "limits: {joints: {base_joint_1: {acceleration: 5}}}"),
     "limits: {joints", "the limits lack the acceleration of planning joint base_joint_2", "acceleration"),
    (lambda t: t.replace("home: [-1.0, 0.0, 0, 0, 0, 0, 0, 0, 0]", "home: [0, 0, 0]"), "home: [0, 0, 0]",
     "pose home has 3 values, the cell has 9 planning joints", "one value per joint"),
    (lambda t: t.replace("linear: [base_joint_1, base_joint_2]", "linear: [base_joint_1]"), "arm_joint_1, arm_joint_2",
     "joint base_joint_2 is prismatic in cell.urdf.xacro but not in joints.linear", "prismatic planning joints"),
    (lambda t: t.replace("planning: [base_joint_1, base_joint_2,", "planning: [base_joint_2, base_joint_1,"),
     "planning: [base_joint_2", "joints.planning is not the movable joints of cell.urdf.xacro in tree order",
     "list them as base_joint_1, base_joint_2, arm_joint_1"),
    (lambda t: t.replace("shape: table_top", "shape: table_plate"), "shape: table_plate",
     "cell.urdf.xacro has no collision shape table_plate", "<collision name=...>"),
    (lambda t: t.replace("links: [arm_link_5, arm_link_7]", "links: [arm_link_5, arm_link_77]"), "arm_link_77",
     "arm_link_77 is not a link of cell.urdf.xacro", "its links"),
    (lambda t: t.replace("safety_distance: 0.03", "safety_distance: 0.5"), "safety_distance: 0.5",
     "safety_distance = 0.5 m is outside [0, 0.2] m", None),
])
def test_a_cell_file_with_a_mistake_is_one_line_with_file_and_line(tmp_path, edit, needle, message, hint):
    path = _cell(tmp_path, edit)
    with pytest.raises(InputError) as info:
        expand_urdf(CellConfig(kind=str(path)))
    text = info.value.one_line()
    assert "\n" not in text
    assert text.startswith(f"{path.resolve()}:{_line(path, needle)}: "), text
    assert message in text, text
    if hint is not None:
        assert hint in (info.value.hint or ""), info.value.hint


def test_a_cell_file_names_its_cell(tmp_path):
    path = _cell(tmp_path, lambda t: t.replace("name: gantry", "name: mine"))
    config = CellConfig(kind=str(path))
    assert config.kind == str(path.resolve()) and config.name == "mine" and config.safety_distance == 0.03
    assert _body(expand_urdf(config)) == _body(expand_urdf(CellConfig()))


def test_an_unknown_cell_names_the_shipped_ones():
    with pytest.raises(InputError, match="unknown cell 'scara'") as info:
        CellName.parse("scara")
    assert f"{', '.join(shipped_cells())}, a cell FILE.yaml" in info.value.hint
    assert info.value.hint.startswith("choose one of: gantry, ceiling, ")


def _edit_file(path: Path, old: str, new: str) -> None:
    text = path.read_text()
    assert old in text, old
    path.write_text(text.replace(old, new))


@pytest.mark.parametrize("file, old, new, needle, message", [
    ("robot/parts/iiwa14.xacro", 'xyz="0 0 0.1525"', 'xyz="0 0 ${().__class__}"', "__class__",
     "attribute '__class__' is not allowed in robot description expressions"),
    ("robot/cell.urdf.xacro", '<material name="grey">', '<material name="$(eval python.vars())">', "$(eval",
     "invalid expression"),
    ("robot/cell.urdf.xacro", '<material name="grey">', '<material name="${python.vars(python)}">', "vars(",
     "vars() is not allowed in robot descriptions"),
    ("robot/camera.yaml", "z_max: 0.939", "z_max: 0.4", "z_max: 0.4", "the working range 0.497 ... 0.4 m is empty"),
    ("robot/camera.yaml", "scan_distance: 0.55", "scan_distance: 0.2", "scan_distance: 0.2",
     "0.2 m lies outside the working range"),
    ("robot/camera.yaml", "hfov_deg: 49.3096", "hfov_deg: .nan", "hfov_deg", "not a finite number"),
    ("robot/board.yaml", "marker_length: 0.025", "marker_length: 0.04", "marker_length: 0.04",
     "marker_length 0.04 m is not smaller than square_length 0.035 m"),
    ("robot/drives.yaml", "  K0: 1875.0", "  K0: -5", "K0: -5", "controller.K0 = -5"),
])
def test_a_mistake_in_a_file_the_cell_names_is_one_line_with_its_file_and_line(tmp_path, file, old, new, needle,
                                                                                message):
    """The description (and what it includes), the sensor, board and drives files of a cell are
    user files too: a hostile or careless one is one line naming its own file and line."""
    from recon_cli.backends.sim.scene import drives
    from recon_cli.perception.charuco import cell_board
    from recon_cli.perception.sensor import cell_sensor

    path = _cell(tmp_path, lambda t: t)
    target = tmp_path / file
    _edit_file(target, old, new)
    with pytest.raises(InputError) as info:
        config = CellConfig(kind=str(path))
        expand_urdf(config)
        cell_sensor(config.cell_file)
        cell_board(config.cell_file)
        drives(config.cell_file)
    text = info.value.one_line()
    assert "\n" not in text
    assert text.startswith(f"{target.resolve()}:{_line(target, needle)}"), text
    assert message in text, text


def test_ik_seeds_name_poses_of_the_cell(tmp_path):
    path = _cell(tmp_path, lambda t: t.replace("safety_distance: 0.03", "safety_distance: 0.03\nik:\n  seeds: [nope]"))
    with pytest.raises(InputError, match="IK seed nope is not a pose of the cell") as info:
        load_cell(str(path))
    assert info.value.one_line().startswith(f"{path.resolve()}:{_line(path, '  seeds: [nope]') + 0}")


@pytest.mark.parametrize("file, old, new, needle, message", [
    ("robot/parts/board.xacro", 'origin xyz="0.1225 -0.1925 0.003"', 'origin xyz="1.5 -0.1925 0.003"', "frame: marker",
     "lies off the table top table_top"),
    ("robot/parts/board.xacro", 'origin xyz="0.1225 -0.1925 0.003"', 'origin xyz="0.1225 -0.1925 0.2"',
     "frame: marker", "lies off the table top table_top"),
    ("robot/cell.urdf.xacro", 'default="-0.0288531 -0.1731820 0.0608131"', 'default="0 0 -0.1"', "frame: camera",
     "the camera's optical centre lies inside arm_link_6/arm_link_6_capsule"),
])
def test_a_board_off_the_table_or_a_camera_inside_a_link_is_one_line(tmp_path, file, old, new, needle, message):
    """What only the built cell shows: where the board lies and where the camera looks from;
    ``recon cell check`` and every session refuse such a cell with the cell file's line."""
    from recon_cli.cell_check import check_layout

    path = _cell(tmp_path, lambda t: t)
    _edit_file(tmp_path / file, old, new)
    with pytest.raises(InputError) as info:
        check_layout(Cell(CellConfig(kind=str(path))))
    text = info.value.one_line()
    assert "\n" not in text and text.startswith(f"{path.resolve()}:{_line(path, needle)}: "), text
    assert message in text, text


@pytest.mark.parametrize("text, message", [
    ("hello <robot", "the robot description is not XML"),
    (b"\xff\xfe\x00garbage", "the robot description is not UTF-8 text"),
])
def test_a_description_that_is_no_urdf_is_one_line(tmp_path, text, message):
    """A cell file naming a URDF that is not one (binary, not XML) is refused in one line."""
    def broken(t: str) -> str:
        head = t.replace("file: ../robot/cell.urdf.xacro", "file: ../robot/broken.urdf").replace(
            "  arguments: {cell: gantry}\n", "").split("  # the xacro arguments")[0]
        return head + "joints:" + t.split("\njoints:", 1)[1]

    path = _cell(tmp_path, broken)
    target = tmp_path / "robot" / "broken.urdf"
    target.write_bytes(text if isinstance(text, bytes) else text.encode())
    with pytest.raises(InputError) as info:
        expand_urdf(CellConfig(kind=str(path)))
    line = info.value.one_line()
    assert "\n" not in line and str(target) in line and message in line, line
