"""`recon autoscan --sides 2` in simulation: side 1, the object turned over by physics, side
2, the sides registered by shape within 0.5 mm / 0.2 deg of the truth, one merged model that
covers more of the whole surface (the resting faces included) than either side, and
`recon evaluate` of the folder measures it against the simulated object."""

from __future__ import annotations

import importlib.util
import json

import pytest

from recon_cli.cli import main
from recon_cli.runs import sides as sides_file


def test_two_sided_autoscan_end_to_end(tmp_path, capsys):
    out = tmp_path / "two"
    code = main(["autoscan", "--sides", "2", "--object", "toy_blocks", "--n", "5", "--resolution", "0.3",
                 "--no-pictures", "--seed", "0", "--record", "--out", str(out)])
    text = capsys.readouterr()
    assert code == 0, text.out + text.err
    report = sides_file.read(out)
    assert report.side_scans == [5, 5] and report.turn["by"] == "physics" and report.turn["tilt_deg"] > 60
    reg = report.registration
    assert reg["reason"] is None and not reg["shape_ambiguous"]
    assert reg["truth"]["rotation_deg"] <= 0.2 and reg["truth"]["translation_mm"] <= 0.5, reg["truth"]
    # against the pose that puts the two clouds onto each other as they are (each side's own offset removed)
    assert reg["truth"]["clouds_rotation_deg"] <= 0.2 and reg["truth"]["clouds_translation_mm"] <= 0.5, reg["truth"]
    assert report.coverage_whole is not None
    assert report.coverage_whole > max(report.contributions.values()) + 0.1, report
    assert (out / "reconstruction" / "mesh.ply").stat().st_size > 10_000
    for side in ("side_1", "side_2"):
        assert json.loads((out / side / "autoscan_report.json").read_text())["scans"] == 5
    assert "sides registered by shape" in text.out and "of the whole surface" in text.out
    _the_page_shows_both_sides(out, report, text.out)
    # `recon evaluate RUN` without --reference: the simulated object, found in side 1's store (side_1/)
    assert main(["evaluate", str(out)]) == 0, capsys.readouterr().err
    ev = json.loads((out / "reconstruction" / "cloud_evaluation.json").read_text())
    assert ev["reference"] == "the simulated toy_blocks" and ev["coverage"] == pytest.approx(report.coverage_whole,
                                                                                            abs=0.01)
    if importlib.util.find_spec("rerun") is not None:  # the recordings: each side's, and the sides registered
        from recon_cli.recording.readback import summarize

        assert summarize(out / "recording.rrd").sides == 2
        assert all(len(summarize(out / side / "recording.rrd").scans) == 5 for side in ("side_1", "side_2"))


def _the_page_shows_both_sides(out, report, printed: str):
    """report.html: the two sides section (the turn, the registration and its confidence, each
    side's share), the picture of the sides registered onto each other, both sides' scans
    with their own registration, the merged model against the whole surface."""
    page = out / "report.html"
    assert f"page: {page}" in printed
    html = page.read_text()
    assert "<h1>recon autoscan --sides 2: toy_blocks" in html and 'id="sides"' in html
    assert "by physics: tipped" in html and "confidence" in html and ">unique<" in html
    assert "onto a face of its hull that tips at" in html and "(side 1 missed" in html
    assert f"{report.contributions['side_1'] * 100:.2f} %" in html and f"{report.coverage_whole * 100:.2f} %" in html
    assert (out / "report_files" / "sides.png").stat().st_size > 20_000 and "report_files/sides.png" in html
    assert "Scans (10)" in html and "Side 1 (5 scans)" in html and "Side 2 (5 scans)" in html
    assert "report_files/scans/side_2/scan_0004.jpg" in html
    assert html.count(">charuco<") + html.count(">kinematics<") == 10  # each scan's pose source
    assert "cloud (both sides)" in html and "true whole toy_blocks surface" in html


@pytest.mark.slow
def test_a_bowl_is_turned_onto_its_rim_and_both_sides_register(tmp_path, capsys):
    """An open container (tests/bowl.py: a thin-walled spherical cap) has one other stable
    face, its rim: physics turns it upside down, and the sides, which share only smooth
    surface, register by the turn's face (its yaw unknown): the merged cloud lies on the true
    surface within the sensor's noise. (With fewer or smaller views the sides' overlap is too
    small to trust, the truth included, and the run says so.)"""
    from ..bowl import write_bowl

    bowl = write_bowl(tmp_path / "bowl.ply")
    out = tmp_path / "two"
    code = main(["autoscan", "--sides", "2", "--object", str(bowl), "--n", "12", "--resolution", "0.5",
                 "--no-pictures", "--seed", "0", "--out", str(out)])
    text = capsys.readouterr()
    assert code == 0, text.out + text.err
    report = sides_file.read(out)
    turn = report.turn
    assert turn["tilt_deg"] > 179.0 and turn["stable_faces"] == 1 and turn["faces_tried"] == 1
    assert turn["face"]["down_object"] == pytest.approx([0.0, 0.0, 1.0], abs=1e-9)  # the opening went down
    assert turn["face"]["registration_fixed"] and turn["face"]["missed_in_view"] > 0.05
    reg = report.registration
    assert reg["reason"] is None and not reg["shape_ambiguous"], reg
    # a body of revolution: any turn about its axis fits; the merged shape is right
    assert report.accuracy["std_mm"] <= 0.29 and abs(report.accuracy["mean_mm"]) < 0.1, report.accuracy
    assert report.coverage_whole > max(report.contributions.values()) + 0.05, report
