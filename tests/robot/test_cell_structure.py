"""A robot description that breaks the URDF model, limits that leave a joint no range, a seed
library, collision mesh or sensor image too large for the work they bound: each refused in one
line naming the file (and line, key or URDF element) before pinocchio, the collision model,
MuJoCo or the IK see it, in bounded time and memory (docs/inputs.md, "Robot descriptions")."""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from recon_cli.cli import main
from recon_cli.paths import ROBOT_DIR
from recon_cli.perception.sensor import MAX_SENSOR_PIXELS
from recon_cli.robot.ik import MAX_LIBRARY_VALUES
from recon_cli.robot.urdf import MAX_DEPTH, MAX_LINKS
from tests.inputs.measure import run_cli

LIMIT = 'lower="-2.5" upper="2.5" velocity="1.0" effort="10"'
INERTIAL = ('<inertial><mass value="1.0"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/>'
            "</inertial>")
SHAPE = '<collision name="c"><origin xyz="0 0 0.1"/><geometry><cylinder radius="0.03" length="0.2"/></geometry>' \
        "</collision>"


def toy_urdf(n: int = 3, limit: Callable[[int], str] = lambda i: LIMIT, link: Callable[[int], str] = lambda i: "",
             extra: str = "", collide: bool = True, step: float = 0.2) -> str:
    """A table with a board frame and an ``n``-joint arm (joints j0..., links l0...) carrying a
    flange and a camera; ``limit(i)``: the attributes of joint i's <limit>, ``link(i)``: more
    elements of link i, ``extra``: more elements of the robot."""
    rows = ['<link name="world"/>',
            '<link name="table"><collision name="table_top"><origin xyz="0 0 0.7"/><geometry><box size="1.2 0.8 0.05"/>'
            "</geometry></collision></link>",
            '<joint name="table_joint" type="fixed"><parent link="world"/><child link="table"/></joint>',
            '<link name="marker"/>',
            '<joint name="marker_joint" type="fixed"><parent link="table"/><child link="marker"/>'
            '<origin xyz="0.0 -0.1 0.728"/></joint>',
            '<link name="base"/>',
            '<joint name="base_joint" type="fixed"><parent link="table"/><child link="base"/>'
            '<origin xyz="-0.4 0 0.725"/></joint>']
    parent = "base"
    for i in range(n):
        rows.append(f'<link name="l{i}">{INERTIAL}{SHAPE if collide else ""}{link(i)}</link>')
        rows.append(f'<joint name="j{i}" type="revolute"><parent link="{parent}"/><child link="l{i}"/>'
                    f'<origin xyz="0 0 {0.05 if i == 0 else step}"/><axis xyz="{"0 0 1" if i % 2 == 0 else "0 1 0"}"/>'
                    f"<limit {limit(i)}/></joint>")
        parent = f"l{i}"
    rows += ['<link name="flange"/>',
             f'<joint name="flange_joint" type="fixed"><parent link="{parent}"/><child link="flange"/>'
             '<origin xyz="0 0 0.2"/></joint>',
             '<link name="camera"/>',
             '<joint name="camera_joint" type="fixed"><parent link="flange"/><child link="camera"/>'
             '<origin xyz="0 0 0.05"/></joint>']
    return '<?xml version="1.0"?>\n<robot name="toy">\n  ' + "\n  ".join(rows) + f"\n  {extra}\n</robot>\n"


def toy_cell(folder: Path, urdf: str | None = None, n: int = 3, limits: Callable[[int], str] = lambda i: "",
             margin: float | None = None, library: int = 0) -> Path:
    """A cell file of :func:`toy_urdf` (or ``urdf``) with the D435's sensor file and the board;
    ``limits(i)``: more keys of joint i's cell-file limits (deg)."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "toy.urdf").write_text(urdf if urdf is not None else toy_urdf(n))
    shutil.copy(ROBOT_DIR / "sensors" / "realsense_d435.yaml", folder / "sensor.yaml")
    shutil.copy(ROBOT_DIR / "board.yaml", folder / "board.yaml")
    rows = "\n".join(f"    j{i}: {{acceleration: 90.0{limits(i)}}}" for i in range(n))
    soft = f"  soft_margin_revolute_deg: {margin}\n" if margin is not None else ""
    cell = folder / "cell.yaml"
    cell.write_text(f"""format: 1
