"""``sides_report.json`` (recon_cli/runs/sides.py) reads back as written, and a broken or
hostile file is one MetadataError line naming the file and never quoting what it holds:
truncated JSON, wrong types, NaN, numbers too large for a float or beyond the schema's
bounds, a huge or sparse 1 GB file (refused by its size before it is read), a FIFO, a link
leading out of the run folder (to a device, to /etc/passwd, to a good report elsewhere), a
dangling link, a folder in its place."""

from __future__ import annotations

import json
import os
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
    "link to a device": (lambda p: (p.unlink(), p.symlink_to("/dev/zero")), "is a link leading out of"),
    "link to /etc/passwd": (lambda p: (p.unlink(), p.symlink_to("/etc/passwd")), "is a link leading out of"),
    "FIFO": (lambda p: (p.unlink(), os.mkfifo(p)), "not a regular file (a FIFO)"),
    "huge": (lambda p: p.write_text('{"sides": 2, "registration": {}, "object": "' + "x" * (17 * 2**20) + '"}'),
             "more than the 16,777,216 recon reads"),
    "sparse 1 GB": (lambda p: os.truncate(p, 2**30), "has 1,073,741,824 bytes, more than"),
    "object a list": (lambda p: _edited(p, lambda d: d.update(object=["SECRET"])),
                      "key 'object' is a list, not a text or null"),
    "cloud a number": (lambda p: _edited(p, lambda d: d.update(cloud=12345)), "key 'cloud' is a whole number"),
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
    assert not any(word in line for word in ("SECRET", "root:", "xxxx", "12345", "two")), line  # nothing it holds


def test_a_link_leading_out_of_the_run_folder_is_refused_before_it_is_read(tmp_path):
    """A good report elsewhere, linked into the run folder: refused, naming the link and the
    run folder, not where it leads; a link inside the run folder is followed; the run folder
    given decides (a report below it, behind a link to a folder outside it, is refused too)."""
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    good = _written(elsewhere)
    run = tmp_path / "run"
    run.mkdir()
    (run / sides_file.SIDES_REPORT).symlink_to(good)
    with pytest.raises(MetadataError) as info:
        sides_file.read(run)
    line = info.value.one_line()
    assert f"{run / sides_file.SIDES_REPORT}: sides_report.json is a link leading out of {run}" in line, line
    assert "elsewhere" not in line.replace(str(run), "")
    (run / sides_file.SIDES_REPORT).unlink()
    (run / "kept").mkdir()
    _written(run / "kept")
    (run / sides_file.SIDES_REPORT).symlink_to(run / "kept" / sides_file.SIDES_REPORT)
    assert sides_file.read(run) == sides_file.read(good)  # inside: read as the report
    (run / "side_1").symlink_to(elsewhere)
    with pytest.raises(MetadataError, match="lies behind the link .*side_1, which leads out of"):
        sides_file.read(run / "side_1" / sides_file.SIDES_REPORT, root=run)
