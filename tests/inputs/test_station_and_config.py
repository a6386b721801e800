"""Station files and the config.yaml of --config, read as a careless or hostile user would
write them: a file that is a link leading out of its folder is refused before it is read, a
cell file a station names stays in the station file's folder, no refusal quotes what was
read, a number that is not finite is named by its key path, a config.yaml takes the values
the command line takes (the options' ranges) and is refused when another command wrote it.
Each test is a row of docs/inputs.md ("Station files and --config")."""

from __future__ import annotations

import json
import textwrap
from pathlib import Path

import pytest
import yaml

from recon_cli.cli import main
from recon_cli.config import DEFAULTS, write_config
from recon_cli.paths import SCHEMA_DIR

STATION = "format: 1\nrobot: {adapter: sim}\ncamera: {adapter: sim}\n"
SECRET = "root:x:0:0:root:/root:/bin/bash SECRET_LINE_OF_THE_OUTSIDE_FILE\n"


def _one_line_error(capsys, argv: list[str], code: int = 1) -> str:
    assert main(argv) == code
    out, err = capsys.readouterr()
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: ") and "Traceback" not in out + err, err
    return lines[0]


def _outside(tmp_path: Path) -> Path:
    """A file outside the folder of the file under test, holding text that must not be shown."""
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "passwd").write_text(SECRET)
    (outside / "cell.yaml").write_text("secret_key_of_the_outside_file: 1\n")
    return outside


# ----------------------------------------------------------------------------- station files
def test_a_station_file_linked_out_of_its_folder_is_not_read(tmp_path, capsys):
    outside = _outside(tmp_path)
    (tmp_path / "cell").mkdir()
    station = tmp_path / "cell" / "station.yaml"
    station.symlink_to(outside / "passwd")
    line = _one_line_error(capsys, ["station", "check", str(station)])
    assert f"station file {station} is a link leading out of its folder {station.parent}; not read" in line, line
    assert "SECRET" not in line and "root:x" not in line and str(outside) not in line
    inside = tmp_path / "cell" / "lab.yaml"  # a link inside the folder is followed
    inside.write_text(STATION)
    (tmp_path / "cell" / "current.yaml").symlink_to("lab.yaml")
    assert main(["station", "check", str(tmp_path / "cell" / "current.yaml")]) == 0
    capsys.readouterr()


def test_a_station_file_that_is_not_yaml_is_named_not_shown(tmp_path, capsys):
    station = tmp_path / "station.yaml"
    station.write_text(SECRET)
    line = _one_line_error(capsys, ["station", "check", str(station)])
    assert f"{station}: the file is a text of {len(SECRET.strip())} characters, not a mapping" in line, line
    assert "SECRET" not in line and "root:x" not in line


@pytest.mark.parametrize("kind", ["../outside/cell.yaml", "{outside}/cell.yaml", "link.yaml"])
def test_a_cell_file_a_station_names_stays_in_its_folder(tmp_path, capsys, kind):
    outside = _outside(tmp_path)
    folder = tmp_path / "cell"
    folder.mkdir()
    (folder / "link.yaml").symlink_to(outside / "cell.yaml")
    station = folder / "station.yaml"
    station.write_text(STATION + f"cell: {{kind: {kind.format(outside=outside)}}}\n")
    line = _one_line_error(capsys, ["station", "check", str(station)])
    assert f"{station}:4: cell.kind names a file outside the station file's folder {folder}" in line, line
    assert "secret_key" not in line


@pytest.mark.parametrize("text, message", [
    (STATION + "hand_eye:\n  - [.nan, 0, 0, 0]\n  - [0, 1, 0, 0]\n  - [0, 0, 1, 0]\n  - [0, 0, 0, 1]\n",
     ":5: hand_eye[0][0] = nan is not a finite number"),
    (STATION.replace("camera: {adapter: sim}", "camera:\n  adapter: sim\n  sim: {resolution: -.inf}"),
     ":5: camera.sim.resolution = -inf is not a finite number"),
    ("format: 1\nrobot:\n  adapter: ads\n  ads: {ams_net_id: 127.0.0.1.1.1, poll: 1e999}\ncamera: {adapter: sim}\n",
     ":4: robot.ads.poll = inf is not a finite number"),
])
def test_a_number_that_is_not_finite_is_named_by_its_key_path(tmp_path, capsys, text, message):
    station = tmp_path / "station.yaml"
    station.write_text(text)
    line = _one_line_error(capsys, ["station", "check", str(station)])
    assert f"{station}{message}" in line, line


