"""`recon run`: the smoke script end to end, dry runs, failure policies, the thesis dialect."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from recon_cli.cli import main
from recon_cli.paths import SCRIPTS_DIR
from recon_cli.reconstruction.scan_store import ScanStore

HEAD = '<?xml version="1.0"?>\n'
GOOD = '<move focus="0 0 0.8" radius="0.6" theta="60" phi="{phi}"/>\n  <scan/>\n'
UNREACHABLE = '<move focus="0 0 0.8" radius="2.5" theta="60" phi="90"/>\n  <scan/>\n'


def _script(tmp_path: Path, body: str, policy: str = "skip") -> Path:
    p = tmp_path / "s.xml"
    p.write_text(HEAD + f'<recon name="t" on_failure="{policy}">\n  <cell resolution="0.25"/>\n'
                 f'  <object name="bottle"/>\n  <box/>\n  {body}</recon>\n')
    return p


def test_smoke_script_end_to_end(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["run", str(SCRIPTS_DIR / "smoke.xml"), "--out", str(out)]) == 0
    report = json.loads((out / "run_report.json").read_text())
    assert [c["status"] for c in report["commands"]] == ["done"] * len(report["commands"])
    assert report["scans"] == 3 and len(ScanStore(out / "scans")) == 3
    for name in ("bottle_cloud.ply", "bottle_mesh.ply", "script.expanded.xml"):
        assert (out / name).stat().st_size > 0
    moves = [c for c in report["commands"] if c["command"].startswith("move")]
    assert all(c["trajectory_s"] > 0 for c in moves)  # every move planned and timed
    ev = next(c for c in report["commands"] if c["command"].startswith("evaluate"))
    assert abs(ev["mean_mm"]) < 1.0


def test_a_scripts_registration_reuses_what_each_scan_made_and_reads_no_depth_image(tmp_path, monkeypatch):
    """Each scan's board pose and cropped cloud are made while its images are in memory
    (CloudMemo.keep); the <register/> at the end reuses them and decodes no depth image."""
    from recon_cli.reconstruction import scan_store

    read = scan_store._read_image
    depth_reads: list[str] = []

    def counted(path, *args, **kwargs):
        if path.name == "depth.png":
            depth_reads.append(path.parent.name)
        return read(path, *args, **kwargs)

    monkeypatch.setattr(scan_store, "_read_image", counted)
    out = tmp_path / "run"
    assert main(["run", str(SCRIPTS_DIR / "smoke.xml"), "--out", str(out)]) == 0
    report = json.loads((out / "run_report.json").read_text())
    assert report["scans"] == 3 and [c["status"] for c in report["commands"]] == ["done"] * len(report["commands"])
    assert depth_reads == []


def test_dry_run_plans_but_does_not_move(tmp_path):
    out = tmp_path / "dry"
    p = _script(tmp_path, GOOD.format(phi=0) + GOOD.format(phi=120) + "<register/>\n")
    assert main(["run", str(p), "--out", str(out), "--dry-run"]) == 0
    report = json.loads((out / "run_report.json").read_text())
    statuses = [c["status"] for c in report["commands"] if c["command"].startswith(("move", "scan", "register"))]
    assert statuses == ["planned", "skipped", "planned", "skipped", "skipped"]
    assert not (out / "scans").exists()
    assert "status done" in (out / "report.html").read_text()  # the page of the planned moves


def test_failed_move_skips_its_scan(tmp_path, capsys):
    out = tmp_path / "skip"
    p = _script(tmp_path, GOOD.format(phi=0) + UNREACHABLE + GOOD.format(phi=180))
    assert main(["run", str(p), "--out", str(out)]) == 3  # some commands failed
    report = json.loads((out / "run_report.json").read_text())
    statuses = [c["status"] for c in report["commands"][3:]]
    assert statuses == ["done", "done", "failed", "skipped", "done", "done"]
    failed = report["commands"][5]
    assert failed["source"] == "s.xml:8" and "out of reach" in failed["message"]
    assert len(ScanStore(out / "scans")) == 2
    assert "failed" in capsys.readouterr().out


def test_abort_keeps_earlier_scans(tmp_path, capsys):
    out = tmp_path / "abort"
    p = _script(tmp_path, GOOD.format(phi=0) + UNREACHABLE + GOOD.format(phi=180), policy="abort")
    assert main(["run", str(p), "--out", str(out)]) == 4  # aborted
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "s.xml:8" in err and "abort" in err
    assert len(ScanStore(out / "scans")) == 1  # the scan before the failure is kept
    report = json.loads((out / "run_report.json").read_text())
    assert report["aborted"] and report["commands"][-1]["status"] == "failed"
    assert "status aborted" in (out / "report.html").read_text()  # the page of what was done


def test_hardware_backend_is_a_clear_error(tmp_path, capsys):
    p = _script(tmp_path, GOOD.format(phi=0))
    assert main(["run", str(p), "--out", str(tmp_path / "hw"), "--backend", "hardware"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "the hardware backend needs a station file" in err and "--station" in err
    assert not (tmp_path / "hw").exists()  # refused before anything was written


def test_thesis_dialect_runs_unchanged(tmp_path):
    p = tmp_path / "t.xml"
    p.write_text(HEAD + """<script name="t" optimization="false">
  <move reference="world"><sphere xyz="0 0 0.8" radius="0.6"/><coordinates phi="0" theta="1.0"/></move>
  <scan name="a" path_color="/home/someone/a.png"/>
  <move reference="world"><sphere xyz="0 0 0.8" radius="0.6"/><coordinates phi="0.8" theta="1.0"/></move>
  <scan name="b"/>
  <register source="b" target="a" threshold="0.01"/>
  <multiway threshold="0.01"/>
  <add fragment="a" target="all"/><add fragment="b" target="all"/>
  <downsample fragment="all" voxel_size="0.002"/>
  <hide fragment="a"/>
  <export fragment="all" type="point_cloud" path="/somewhere/else/all.ply"/>
  <export fragment="all" type="mesh" path="mesh.ply"/>
  <delete fragment="b"/>
