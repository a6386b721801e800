"""A cell file is a user's file: its xacro description runs no code, whoever names the cell
(the command line, a script, a station file), and nothing it names is read from outside the
cell file's folder and recon's robot/ folder. Each case is refused in one line before it
reads or runs anything."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from recon_cli.cli import main
from recon_cli.paths import CELLS_DIR, ROBOT_DIR

HEAD = '<?xml version="1.0"?>\n'
ARM = "ur5e/ur5e.urdf.xacro"


def _cell(folder: Path) -> Path:
    """The UR5e cell file beside a copy of robot/ in ``folder`` (its paths relative to the copy)."""
    shutil.copytree(ROBOT_DIR, folder / "robot", ignore=shutil.ignore_patterns("realism"))
    cell = folder / "cell.yaml"
    cell.write_text((CELLS_DIR / "ur5e.yaml").read_text().replace("../robot/", "robot/"))
    return cell


def _insert(folder: Path, xml: str, file: str = ARM) -> None:
    """Put ``xml`` into the description right after <link name="world"/>."""
    path = folder / "robot" / file
    text = path.read_text()
    assert '<link name="world"/>' in text
    path.write_text(text.replace('<link name="world"/>', '<link name="world"/>\n  ' + xml, 1))


def _one_line_error(capsys, *words: str) -> str:
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in captured.err, captured.err
    for w in words:
        assert w in lines[0], (w, lines[0])
    return lines[0]


def _marker(tmp_path: Path) -> Path:
    return tmp_path / "ran"


#: descriptions that would run ``touch MARK`` through xacro's expressions, each written differently
PAYLOADS = {
    "dunder by name": '<link name="${().__class__.__base__.__subclasses__()}"/>',
    "dunder built at run time": "<link name=\"${python.getattr(python, '_'*2 + 'import' + '_'*2)('os')}\"/>",
    "builtins through python.vars": '<link name="${python.vars(python)}"/>',
    "a class through python.type": "<link name=\"${python.type('x', (), {})}\"/>",
    "eval": "<link name=\"$(eval __import__('os').system('touch MARK'))\"/>",
    "eval split by an expression": "<link name=\"$(${'eval'} __import__('os').system('touch MARK'))\"/>",
    "eval by character references": "<link name=\"&#36;(eval __import__('os').system('touch MARK'))\"/>",
    "lambda": "<link name=\"${(lambda: 0).__globals__}\"/>",
    "an include named by an expression": '<xacro:include filename="${\'evil\' + \'.xacro\'}"/>',
    "an include made by xacro:element": '<xacro:element xacro:name="xacro:include" filename="evil.xacro"/>',
    "the environment": '<link name="$(env HOME)"/>',
    "os.system reached through python.vars and python.type": (
        "<xacro:property name=\"u\" value=\"${'_'*2}\"/>\n"
        '  <xacro:property name="obj" value="${python.int.mro()[1]}"/>\n'
        "  <xacro:property name=\"ga\" value=\"${python.vars(obj)[u+'getattribute'+u]}\"/>\n"
        "  <xacro:property name=\"subs\" value=\"${python.vars(python.type)[u+'subclasses'+u](obj)}\"/>\n"
        "  <xacro:property name=\"wc\" value=\"${[c for c in subs if ga(c, u+'name'+u) == '_wrap_close'][0]}\"/>\n"
        "  <link name=\"${ga(ga(wc, u+'init'+u), u+'globals'+u)['system']('touch MARK')}\"/>"),
    "a file outside through load_yaml": "<link name=\"${xacro.load_yaml('../../../outside.yaml')}\"/>",
}
EVIL = ('<?xml version="1.0"?>\n<robot xmlns:xacro="http://www.ros.org/wiki/xacro">\n'
        "  <link name=\"$(eval __import__('os').system('touch MARK'))\"/>\n</robot>\n")


@pytest.mark.parametrize("name", list(PAYLOADS))
def test_a_cell_description_runs_no_code(tmp_path, capsys, monkeypatch, name):
    monkeypatch.chdir(tmp_path)
    cell = _cell(tmp_path / "lab")
    (tmp_path / "lab" / "robot" / "ur5e" / "evil.xacro").write_text(EVIL.replace("MARK", str(_marker(tmp_path))))
    (tmp_path / "outside.yaml").write_text("secret_of_the_outside_file: 9137462518\n")  # in no temporary path
    _insert(tmp_path / "lab", PAYLOADS[name].replace("MARK", str(_marker(tmp_path))))
    assert main(["cell", "--cell", str(cell)]) == 1
    line = _one_line_error(capsys, "ur5e.urdf.xacro:")
    assert "secret_of_the_outside_file" not in line and "9137462518" not in line
    assert not _marker(tmp_path).exists()


def test_a_script_whose_cell_file_runs_code_is_refused_by_validate_and_run(tmp_path, capsys):
    """`recon validate` and `recon run` of a script naming such a cell refuse it at the
    script's <cell> line; nothing runs, nothing is written."""
    cell = _cell(tmp_path)
    _insert(tmp_path, PAYLOADS["eval by character references"].replace("MARK", str(_marker(tmp_path))))
    script = tmp_path / "scan.xml"
    script.write_text(HEAD + f'<recon name="s">\n  <cell kind="{cell.name}"/>\n  <object name="bottle"/>\n'
                      '</recon>\n')
    assert main(["validate", str(script)]) == 1
    _one_line_error(capsys, "scan.xml:3:", "__import__")
    assert main(["run", str(script), "--out", str(tmp_path / "run")]) == 1
    _one_line_error(capsys, "scan.xml:3:")
    assert not _marker(tmp_path).exists() and not (tmp_path / "run").exists()


