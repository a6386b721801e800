"""What recon reads back from a run folder is read like any user file (docs/inputs.md, "Run
folders read back"): a two-sided folder's ``sides_report.json``, its sides' clouds and scan
stores, the reports of ``recon_cli/runs``, a store's ``session.json`` and ``scan.json``, the
``config.yaml`` given to ``--config`` and what a report page shows. A file that is (or lies
behind) a link leading out of its folder is refused before it is read; a huge, sparse,
NaN-holding or wrongly typed file is one line naming the file and the key, never quoting what
it holds; and ``recon evaluate`` of a two-sided simulation folder measures against the
simulated object whichever command wrote the folder."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from recon_cli.cli import main
from recon_cli.errors import FileError, MetadataError
from recon_cli.objects import load_object
from recon_cli.reconstruction.metadata import read_scan_meta, read_session
from recon_cli.runs import autoscan as autoscan_file
from recon_cli.runs import capture as capture_file
from recon_cli.runs import evaluation as evaluation_file
from recon_cli.runs import register as register_file
from recon_cli.runs import script_run as run_file
from recon_cli.runs import sides as sides_file
from recon_cli.runs.codec import plain

OBJECT = "toy_blocks"
SECRET = "SECRET-7f3a"


def _write_cloud(path: Path, points: np.ndarray) -> None:
    import open3d as o3d

    path.parent.mkdir(parents=True, exist_ok=True)
    assert o3d.io.write_point_cloud(str(path), o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points)))


def _two_sided(tmp_path: Path, layout: str = "autoscan") -> Path:
    """A two-sided simulation folder of the toy blocks as ``recon autoscan --sides 2`` lays it
    out (each side its own scan store) or as a script's ``<turn_over/>`` does (``side_k/scans``):
    both sides' clouds on the true surface, the merged cloud, the sides report."""
    run = tmp_path / "run"
    obj = load_object(OBJECT)
    points = obj.surface_points(20_000, np.random.default_rng(0), exclude_base=-np.inf)
    upper = points[:, 2] > np.median(points[:, 2])
    _write_cloud(run / "side_1" / "reconstruction" / "cloud.ply", points[upper])
    _write_cloud(run / "side_2" / "reconstruction" / "cloud.ply", points[~upper])
    _write_cloud(run / "reconstruction" / "cloud.ply", points)
    for k in (1, 2):
        store = run / f"side_{k}" / ("scans" if layout == "script" else "")
        store.mkdir(parents=True, exist_ok=True)
        session = {"format": 1, "created": 0.0, "backend": "sim",
                   "object": {"name": OBJECT, "world_T_object": obj.world_T_object}}
        (store / "session.json").write_text(json.dumps(plain(session)))
    sides_file.write(run, sides_file.SidesReport(
        object=OBJECT, turn={"by": "physics", "tilt_deg": 90.0}, seconds=1.0, side_seconds=[0.5, 0.5],
        side_scans=[5, 5], registration={"side1_T_side2": np.eye(4).tolist(), "fitness": 0.9, "reason": None},
        cloud=str(run / "reconstruction" / "cloud.ply")))
    return run


def _one_line(capsys) -> str:
    captured = capsys.readouterr()
    lines = [ln for ln in captured.err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), captured.err
    assert "Traceback" not in captured.err + captured.out
    return lines[0]


# ----------------------------------------------------------------------------- recon evaluate RUN
@pytest.mark.parametrize("layout", ["autoscan", "script"])
def test_evaluate_of_a_two_sided_simulation_folder_measures_against_the_simulated_object(layout, tmp_path,
                                                                                          capsys):
    """Without --reference: the simulated object where side 1 saw it, found in side 1's scan
    store whether that is side_1/ (autoscan --sides 2) or side_1/scans (a script)."""
    run = _two_sided(tmp_path, layout)
    assert main(["evaluate", str(run), "--samples", "20000"]) == 0, capsys.readouterr().err
    out = capsys.readouterr().out
    assert "alone: side 1 covers" in out, out
    report = evaluation_file.read(run / "reconstruction" / "cloud_evaluation.json")
    assert report.reference == f"the simulated {OBJECT}" and report.coverage is not None
    assert report.coverage > 0.95 and abs(report.mean_mm) < 0.1, report  # the clouds lie on the true surface
    assert set(report.contributions) == {"side_1", "side_2"}


def _spoil(case: str, path: Path) -> None:
    data = json.loads(path.read_text())
    if case == "link to /etc/passwd":
        path.unlink()
        path.symlink_to("/etc/passwd")
    elif case == "NaN":
        path.write_text(path.read_text().replace('"seconds": 1.0', '"seconds": NaN'))
    elif case == "huge":
        data["object"] = "x" * (17 * 2**20)
        path.write_text(json.dumps(data))
    elif case == "sparse 1 GB":
        os.truncate(path, 2**30)
    elif case == "wrong types":
        data["registration"]["side1_T_side2"] = SECRET
        path.write_text(json.dumps(data))
    elif case == "a list for a text":
        data["object"] = [SECRET]
        path.write_text(json.dumps(data))
    else:
        raise AssertionError(case)


