"""`<turn_over/>` in a script: scanned end to end in simulation (scripts_xml/two_sided_toy_blocks.xml),
the sides registered by shape against the truth of the physics turn and merged; a script that
turns twice, before any scan or with nothing after the turn is refused with one line naming
file:line; the sequence optimizer never moves a view across the turn; a dry run plans the
parking move and turns nothing."""

from __future__ import annotations

import importlib.util
import json
import shutil

import numpy as np
import pytest

from recon_cli.cli import main
from recon_cli.paths import SCRIPTS_DIR
from recon_cli.reconstruction.scan_store import ScanStore
from recon_cli.runs import sides as sides_file
from recon_cli.scripts import commands as C
from recon_cli.scripts.loader import load_script
from recon_cli.scripts.optimize import movable_groups

VIEW = '<move focus="0 0 0.8" radius="0.6" theta="60" phi="{phi}"/>\n  <scan/>\n'


def _script(tmp_path, body: str):
    p = tmp_path / "s.xml"
    p.write_text('<?xml version="1.0"?>\n<recon name="t">\n  <cell resolution="0.25"/>\n  <object name="bottle"/>\n'
                 f"  {body}</recon>\n")
    return p


def test_a_script_scans_both_sides_and_merges_them(tmp_path, capsys):
    out = tmp_path / "run"
    record = importlib.util.find_spec("rerun") is not None
    code = main(["run", str(SCRIPTS_DIR / "two_sided_toy_blocks.xml"), "--out", str(out), *(["--record"] * record)])
    text = capsys.readouterr()
    assert code == 0, text.out + text.err
    if record:  # one recording: both sides' scans (side 2's under side_2/) and the sides registered
        from recon_cli.recording.readback import summarize

        summary = summarize(out / "recording.rrd")
        assert len(summary.scans) == 10 and summary.sides == 2 and summary.registered == 10, summary.describe()
    # each side its own scan store; side 2's is of the object as physics laid it down
    side_1, side_2 = ScanStore(out / "side_1" / "scans"), ScanStore(out / "side_2" / "scans")
    assert len(side_1) == 5 and len(side_2) == 5 and not (out / "scans").exists()
    poses = [np.asarray(store.session().world_T_object) for store in (side_1, side_2)]
    report = sides_file.read(out)
    tilt = np.degrees(np.arccos(np.clip(poses[0][:3, 2] @ poses[1][:3, 2], -1.0, 1.0)))
    assert report.turn["by"] == "physics" and tilt == pytest.approx(report.turn["tilt_deg"], abs=1e-6) and tilt > 60
    # the sides registered by shape, as the truth of the turn says
    assert report.side_scans == [5, 5]
    reg = report.registration
    assert reg["reason"] is None and not reg["shape_ambiguous"]
    assert reg["truth"]["rotation_deg"] <= 0.2 and reg["truth"]["translation_mm"] <= 0.5, reg["truth"]
    assert report.coverage_whole > max(report.contributions.values()) + 0.1, report
    assert abs(report.accuracy["mean_mm"]) < 0.5
    # the merged model beside the sides' own
    assert (out / "reconstruction" / "cloud.ply").stat().st_size > 10_000
    assert (out / "reconstruction" / "mesh.ply").stat().st_size > 10_000
    for k in (1, 2):
        assert json.loads((out / f"side_{k}" / "reconstruction" / "report.json").read_text())["scans_registered"] == 5
    run = json.loads((out / "run_report.json").read_text())
    assert run["status"] == "done" and run["scans"] == 10
    turn = next(c for c in run["commands"] if c["command"].startswith("turn the object over"))
    merge = run["commands"][-1]
    assert merge["command"] == "register the two sides by shape and merge them" and merge["source"] == turn["source"]
    assert turn["source"] == "two_sided_toy_blocks.xml:20" and turn["trajectory_s"] > 0  # parked at home
    assert run["outputs"]["cloud"] == str(out / "reconstruction" / "cloud.ply")
    assert run["outputs"]["sides_report"] == str(out / "sides_report.json")
    assert "sides registered by shape: fitness" in text.out and "of the whole surface" in text.out
    html = (out / "report.html").read_text()  # the run's page: both sides and their registration
    assert "Scans (10)" in html and "Side 2 (5 scans)" in html and 'id="sides"' in html
    assert (out / "report_files" / "sides.png").is_file()
    _evaluate_the_two_sided_folder(out, report, tmp_path, capsys)


