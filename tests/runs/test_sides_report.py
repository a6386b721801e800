"""``sides_report.json`` (recon_cli/runs/sides.py) reads back as written, and a broken or
hostile file is one MetadataError line naming the file: truncated JSON, wrong types, NaN,
numbers too large for a float or beyond the schema's bounds, a link to a device, a
dangling link, a folder in its place."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from recon_cli.errors import MetadataError
from recon_cli.runs import sides as sides_file


def _report() -> sides_file.SidesReport:
    registration = {"side1_T_side2": np.eye(4), "fitness": 0.97, "fitness_reverse": 0.89, "rmse_m": 0.00014,
                    "overlap": 0.63, "ambiguous": False, "shape_ambiguous": False, "reason": None, "candidates": 21,
                    "alternatives": [{"side1_T_side2": np.eye(4), "fitness": 0.95, "angle_deg": 180.0}]}
    return sides_file.SidesReport(
        object="toy_blocks", sides=2, turn={"by": "physics", "tilt_deg": 100.5, "settle_s": 0.35},
        seconds=22.4, side_seconds=[6.9, 5.0], side_scans=[5, 5], side_2_prior=None,
        registration=sides_file.registration_entry(registration, {"rotation_deg": 0.03, "translation_mm": 0.05}),
        coverage_whole=0.92, contributions={"side_1": 0.71, "side_2": 0.6},
        accuracy={"mean_mm": 0.02, "std_mm": 0.11, "within": {"±1 mm": 1.0}}, error=None,
        cloud="run/reconstruction/cloud.ply", mesh="run/reconstruction/mesh.ply")


def test_the_report_reads_back_as_written(tmp_path):
    report = _report()
    path = sides_file.write(tmp_path, report)
    assert path == tmp_path / sides_file.SIDES_REPORT and not list(tmp_path.glob(".*"))
    again = sides_file.read(tmp_path)
    assert again == sides_file.read(path)
    assert again.registration["side1_T_side2"] == np.eye(4).tolist()
    assert again.registration["truth"] == {"rotation_deg": 0.03, "translation_mm": 0.05}
    assert again.side_scans == [5, 5] and again.coverage_whole == 0.92 and again.turn["by"] == "physics"


def _written(tmp_path: Path) -> Path:
    return sides_file.write(tmp_path, _report())


def _edited(path: Path, edit) -> None:
    data = json.loads(path.read_text())
    edit(data)
    path.write_text(json.dumps(data))


def _truncated(path: Path) -> None:
    text = path.read_text()
    path.write_text(text[: len(text) // 2])


CASES = {
    "truncated": (_truncated, "is broken JSON"),
    "empty": (lambda p: p.write_text(""), "is broken JSON"),
    "not an object": (lambda p: p.write_text("[2]"), "holds a list, not a JSON object"),
    "sides as text": (lambda p: _edited(p, lambda d: d.update(sides="two")), "key 'sides'"),
    "scans as text": (lambda p: _edited(p, lambda d: d.update(side_scans=["5", 5])), "key 'side_scans[0]'"),
    "registration a list": (lambda p: _edited(p, lambda d: d.update(registration=[])), "key 'registration'"),
    "missing registration": (lambda p: _edited(p, lambda d: d.pop("registration")), "'registration' is a required"),
    "unknown key": (lambda p: _edited(p, lambda d: d.update(bogus=1)), "bogus"),
    "NaN": (lambda p: p.write_text(p.read_text().replace('"coverage_whole": 0.92', '"coverage_whole": NaN')),
            "not a finite number"),
    "Infinity": (lambda p: p.write_text(p.read_text().replace('"seconds": 22.4', '"seconds": Infinity')),
                 "not a finite number"),
    "too large for a float": (lambda p: p.write_text(p.read_text().replace('"seconds": 22.4', '"seconds": 1e999')),
                              "1e999"),
    "huge seconds": (lambda p: _edited(p, lambda d: d.update(seconds=1e300)), "key 'seconds'"),
    "huge integer": (lambda p: p.write_text(p.read_text().replace('"side_scans": [\n    5', '"side_scans": [\n    '
                                                                  + "9" * 40)),
                     "digits"),
    "coverage above 1": (lambda p: _edited(p, lambda d: d.update(coverage_whole=1.5)), "key 'coverage_whole'"),
    "fitness above 1": (lambda p: _edited(p, lambda d: d["registration"].update(fitness=7)),
                        "key 'registration.fitness'"),
    "pose not 4 x 4": (lambda p: _edited(p, lambda d: d["registration"].update(side1_T_side2=[[1, 0, 0]])),
                       "key 'registration.side1_T_side2'"),
    "huge number in the turn": (lambda p: _edited(p, lambda d: d["turn"].update(tilt_deg=1e300)),
                                "key 'turn.tilt_deg'"),
    "truth beyond half a turn": (lambda p: _edited(p, lambda d: d["registration"]["truth"].update(rotation_deg=400)),
                                 "key 'registration.truth.rotation_deg'"),
    "nested too deep": (lambda p: p.write_text('{"sides": 2, "registration": ' + "[" * 100 + "]" * 100 + "}"),
                        "nests lists and objects"),
    "a key twice": (lambda p: p.write_text('{"sides": 2, "sides": 2, "registration": {}}'), "twice"),
    "link to a device": (lambda p: (p.unlink(), p.symlink_to("/dev/zero")), "not a regular file (a character device)"),
    "dangling link": (lambda p: (p.unlink(), p.symlink_to(p.parent / "gone.json")), "is missing"),
    "link to itself": (lambda p: (p.unlink(), p.symlink_to(p)), "cannot be read"),
    "folder in its place": (lambda p: (p.unlink(), p.mkdir()), "sides_report.json is missing"),
}


@pytest.mark.parametrize("case", CASES)
def test_a_hostile_file_is_one_line_naming_it(case, tmp_path):
    path = _written(tmp_path)
    spoil, needle = CASES[case]
    spoil(path)
    with pytest.raises(MetadataError) as info:
        sides_file.read(path)
    line = info.value.one_line()
    assert "\n" not in line and str(path) in line and needle in line, line
    assert "Traceback" not in line


def test_a_link_to_a_good_report_is_read_as_the_report(tmp_path):
    """A link is followed to what it names: a regular file within the limits reads as any."""
    folder = tmp_path / "elsewhere"
    folder.mkdir()
    path = _written(folder)
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / sides_file.SIDES_REPORT).symlink_to(path)
    assert sides_file.read(tmp_path / "run") == sides_file.read(path)