HOSTILE = {
    "link to /etc/passwd": "sides_report.json is a link leading out of",
    "NaN": "holds NaN, which is not a finite number",
    "huge": "more than the 16,777,216 recon reads",
    "sparse 1 GB": "has 1,073,741,824 bytes, more than the 16,777,216 recon reads",
    "wrong types": "key 'registration.side1_T_side2' is a text, not a list",
    "a list for a text": "key 'object' is a list, not a text or null",
}


@pytest.mark.parametrize("case", HOSTILE)
def test_evaluate_of_a_hostile_sides_report_is_one_line_and_writes_nothing(case, tmp_path, capsys):
    run = _two_sided(tmp_path)
    _spoil(case, run / sides_file.SIDES_REPORT)
    before = sorted(p.name for p in (run / "reconstruction").iterdir())
    assert main(["evaluate", str(run), "--samples", "20000"]) == 1
    line = _one_line(capsys)
    assert f"{run / sides_file.SIDES_REPORT}" in line and HOSTILE[case] in line, line
    assert SECRET not in line and "root:" not in line and "xxxx" not in line, line
    assert sorted(p.name for p in (run / "reconstruction").iterdir()) == before


def test_evaluate_reads_no_side_cloud_or_session_through_a_link_out_of_the_run(tmp_path, capsys):
    """side_2 a link to a copy outside the run folder; side 1's session.json a link to a session
    outside: each refused before it is read, naming the link and not where it leads."""
    run = _two_sided(tmp_path)
    elsewhere = tmp_path / "elsewhere"
    (run / "side_2").rename(elsewhere)
    (run / "side_2").symlink_to(elsewhere)
    assert main(["evaluate", str(run), "--samples", "20000"]) == 1
    line = _one_line(capsys)
    assert f"side 2 cloud lies behind the link {run / 'side_2'}, which leads out of {run}" in line, line
    assert "elsewhere" not in line
    (run / "side_2").unlink()
    elsewhere.rename(run / "side_2")
    session = run / "side_1" / "session.json"
    session.rename(tmp_path / "session.json")
    session.symlink_to(tmp_path / "session.json")
    assert main(["evaluate", str(run), "--samples", "20000"]) == 1
    assert f"{session}: side 1 session.json is a link leading out of {run}" in _one_line(capsys)
    assert not (run / "reconstruction" / "cloud_evaluation.json").exists()


def _snapshot(root: Path) -> dict[str, tuple]:
    return {str(p.relative_to(root)): (p.is_symlink(), p.read_bytes() if p.is_file() else b"", p.lstat().st_mtime_ns)
            for p in sorted(root.rglob("*"))}


@pytest.mark.parametrize("how", ["reconstruction", "behind"])
def test_evaluate_writes_nothing_through_a_link_leading_out_of_the_run(how, tmp_path, capsys):
    """RUN/reconstruction a link to a folder outside the run (or lying behind one: the run's
    reconstruction reached through a link of the run to the outside): refused in one line
    naming the link, nothing written outside, non-zero exit; with --out the report goes there."""
    run = _two_sided(tmp_path)
    outside = tmp_path / "outside"
    if how == "reconstruction":
        (run / "reconstruction").rename(outside)
        (run / "reconstruction").symlink_to(outside)
        link = run / "reconstruction"
        words = f"output folder {link} is a link leading out of the run folder {run}"
    else:
        outside.mkdir()
        (run / "reconstruction").rename(outside / "reconstruction")
        (run / "parts").symlink_to(outside)
        (run / "reconstruction").symlink_to("parts/reconstruction")
        link = run / "reconstruction"
        words = f"output folder {link} is a link leading out of the run folder {run}"
    reference = tmp_path / "ref.ply"
    import open3d as o3d

    assert o3d.io.write_triangle_mesh(str(reference), load_object(OBJECT).mesh_world())
    before = _snapshot(outside)
    assert main(["evaluate", str(run), "--reference", str(reference), "--samples", "20000"]) == 1
    line = _one_line(capsys)
    assert words in line and "recon does not write through links" in line, line
    assert str(outside) not in line.replace(str(run), "")
    assert _snapshot(outside) == before
    out = tmp_path / "chosen"
    assert main(["evaluate", str(run), "--reference", str(reference), "--samples", "20000", "--out", str(out)]) == 1
    assert "merged cloud" in _one_line(capsys)  # reading the run's cloud through the link is refused too
    assert _snapshot(outside) == before and not out.exists()


