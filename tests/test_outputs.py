"""One owner for every output folder (recon_cli.outputs): every command refuses a non-empty
--out before any work unless told to append or to replace what recon wrote there; nothing
is written, replaced or deleted through a link that leaves the folder; a scan store's links
out of it are not read; a station file reached through a link is updated where it points.

Every hostile case keeps a sentinel outside the output folder and checks that its content
and modification time stay as they were."""

from __future__ import annotations

import importlib
import json
import os
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

from recon_cli.cli import main
from recon_cli.errors import FileError, InputError, ReconError
from recon_cli.outputs import (
    WRITTEN,
    OutputMode,
    claim_output,
    keep_earlier,
    remove_inside,
    written_by_recon,
)
from recon_cli.paths import SCRIPTS_DIR


# ----------------------------------------------------------------------------- helpers
def snapshot(root: Path) -> dict[str, tuple]:
    """Every entry under ``root`` (links not followed): its kind, content and mtime."""
    out = {}
    for dirpath, dirnames, filenames in os.walk(root):
        for name in (*dirnames, *filenames):
            p = Path(dirpath) / name
            rel = str(p.relative_to(root))
            st = p.lstat()
            if p.is_symlink():
                out[rel] = ("link", os.readlink(p))
            elif p.is_dir():
                out[rel] = ("dir",)
            else:
                out[rel] = ("file", p.read_bytes(), st.st_mtime_ns)
    return out


@pytest.fixture
def outside(tmp_path) -> Path:
    """A folder beside the output folders that nothing may touch: a file and a folder."""
    d = tmp_path / "outside"
    (d / "victim_dir").mkdir(parents=True)
    (d / "victim.txt").write_text("keep me\n")
    (d / "victim_dir" / "keep.txt").write_text("keep me too\n")
    os.utime(d / "victim.txt", ns=(1_000_000_000, 1_000_000_000))
    return d


@pytest.fixture
def used(tmp_path, outside) -> Path:
    """An output folder an earlier run used: recon's entries (a scan, a report, hidden
    temporary files, links among them), the user's notes and a link of the user."""
    out = tmp_path / "out"
    (out / "scan_0000").mkdir(parents=True)
    (out / "scan_0000" / "scan.json").write_text("{}")
    (out / "scan_0000" / "escape").symlink_to(outside / "victim_dir")  # inside a folder --force removes
    (out / "session.json").write_text("{}")
    (out / ".config.yaml.x1y2.yaml").write_text("")  # an atomic write's leftover
    (out / "report.html").symlink_to(outside / "victim.txt")  # a recon name that is a link
    (out / "notes.txt").write_text("mine\n")
    (out / "mine").symlink_to(outside)  # not recon's: stays
    return out


def one_error_line(capsys) -> str:
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip() and "leak" not in ln]
    assert len(lines) == 1, err
    assert lines[0].startswith("error: ") and "Traceback" not in err
    return lines[0]


class Tripwire(ReconError):
    """Raised where a command's real work would start."""


@pytest.fixture
def tripwire(monkeypatch):
    """Make the work of every command raise Tripwire, so a test sees whether the output
    folder was claimed before any work started."""
    def trip(*args, **kwargs):
        raise Tripwire("the command started its work")

    for target in ("recon_cli.workflows.capture.run_capture", "recon_cli.workflows.script_run.ScriptRunner",
                   "recon_cli.workflows.autoscan.Autoscan", "recon_cli.workflows.replay.run_replay",
                   "recon_cli.workflows.register.register_folder", "recon_cli.workflows.calibrate.run_handeye",
                   "recon_cli.workflows.calibrate.run_intrinsics", "recon_cli.batch.runner.make_executor",
                   "recon_cli.bench.ik.run_ik_bench", "recon_cli.bench.sim.run_sim_bench",
                   "recon_cli.bench.registration.run_registration_bench",
                   "recon_cli.bench.sequence.run_sequence_bench", "recon_cli.bench.tour.run_tour_bench",
                   "recon_cli.bench.profile.run_profile",
                   "recon_cli.bench.viewplan.run_viewplan_bench",
                   "recon_cli.bench.planners.run_planner_bench"):
        module_name, name = target.rsplit(".", 1)
        original = getattr(importlib.import_module(module_name), name)
        for module in [m for k, m in sys.modules.items() if k.startswith("recon_cli.")]:
            if getattr(module, name, None) is original:  # where the commands imported it too
                monkeypatch.setattr(module, name, trip)