@pytest.mark.parametrize("text, secret", [
    (STATION + "secret_key: 1\n", None),  # a key that is a plain name is named (a typo must be found)
    (STATION + "'root:x:0:0:root': 1\n", "root:x"),
    ("format: 1\nrobot: {adapter: SECRET_VALUE}\ncamera: {adapter: sim}\n", "SECRET_VALUE"),
    ("format: 1\nrobot:\n  adapter: ads\n  ads: {ams_net_id: SECRET_VALUE}\ncamera: {adapter: sim}\n", "SECRET_VALUE"),
    ("format: 1\nrobot:\n  adapter: ads\n  ads: {ams_net_id: 127.0.0.1.1.1, ip: 'SECRET VALUE'}\n"
     "camera: {adapter: sim}\n", "SECRET"),
    ("format: 1\nrobot:\n  adapter: ads\n  ads: {ams_net_id: 127.0.0.1.1.1, symbols: {stop: 'SECRET VALUE'}}\n"
     "camera: {adapter: sim}\n", "SECRET"),
    ("format: 1\nrobot: {adapter: sim}\ncamera:\n  adapter: realsense\n  realsense: {width: SECRET_VALUE}\n",
     "SECRET_VALUE"),
    ("format: 1\nrobot: {adapter: sim}\ncamera:\n  adapter: replay\n  replay: {source: x, loop: SECRET_VALUE}\n",
     "SECRET_VALUE"),
    ("format: 1\ncell: {kind: SECRET_VALUE}\nrobot: {adapter: sim}\ncamera: {adapter: sim}\n", "SECRET_VALUE"),
    ("format: 1\nrobot: {adapter: sim}\ncamera: {adapter: sim}\nname: !SECRET_TAG x\n", "SECRET_TAG"),
    ("format: 1\nrobot: {adapter: sim}\ncamera: {adapter: sim}\nname: \"SECRET\\q\"\n", "SECRET"),
])
def test_no_refusal_quotes_a_text_of_the_file(tmp_path, capsys, text, secret):
    """Texts, tags and keys that are not plain names are described, never repeated."""
    station = tmp_path / "station.yaml"
    station.write_text(text)
    line = _one_line_error(capsys, ["station", "check", str(station)])
    assert line.startswith(f"error: {station}:"), line
    if secret is not None:
        assert secret not in line, line
    else:
        assert "secret_key is not a known key" in line


