"""One configuration: the XSD's attribute defaults are the configuration's defaults, and a
run folder records the effective configuration."""

from __future__ import annotations

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
        ("cell", "safety_distance"): DEFAULTS.cell.safety_distance,
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