def _evaluate_the_two_sided_folder(out, report, tmp_path, capsys):
    """`recon evaluate RUN` on the two-sided folder: against the simulated object by default,
    the whole surface's coverage and each side's alone as the run measured them; a folder
    whose side is missing, a folder of another kind, or a scan store are one line each."""
    assert main(["evaluate", str(out)]) == 0
    text = capsys.readouterr().out
    assert "alone: side 1 covers" in text and "side 2 covers" in text, text
    ev = json.loads((out / "reconstruction" / "cloud_evaluation.json").read_text())
    assert ev["reference"] == "the simulated toy_blocks" and ev["coverage"] == pytest.approx(report.coverage_whole,
                                                                                            abs=0.01)
    assert ev["contributions"] == pytest.approx(dict(report.contributions), abs=0.01)
    assert ev["std_mm"] == pytest.approx(report.accuracy["std_mm"], rel=0.05)
    assert (out / "reconstruction" / "cloud_distances.png").stat().st_size > 10_000
    broken = tmp_path / "broken"
    shutil.copytree(out, broken)
    (broken / "side_2" / "reconstruction" / "cloud.ply").unlink()
    cases = [(["evaluate", str(broken)], "side 2 cloud"),
             (["evaluate", str(out / "side_1")], "not a two-sided run (no sides_report.json)"),
             (["evaluate", str(out), "--scan-store", str(out / "side_1" / "scans")], "two-sided run folder")]
    for argv, words in cases:
        assert main(argv) != 0
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and words in err and "Traceback" not in err, (argv, err)


def test_a_symmetric_object_merged_from_few_views_names_the_pose_it_cannot_tell_apart(tmp_path, capsys):
    """The bottle (a body of revolution: turned about its axis it is itself) from the
    script's 5 + 5 small views: the sides fit under several poses turned about its axis,
    all are reported, and as they give the same shape the merged model is trusted and right
    (the reported pose puts the bottle's origin where the true turn does)."""
    out = tmp_path / "run"
    code = main(["run", str(SCRIPTS_DIR / "two_sided_toy_blocks.xml"), "--object", "bottle", "--out", str(out)])
    text = capsys.readouterr()
    assert code == 0, text.out + text.err
    reg = sides_file.read(out).registration
    assert reg["ambiguous"] and not reg["shape_ambiguous"] and reg["reason"] is None
    w1, w2 = (np.asarray(ScanStore(out / f"side_{k}" / "scans").session().world_T_object) for k in (1, 2))
    truth = w1 @ np.linalg.inv(w2)
    centre = w2[:, 3]  # the object's origin on side 2 (homogeneous), on its axis
    poses = [np.asarray(reg["side1_T_side2"]), *(np.asarray(a["side1_T_side2"]) for a in reg["alternatives"])]
    assert any(1e3 * np.linalg.norm((T @ centre - truth @ centre)[:3]) <= 0.5 for T in poses)
    assert all(a["shape_difference_m"] < 0.5e-3 for a in reg["alternatives"])
    report = sides_file.read(out)
    assert report.accuracy["std_mm"] <= 0.29 and abs(report.accuracy["mean_mm"]) < 0.1
    assert "ambiguous" in text.out