# ----------------------------------------------------------------------------- --config
def _config(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "run" / "config.yaml"
    path.parent.mkdir(exist_ok=True)
    path.write_text(textwrap.dedent(text))
    return path


def test_a_config_linked_to_a_system_file_is_not_read(tmp_path, capsys):
    outside = _outside(tmp_path)
    (tmp_path / "run").mkdir()
    config = tmp_path / "run" / "config.yaml"
    config.symlink_to(outside / "passwd")
    line = _one_line_error(capsys, ["autoscan", "--config", str(config), "--out", str(tmp_path / "out")])
    assert f"{config}" in line and "link leading out of" in line, line
    assert "SECRET" not in line and "root:x" not in line
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("command, text, message", [
    ("register", """\
        format: 1
        registration:
          surface: {voxel: 1.0e-9}
        run: {command: register, store: nowhere}
        """, ":3: registration.surface.voxel = 1e-09 m is outside [0.0001, 0.1] m"),
    ("capture", """\
        format: 1
        planner: {time_limit: 0.01}
        run: {command: capture}
        """, ":2: planner.time_limit = 0.01 is outside 0.1 ... 3600, the range of --planning-time"),
    ("capture", """\
        format: 1
        scene: {object_scale: 1.0e-9}
        run: {command: capture}
        """, ":2: scene.object_scale = 1e-09 is outside 1e-06 ... 1000, the range of --scale"),
    ("capture", """\
        format: 1
        run:
          command: capture
          view: {radius: 50}
        """, ":4: run.view.radius = 50 is outside 0.001 ... 10, the range of --radius"),
    ("capture", """\
        format: 1
        run:
          command: capture
          view: {theta: SECRET_VALUE}
        """, ":4: run.view.theta is a text, not a number (the value of --theta)"),
    ("autoscan", """\
        format: 1
        registration:
          surface: {poisson_depth: 16}
        run: {command: autoscan}
        """, ":3: registration.surface.poisson_depth = 16 is outside [5, 12]"),
])
def test_a_config_takes_what_the_command_line_takes(tmp_path, capsys, command, text, message):
    """A value the config gives in place of an option is refused outside that option's range
    (what `--voxel 1e-9` on the command line is), before anything runs."""
    config = _config(tmp_path, text)
    line = _one_line_error(capsys, [command, "--config", str(config), "--out", str(tmp_path / "out")]
                           if command != "register" else [command, "--config", str(config)])
    assert f"{config}{message}" in line and "SECRET" not in line, line
    assert not (tmp_path / "out").exists()


def test_the_config_schema_has_the_ranges_of_the_options_and_the_script():
    """registration.surface: the ranges of recon register --voxel/--depth/--trim, which are a
    script's <reconstruct voxel/depth/trim> too."""
    import typer

    from recon_cli.cli import app

    schema = json.loads((SCHEMA_DIR / "config.schema.json").read_text())
    surface = schema["properties"]["registration"]["properties"]["surface"]["properties"]
    register = typer.main.get_command(app).get_command(None, "register")
    options = {p.name: (p.min, p.max) for p in register.params}
    xsd = (SCHEMA_DIR / "recon_script.xsd").read_text().split('<xs:element name="reconstruct">')[1][:1200]
    for option, key in (("voxel", "voxel"), ("depth", "poisson_depth"), ("trim", "density_quantile")):
        assert (surface[key]["minimum"], surface[key]["maximum"]) == options[option], key
        lo, hi = options[option]
        part = xsd.split(f'name="{option}"')[1][:300]
        assert f'<xs:minInclusive value="{lo:g}"/>' in part and f'<xs:maxInclusive value="{hi:g}"/>' in part, option
    assert yaml.safe_load(yaml.safe_dump(DEFAULTS.to_dict()))["registration"]["surface"]["voxel"] == 0.001


@pytest.mark.parametrize("written, command, message", [
    ("register", "autoscan", "run.command: this config.yaml was written by recon register; give one written by "
                             "recon autoscan; repeat it with recon register --config"),
    ("calibrate", "capture", "run.command: this config.yaml was written by recon calibrate; give one written by "
                             "recon capture"),
    ("SECRET_VALUE", "autoscan", "run.command names no command that writes a config.yaml"),
])
def test_the_config_of_another_command_is_refused_by_name(tmp_path, capsys, written, command, message):
    (tmp_path / "run").mkdir()
    path = write_config(tmp_path / "run", DEFAULTS, command=written)
    line = _one_line_error(capsys, [command, "--config", str(path), "--out", str(tmp_path / "out")])
    assert f"{path}:" in line and message in line and "SECRET" not in line, line
    assert not (tmp_path / "out").exists()


def test_a_config_recon_wrote_is_taken_back(tmp_path, capsys):
    """The defaults a command writes lie inside its options' ranges: a run is repeated from its
    folder (here up to the missing scan store of the register run)."""
    (tmp_path / "run").mkdir()
    path = write_config(tmp_path / "run", DEFAULTS, command="register", store=str(tmp_path / "nowhere"))
    line = _one_line_error(capsys, ["register", "--config", str(path)])
    assert "nowhere is not a folder" in line, line