</script>
""")
    out = tmp_path / "run"
    assert main(["run", str(p), "--out", str(out), "--object", "bottle"]) == 0
    report = json.loads((out / "run_report.json").read_text())
    statuses = {c["command"]: c["status"] for c in report["commands"]}
    assert statuses["hide a (display only, recorded)"] == "recorded"
    assert all(s in ("done", "recorded") for s in statuses.values())
    assert (out / "all.ply").stat().st_size > 0 and (out / "mesh.ply").stat().st_size > 0
    scans = [c for c in report["commands"] if c["command"].startswith("scan")]
    assert [c["fragment"] for c in scans] == ["a", "b"] and all(c["fragment_points"] > 100 for c in scans)


def test_optimize_reorders_independent_moves(tmp_path):
    """--optimize: the moves between set-up and registration are reordered as one group,
    every view is visited once, the planned paths are the ones executed (no second
    planning), and the report gives the planned total time and the request count."""
    from recon_cli.scripts.optimize import movable_groups

    body = "".join(GOOD.format(phi=phi) for phi in (0, 180, 60, 240)) + "<register/>\n"
    p = _script(tmp_path, body)
    out = tmp_path / "opt"
    assert main(["run", str(p), "--out", str(out), "--optimize"]) == 0
    report = json.loads((out / "run_report.json").read_text())
    seq = report["sequence_optimization"][0]
    assert seq["moves"] == 4 and len(seq["order"]) == 4 and len(set(seq["order"])) == 4
    assert 4 <= seq["planning_requests"] <= 8 and seq["planned_duration_s"] > 0
    moves = [c for c in report["commands"] if c["command"].startswith("move")]
    assert [c["planner"] for c in moves] == ["sequence"] * 4 and all(c["status"] == "done" for c in moves)
    assert sum(c["trajectory_s"] for c in moves) == pytest.approx(seq["planned_duration_s"])
    assert len(ScanStore(out / "scans")) == 4
    # what may move: runs of moves with their scans, nothing else
    from recon_cli.scripts.loader import load_script

    cmds = load_script(p).commands
    assert movable_groups(cmds) == {3: 11}


def test_scan_name_and_append(tmp_path, capsys):
    """A named scan keeps its name in scan.json; a second run into the same folder is
    refused unless --append, which adds its scans to the same store."""
    out = tmp_path / "named"
    p = _script(tmp_path, '<move focus="0 0 0.8" radius="0.6" theta="60" phi="0"/>\n  <scan name="front"/>\n')
    assert main(["run", str(p), "--out", str(out)]) == 0
    meta = json.loads((out / "scans" / "scan_0000" / "scan.json").read_text())
    assert meta["name"] == "front"
    assert main(["run", str(p), "--out", str(out)]) == 1
    assert "not empty" in capsys.readouterr().err
    assert main(["run", str(p), "--out", str(out), "--append"]) == 0
    assert len(ScanStore(out / "scans")) == 2
    assert json.loads((out / "run_report.json").read_text())["append"] is True
    assert json.loads((out / "run_report-1.json").read_text())["append"] is False  # the first run's report


def test_the_cell_option_runs_a_script_on_another_cell(tmp_path):
    """``recon run --cell`` puts the script on another cell (its own safety distance), and the
    views given in the marker frame find the board there: the FR3 script on a copy of the
    FR3's cell file, two views only."""
    import shutil

    from recon_cli.paths import CELLS_DIR, ROBOT_DIR

    shutil.copytree(ROBOT_DIR, tmp_path / "robot", ignore=shutil.ignore_patterns("realism"))
    cell = tmp_path / "lab.yaml"
    text = (CELLS_DIR / "fr3.yaml").read_text()
    cell.write_text(text.replace("name: fr3", "name: lab").replace("../robot/", "robot/"))
    script = tmp_path / "two.xml"
    script.write_text(HEAD + '<recon name="two" on_failure="skip">\n  <cell kind="gantry" resolution="0.25"/>\n'
                      '  <object name="bottle"/>\n  <box/>\n'
                      '  <move focus="0.1925 0.1225 0.08" radius="0.22" theta="60" phi="180" frame="marker"/>\n'
                      '  <scan/>\n'
                      '  <move focus="0.1925 0.1225 0.08" radius="0.22" theta="35" phi="250" frame="marker"/>\n'
                      '  <scan/>\n</recon>\n')
    out = tmp_path / "run"
    assert main(["run", str(script), "--cell", str(cell), "--out", str(out)]) == 0
    session = json.loads((out / "scans" / "session.json").read_text())
    assert session["cell"]["kind"] == str(cell.resolve()) and session["cell"]["safety_distance"] == 0.02
    assert session["board"]["squares_x"] == 11 and session["sensor"] == "Intel RealSense D405"
    assert len(ScanStore(out / "scans")) == 2