def _batch_file(tmp_path) -> Path:
    path = tmp_path / "b.yaml"
    path.write_text("jobs:\n  - {name: first, validate: smoke.xml}\n")
    return path


def _store(tmp_path) -> Path:
    store = tmp_path / "store"
    (store / "scan_0000").mkdir(parents=True)
    return store


#: every command that writes an output folder: its arguments before --out, and its options
#: to append (None: it cannot) and to replace
COMMANDS = {
    "capture": (lambda t: ["capture", "--object", "bottle"], "--append", "--force"),
    "run": (lambda t: ["run", str(SCRIPTS_DIR / "smoke.xml")], "--append", "--force"),
    "autoscan": (lambda t: ["autoscan", "--object", "bottle"], None, "--force"),
    "replay": (lambda t: ["replay", str(_store(t))], None, "--force"),
    "register": (lambda t: ["register", str(_store(t))], None, "--force"),
    "calibrate handeye": (lambda t: ["calibrate", "handeye"], None, "--force"),
    "calibrate intrinsics": (lambda t: ["calibrate", "intrinsics", str(_store(t))], None, "--force"),
    "batch": (lambda t: ["batch", str(_batch_file(t))], "--resume", "--force"),
    "bench ik": (lambda t: ["bench", "ik", "--poses", "1"], None, "--force"),
    "bench sim": (lambda t: ["bench", "sim"], None, "--force"),
    "bench registration": (lambda t: ["bench", "registration"], None, "--force"),
    "bench sequence": (lambda t: ["bench", "sequence", "--quick"], None, "--force"),
    "bench tour": (lambda t: ["bench", "tour", "--quick"], None, "--force"),
    "bench profile": (lambda t: ["bench", "profile", "--quick"], None, "--force"),
    "bench viewplan": (lambda t: ["bench", "viewplan"], None, "--force"),
    "bench planners": (lambda t: ["bench", "planners", "--quick"], None, "--force"),
}


# ----------------------------------------------------------------------------- claim_output
def test_a_new_folder_is_made_and_an_empty_one_is_fine(tmp_path):
    folder = claim_output(tmp_path / "a" / "b", command="capture")
    assert folder.path.is_dir() and folder.made and folder.mode is OutputMode.NEW and not os.listdir(folder.path)
    (tmp_path / "empty").mkdir()
    assert claim_output(tmp_path / "empty", command="capture").path == tmp_path / "empty"
    (tmp_path / "real").mkdir()
    (tmp_path / "via").symlink_to(tmp_path / "real")  # the folder itself may be reached through a link
    claim_output(tmp_path / "via", command="capture")


def test_a_non_empty_folder_is_refused_naming_it_what_it_holds_and_the_options(used):
    before = snapshot(used)
    with pytest.raises(FileError) as exc:
        claim_output(used, command="run", append="--append to add this run's scans to the scan store in it")
    line = exc.value.one_line()
    assert "\n" not in line and f"output folder {used} is not empty" in line
    assert "it holds .config.yaml.x1y2.yaml, mine, notes.txt and 3 more" in line
    assert "--append" in line and "--force" in line and "--out" in line
    with pytest.raises(FileError, match=r"not empty .*; pass --force to replace what recon wrote there, or choose"):
        claim_output(used, command="autoscan")
    assert snapshot(used) == before


def test_a_file_or_a_dangling_link_is_refused(tmp_path):
    (tmp_path / "f").write_text("x")
    for mode in OutputMode:
        with pytest.raises(FileError, match="is a file"):
            claim_output(tmp_path / "f", mode, command="capture")
    (tmp_path / "dangling").symlink_to(tmp_path / "nowhere")
    with pytest.raises(FileError, match="link to a missing folder"):
        claim_output(tmp_path / "dangling", command="capture")
    assert not (tmp_path / "nowhere").exists()
    with pytest.raises(FileError, match="not writable"):
        claim_output(tmp_path / "f" / "sub", command="capture")


