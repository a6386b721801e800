"""The report files of run folders (recon_cli.runs): every model survives a write and a
read unchanged, a malformed file is one line naming the file and the key, and every report
a real (small) run, capture and autoscan writes reads back through runs/ with the keys it
has always had."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from recon_cli.errors import MetadataError
from recon_cli.runs import autoscan, capture, evaluation, register, script_run
from recon_cli.runs.codec import matrix

POSE = matrix(np.array([[0.0, -1, 0, 0.1], [1, 0, 0, -0.2], [0, 0, 1, 0.75], [0, 0, 0, 1]]))
EYE = matrix(np.eye(4))


def _run_report() -> script_run.ScriptRunReport:
    return script_run.ScriptRunReport(
        script="scripts_xml/smoke.xml", name="smoke", dialect="recon", on_failure="skip", dry_run=False,
        backend="sim", seed=3, seconds=12.5, scans=2, status="interrupted", exit_code=130, aborted=None,
        interrupted=script_run.Interruption("SIGINT", "interrupted by SIGINT at smoke.xml:12", "smoke.xml:12", 2),
        append=True, outputs={"cloud": "out/reconstruction/cloud.ply", "export_mesh": "out/bottle_mesh.ply"},
        sequence_optimization=(script_run.SequenceOptimization(3, "ours", 8, ("smoke.xml:10", "smoke.xml:12"), 9.5,
                                                                 6, 7.25, 0.5),),
        commands=(script_run.Command("smoke.xml:10", "move view", "done", 1.25, "",
                                     {"planner": "RRTConnect", "plan_time_s": 0.5, "trajectory_s": None}),
                  script_run.Command("smoke.xml:11", "scan", "done", 0.5, "", {"scan": 0, "points": 12000}),
                  script_run.Command("smoke.xml:14", "evaluate", "failed", 0.0, "no cloud",
                                     {"coverage": 0.81, "std_mm": 0.2, "pose_sources": {"charuco": 2}})))


def _autoscan_report() -> autoscan.AutoscanReport:
    return autoscan.AutoscanReport(
        method="ellipsoid", object="bottle", cell="gantry", n=3, d_c=0.55, m=200, sigma=1e-5, seed=1, scans=3,
        interrupted=False, error=None, infeasible_views=1, planning_requests=5, trajectory_s=20.5,
        coverage_1mm=0.8123, accuracy=autoscan.Accuracy(-0.1, 0.25, 5000, {"±0.5 mm": 0.9, "±1 mm": 0.99}),
        seconds_scanning=40.0, seconds_total=55.5,
        views=(autoscan.ViewOutcome("completed", 0, POSE, None, None),
               autoscan.ViewOutcome("infeasible", 1, EYE),
               autoscan.ViewOutcome("completed", 1, POSE, 0.75, 4.5)),
        outputs=autoscan.AutoscanOutputs("a/reconstruction/cloud.ply", None, ("a/iterations/iteration_01.png",)))


def _capture_report() -> capture.CaptureReport:
    return capture.CaptureReport(status="incomplete", views=3, scans=2, seconds=8.25, error=None,
                                 failures=(capture.ViewFailure(2, "view 2: no inverse kinematics solution"),))


def _register_report() -> register.RegisterReport:
    error = register.PoseError(1.5, 0.25)
    pose = register.GlobalPose(0, "charuco", 24, 0.31, "", POSE, EYE, 15000)
    return register.RegisterReport(
        scan_store="runs/a/scans", frame="world", world_T_marker=POSE, scans_registered=2, scans_skipped=1,
        crop_box_marker=register.CropBoxRecord(EYE, (0.1, 0.2, 0.3), 0.0015),
        scans=(register.ScanRegistration(0, "scan_0000", 9000, None, pose, POSE, charuco_error=error,
                                         global_pose_error=error, final_pose_error=register.PoseError(0.5, 0.1),
                                         global_relative_pose_error=error, final_relative_pose_error=error),
               register.ScanRegistration(1, "scan_0001", 8000, None,
                                         register.GlobalPose(1, "kinematics", None, None, "board not found", POSE),
                                         POSE),
               register.ScanRegistration(2, "scan_0002", 12, "12 points inside the crop box")),
        pose_sources={"charuco": 1, "kinematics": 1},
        kinematic_correction=register.KinematicCorrection(EYE, POSE, 4, 3.5, 0.5),
        charuco_error_mean=error, pose_error_mean=register.PoseErrorMean(global_=error, final=error),
        pose_graph=register.PoseGraph((register.PairEdge(0, 1, "odometry", False, 4000, 0.6, 0.0012, EYE),), 0, 1,
                                      0, 0),
        points=register.PointCounts(120000), options={"use_board": True, "perturb": None, "surface": {"voxel": 0.002}},
        timings={"global_s": 1.5, "local_s": 2.0, "surface_s": 3.0, "total_s": 6.5},
        outputs=register.RegisterOutputs("cloud.ply", "cloud_global.ply", None))


def _evaluation_report() -> evaluation.EvaluationReport:
    return evaluation.EvaluationReport(
        reconstruction="out/cloud.ply", reference="bottle.ply", alignment="icp", alignment_transform=POSE,
        points=50000, mean_mm=-0.05, std_mm=0.3, rms_mm=0.31, median_abs_mm=0.2, within={"±1 mm": 0.99},
        coverage=0.9, coverage_visible=None, visible_share=0.8, coverage_tolerance_mm=1.0, reference_samples=200000)


MODELS = {"run": (script_run, _run_report, script_run.RUN_REPORT),
          "autoscan": (autoscan, _autoscan_report, autoscan.AUTOSCAN_REPORT),
          "capture": (capture, _capture_report, capture.CAPTURE_REPORT),
          "register": (register, _register_report, register.REGISTER_REPORT),
          "evaluation": (evaluation, _evaluation_report, "cloud_evaluation.json")}


@pytest.mark.parametrize("kind", MODELS)
def test_every_model_reads_back_as_written(kind, tmp_path):
    module, make, name = MODELS[kind]
    model = make()
    path = module.write(tmp_path, model)
    assert path == tmp_path / name and not list(tmp_path.glob(".*"))  # no temporary file left
    assert module.read(path) == model
    if kind != "evaluation":
        assert module.read(tmp_path) == model  # the folder names its file


def test_the_files_keep_their_keys(tmp_path):
    """Keys a file holds only sometimes are left out when there is nothing to say; the
    details of a command sit beside its own keys; pose errors keep their names."""
    data = json.loads(script_run.write(tmp_path, _run_report()).read_text())
    assert list(data["commands"][0]) == ["source", "command", "status", "seconds", "message", "planner",
                                         "plan_time_s", "trajectory_s"]
    assert data["commands"][0]["trajectory_s"] is None and data["interrupted"]["scans_kept"] == 2
    data = json.loads(register.write(tmp_path, _register_report()).read_text())
    assert list(data["scans"][1]) == ["scan", "folder", "points", "skipped", "pose", "final_marker_T_camera"]
    assert set(data["scans"][0]) >= {"charuco_error", "global_pose_error", "final_pose_error",
                                     "global_relative_pose_error", "final_relative_pose_error"}
    assert data["pose_error_mean"] == {"global": {"translation_mm": 1.5, "rotation_deg": 0.25},
                                       "final": {"translation_mm": 1.5, "rotation_deg": 0.25}}
    assert data["points"] == {"fused": 120000} and data["world_T_marker"][2][3] == 0.75


def _spoil(path: Path, edit) -> None:
    data = json.loads(path.read_text())
    edit(data)
    path.write_text(json.dumps(data))


CASES = {
    "run": (lambda d: d["commands"][1].update(seconds=-1.0), "commands[1].seconds"),
    "run status": (lambda d: d.update(status="finished"), "status"),
    "autoscan": (lambda d: d["views"][0].update(world_T_camera=[[1, 0, 0]]), "views[0].world_T_camera"),
    "capture": (lambda d: d["failures"][0].update(view="two"), "failures[0].view"),
    "register": (lambda d: d["scans"][0]["pose"].update(corners=1e40), "scans[0].pose.corners"),
    "evaluation": (lambda d: d.update(coverage=1.5), "coverage"),
}


@pytest.mark.parametrize("case", CASES)
def test_a_malformed_file_is_one_line_naming_file_and_key(case, tmp_path):
    module, make, name = MODELS[case.split()[0]]
    path = module.write(tmp_path, make())
    edit, key = CASES[case]
    _spoil(path, edit)
    with pytest.raises(MetadataError) as info:
        module.read(path)
    line = info.value.one_line()
    assert "\n" not in line and str(path) in line and f"key '{key}" in line, line


def test_a_hostile_or_missing_file_is_one_line(tmp_path):
    path = tmp_path / script_run.RUN_REPORT
    for text, needle in (('{"status": NaN, "commands": []}', "not a finite number"),
                         ("[" * 100 + "]" * 100, "nests lists and objects"),
                         ('{"status": "done", "status": "done", "commands": []}', "twice"),
                         ("[]", "holds a list, not a JSON object"),
                         ('{"commands": []}', "'status' is a required property")):
        path.write_text(text)
        with pytest.raises(MetadataError) as info:
            script_run.read(tmp_path)
        line = info.value.one_line()
        assert needle in line and str(path) in line and "\n" not in line, line
    with pytest.raises(MetadataError, match="is missing"):
        capture.read(tmp_path)


def test_every_report_schema_bounds_every_number():
    from recon_cli.paths import SCHEMA_DIR

    def walk(node, where):
        if isinstance(node, dict):
            if node.get("type") in ("number", "integer") or "number" in (node.get("type") or ()):
                assert "maximum" in node and ("minimum" in node or "exclusiveMinimum" in node), where
            for k, v in node.items():
                walk(v, f"{where}.{k}")
        elif isinstance(node, list):
            for i, v in enumerate(node):
                walk(v, f"{where}[{i}]")

    for name in ("run_report", "autoscan_report", "capture_report", "register_report", "evaluation_report",
                 "sides_report"):
        walk(json.loads((SCHEMA_DIR / f"{name}.schema.json").read_text()), name)


# ----------------------------------------------------------------------------- real runs
RUN_KEYS = ["script", "name", "dialect", "on_failure", "dry_run", "backend", "seed", "seconds", "scans", "status",
            "exit_code", "aborted", "interrupted", "append", "outputs", "sequence_optimization", "commands"]
REGISTER_KEYS = ["scan_store", "frame", "world_T_marker", "scans_registered", "scans_skipped", "crop_box_marker",
                 "scans", "pose_sources", "kinematic_correction", "charuco_error_mean", "pose_error_mean",
                 "pose_graph", "points", "options", "timings", "outputs"]


@pytest.fixture(scope="module")
def smoke(tmp_path_factory) -> Path:
    from recon_cli.cli import main
    from recon_cli.paths import SCRIPTS_DIR

    out = tmp_path_factory.mktemp("runs") / "smoke"
    assert main(["run", str(SCRIPTS_DIR / "smoke.xml"), "--out", str(out)]) == 0
    return out


def _rewrites_the_same(module, path: Path, model) -> None:
    """Written again from the model read, the file is the same document."""
    copy = path.parent / f".copy-{path.name}"
    copy.write_text(json.dumps(json.loads(path.read_text())))
    again = module.write(path.parent, model)
    try:
        assert json.loads(again.read_text()) == json.loads(copy.read_text())
    finally:
        again.write_text(copy.read_text())
        copy.unlink()


def test_a_script_run_reads_back(smoke):
    run = script_run.read(smoke)
    assert list(json.loads((smoke / script_run.RUN_REPORT).read_text())) == RUN_KEYS
    assert run.status == "done" and run.scans == 3 and run.name == "smoke"
    assert len(run.moves) == 4 and all(c.command.startswith("move") for c in run.moves)  # three views, home
    assert all(c.number("plan_time_s") > 0 and c.planner for c in run.moves)
    _rewrites_the_same(script_run, smoke / script_run.RUN_REPORT, run)
    reg = register.read(Path(run.outputs["registration_report"]))
    assert list(json.loads((smoke / "reconstruction" / "report.json").read_text())) == REGISTER_KEYS
    assert reg.scans_registered == 3 and len(reg.registered) == 3 and reg.frame == "world"
    assert reg.pose_graph is not None and reg.pose_graph.edges and reg.pose_error_mean.final.translation_mm < 20
    _rewrites_the_same(register, smoke / "reconstruction" / "report.json", reg)
    [path] = evaluation.reports(smoke / "reconstruction")
    e = evaluation.read(path)
    assert e.name == "cloud" and 0 < e.coverage <= 1 and e.points > 1000
    _rewrites_the_same(evaluation, path, e)


def test_a_capture_and_an_autoscan_read_back(tmp_path):
    from recon_cli.config import DEFAULTS, SceneConfig, SensorConfig, ViewPlanConfig
    from recon_cli.geometry.view import View
    from recon_cli.workflows.autoscan import Autoscan, AutoscanOptions
    from recon_cli.workflows.capture import CaptureOptions, run_capture

    config = DEFAULTS.replace(scene=SceneConfig("bottle"), seed=1, sensor=SensorConfig(resolution=0.2),
                              viewplan=ViewPlanConfig(n=2))
    views = (View.from_degrees((0, 0, 0.78), 0.6, 70, 0), View.from_degrees((0, 0, 0.78), 0.05, 70, 0))
    done = run_capture(CaptureOptions(views=views, out=tmp_path / "c", config=config, page=False))
    report = capture.read(done.folder)
    assert report.status == "incomplete" and (report.views, report.scans) == (2, 1)
    assert [f.view for f in report.failures] == [2] and report.failures == tuple(done.failures)
    _rewrites_the_same(capture, done.report, report)

    result = Autoscan(AutoscanOptions(tmp_path / "a", config, pictures=False, mesh=False, page=False)).run()
    report = autoscan.read(result.report)
    assert report.scans == 2 and report.status == "done" and report.accuracy == result.accuracy
    assert [v.status for v in report.views].count("completed") == 2 and report.coverage_1mm == result.coverage
    assert report.outputs.cloud == str(result.cloud)
    _rewrites_the_same(autoscan, result.report, report)
    assert register.read(tmp_path / "a" / "reconstruction").scans_registered == 2


def test_the_page_says_why_a_report_cannot_be_read(smoke, tmp_path):
    import shutil

    from recon_cli.cli import main

    run = tmp_path / "run"
    shutil.copytree(smoke, run)
    _spoil(run / script_run.RUN_REPORT, lambda d: d.update(status="finished"))
    _spoil(run / "reconstruction" / "report.json", lambda d: d["timings"].update(total_s=-5))
    assert main(["report", str(run), "--no-render"]) == 0
    text = (run / "report.html").read_text()
    assert "run_report.json key &#x27;status&#x27;" in text or "run_report.json key 'status'" in text
    assert "timings.total_s" in text
