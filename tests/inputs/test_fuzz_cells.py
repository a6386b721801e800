"""Fuzzing of cell files and their xacro descriptions: whatever a careless or hostile user
writes, reading the cell and building its model gives the cell or the project's one-line
error, never another exception, never code run, never a word of a file outside the cell's
folder."""

from __future__ import annotations

import shutil
from pathlib import Path

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from recon_cli.errors import ReconError
from recon_cli.paths import CELLS_DIR, ROBOT_DIR

_fuzz = settings(max_examples=50, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                        HealthCheck.function_scoped_fixture])
SECRET = "secret_word_of_an_outside_file"
ARM = Path("robot") / "ur5e" / "ur5e.urdf.xacro"

CELL_PIECES = ["\n", ": ", "- ", "[", "]", "{", "}", "'", '"', "&a ", "*a", "!!python/object:os.system ", ".nan",
               "-1", "1e999", "0", "../outside/secret.yaml", "/etc/passwd", "robot/../../outside/secret.yaml",
               "\x00", "é", "limits: ../outside/secret.yaml\n", "file: ../outside/secret.urdf\n"]
XACRO_PIECES = ["<", ">", "/>", "</robot>", '"', "${", "}", "$(", ")", "$(eval ", "$(env HOME)", "$(find x)",
                "__class__", "python.vars(python)", "python.type('x', (), {})", "'_'*2 + 'globals'",
                "&#36;(eval 1)", "&a;", "<!DOCTYPE r [<!ENTITY a \"aaaaaaaaaa\">]>",
                '<xacro:include filename="../../outside/secret.xacro"/>',
                "<xacro:include filename=\"${'x' + '.xacro'}\"/>", "${xacro.load_yaml('../../outside/secret.yaml')}",
                '<mesh filename="../../outside/secret.stl"/>', "nan", "-1", "1e999", "<joint", "</link>", "<link",
                'type="revolute"', 'lower="1" upper="-1"', "<mass value=\"nan\"/>", "\x00", "é", "\n", " ", "0",
                "<?ml x?>"]


def _folder(root: Path) -> Path:
    """A UR5e cell beside a copy of robot/ in ``root``/lab, and a folder of secrets beside it."""
    lab = root / "lab"
    if not lab.exists():
        shutil.copytree(ROBOT_DIR, lab / "robot", ignore=shutil.ignore_patterns("realism", "fr3", "parts", "lab"))
        shutil.copytree(ROBOT_DIR / "parts", lab / "robot" / "parts")
        shutil.copytree(ROBOT_DIR / "lab", lab / "robot" / "lab")
        outside = root / "outside"
        outside.mkdir()
        for name in ("secret.yaml", "secret.urdf", "secret.xacro", "secret.stl"):
            (outside / name).write_text(f"{SECRET}: 1\n")
    return lab


def _mutate(draw, text: str, pieces: list[str]) -> str:
    for _ in range(draw(st.integers(1, 4))):
        at = draw(st.integers(0, len(text)))
        if draw(st.booleans()):
            text = text[:at] + draw(st.sampled_from(pieces)) + text[at:]
        else:
            text = text[:at] + text[min(len(text), at + draw(st.integers(1, 12))):]
    return text


_CELL = (CELLS_DIR / "ur5e.yaml").read_text().replace("../robot/", "robot/")
_ARM = (ROBOT_DIR / "ur5e" / "ur5e.urdf.xacro").read_text()


@st.composite
def _cell_text(draw) -> str:
    return _mutate(draw, _CELL, CELL_PIECES)


@st.composite
def _arm_text(draw) -> str:
    return _mutate(draw, _ARM, XACRO_PIECES)


def _build(cell: Path) -> None:
    """What every command does with a cell first: read it, expand its description, build the
    kinematic model and the limits (the collision model, seconds per cell, is left out)."""
    from recon_cli.robot.description import CellConfig, expand_urdf
    from recon_cli.robot.kinematics import Kinematics
    from recon_cli.robot.limits import limits_from_urdf

    config = CellConfig(kind=str(cell))
    urdf = expand_urdf(config)
    Kinematics(urdf, config.cell_file)
    limits_from_urdf(urdf, config.cell_file.planning_joints, config.cell_file.limits)


def _check(cell: Path, root: Path) -> None:
    try:
        _build(cell)
    except ReconError as exc:
        line = exc.one_line()
        assert "\n" not in line and SECRET not in line, line
    assert not (root / "ran").exists()


def test_the_unmutated_cell_builds(tmp_path):
    lab = _folder(tmp_path)
    (lab / "cell.yaml").write_text(_CELL)
    _build(lab / "cell.yaml")


@_fuzz
@given(text=_cell_text())
def test_fuzz_cell_files(tmp_path_factory, text):
    root = _shared(tmp_path_factory)
    lab = _folder(root)
    cell = lab / "cell.yaml"
    cell.write_bytes(text.encode("utf-8", "surrogatepass"))
    _check(cell, root)


@_fuzz
@given(text=_arm_text())
def test_fuzz_cell_descriptions(tmp_path_factory, text):
    root = _shared(tmp_path_factory)
    lab = _folder(root)
    (lab / "cell.yaml").write_text(_CELL)
    (lab / ARM).write_bytes(text.replace("MARK", str(root / "ran")).encode("utf-8", "surrogatepass"))
    try:
        _check(lab / "cell.yaml", root)
    finally:
        (lab / ARM).write_text(_ARM)


_ROOTS: dict[int, Path] = {}


def _shared(factory) -> Path:
    """One folder for all examples of a test session (copying robot/ per example is slow)."""
    key = id(factory)
    if key not in _ROOTS:
        _ROOTS[key] = factory.mktemp("fuzz_cell")
    return _ROOTS[key]