def test_append_and_force_exclude_each_other(tmp_path, capsys):
    with pytest.raises(InputError, match="--append and --force exclude each other"):
        OutputMode.of(append=True, force=True)
    assert OutputMode.of() is OutputMode.NEW and OutputMode.of(force=True) is OutputMode.FORCE
    assert main(["run", str(SCRIPTS_DIR / "smoke.xml"), "--out", str(tmp_path / "o"), "--append", "--force"]) == 1
    assert "exclude each other" in one_error_line(capsys)
    assert main(["batch", str(_batch_file(tmp_path)), "--out", str(tmp_path / "o"), "--resume", "--force"]) == 1
    assert "--resume and --force exclude each other" in one_error_line(capsys)
    assert not (tmp_path / "o").exists()


def test_append_keeps_everything_and_refuses_a_link_anywhere(tmp_path, outside):
    out = tmp_path / "out"
    (out / "scans" / "scan_0000").mkdir(parents=True)
    (out / "run_report.json").write_text("{}")
    folder = claim_output(out, OutputMode.APPEND, command="run")
    assert folder.mode is OutputMode.APPEND and (out / "run_report.json").read_text() == "{}"
    (out / "scans" / "scan_0000" / "depth.png").symlink_to(outside / "victim.txt")
    with pytest.raises(FileError, match="holds a link .*depth.png"):
        claim_output(out, OutputMode.APPEND, command="run")


def test_force_removes_what_recon_wrote_and_nothing_else(tmp_path, used, outside):
    before = snapshot(outside)
    folder = claim_output(used, OutputMode.FORCE, command="capture")
    assert sorted(os.listdir(used)) == ["mine", "notes.txt"]
    assert set(folder.removed) == {"scan_0000", "session.json", ".config.yaml.x1y2.yaml", "report.html"}
    assert (used / "mine").is_symlink() and (used / "notes.txt").read_text() == "mine\n"
    assert snapshot(outside) == before  # the links were removed, not followed


def test_force_never_removes_an_input(tmp_path):
    out = tmp_path / "cal"
    (out / "scans" / "scan_0000").mkdir(parents=True)
    (out / "handeye.json").write_text("{}")
    with pytest.raises(FileError, match=r"--force would remove .*scans, which this command reads"):
        claim_output(out, OutputMode.FORCE, command="calibrate handeye", force="--force",
                     inputs=(out / "scans",))
    with pytest.raises(FileError, match="which this command reads"):  # the folder itself is the input
        claim_output(out / "scans", OutputMode.FORCE, command="register", inputs=(out / "scans",))
    assert (out / "scans" / "scan_0000").is_dir() and (out / "handeye.json").is_file()


def test_force_removes_the_exports_an_earlier_run_recorded(tmp_path, outside):
    out = tmp_path / "run"
    (out / "sub").mkdir(parents=True)
    (out / "sub" / "x.ply").write_text("ply")
    (out / "sub" / "mine.txt").write_text("mine")
    (out / "y.ply").write_text("ply")
    (out / "run_report.json").write_text(json.dumps({"outputs": {
        "export_cloud": str(out / "sub" / "x.ply"), "export_mesh": str(out / "y.ply"),
        "export_far": str(outside / "victim.txt")}}))
    folder = claim_output(out, OutputMode.FORCE, command="run")
    assert set(folder.removed) == {"run_report.json", "sub/x.ply", "y.ply"}
    assert (out / "sub" / "mine.txt").is_file() and (outside / "victim.txt").is_file()