def test_a_station_file_naming_such_a_cell_is_refused(tmp_path, capsys):
    from tests.backends.test_station import STATION

    _cell(tmp_path)
    _insert(tmp_path, PAYLOADS["builtins through python.vars"])
    station = tmp_path / "station.yaml"
    station.write_text(STATION.replace("cell: {kind: gantry, safety_distance: 0.03}", "cell: {kind: cell.yaml}"))
    assert main(["station", "check", str(station)]) == 1
    _one_line_error(capsys, "vars() is not allowed")


# ----------------------------------------------------------------------------- the folder boundary
def _outside(tmp_path: Path) -> Path:
    out = tmp_path / "outside"
    out.mkdir()
    (out / "limits.yaml").write_text("secret_key_of_the_outside_file: 1\n")
    return out


@pytest.mark.parametrize("key, old, new", [
    ("limits", "limits: robot/ur5e/limits.yaml", "limits: ../outside/limits.yaml"),
    ("limits", "limits: robot/ur5e/limits.yaml", "limits: {outside}/limits.yaml"),
    ("camera.sensor", "sensor: robot/sensors/", "sensor: ../outside/"),
    ("description.file", "file: robot/ur5e/ur5e.urdf.xacro", "file: ../outside/arm.urdf"),
])
def test_files_a_cell_names_stay_in_its_folder(tmp_path, capsys, key, old, new):
    """`limits: ../outside/limits.yaml` (or an absolute path) is refused before it is read:
    nothing of the outside file is printed."""
    out = _outside(tmp_path)
    (out / "realsense_d435.yaml").write_text("secret_key_of_the_outside_file: 1\n")
    (out / "arm.urdf").write_text('<robot name="secret_key_of_the_outside_file"/>\n')
    cell = _cell(tmp_path / "lab")
    text = cell.read_text()
    assert old in text
    cell.write_text(text.replace(old, new.format(outside=out)))
    assert main(["cell", "--cell", str(cell)]) == 1
    line = _one_line_error(capsys, f"{key}:", "outside the cell file's folder")
    assert "secret_key" not in line


def test_a_link_leading_out_of_the_cell_folder_is_refused(tmp_path, capsys):
    out = _outside(tmp_path)
    cell = _cell(tmp_path / "lab")
    (tmp_path / "lab" / "robot" / "ur5e" / "limits.yaml").unlink()
    (tmp_path / "lab" / "robot" / "ur5e" / "limits.yaml").symlink_to(out / "limits.yaml")
    assert main(["cell", "--cell", str(cell)]) == 1
    line = _one_line_error(capsys, "limits:", "a link that leads outside")
    assert "secret_key" not in line


def test_a_collision_mesh_outside_the_cell_folder_is_refused_by_validate(tmp_path, capsys):
    """A URDF collision mesh ``../outside/part.stl`` is refused at `recon validate` of a
    script naming the cell, before the mesh is read."""
    out = _outside(tmp_path)
    (out / "part.stl").write_bytes(b"solid secret_key_of_the_outside_file\nendsolid\n")
    cell = _cell(tmp_path)
    _insert(tmp_path, '<link name="part"><collision><geometry><mesh filename="../../../outside/part.stl"/>'
                      '</geometry></collision></link>\n  <joint name="part_joint" type="fixed"><parent link="world"/>'
                      '<child link="part"/></joint>')
    for name in ("../../../outside/part.stl", f"file://{out}/part.stl", f"{out}/part.stl"):
        arm = tmp_path / "robot" / ARM
        text = arm.read_text()
        arm.write_text(text.replace(text.split('<mesh filename="')[1].split('"')[0], name))
        script = tmp_path / "scan.xml"
        script.write_text(HEAD + f'<recon name="s">\n  <cell kind="{cell.name}"/>\n  <object name="bottle"/>\n'
                          '</recon>\n')
        assert main(["validate", str(script)]) == 1
        line = _one_line_error(capsys, "scan.xml:3:", "part")
        assert "outside" in line and "secret_key" not in line


def test_a_cell_may_name_recons_own_robot_files(tmp_path):
    """Beside the cell file first, then recon's robot/ folder: a cell of its own folder uses
    the shipped sensor, board, drives and description by their plain relative paths."""
    cell = tmp_path / "cell.yaml"
    cell.write_text((CELLS_DIR / "ur5e.yaml").read_text().replace("../robot/", "").replace("name: ur5e", "name: mine"))
    assert main(["cell", "--cell", str(cell)]) == 0