# ----------------------------------------------------------------------------- the readers of run folders
READERS = {
    "run_report.json": lambda folder, root: run_file.read(folder, root),
    "autoscan_report.json": lambda folder, root: autoscan_file.read(folder, root),
    "capture_report.json": lambda folder, root: capture_file.read(folder, root),
    "report.json": lambda folder, root: register_file.read(folder, root),
    "cloud_evaluation.json": lambda folder, root: evaluation_file.read(folder / "cloud_evaluation.json", root),
    "sides_report.json": lambda folder, root: sides_file.read(folder, root),
}


@pytest.mark.parametrize("name", READERS)
def test_every_run_report_linked_out_of_its_run_folder_is_refused_before_it_is_read(name, tmp_path):
    run = tmp_path / "run"
    (run / "reconstruction").mkdir(parents=True)
    (run / name).symlink_to("/etc/passwd")
    with pytest.raises(MetadataError) as info:
        READERS[name](run, None)
    line = info.value.one_line()
    assert f"{run / name}: {name} is a link leading out of {run}" in line and "root:" not in line, line
    # a folder of the run that leads out of it: refused for what lies behind it, given the run folder
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / name).write_text("{}")
    (run / "reconstruction").rmdir()
    (run / "reconstruction").symlink_to(outside)
    with pytest.raises(MetadataError, match=f"lies behind the link {run / 'reconstruction'}, which leads out of"):
        READERS[name](run / "reconstruction", run)


def test_a_scan_stores_session_and_scan_json_are_not_read_through_links_out_of_it(tmp_path):
    store = tmp_path / "store"
    (store / "scan_0000").mkdir(parents=True)
    (store / "session.json").symlink_to("/etc/passwd")
    (store / "scan_0000" / "scan.json").symlink_to("/etc/passwd")
    with pytest.raises(MetadataError, match="session.json is a link leading out of") as info:
        read_session(store)
    assert "root:" not in info.value.one_line()
    with pytest.raises(MetadataError, match="scan.json is a link leading out of"):
        read_scan_meta(store / "scan_0000")
    (store / "session.json").unlink()
    (store / "session.json").write_text(json.dumps({"format": 1, "sensor": [SECRET]}))
    with pytest.raises(MetadataError) as info:
        read_session(store)
    assert "key 'sensor' is a list" in info.value.one_line() and SECRET not in info.value.one_line()


def test_config_given_to_repeat_a_run_is_not_read_through_a_link_out_of_its_folder(tmp_path, capsys):
    run = tmp_path / "run"
    run.mkdir()
    (run / "config.yaml").symlink_to("/etc/passwd")
    assert main(["register", "--config", str(run / "config.yaml")]) == 1
    line = _one_line(capsys)
    assert f"{run / 'config.yaml'}: configuration file is a link leading out of {run}" in line, line
    assert "root:" not in line


def test_the_page_of_a_run_folder_reads_nothing_through_a_link_out_of_it(tmp_path, capsys):
    """`recon report RUN`: a sides report linked to /etc/passwd and a side whose folder leads
    out of the run are notes naming the links; nothing of them is on the page."""
    run = _two_sided(tmp_path)
    elsewhere = tmp_path / "elsewhere"
    (run / "side_1").rename(elsewhere)
    (run / "side_1").symlink_to(elsewhere)
    assert main(["report", str(run), "--no-render"]) == 0, capsys.readouterr().err
    out = capsys.readouterr().out
    assert f"note: {run / 'side_1'}: scan store is a link leading out of {run}" in out, out
    (run / sides_file.SIDES_REPORT).unlink()
    (run / sides_file.SIDES_REPORT).symlink_to("/etc/passwd")
    assert main(["report", str(run), "--no-render"]) == 0
    out = capsys.readouterr().out
    assert f"note: {run / sides_file.SIDES_REPORT}: sides_report.json is a link leading out of {run}" in out, out
    html = (run / "report.html").read_text()
    assert "root:" not in html and "elsewhere" not in html


def test_a_file_outside_is_refused_as_a_file_error_too(tmp_path):
    """The guard of inputs/files.py words its refusal for a user's data file as well."""
    from recon_cli.inputs import files

    (tmp_path / "a").mkdir()
    (tmp_path / "a" / "x").symlink_to("/etc/passwd")
    refuse = files.file_errors(tmp_path / "a" / "x", "data file", "check it", lambda n: ("big", "smaller"))
    with pytest.raises(FileError, match="data file is a link leading out of"):
        files.read_limited(tmp_path / "a" / "x", 1000, refuse, root=tmp_path / "a")
    assert files.link_out_of(tmp_path / "a" / ".." / "b", tmp_path / "a") is not None
    assert files.link_out_of(tmp_path / "a" / "x", tmp_path) is not None
    (tmp_path / "a" / "y").symlink_to(tmp_path / "a")
    assert files.link_out_of(tmp_path / "a" / "y" / "x2", tmp_path / "a") is None