def test_a_link_where_recon_puts_its_folder_is_refused_or_replaced(tmp_path, outside):
    store = tmp_path / "store"
    store.mkdir()
    (store / "reconstruction").symlink_to(outside / "victim_dir")
    before = snapshot(outside)
    with pytest.raises(FileError, match=r"reconstruction is a link to .*recon does not write through links; "
                                        r"remove the link, pass --force"):
        claim_output(store / "reconstruction", command="register", nested_in=store)
    folder = claim_output(store / "reconstruction", OutputMode.FORCE, command="register", nested_in=store,
                          make=False)
    assert (store / "reconstruction").is_symlink()  # nothing happens before the command writes
    folder.make()
    assert (store / "reconstruction").is_dir() and not (store / "reconstruction").is_symlink()
    assert folder.removed == ("reconstruction",) and snapshot(outside) == before


def test_make_false_checks_now_and_changes_nothing_until_made(tmp_path, used):
    before = snapshot(used)
    with pytest.raises(FileError, match="not empty"):
        claim_output(used, command="register", make=False)
    folder = claim_output(used, OutputMode.FORCE, command="register", make=False)
    assert snapshot(used) == before and not folder.made and "scan_0000" in folder.pending
    assert folder.make() == used and not (used / "scan_0000").exists()
    new = claim_output(tmp_path / "later", command="register", make=False)
    assert not (tmp_path / "later").exists()
    new.make()
    assert (tmp_path / "later").is_dir()


def test_default_folders_are_always_new(tmp_path, monkeypatch):
    import recon_cli.outputs as outputs

    monkeypatch.setattr(outputs, "RUNS", tmp_path / "runs")
    a = claim_output(None, command="bench ik")
    b = claim_output(None, command="bench ik")
    assert a.path != b.path and a.path.parent == b.path.parent == tmp_path / "runs"
    assert a.path.name.startswith("bench-ik-") and b.path.is_dir()
    assert claim_output(None, command="calibrate handeye", default="handeye").path.name.startswith("handeye-")


def test_remove_inside_never_deletes_through_a_link(tmp_path, outside):
    root = tmp_path / "batch"
    root.mkdir()
    (root / "jobs").symlink_to(outside)
    before = snapshot(outside)
    with pytest.raises(FileError, match="lies behind the link .*jobs"):
        remove_inside(root, Path("jobs") / "victim_dir")
    with pytest.raises(FileError, match="not a name inside"):
        remove_inside(root, "../outside")
    assert remove_inside(root, "jobs") and not (root / "jobs").exists()
    assert not remove_inside(root, "jobs")
    assert snapshot(outside) == before


def test_keep_earlier_numbers_the_earlier_files(tmp_path):
    (tmp_path / "run_report.json").write_text("1")
    (tmp_path / "run_report-1.json").write_text("0")
    kept = keep_earlier(tmp_path, "run_report.json", "config.yaml")
    assert kept == [tmp_path / "run_report-2.json"] and (tmp_path / "run_report-2.json").read_text() == "1"


def test_the_table_of_what_recon_writes():
    assert all(written_by_recon(n) for n in ("scan_0012", ".scan_0003.tmp-77", "session.json",
                                             ".session.json.tmp", "report_files", ".report_files.tmp-5",
                                             "run_report-3.json", "config-2.yaml", "mug_ellipsoid", ".lock",
                                             "cloud_evaluation.json", ".write-testab12"))
    assert not any(written_by_recon(n) for n in ("notes.txt", "scan_notes", ".git", "my.ply", "data"))
    assert "recon run" in WRITTEN and "recon batch" in WRITTEN


# ----------------------------------------------------------------------------- every command
@pytest.mark.parametrize("command", COMMANDS)
def test_every_command_refuses_a_non_empty_out_before_any_work(command, tmp_path, used, outside, tripwire,
                                                                capsys):
    argv, append, force = COMMANDS[command]
    before, far = snapshot(used), snapshot(outside)
    assert main([*argv(tmp_path), "--out", str(used)]) == 1
    line = one_error_line(capsys)
    assert f"output folder {used} is not empty" in line and "notes.txt" in line, line
    assert force in line and (append is None or append in line) and "started its work" not in line, line
    assert snapshot(used) == before and snapshot(outside) == far


