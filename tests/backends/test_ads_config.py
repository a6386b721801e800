"""The safety values of a station file's robot.ads section: every numeric value finite and in
its documented range, every wrong type one line, through `recon station check FILE` (exit 1,
one line, no traceback) and through AdsConfig itself; the ranges table of docs/hardware.md
equal to the code's."""

from __future__ import annotations

import math
import re
from dataclasses import fields, replace
from pathlib import Path

import pytest

from recon_cli.backends.hardware.ads import PAIRS, RANGES, AdsConfig, range_rows
from recon_cli.cli import main
from recon_cli.errors import InputError

DOCS = Path(__file__).resolve().parents[2] / "docs" / "hardware.md"
NON_NUMERIC = {"ams_net_id", "ip", "symbols", "axes"}
NAN, INF = float("nan"), float("inf")


def _station(key: str, value: str) -> tuple[str, int]:
    """A station file with ``robot.ads.key: value`` on a line of its own, and that line."""
    lines = ["format: 1", "name: check", "robot:", "  adapter: ads", "  ads:",
             "    ams_net_id: 127.0.0.1.1.1", f"    {key}: {value}", "camera:", "  adapter: sim"]
    return "\n".join(lines) + "\n", next(i for i, line in enumerate(lines, start=1) if line.startswith(f"    {key}:"))


def _bad_values() -> list[tuple[str, str]]:
    """For every numeric key: NaN, infinities, a value below and above its range, a text."""
    cases = []
    for key, (ranges, _, _) in RANGES.items():
        r = ranges[0]
        if key in PAIRS:
            good = [ranges[0].hi / 2, ranges[1].hi / 2]
            for k in (0, 1):
                for bad in (".nan", ".inf", "-.inf", "1e999", "0", str(ranges[k].hi * 10), "-1"):
                    pair = [str(v) for v in good]
                    pair[k] = bad
                    cases.append((key, f"[{', '.join(pair)}]"))
            cases += [(key, "[0.01]"), (key, "0.01"), (key, "[a, b]")]
            continue
        if key == "scale":
            ones = "1, " * 8  # the cell has 9 joints
            cases += [(key, f"[{ones}{v}]") for v in (".nan", ".inf", "1e999", "0", "1e-9", "-1e9", "x")]
            cases += [(key, "1000")]
            continue
        below = r.lo - 1 if r.whole else (r.lo if r.lo_open else r.lo - abs(r.lo) / 2 - 1e-3)
        above = r.hi + 1 if r.whole else r.hi * 2 + 1
        for bad in (".nan", ".inf", "-.inf", "1e999", repr(below), repr(above), "fast", "[1, 2]", "true"):
            cases.append((key, bad))
    return cases