def _lab_cell(folder: Path, name: str = "lab.yaml") -> Path:
    """The FR3 cell file copied into ``folder``/cells with its robot files beside it."""
    import shutil

    from recon_cli.paths import CELLS_DIR, ROBOT_DIR

    shutil.copytree(ROBOT_DIR, folder / "cells" / "robot", ignore=shutil.ignore_patterns("realism"))
    cell = folder / "cells" / name
    text = (CELLS_DIR / "fr3.yaml").read_text()
    cell.write_text(text.replace("name: fr3", "name: lab").replace("../robot/", "robot/"))
    return cell


def test_a_script_names_a_cell_file_beside_it(tmp_path):
    """<cell kind="cells/lab.yaml">: the cell file and everything it names lie in the script's
    folder; the run happens on that cell with its own safety distance."""
    _lab_cell(tmp_path)
    script = tmp_path / "lab.xml"
    script.write_text(HEAD + '<recon name="lab" on_failure="skip">\n  <cell kind="cells/lab.yaml" resolution="0.25"/>\n'
                      '  <object name="bottle"/>\n  <box/>\n'
                      '  <move focus="0.1925 0.1225 0.08" radius="0.22" theta="60" phi="180" frame="marker"/>\n'
                      '  <scan/>\n</recon>\n')
    out = tmp_path / "run"
    assert main(["run", str(script), "--out", str(out)]) == 0
    session = json.loads((out / "scans" / "session.json").read_text())
    assert session["cell"]["kind"] == str((tmp_path / "cells" / "lab.yaml").resolve())
    assert session["cell"]["safety_distance"] == 0.02 and len(ScanStore(out / "scans")) == 1


def test_a_script_cell_file_that_names_files_elsewhere_is_refused(tmp_path, capsys):
    """A script reads only its own folder (and scripts_xml/): a cell file beside it whose
    description lies elsewhere is one line naming the script's line, before anything runs."""
    cell = _lab_cell(tmp_path / "elsewhere")
    here = tmp_path / "here"
    (here / "cells").mkdir(parents=True)
    text = cell.read_text().replace("robot/", str(tmp_path / "elsewhere" / "cells" / "robot") + "/")
    (here / "cells" / "lab.yaml").write_text(text)
    script = here / "lab.xml"
    script.write_text(HEAD + '<recon name="lab">\n  <cell kind="cells/lab.yaml"/>\n  <object name="bottle"/>\n'
                      '</recon>\n')
    assert main(["run", str(script), "--out", str(tmp_path / "run")]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "lab.xml:3: " in err and "description.file" in err
    assert "outside the cell file's folder" in err and not (tmp_path / "run").exists()