@pytest.mark.parametrize("command", [c for c in COMMANDS if c != "register"])
def test_force_replaces_what_recon_wrote_then_the_work_starts(command, tmp_path, used, outside, tripwire,
                                                               capsys):
    argv, _, force = COMMANDS[command]
    far = snapshot(outside)
    assert main([*argv(tmp_path), "--out", str(used), force]) == 1
    assert "the command started its work" in one_error_line(capsys)
    left = set(os.listdir(used))
    assert {"mine", "notes.txt"} <= left and not left & {"scan_0000", "session.json", "report.html"}, left
    assert left - {"mine", "notes.txt"} <= {"batch.json", ".lock"}  # what a batch writes before its jobs
    assert snapshot(outside) == far


def test_the_report_page_is_not_written_through_a_link(tmp_path, outside, capsys):
    run = tmp_path / "run"
    (run / "scan_0000").mkdir(parents=True)
    (run / "session.json").write_text("{}")
    (run / "report_files").symlink_to(outside / "victim_dir")
    far = snapshot(outside)
    assert main(["report", str(run), "--no-render"]) == 1
    assert "report_files is a link" in one_error_line(capsys)
    assert main(["report", str(tmp_path / "none")]) == 1
    assert "does not exist" in one_error_line(capsys)
    assert snapshot(outside) == far


def test_evaluate_writes_beside_the_reconstruction_but_not_through_a_link(tmp_path, outside, capsys):
    rec = tmp_path / "rec"
    rec.mkdir()
    (rec / "cloud.ply").write_text("ply")
    (rec / "cloud_distances.png").symlink_to(outside / "victim.txt")
    far = snapshot(outside)
    assert main(["evaluate", str(rec / "cloud.ply"), "--reference", str(tmp_path / "ref.ply")]) == 1
    assert "cloud_distances.png is a link to" in one_error_line(capsys)
    assert snapshot(outside) == far


def test_force_removes_the_sides_of_an_earlier_two_sided_run_links_as_links(tmp_path, outside):
    """side_1, side_2 and sides_report.json are recon's: --force removes them (a link among
    them as a link), so that a two-sided run never writes a side into a folder a link leads to."""
    out = tmp_path / "two"
    (out / "side_2").mkdir(parents=True)
    (out / "side_1").symlink_to(outside / "victim_dir")
    (out / "sides_report.json").write_text("{}")
    (out / "notes.txt").write_text("mine\n")
    far = snapshot(outside)
    folder = claim_output(out, OutputMode.FORCE, command="autoscan")
    assert set(folder.removed) == {"side_1", "side_2", "sides_report.json"} and os.listdir(out) == ["notes.txt"]
    assert snapshot(outside) == far


# ----------------------------------------------------------------------------- capture, end to end
CAPTURE = ["capture", "--object", "bottle", "--resolution", "0.1", "--no-noise"]


@pytest.fixture(scope="module")
def capture_store(tmp_path_factory) -> Path:
    """One scan of the bottle at a tenth of the image size."""
    out = tmp_path_factory.mktemp("capture") / "store"
    assert main([*CAPTURE, "--out", str(out)]) == 0
    return out


def test_capture_append_and_force(capture_store, tmp_path, outside, capsys):
    out = tmp_path / "store"
    shutil.copytree(capture_store, out)
    assert all(written_by_recon(n) for n in os.listdir(out)), os.listdir(out)  # the table knows every name
    assert main([*CAPTURE, "--out", str(out)]) == 1
    assert "--append" in one_error_line(capsys)
    report = (out / "capture_report.json").read_text()
    assert main([*CAPTURE, "--theta", "60", "--out", str(out), "--append"]) == 0
    assert sorted(p.name for p in out.glob("scan_*")) == ["scan_0000", "scan_0001"]
    assert (out / "capture_report-1.json").read_text() == report and (out / "config-1.yaml").is_file()
    assert all(written_by_recon(n) for n in os.listdir(out)), os.listdir(out)
    (out / "notes.txt").write_text("mine\n")
    (out / "recording.rrd").symlink_to(outside / "victim.txt")
    far = snapshot(outside)
    assert main([*CAPTURE, "--out", str(out), "--force"]) == 0
    assert sorted(p.name for p in out.glob("scan_*")) == ["scan_0000"]
    assert not (out / "capture_report-1.json").exists() and not (out / "recording.rrd").exists()
    assert (out / "notes.txt").read_text() == "mine\n" and snapshot(outside) == far
    assert json.loads((out / "capture_report.json").read_text())["scans"] == 1