@pytest.mark.parametrize("key, value", _bad_values())
def test_station_check_refuses_bad_safety_values(key, value, tmp_path, capsys):
    text, line = _station(key, value)
    path = tmp_path / "cell.yaml"
    path.write_text(text)
    assert main(["station", "check", str(path)]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err and err.startswith("error: "), err
    assert key in err or f"{path}:{line}:" in err, err  # names the key or its line


@pytest.mark.parametrize("mapping, message", [
    ({"ams_net_id": "5.80.201.232.1"}, r"ams_net_id is not an AMS Net ID"),
    ({"ams_net_id": "5.80.201.232.1.256"}, r"is not an AMS Net ID; six numbers 0-255"),
    ({"ams_net_id": 5.8}, r"ams_net_id is not an AMS Net ID"),
    ({"ip": 192}, r"ip is not an address"),
    ({"ip": ["192.168.0.1"]}, r"ip is not an address"),
    ({"ip": "192.168.0.1; rm"}, r"is not an address"),
    ({"symbols": ["MAIN.recon"]}, r"symbols is not a mapping"),
    ({"symbols": {"prefix": 5}}, r"symbols.prefix is not a symbol name"),
    ({"symbols": {"stop": ["a"]}}, r"symbols.stop is not a symbol name"),
    ({"symbols": {5: "MAIN.x"}}, r"symbols.5 is not a symbol of the contract"),
    ({"symbols": {"stop": "GVL stop"}}, r"symbols.stop is not a symbol name \(1 to 255 characters, no spaces\)"),
    ({"axes": "arm_joint_1"}, r"axes is not a list of joint names"),
    ({"axes": [1, 2]}, r"axes is not a list of joint names"),
    ({"axes": ["a", "a"]}, r"axes names a joint twice"),
    ({"axes": ["a", "b"], "scale": [1, 2, 3]}, r"scale has 3 numbers for 2 axes"),
    ({"poll": 0.05, "watchdog": 0.2}, r"poll = 0.05 s is more than watchdog / 5 = 0.04 s"),
    ({"watchdog": 0.04}, r"poll = 0.02 s is more than watchdog / 5 = 0.008 s"),
    ({"settle_tolerance": [0.01, 0.001], "tracking_bound": [0.005, 0.005]},
     r"settle_tolerance\[0\] = 0.01 rad is more than tracking_bound\[0\] = 0.005 rad"),
    ({"settle_tolerance": [1e-12, 5e-5]},
     r"settle_tolerance\[0\] = 1e-12 rad is below 4 counts of the encoder resolution encoder_resolution\[0\] = "
     r"1.46292e-09 rad: a drive at rest reads ±1 count, so no drive could ever settle within it"),
    ({"settle_tolerance": [2e-4, 3e-6], "encoder_resolution": [1e-7, 1e-6]},
     r"settle_tolerance\[1\] = 3e-06 m is below 4 counts of the encoder resolution encoder_resolution\[1\] = 1e-06 m"),
    ({"port": 851.5}, r"port = 851.5 is not a whole number"),
    ({"port": True}, r"port is true, not a whole number"),
    ({"watchdog": NAN}, r"watchdog = nan is not a finite number"),
    ({"tracking_bound": [NAN, 0.005]}, r"tracking_bound\[0\] = nan is not a finite number"),
    ({"tracking_bound": [0.02, INF]}, r"tracking_bound\[1\] = inf is not a finite number"),
    ({"time_margin": INF}, r"time_margin = inf is not a finite number"),
    ({"limit_tolerance": NAN}, r"limit_tolerance = nan is not a finite number"),
    ({"scale": [1.0, NAN]}, r"scale\[1\] = nan is not a finite number"),
    ({"scale": [1.0, 0.0]}, r"scale\[1\] = 0 is outside ±\[1e-06, 1e\+06\]"),
])
def test_wrong_types_and_values_are_one_line(mapping, message):
    with pytest.raises(InputError, match=message) as info:
        AdsConfig.from_mapping(mapping, "cell.yaml: robot.ads")
    assert "\n" not in info.value.one_line() and info.value.one_line().startswith("cell.yaml: robot.ads.")
    texts = [v for value in mapping.values() for v in (value.values() if isinstance(value, dict) else
                                                         value if isinstance(value, list) else [value])]
    assert not [t for t in texts if isinstance(t, str) and len(t) > 3 and t in info.value.message], \
        info.value.message  # not quoted


def test_every_nonfinite_value_is_refused_also_when_built_in_code():
    """AdsConfig checks itself: replace() or a constructor cannot switch a check off."""
    for f in fields(AdsConfig):
        if f.name in NON_NUMERIC:
            continue
        for bad in (NAN, INF, -INF):
            value = (bad, 0.005) if f.name in PAIRS else (1.0, bad) if f.name == "scale" else bad
            with pytest.raises(InputError, match=rf"robot\.ads\.{f.name}(\[\d\])? = -?(nan|inf) is not a"):
                replace(AdsConfig(), **{f.name: value})


def test_line_numbers_when_the_reader_knows_them():
    class Map(dict):  # what the YAML reader returns: a dict that knows the line of each key
        lines: dict

    d = Map(watchdog=NAN)
    d.lines = {"watchdog": 12}
    with pytest.raises(InputError, match=r"^cell.yaml:12: robot.ads.watchdog = nan is not a finite number"):
        AdsConfig.from_mapping(d, "cell.yaml: robot.ads")


def test_every_numeric_value_has_a_range_and_the_defaults_are_inside():
    numeric = {f.name for f in fields(AdsConfig)} - NON_NUMERIC
    assert numeric == set(RANGES)
    cfg = AdsConfig()
    for key, (ranges, _, _) in RANGES.items():
        values = getattr(cfg, key)
        for r, v in zip(ranges, values if isinstance(values, tuple) else (values,), strict=False):
            assert math.isfinite(v) and (r.lo < v if r.lo_open else r.lo <= v) and v <= r.hi, key


def test_docs_table_equals_the_code():
    """docs/hardware.md's ranges table is the code's, row for row."""
    text = DOCS.read_text(encoding="utf-8").split("## 3. Safety values")[1].split("## 4.")[0]
    rows = range_rows()
    for row in rows:
        assert row in text, f"docs/hardware.md lacks the row\n{row}"
    documented = re.findall(r"^\| `(\w+)` \| [\[(]", text, flags=re.M)
    assert documented == list(RANGES), "the docs table has other rows or another order than RANGES"


def test_docs_franka_table_equals_the_code():
    """docs/hardware.md's Franka safety values are the code's, row for row."""
    from recon_cli.backends.hardware import franka_config

    text = DOCS.read_text(encoding="utf-8").split("## 7. Franka")[1].split("## 8.")[0]
    for row in franka_config.range_rows():
        assert row in text, f"docs/hardware.md lacks the row\n{row}"
    documented = re.findall(r"^\| `(\w+)` \| [\[(]", text, flags=re.M)
    assert documented == list(franka_config.RANGES)


def test_the_documented_example_is_valid():
    """The station file of docs/hardware.md passes the checks (its axes are the cell's joints)."""
    import yaml

    from recon_cli.robot.cell import Cell
    from recon_cli.robot.description import CellConfig

    text = DOCS.read_text(encoding="utf-8")
    example = yaml.safe_load(text.split("```yaml\n", 1)[1].split("```", 1)[0])
    cfg = AdsConfig.from_mapping(example["robot"]["ads"])
    assert sorted(cfg.axes) == sorted(Cell(CellConfig()).joint_names) and len(cfg.scale) == len(cfg.axes)


@pytest.mark.parametrize("robot, message", [
    ("  adapter: ads\n  ads: {ams_net_id: 127.0.0.1.1.1, settle_tolerance: [1.0e-12, 5.0e-5]}\n",
     ":5: robot.ads.settle_tolerance[0] = 1e-12 rad is below 4 counts of the encoder resolution "
     "encoder_resolution[0] = 1.46292e-09 rad"),
    ("  adapter: franka\n  franka: {ip: 172.16.0.2, settle_tolerance: 1.0e-12}\n",
     ":5: robot.franka.settle_tolerance = 1e-12 rad is below 4 counts of the finest joint encoder (resolution "
     "1.46292e-09 rad"),
])
def test_a_settle_tolerance_no_drive_can_meet_is_refused(tmp_path, capsys, robot, message):
    """1e-12 rad is inside (0, 0.01] rad but finer than any encoder counts: refused with the
    encoder resolution, before anything connects."""
    path = tmp_path / "station.yaml"
    path.write_text("format: 1\nname: check\nrobot:\n" + robot + "camera:\n  adapter: sim\n")
    assert main(["station", "check", str(path)]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err and f"{path}{message}" in err, err