def test_a_mug_is_laid_on_its_handle_and_its_sides_register_uniquely(tmp_path, capsys):
    """The mug's other stable faces: its top (upside down, where side 1's surface still in
    view is its vertical side only and cannot fix the registration) and its side, on which
    it rests on the body and the handle. On that face its old bottom faces sideways, and the
    two sides register uniquely from the script's 5 + 5 small views."""
    out = tmp_path / "run"
    code = main(["run", str(SCRIPTS_DIR / "two_sided_toy_blocks.xml"), "--object", "mug", "--out", str(out)])
    text = capsys.readouterr()
    assert code == 0, text.out + text.err
    report = sides_file.read(out)
    face = report.turn["face"]
    assert abs(face["down_object"][2]) < 0.05 and face["registration_fixed"]  # a side face, not the top
    reg = report.registration
    assert not reg["ambiguous"] and reg["reason"] is None
    assert reg["truth"]["rotation_deg"] <= 0.2 and reg["truth"]["translation_mm"] <= 0.5, reg["truth"]
    assert report.accuracy["std_mm"] <= 0.29 and abs(report.accuracy["mean_mm"]) < 0.1


@pytest.mark.parametrize("body, line, words", [
    (VIEW.format(phi=0) + "<turn_over/>\n  " + VIEW.format(phi=90) + '<turn_over seed="3"/>\n  '
     + VIEW.format(phi=180), 10, "a second <turn_over/> (the first is at s.xml:7)"),
    ("<turn_over/>\n  " + VIEW.format(phi=0), 5, "<turn_over/> before any scan"),
    (VIEW.format(phi=0) + "<turn_over/>\n", 7, "no scan after <turn_over/>: the second side is never scanned"),
    (VIEW.format(phi=0) + "<turn_over/>\n  <register/>\n  " + VIEW.format(phi=90), 8, "<register> before any scan"),
])
def test_a_script_that_cannot_turn_as_written_is_one_line(tmp_path, capsys, body, line, words):
    p = _script(tmp_path, body)
    for argv in (["validate", str(p)], ["run", str(p), "--out", str(tmp_path / "run")]):
        assert main(argv) == 1
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and f"s.xml:{line}: " in err and words in err, err
        assert "Traceback" not in err
    assert not (tmp_path / "run").exists()  # refused before anything was written


def test_append_is_refused_for_a_script_that_turns(tmp_path, capsys):
    p = _script(tmp_path, VIEW.format(phi=0) + "<turn_over/>\n  " + VIEW.format(phi=90))
    (tmp_path / "run").mkdir()
    assert main(["run", str(p), "--out", str(tmp_path / "run"), "--append"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "s.xml:7: --append cannot add to the scans" in err, err


def test_the_optimizer_orders_each_side_on_its_own_and_a_dry_run_turns_nothing(tmp_path):
    body = "".join(VIEW.format(phi=phi) for phi in (0, 180, 90)) + '<turn_over seed="5"/>\n  ' + "".join(
        VIEW.format(phi=phi) for phi in (270, 45)) + "<register/>\n"
    p = _script(tmp_path, body)
    commands = load_script(p).commands
    turn = next(k for k, c in enumerate(commands) if isinstance(c, C.TurnOver))
    assert commands[turn] == C.TurnOver(C.Source("s.xml", 11), 5)
    groups = movable_groups(commands)
    assert groups == {2: turn, turn + 1: turn + 5}  # one group per side, the turn in neither
    out = tmp_path / "dry"
    assert main(["run", str(p), "--out", str(out), "--dry-run", "--optimize"]) == 0
    report = json.loads((out / "run_report.json").read_text())
    assert [s["moves"] for s in report["sequence_optimization"]] == [3, 2]
    turned = next(c for c in report["commands"] if c["command"].startswith("turn the object over"))
    assert turned["status"] == "planned" and "the object is not turned over" in turned["message"]
    assert not any(c["command"].startswith("register the two sides") for c in report["commands"])
    assert not (out / "side_1").exists() and not (out / "sides_report.json").exists()