# ----------------------------------------------------------------------------- register
REGISTER = ["--no-board", "--global-only", "--depth", "5", "--voxel", "0.004"]


def test_register_refuses_a_reconstruction_link_and_force_replaces_it(capture_store, tmp_path, outside, capsys):
    store = tmp_path / "store"
    shutil.copytree(capture_store, store)
    (store / "reconstruction").symlink_to(outside / "victim_dir")
    far = snapshot(outside)
    assert main(["register", str(store), *REGISTER]) == 1
    line = one_error_line(capsys)
    assert "reconstruction is a link to" in line and "--force" in line
    assert main(["register", str(store), *REGISTER, "--force"]) == 0, capsys.readouterr().err
    rec = store / "reconstruction"
    assert rec.is_dir() and not rec.is_symlink() and (rec / "cloud.ply").is_file()
    assert snapshot(outside) == far
    # a second registration: refused, then replaced with --force (the user's file stays)
    (rec / "mine.txt").write_text("mine")
    (rec / "mesh.ply").unlink()
    (rec / "mesh.ply").symlink_to(outside / "victim.txt")
    assert main(["register", str(store), *REGISTER]) == 1
    assert f"output folder {rec} is not empty" in one_error_line(capsys)
    assert main(["register", str(store), *REGISTER, "--force"]) == 0
    assert (rec / "mine.txt").read_text() == "mine" and not (rec / "mesh.ply").is_symlink()
    assert snapshot(outside) == far


def test_register_force_removes_nothing_when_no_scan_is_usable(capture_store, tmp_path, capsys):
    store = tmp_path / "store"
    shutil.copytree(capture_store, store)
    (store / "reconstruction").mkdir()
    (store / "reconstruction" / "cloud.ply").write_text("earlier")
    assert main(["register", str(store), "--no-board", "--crop-box", "5,5,5,0.1,0.1,0.1", "--force"]) == 1
    assert "points inside the crop box" in one_error_line(capsys)
    assert (store / "reconstruction" / "cloud.ply").read_text() == "earlier"


def test_register_skips_scans_that_are_links_out_of_the_store(capture_store, tmp_path, outside, capsys):
    store = tmp_path / "store"
    shutil.copytree(capture_store, store)
    elsewhere = outside / "scans"
    shutil.copytree(store / "scan_0000", elsewhere / "scan_0000")
    (store / "scan_0001").symlink_to(elsewhere / "scan_0000")  # a whole scan
    shutil.copytree(store / "scan_0000", store / "scan_0002")
    (store / "scan_0002" / "depth.png").unlink()
    (store / "scan_0002" / "depth.png").symlink_to(elsewhere / "scan_0000" / "depth.png")  # one file
    shutil.copytree(store / "scan_0000", store / "scan_0003")
    (store / "scan_0003" / "color.png").unlink()
    (store / "scan_0003" / "color.png").symlink_to(store / "scan_0000" / "color.png")  # stays inside: fine
    far = snapshot(outside)
    assert main(["register", str(store), *REGISTER]) == 0
    out = capsys.readouterr().out
    assert "2 of 4 scans registered (2 skipped)" in out
    assert "scan_0001 skipped:" in out and "outside the scan store" in out
    assert "scan_0002 skipped:" in out and "depth.png is a link to" in out
    report = json.loads((store / "reconstruction" / "report.json").read_text())
    assert [s["skipped"] is None for s in report["scans"]] == [True, False, False, True]
    assert snapshot(outside) == far
    # only links out of the store: nothing usable, one line with the reasons
    only = tmp_path / "only"
    only.mkdir()
    shutil.copy(store / "session.json", only)
    (only / "scan_0000").symlink_to(elsewhere / "scan_0000")
    assert main(["register", str(only), *REGISTER]) == 1
    assert "none of the 1 scans" in (line := one_error_line(capsys)) and "outside the scan store" in line
    (only / "scan_0000").unlink()
    shutil.copytree(store / "scan_0000", only / "scan_0000")
    (only / "session.json").unlink()
    (only / "session.json").symlink_to(store / "session.json")
    assert main(["register", str(only), *REGISTER]) == 1
    assert "session.json is a link to" in one_error_line(capsys)
    assert not (only / "reconstruction").exists()


