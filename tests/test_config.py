"""One configuration: the XSD's attribute defaults are the configuration's defaults, and a
run folder records the effective configuration."""

from __future__ import annotations

import pytest
import yaml
from lxml import etree

from recon_cli.config import DEFAULTS, write_config
from recon_cli.paths import SCHEMA_DIR

XS = "{http://www.w3.org/2001/XMLSchema}"


def _defaults(xsd: str) -> dict[tuple[str, str], str]:
    """(element, attribute) -> default of every attribute that has one."""
    root = etree.parse(str(SCHEMA_DIR / xsd)).getroot()
    out = {}
    for el in root.iter(f"{XS}element"):
        for att in el.iter(f"{XS}attribute"):
            if att.get("default") is not None and att.getparent() is not None:
                owner = att
                while owner is not None and owner.tag != f"{XS}element":
                    owner = owner.getparent()
                if owner is el:
                    out[(el.get("name"), att.get("name"))] = att.get("default")
    return out


def test_xsd_defaults_are_the_configuration():
    d = _defaults("recon_script.xsd")
    surface, plan = DEFAULTS.registration.surface, DEFAULTS.planner
    expected = {
        ("cell", "kind"): DEFAULTS.cell.kind.value,
        ("cell", "resolution"): DEFAULTS.sensor.resolution,
        ("cell", "noise"): DEFAULTS.sensor.noise,
        ("object", "scale"): DEFAULTS.scene.object_scale,
        ("box", "margin"): DEFAULTS.scene.box_margin,
        ("planner", "name"): plan.planner,
        ("planner", "time"): plan.time_limit,
        ("planner", "velocity_scale"): plan.velocity_scale,
        ("planner", "acceleration_scale"): plan.acceleration_scale,
        ("register", "local"): DEFAULTS.registration.local,
        ("register", "board"): DEFAULTS.registration.use_board,
        ("register", "loop_closures"): DEFAULTS.registration.multiway.loop_closure_init,
        ("reconstruct", "voxel"): surface.voxel,
        ("reconstruct", "depth"): surface.poisson_depth,
        ("reconstruct", "trim"): surface.density_quantile,
    }
    # the safety distance has no XSD default: a script's cell brings its own (its cell file's)
    assert ("cell", "safety_distance") not in d
    for key, value in expected.items():
        written = d[key]
        if isinstance(value, bool):
            assert written == str(value).lower(), key
        elif isinstance(value, (int, float)):
            assert float(written) == float(value), key
        else:
            assert written == value, key


def test_config_yaml_round_trip(tmp_path):
    path = write_config(tmp_path, DEFAULTS, command="test")
    data = yaml.safe_load(path.read_text())
    assert data["format"] == 1 and data["run"] == {"command": "test"}
    assert data["planner"]["velocity_scale"] == DEFAULTS.planner.velocity_scale
    assert data["viewplan"]["d_c"] == DEFAULTS.viewplan.d_c
    assert data["cell"]["kind"] == "gantry"


# ----------------------------------------------------------------------------- from_dict
def _doc(data: dict, where: str = "config.yaml"):
    """``data`` as the YAML reader returns it (with the lines of its keys)."""
    from recon_cli.inputs.yamlfile import parse_yaml

    return parse_yaml(yaml.safe_dump(data, sort_keys=False), where)


def test_config_round_trip_to_dict_from_dict():
    import dataclasses

    import numpy as np

    from recon_cli.config import Config
    from recon_cli.perception.charuco import thesis_board
    from recon_cli.realism import load_profile
    from recon_cli.reconstruction.crop import CropBox
    from recon_cli.robot.description import CellConfig, CellKind

    T = np.eye(4)
    T[:3, 3] = (0.1, -0.2, 0.8)
    config = DEFAULTS.replace(
        seed=12345, realism=load_profile("thesis"),
        cell=CellConfig(kind=CellKind.CEILING, safety_distance=0.05),
        registration=dataclasses.replace(DEFAULTS.registration, board=thesis_board(), perturb=(0.002, 0.01),
                                         box=CropBox(T, (0.2, 0.3, 0.4)), local=False),
        viewplan=dataclasses.replace(DEFAULTS.viewplan, n=5, d_c=0.6))
    data = config.to_dict()
    again = Config.from_dict(_doc(data))
    assert again.to_dict() == data
    assert again.realism == config.realism and again.cell == config.cell and again.seed == 12345
    assert np.array_equal(again.registration.box.frame_T_box, T)
    assert Config.from_dict(_doc(DEFAULTS.to_dict())) == DEFAULTS
    # a part of a configuration: the rest keeps its defaults
    part = Config.from_dict(_doc({"sensor": {"resolution": 0.25}, "seed": 4}))
    assert part == DEFAULTS.replace(sensor=dataclasses.replace(DEFAULTS.sensor, resolution=0.25), seed=4)