name: toy
description:
  file: toy.urdf
joints:
  planning: [{", ".join(f"j{i}" for i in range(n))}]
base: base
flange: flange
camera:
  frame: camera
  sensor: sensor.yaml
table:
  shape: table_top
board:
  frame: marker
  spec: board.yaml
objects:
  position: [0.19, 0.02, 0.73]
limits:
{soft}  joints:
{rows}
safety_distance: 0.02
poses:
  home: [{", ".join("0" for _ in range(n))}]
collision: {{}}
""" + (f"ik:\n  library: {library}\n" if library else ""))
    return cell


def one_line(capsys, *words: str) -> str:
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in captured.err, captured.err
    for w in words:
        assert w in lines[0], (w, lines[0])
    return lines[0]


def line_of(path: Path, needle: str) -> int:
    return next(i for i, text in enumerate(path.read_text().splitlines(), 1) if needle in text)


def test_the_toy_cell_is_a_cell(tmp_path):
    assert main(["cell", "--cell", str(toy_cell(tmp_path))]) == 0


def _limit(joint: int, attributes: str) -> Callable[[int], str]:
    return lambda i: attributes if i == joint else LIMIT


def _link(index: int, elements: str) -> Callable[[int], str]:
    return lambda i: elements if i == index else ""


_NAN_MASS = INERTIAL.replace('value="1.0"', 'value="nan"')
CASES = {
    # name: (toy_urdf arguments, the line's element, words of the message)
    "NaN mass": (dict(link=_link(1, "")), "l1", ("link 'l1'", "<mass value> is not finite")),
    "zero-width joint limit": (dict(limit=_limit(1, 'lower="0.5" upper="0.5" velocity="1" effort="10"')),
                               'name="j1"', ("joint 'j1'", "lower limit 0.5 rad is equal to the upper limit")),
    "lower limit above the upper": (dict(limit=_limit(1, 'lower="1" upper="-1" velocity="1" effort="10"')),
                                    'name="j1"', ("joint 'j1'", "lower limit 1 rad is above the upper limit -1")),
    "no lower or upper limit": (dict(limit=_limit(2, 'velocity="1" effort="10"')), 'name="j2"',
                                ("joint 'j2'", "URDF reads a missing one as 0")),
    "two root links": (dict(extra='<link name="orphan"/>'), "orphan", ("2 root links ('world', 'orphan')",)),
    "a cycle of joints": (dict(extra='<joint name="back" type="fixed"><parent link="l2"/><child link="world"/>'
                                     "</joint>"), 'name="back"', ("the joints form a cycle", "joint 'back' closes it")),
    "a link with two parents": (dict(extra='<joint name="back" type="fixed"><parent link="l2"/><child link="l0"/>'
                                           "</joint>"), 'name="back"', ("link 'l0' is the child of two joints",)),
    "a loop apart from the tree": (
        dict(extra='<link name="a"/><link name="b"/><joint name="ab" type="fixed"><parent link="a"/><child link="b"/>'
                   '</joint><joint name="ba" type="fixed"><parent link="b"/><child link="a"/></joint>'),
        'name="ab"', ("the joints form a cycle",)),
    "NaN origin": (dict(extra='<link name="x"/><joint name="jx" type="fixed"><parent link="world"/><child link="x"/>'
                              '<origin xyz="0 nan 0"/></joint>'), 'name="jx"',
                   ("joint 'jx'", "<origin xyz> is not finite")),
    "an origin 1e9 m away": (dict(extra='<link name="x"/><joint name="jx" type="fixed"><parent link="world"/><child '
                                        'link="x"/><origin xyz="0 1e9 0"/></joint>'), 'name="jx"',
                             ("<origin xyz> has a value beyond 1000 m",)),
    "negative velocity limit": (dict(limit=_limit(0, 'lower="-1" upper="1" velocity="-1" effort="10"')), 'name="j0"',
                                ("joint 'j0'", "velocity limit -1 is not above zero")),
    "zero effort limit": (dict(limit=_limit(0, 'lower="-1" upper="1" velocity="1" effort="0"')), 'name="j0"',
                          ("joint 'j0'", "effort limit 0 is not above zero")),
    "no velocity limit": (dict(limit=_limit(0, 'lower="-1" upper="1" effort="10"')), 'name="j0"',
                          ("joint 'j0'", "<limit> has no velocity")),
    "infinite inertia": (dict(link=_link(2, "")), "l2", ("link 'l2'", "<inertia ixx> is not finite")),
    "negative mass": (dict(link=_link(0, "")), "l0", ("link 'l0'", "the mass -2 kg is negative")),
    "a link twice": (dict(extra='<link name="l1"/>'), '<link name="l1"/>', ("link 'l1' is defined twice",)),
    "a joint twice": (dict(extra='<link name="x"/><joint name="j1" type="fixed"><parent link="world"/>'
                                 '<child link="x"/></joint>'), '<link name="x"/>', ("joint 'j1' is defined twice",)),
    "a joint to a missing link": (dict(extra='<link name="x"/><joint name="jx" type="fixed"><parent link="nowhere"/>'
                                             '<child link="x"/></joint>'), 'name="jx"',
                                  ("joint 'jx': its parent link 'nowhere' is not a link",)),
    "an unknown joint type": (dict(extra='<link name="x"/><joint name="jx" type="hinge"><parent link="world"/>'
                                         '<child link="x"/></joint>'), 'name="jx"',
                              ("joint 'jx' has the type 'hinge'",)),
    "a zero axis": (dict(extra='<link name="x"/><joint name="jx" type="prismatic"><parent link="world"/><child '
                               'link="x"/><axis xyz="0 0 0"/><limit lower="0" upper="1" velocity="1" effort="1"/>'
                               "</joint>"), 'name="jx"', ("joint 'jx': the axis is 0 0 0",)),
    "a NaN box": (dict(link=_link(1, '<collision><geometry><box size="0.1 nan 0.1"/></geometry></collision>')),
                  "l1", ("link 'l1': <collision>", "<box size> is not finite")),
    "a capsule": (dict(link=_link(1, '<collision><geometry><capsule radius="0.1" length="0.2"/></geometry>'
                                     "</collision>")), "l1", ("<capsule> is not a URDF shape",)),
}
_EDITS = {"NaN mass": ('<link name="l1"><inertial><mass value="1.0"/>',
                       '<link name="l1"><inertial><mass value="nan"/>'),
          "infinite inertia": ('<link name="l2"><inertial><mass value="1.0"/><inertia ixx="0.01"',
                               '<link name="l2"><inertial><mass value="1.0"/><inertia ixx="inf"'),
          "negative mass": ('<link name="l0"><inertial><mass value="1.0"/>',
                            '<link name="l0"><inertial><mass value="-2"/>')}


@pytest.mark.parametrize("case", list(CASES))
def test_a_description_that_breaks_the_urdf_model_is_one_line_with_its_line(tmp_path, capsys, case):
    """Before pinocchio parses the URDF: each of these was a traceback, a parser line on the
    terminal followed by an endless IK (NaN mass, zero-width limit), or unbounded growth
    (a cycle)."""
    kwargs, element, words = CASES[case]
    urdf = toy_urdf(**kwargs)
    if case in _EDITS:
        old, new = _EDITS[case]
        assert old in urdf
        urdf = urdf.replace(old, new)
    cell = toy_cell(tmp_path, urdf)
    assert main(["cell", "--cell", str(cell)]) == 1
    description = tmp_path / "toy.urdf"
    one_line(capsys, f"{description}:{line_of(description, element)}: ", *words)


def test_too_many_links_and_too_deep_a_tree_are_refused(tmp_path, capsys):
    """A tree 3000 links deep (a RecursionError before) and one deeper than MAX_DEPTH."""
    def chain(count: int) -> str:
        return "".join(f'<link name="d{i}"/><joint name="dj{i}" type="fixed">'
                       f'<parent link="{"marker" if i == 0 else f"d{i - 1}"}"/><child link="d{i}"/>'
                       '<origin xyz="0 0 0.001"/></joint>\n' for i in range(count))
    assert main(["cell", "--cell", str(toy_cell(tmp_path / "wide", toy_urdf(extra=chain(3000))))]) == 1
    one_line(capsys, "toy.urdf:", f"3009 links, more than the {MAX_LINKS}")
    assert main(["cell", "--cell", str(toy_cell(tmp_path / "deep", toy_urdf(extra=chain(MAX_DEPTH))))]) == 1
    one_line(capsys, "toy.urdf:", f"link 'd{MAX_DEPTH - 2}' hangs {MAX_DEPTH + 1} joints below the root link")


def test_an_arm_without_collision_geometry_is_refused(tmp_path, capsys):
    assert main(["cell", "--cell", str(toy_cell(tmp_path, toy_urdf(collide=False)))]) == 1
    one_line(capsys, "toy.urdf: no link that a joint moves has a <collision> shape")


def test_a_continuous_planning_joint_is_refused(tmp_path, capsys):
    urdf = toy_urdf().replace('<joint name="j1" type="revolute">', '<joint name="j1" type="continuous">')
    assert main(["cell", "--cell", str(toy_cell(tmp_path, urdf))]) == 1
    one_line(capsys, "toy.urdf: joint j1 is a continuous joint", "write joint j1 as a revolute joint")


@pytest.mark.parametrize("case, joint, limits, margin, words", [
    ("lower above upper", "j1", ", lower: 30.0, upper: -30.0", None,
     ("joint j1: the lower limit 30 deg is not below the upper limit -30 deg", "limits.joints.j1.lower")),
    ("empty range", "j1", ", lower: 10.0, upper: 10.0", None, ("joint j1: the lower limit 10 deg",)),
    ("margin wider than the range", "j2", ", lower: -40.0, upper: 40.0", 45.0,
     ("joint j2: the soft margin 45 deg leaves no range inside its limits -40 ... 40 deg",)),
    ("margin half the range", "j2", ", lower: -10.0, upper: 10.0", 10.0,
     ("joint j2: the soft margin 10 deg leaves no range",)),
])
def test_cell_file_limits_that_leave_no_range_are_one_line(tmp_path, capsys, case, joint, limits, margin, words):
    """`recon ik` of such a cell ended in a traceback in the IK's random seeding (numpy's
    uniform(low, high) with high < low) or ran without end (a zero range)."""
    cell = toy_cell(tmp_path, limits=lambda i: limits if f"j{i}" == joint else "", margin=margin)
    assert main(["ik", "--cell", str(cell)]) == 1
    one_line(capsys, f"{cell}:{line_of(cell, f'    {joint}: ')}: ", *words)


def test_safety_controller_limits_that_leave_no_range_are_one_line(tmp_path, capsys):
    urdf = toy_urdf(limit=_limit(1, LIMIT + '/><safety_controller soft_lower_limit="1" soft_upper_limit="0.5" '
                                           'k_velocity="1"'))
    assert '<safety_controller soft_lower_limit="1"' in urdf
    assert main(["ik", "--cell", str(toy_cell(tmp_path, urdf))]) == 1
    one_line(capsys, "toy.urdf: joint j1: its <safety_controller> soft limits leave no range inside its limits")


def test_the_docs_state_the_limits():
    from recon_cli.robot.ik import LIBRARY_CHUNK
    from recon_cli.robot.limits import MIN_SOFT_RANGE
    from recon_cli.robot.urdf import MAX_LENGTH_M

    text = (Path(__file__).parents[2] / "docs" / "inputs.md").read_text()
    section = text.split("\n## Robot descriptions\n")[1].split("\n## ")[0]
    for value in (f"at most {MAX_LINKS}", f"at most {MAX_DEPTH} joints", f"at least {MIN_SOFT_RANGE:g}",
                  f"within {MAX_LENGTH_M:g} m", f"at most {MAX_LIBRARY_VALUES:,}", f"chunks of {LIBRARY_CHUNK:,}",
                  f"at most {MAX_SENSOR_PIXELS:,} pixels"):
        assert value in section, value


# ----------------------------------------------------------------------------- measured through the CLI
@pytest.mark.parametrize("case", ["NaN mass", "zero-width joint limit", "a cycle of joints"])
def test_cell_check_refuses_a_broken_description_in_bounded_time_and_memory(tmp_path, case):
    """`recon cell check` ran past 40 s on the first two (killed) and grew without end on a
    cycle; now one line, well within 20 s and 1 GB."""
    kwargs, _, words = CASES[case]
    urdf = toy_urdf(**kwargs)
    if case in _EDITS:
        urdf = urdf.replace(*_EDITS[case])
    cell = toy_cell(tmp_path / "cell", urdf)
    run = run_cli(["cell", "check", str(cell), "--out", str(tmp_path / "out")], tmp_path)
    assert run.code == 1 and run.err.count("\n") == 1 and "Traceback" not in run.err, run.err
    assert all(w in run.err for w in words), run.err
    assert run.seconds < 20 and run.peak_gb < 1.0, (run.seconds, run.peak_gb)
    assert not (tmp_path / "out").exists()


def test_capture_refuses_a_nan_mass(tmp_path, capsys):
    """`recon capture` with such a cell ended in a traceback (the simulation's scene)."""
    urdf = toy_urdf().replace(*_EDITS["NaN mass"])
    cell = toy_cell(tmp_path / "cell", urdf)
    assert main(["capture", "--cell", str(cell), "--object", "bottle", "--out", str(tmp_path / "out")]) == 1
    one_line(capsys, "toy.urdf:", "link 'l1': <mass value> is not finite")
    assert not (tmp_path / "out").exists()


# ----------------------------------------------------------------------------- IK seed library
def test_a_seed_library_too_large_for_the_joints_is_refused(tmp_path, capsys):
    """32 joints x 100,000 configurations ran for minutes with nothing printed."""
    urdf = toy_urdf(32, step=0.03)
    cell = toy_cell(tmp_path, urdf, n=32, library=100_000)
    assert main(["cell", "--cell", str(cell)]) == 1
    line = next(i for i, t in enumerate(cell.read_text().splitlines(), 1) if t.strip().startswith("library:"))
    one_line(capsys, f"{cell}:{line}: ik.library: 100,000 configurations of 32 joints are 3,200,000 joint values, "
                     f"more than the {MAX_LIBRARY_VALUES:,}", f"at most {MAX_LIBRARY_VALUES // 32:,} configurations")


def test_the_seed_library_is_made_in_chunks_with_progress(tmp_path):
    from recon_cli.robot.batch_fk import BatchFK
    from recon_cli.robot.cell import Cell
    from recon_cli.robot.description import CellConfig
    from recon_cli.robot.ik import LIBRARY_CHUNK, LIBRARY_DRAW_SEED

    n = LIBRARY_CHUNK * 2 + 7
    cell = Cell(CellConfig(str(toy_cell(tmp_path, library=n))))
    seen: list[tuple[int, int]] = []
    Q, p, R = cell.ik.seed_library(progress=lambda done, total: seen.append((done, total)))
    assert seen == [(LIBRARY_CHUNK, n), (2 * LIBRARY_CHUNK, n), (n, n)]
    # the configurations and poses of the one-piece computation
    model = cell.kin.model
    frame = model.frames[cell.kin.camera_frame_id]
    lo, hi = cell.limits.soft_lower, cell.limits.soft_upper
    assert np.array_equal(Q, np.random.default_rng(LIBRARY_DRAW_SEED).uniform(lo, hi, size=(n, model.nq)))
    T = BatchFK(model).joint_poses(Q)[:, int(frame.parentJoint)] @ frame.placement.homogeneous
    assert np.array_equal(p, T[:, :3, 3]) and np.array_equal(R, T[:, :3, :3])


# ----------------------------------------------------------------------------- collision meshes, sensor
def test_a_huge_collision_mesh_is_refused_before_it_is_read(tmp_path):
    """A 1.5 GB collision mesh (sparse: no disk used) was read whole (1.5 GB) before it was
    refused; now its size is taken from its stat."""
    urdf = toy_urdf(link=_link(2, '<collision name="m"><geometry><mesh filename="big.stl"/></geometry></collision>'))
    cell = toy_cell(tmp_path / "cell", urdf)
    with (tmp_path / "cell" / "big.stl").open("wb") as f:
        f.truncate(1500 * 2**20)
    run = run_cli(["cell", "--cell", str(cell)], tmp_path)
    assert run.code == 1 and run.err.count("\n") == 1 and "Traceback" not in run.err, run.err
    assert "big.stl: collision mesh of link 'l2' is 1500.0 MiB, more than the 512 MiB" in run.err
    assert run.seconds < 20 and run.peak_gb < 1.0, (run.seconds, run.peak_gb)


def test_a_collision_mesh_whose_header_claims_too_much_is_refused(tmp_path, capsys):
    urdf = toy_urdf(link=_link(2, '<collision name="m"><geometry><mesh filename="part.ply"/></geometry></collision>'))
    cell = toy_cell(tmp_path, urdf)
    header = (b"ply\nformat binary_little_endian 1.0\nelement vertex 1000000000\n"
              b"property float x\nproperty float y\nproperty float z\nend_header\n")
    (tmp_path / "part.ply").write_bytes(header + bytes(36))
    assert main(["cell", "--cell", str(cell)]) == 1
    one_line(capsys, "part.ply: collision mesh of link 'l2'", "1000000000")


def test_a_sensor_image_of_too_many_pixels_is_refused_before_anything_is_allocated(tmp_path):
    """8192 x 8192 px (each inside the schema's range) grew past 3 GB in `recon capture`
    before MuJoCo's framebuffer failed."""
    cell = toy_cell(tmp_path / "cell")
    sensor = tmp_path / "cell" / "sensor.yaml"
    text = sensor.read_text()
    assert "\nwidth: 1280\n" in text and "\nheight: 720\n" in text
    sensor.write_text(text.replace("\nwidth: 1280\n", "\nwidth: 8192\n").replace("\nheight: 720\n", "\nheight: 8192\n"))
    run = run_cli(["capture", "--cell", str(cell), "--object", "bottle", "--out", str(tmp_path / "out")], tmp_path)
    assert run.code == 1 and run.err.count("\n") == 1 and "Traceback" not in run.err, run.err
    assert f"{sensor}:{line_of(sensor, 'width:')}: width: 8192 x 8192 px are 67,108,864 pixels, more than the " \
           f"{MAX_SENSOR_PIXELS:,}" in run.err
    assert run.seconds < 20 and run.peak_gb < 1.0, (run.seconds, run.peak_gb)
    assert not (tmp_path / "out").exists()


def test_a_sensor_image_at_the_pixel_limit_is_read(tmp_path):
    from recon_cli.perception.sensor import sensor_file

    sensor = tmp_path / "sensor.yaml"
    text = (ROBOT_DIR / "sensors" / "realsense_d435.yaml").read_text()
    sensor.write_text(text.replace("\nwidth: 1280\n", "\nwidth: 3000\n").replace("\nheight: 720\n", "\nheight: 2000\n"))
    assert 3000 * 2000 == MAX_SENSOR_PIXELS and sensor_file(sensor).width == 3000


def test_a_description_with_transmissions_and_gazebo_tags_builds(tmp_path):
    """Vendor URDFs carry <transmission> (with a nested <joint name=...>) and <gazebo>
    elements; only the robot's own <link> and <joint> children are the model."""
    extra = ('<transmission name="t0"><type>transmission_interface/SimpleTransmission</type>'
             '<joint name="j0"><hardwareInterface>PositionJointInterface</hardwareInterface></joint>'
             '<actuator name="m0"><mechanicalReduction>1</mechanicalReduction></actuator></transmission>'
             '<gazebo reference="l0"><link name="ignored"/></gazebo>')
    cell = toy_cell(tmp_path, toy_urdf(extra=extra))
    assert main(["cell", "--cell", str(cell)]) == 0