# ----------------------------------------------------------------------------- batch --resume
@pytest.mark.parametrize("link", ["jobs", "jobs/first", "jobs/first/output"])
def test_batch_resume_never_deletes_through_a_link(link, tmp_path, outside, capsys):
    out = tmp_path / "batch"
    (out / "jobs" / "first").mkdir(parents=True)
    (out / "batch.json").write_text("{}")
    if (out / link).exists():
        shutil.rmtree(out / link)
    (out / link).symlink_to(outside / "victim_dir")
    far = snapshot(outside)
    assert main(["batch", str(_batch_file(tmp_path)), "--out", str(out), "--resume"]) == 1
    line = one_error_line(capsys)
    assert f"holds a link {out / link}" in line and "recon does not write through links" in line
    assert snapshot(outside) == far and (out / link).is_symlink()


def test_batch_lock_is_not_opened_through_a_link(tmp_path, outside, capsys):
    from recon_cli.batch.runner import _Lock

    (tmp_path / ".lock").symlink_to(outside / "victim.txt")
    far = snapshot(outside)
    with pytest.raises(FileError, match="it is a link"), _Lock(tmp_path):
        pass
    assert snapshot(outside) == far


# ----------------------------------------------------------------------------- station file
def test_a_station_file_link_is_updated_where_it_points(tmp_path):
    from recon_cli.backends.station_file import load_station
    from recon_cli.calibration.station_update import write_station_hand_eye
    from tests.calibration.test_station_update import STATION, _calibrated

    # (inside the link's folder: a station file linked out of its folder is not read)
    link_dir = tmp_path / "cwd"
    real_dir = link_dir / "stations"
    real_dir.mkdir(parents=True)
    real = real_dir / "cell.yaml"
    real.write_text(STATION)
    real.chmod(0o640)
    (real_dir / "cell.yaml.bak").symlink_to(tmp_path / "victim.txt")  # a link where the backup goes
    (tmp_path / "victim.txt").write_text("keep me\n")
    link = link_dir / "cell.yaml"
    link.symlink_to(real)
    X = _calibrated()
    backup = write_station_hand_eye(link, X, "test")
    assert link.is_symlink() and link.resolve() == real  # the link stays a link
    assert backup == real_dir / "cell.yaml.bak" and not backup.is_symlink() and backup.read_text() == STATION
    assert (tmp_path / "victim.txt").read_text() == "keep me\n"
    assert np.allclose(np.reshape(load_station(link).cell.flange_T_camera, (4, 4)), X, atol=1e-9)
    assert "a comment that must survive" in real.read_text() and real.stat().st_mode & 0o777 == 0o640
    assert sorted(os.listdir(link_dir)) == ["cell.yaml", "stations"]  # nothing beside the link
    assert sorted(os.listdir(real_dir)) == ["cell.yaml", "cell.yaml.bak"]


@pytest.mark.parametrize("args", [["capture", "--object", "spaceship"], ["autoscan", "--object", "BAD.stl"],
                                  ["run", "NOPE.xml"]])
def test_a_command_that_fails_leaves_no_empty_output_folder(tmp_path, args):
    (tmp_path / "BAD.stl").write_text("x")
    args = [a.replace("BAD.stl", str(tmp_path / "BAD.stl")) for a in args]
    assert main([*args, "--out", str(tmp_path / "out" / "new")]) != 0
    assert not (tmp_path / "out").exists()
    (tmp_path / "kept").mkdir()
    (tmp_path / "kept" / "note.txt").write_text("mine")
    assert main([*args, "--out", str(tmp_path / "kept"), "--force"]) != 0
    assert (tmp_path / "kept" / "note.txt").read_text() == "mine"