@pytest.mark.parametrize("edit, line, needle", [
    (lambda d: d["viewplan"].update(bogus=1), 11, "viewplan.bogus is not a known key"),
    (lambda d: d["sensor"].update(resolution=3.0), 6, "sensor.resolution = 3 is outside [0.05, 1]"),
    (lambda d: d.update(seed=-1), 11, "seed = -1 is outside [0, 4.29497e+09]"),
    (lambda d: d["planner"].update(planner="RRTfast"), 8, "planner.planner is not one of"),
    (lambda d: d["scene"].update(object_name=""), 2, "scene: the object name is empty or not a text"),
])
def test_bad_config_is_one_line_with_file_and_line(tmp_path, edit, line, needle):
    from recon_cli.config import read_config
    from recon_cli.errors import InputError

    data = {"format": 1, "scene": {"object_name": "bottle"}, "sensor": {"noise": True, "resolution": 0.5},
            "planner": {"planner": "RRTConnect"}, "viewplan": {"n": 3}, "seed": 0}
    edit(data)
    path = tmp_path / "config.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    with pytest.raises(InputError) as exc:
        read_config(path)
    text = exc.value.one_line()
    assert "\n" not in text and needle in text, text
    assert text.startswith(f"{path}:{line}: "), text


def test_sections_validate_themselves():
    from recon_cli.config import SceneConfig, SensorConfig
    from recon_cli.errors import InputError
    from recon_cli.reconstruction.options import MultiwayOptions, SurfaceOptions

    for make, needle in ((lambda: SensorConfig(resolution=0.01), "image scale = 0.01 is outside 0.05 ... 1"),
                         (lambda: SceneConfig(object_scale=0.0), "object scale 0.0 is not a positive number"),
                         (lambda: MultiwayOptions(anchor="middle"), "pose graph anchor 'middle' is not one of"),
                         (lambda: SurfaceOptions(voxel=0.0), "surface voxel = 0.0 m is not a positive number"),
                         (lambda: DEFAULTS.replace(seed=2**32), "seed 4294967296 is not a whole number")):
        with pytest.raises(InputError) as exc:
            make()
        assert needle in exc.value.one_line()


def test_the_image_scale_has_one_default_and_one_range():
    import json

    from recon_cli.config import RESOLUTION_RANGE
    from recon_cli.paths import SCHEMA_DIR

    station = json.loads((SCHEMA_DIR / "station.schema.json").read_text())
    sim = station["properties"]["camera"]["properties"]["sim"]
    sim = next(s for s in sim.get("anyOf", [sim]) if "properties" in s)["properties"]["resolution"]
    assert (sim["minimum"], sim["maximum"]) == RESOLUTION_RANGE
    config = json.loads((SCHEMA_DIR / "config.schema.json").read_text())["properties"]["sensor"]["properties"]
    assert (config["resolution"]["minimum"], config["resolution"]["maximum"]) == RESOLUTION_RANGE


def test_the_schema_names_every_field_of_every_section():
    import dataclasses
    import json

    from recon_cli.config import Config
    from recon_cli.paths import SCHEMA_DIR

    schema = json.loads((SCHEMA_DIR / "config.schema.json").read_text())

    def check(cls, node, path):
        props = node["properties"]
        assert set(props) >= {f.name for f in dataclasses.fields(cls)}, path
        for f in dataclasses.fields(cls):
            value = getattr(cls(), f.name) if path != "registration" or f.name not in ("box", "board") else None
            if dataclasses.is_dataclass(value):
                sub = props[f.name]
                check(type(value), sub, f"{path}.{f.name}")

    check(Config, schema, "")
    assert set(schema["properties"]) == {"format", "run", *(f.name for f in dataclasses.fields(Config))}


# ----------------------------------------------------------------------------- --config through the CLI
def test_cli_bad_config_file_is_one_line_exit_1(tmp_path, capsys):
    from recon_cli.cli import main

    bad = tmp_path / "config.yaml"
    bad.write_text("format: 1\nsensor:\n  noise: true\n  resolutoin: 0.5\n")
    for argv in (["autoscan", "--config", str(bad), "--out", str(tmp_path / "a")],
                 ["capture", "--config", str(bad), "--out", str(tmp_path / "c")],
                 ["register", "--config", str(bad)],
                 ["run", "--config", str(bad)]):
        code = main(argv)
        out, err = capsys.readouterr()
        lines = [line for line in err.splitlines() if line.strip()]
        assert code == 1 and len(lines) == 1 and "Traceback" not in out + err, (argv, err)
        assert lines[0].startswith(f"error: {bad}:4: sensor.resolutoin is not a known key"), lines[0]
    assert not (tmp_path / "a").exists() and not (tmp_path / "c").exists()
    missing = tmp_path / "nothing.yaml"
    code = main(["capture", "--config", str(missing)])
    err = capsys.readouterr().err
    assert code == 1 and f"configuration file {missing} does not exist" in err


def test_cli_config_of_another_command_is_refused(tmp_path, capsys):
    from recon_cli.cli import main

    path = write_config(tmp_path, DEFAULTS, command="autoscan")
    code = main(["capture", "--config", str(path), "--out", str(tmp_path / "c")])
    err = capsys.readouterr().err
    assert code == 1 and f"{path}:" in err and ": run.command: this config.yaml was written by recon autoscan; " \
                                              "give one written by recon capture" in err, err
