"""Seeds make runs repeatable: the same planning request with the same seed gives the same
path in one process (whatever ran before); `recon autoscan`, `recon capture`, `recon
register` and `recon run` run twice with the same --seed, and once more from the first run's
config.yaml (--config), write the same reports, scan files and clouds; so do two batches and
two `recon bench planners`. Only wall-clock times and the run folder differ.

Not compared: the Poisson meshes (and their triangle counts). Open3D builds them with
several threads, which sum in varying order; the points they are built from are compared.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest
import yaml

os.environ.setdefault("MUJOCO_GL", "egl")  # before MuJoCo is imported

from typer.testing import CliRunner  # noqa: E402

from recon_cli.cli import app  # noqa: E402
from recon_cli.paths import SCRIPTS_DIR  # noqa: E402
from recon_cli.planning.planner import MotionPlanner, PlanOptions, ompl_seed  # noqa: E402
from recon_cli.thesis import TABLE_4_1_GOAL, TABLE_4_1_START  # noqa: E402

#: keys of wall-clock times (and of the creation instant) in the reports and scan files
CLOCK_KEYS = frozenset({
    "seconds", "seconds_scanning", "seconds_total", "seconds_register", "created",
    "capture_start", "capture_end", "capture_seconds", "global_s", "local_s", "surface_s", "total_s",
    "plan_time_s", "plan_time", "planning_s", "search_time", "simplify_time", "post_time",
    "time_min", "time_median", "time_p90", "time_max", "time_median_all", "post_time_median",
    "simplify_time_s", "planning_total_s",
    "started", "wall_s", "wall_time", "log_tail",  # a batch's jobs (log_tail: the job's output with its times)
})
#: keys of numbers that come from the Poisson mesh (see the module docstring)
MESH_KEYS = frozenset({"triangles"})


# ---------------------------------------------------------------------- planning requests
def _path(planner: MotionPlanner, seed: int) -> np.ndarray:
    r = planner.plan_to_joints(TABLE_4_1_START, TABLE_4_1_GOAL, seed=seed)
    assert r.ok, r.message
    return r.path


@pytest.mark.parametrize("simplify", ["shortcut", "full"])
def test_same_request_and_seed_give_the_same_path(gantry, simplify):
    options = PlanOptions(simplify=simplify)
    planner = MotionPlanner(gantry, options)
    first = _path(planner, 7)
    _path(planner, 8)  # another request in between: OMPL's generators have moved on
    again = _path(planner, 7)
    fresh = _path(MotionPlanner(gantry, options), 7)  # a new planner's first request
    assert np.array_equal(first, again)
    assert np.array_equal(first, fresh)


def test_other_seeds_give_other_paths(gantry):
    planner = MotionPlanner(gantry, PlanOptions())
    paths = [_path(planner, seed) for seed in (7, 8, 9)]
    assert any(p.shape != paths[0].shape or not np.array_equal(p, paths[0]) for p in paths[1:])


def test_pose_goals_are_repeatable_given_the_generator(gantry):
    """IK seeds and the request's seed both come from the generator passed in."""
    from recon_cli.geometry.view import View

    planner = MotionPlanner(gantry, PlanOptions())
    T = gantry.view_pose(View((0.0, 0.0, 0.8), 0.6, np.radians(45.0), 0.0))
    a = planner.plan_to_pose(TABLE_4_1_START, T, np.random.default_rng(3))
    b = planner.plan_to_pose(TABLE_4_1_START, T, np.random.default_rng(3))
    assert a.ok and b.ok
    assert np.array_equal(a.path, b.path)


def test_ompl_seeds_are_positive_and_differ_by_stream():
    seeds = {ompl_seed(s, attempt, part) for s in (0, 1, 2**32 - 1) for attempt in (1, 2) for part in (0, 1)}
    assert len(seeds) == 12 and all(0 < s < 2**31 for s in seeds)
    assert ompl_seed(5, 1, 0) == ompl_seed(5, 1, 0)
    with pytest.raises(ValueError):
        ompl_seed(-1)


# ---------------------------------------------------------------------- whole commands
def _invoke(*argv: str) -> None:
    result = CliRunner().invoke(app, list(argv))
    assert result.exit_code == 0, (result.output, result.exception)


def _comparable(value, folder: Path):
    """The value without wall-clock fields, the run folder in paths replaced by '<out>'."""
    if isinstance(value, dict):
        return {k: _comparable(v, folder) for k, v in value.items() if k not in CLOCK_KEYS | MESH_KEYS}
    if isinstance(value, list):
        return [_comparable(v, folder) for v in value]
    if isinstance(value, str):
        return value.replace(str(folder), "<out>")
    return value


def _files(folder: Path, *patterns: str) -> dict[str, object]:
    """Every JSON file matching the patterns (relative path: comparable content) and the
    points of every cloud (PLY files named cloud*)."""
    import open3d as o3d

    out: dict[str, object] = {}
    for pattern in patterns:
        for path in sorted(folder.glob(pattern)):
            key = str(path.relative_to(folder))
            if path.suffix == ".json":
                out[key] = _comparable(json.loads(path.read_text()), folder)
            else:
                out[key] = np.asarray(o3d.io.read_point_cloud(str(path)).points).tolist()
    return out


def _assert_same(a: dict, b: dict) -> None:
    assert a.keys() == b.keys()
    for key in a:
        assert a[key] == b[key], f"{key} differs between the two runs"


def _config_sections(folder: Path) -> dict:
    data = yaml.safe_load((folder / "config.yaml").read_text())
    return {k: v for k, v in data.items() if k != "run"}


def _same_three_times(tmp_path: Path, argv: tuple, *patterns: str) -> tuple[list[Path], dict[str, object]]:
    """Run argv twice and once from the first run's config.yaml: the files matching the
    patterns and the configurations agree."""
    folders = [tmp_path / name for name in ("first", "second", "repeat")]
    _invoke(*map(str, argv), "--out", str(folders[0]))
    _invoke(*map(str, argv), "--out", str(folders[1]))
    _invoke(str(argv[0]), "--config", str(folders[0] / "config.yaml"), "--out", str(folders[2]))
    files = [_files(f, *patterns) for f in folders]
    _assert_same(files[0], files[1])
    _assert_same(files[0], files[2])
    assert _config_sections(folders[0]) == _config_sections(folders[1]) == _config_sections(folders[2])
    return folders, files[0]


@pytest.mark.slow
def test_autoscan_twice_and_from_its_config(tmp_path):
    argv = ("autoscan", "--n", "3", "--m", "20", "--resolution", "0.1", "--no-pictures", "--seed", "3",
            "--object", "bottle")
    folders, files = _same_three_times(tmp_path, argv, "*.json", "scan_*/*.json", "reconstruction/*.json",
                                       "reconstruction/cloud*.ply")
    report = files["autoscan_report.json"]
    assert report["scans"] == 3 and len(report["views"]) >= 3 and report["trajectory_s"] > 0
    assert report["seed"] == 3 and report["n"] == 3 and report["m"] == 20
    repeat = yaml.safe_load((folders[2] / "config.yaml").read_text())
    assert repeat["sensor"]["resolution"] == 0.1 and repeat["run"]["pictures"] is False


@pytest.mark.slow
def test_capture_and_register_twice_and_from_their_config(tmp_path):
    argv = ("capture", "--object", "bottle", "--resolution", "0.1", "--seed", "5", "--theta", "60")
    folders, files = _same_three_times(tmp_path / "capture", argv, "capture_report.json", "session.json",
                                       "scan_*/*.json")
    assert files["session.json"]["seed"] == 5
    store = folders[0]
    argv = ("register", store, "--voxel", "0.002", "--global-only")
    folders, _ = _same_three_times(tmp_path / "register", argv, "report.json", "cloud*.ply")
    repeat = yaml.safe_load((folders[2] / "config.yaml").read_text())
    assert repeat["run"]["store"] == str(store)
    assert repeat["registration"]["surface"]["voxel"] == 0.002 and repeat["registration"]["local"] is False
    # an option given together with --config overrides the file's value, the others keep it
    _invoke("register", "--config", str(folders[0] / "config.yaml"), "--voxel", "0.003", "--out",
            str(tmp_path / "other"))
    other = yaml.safe_load((tmp_path / "other" / "config.yaml").read_text())
    assert other["registration"]["surface"]["voxel"] == 0.003 and other["registration"]["local"] is False
    assert other["seed"] == 0


@pytest.mark.slow
def test_smoke_script_twice_and_from_its_config(tmp_path):
    argv = ("run", SCRIPTS_DIR / "smoke.xml", "--seed", "3")
    folders, files = _same_three_times(tmp_path, argv, "run_report.json", "scans/scan_*/*.json",
                                       "reconstruction/*.json", "reconstruction/cloud*.ply")
    report = files["run_report.json"]
    assert report["seed"] == 3
    assert len([c for c in report["commands"] if "trajectory_s" in c]) == 4
    repeat = yaml.safe_load((folders[2] / "config.yaml").read_text())
    assert repeat["run"]["script"] == str(SCRIPTS_DIR / "smoke.xml") and repeat["seed"] == 3


@pytest.mark.slow
def test_batch_twice_with_one_seed(tmp_path):
    """A batch's jobs run in their own processes: two batches of one seed, the same jobs'
    reports, scans and summary."""
    batch = tmp_path / "repeat.yaml"
    batch.write_text("name: repeat\njobs:\n  - autoscan: {scans: 2, candidates: 10, resolution: 0.1, "
                     "pictures: false, seed: 4, object: bottle}\n")
    runs = []
    for k in (1, 2):
        out = tmp_path / f"batch{k}"
        _invoke("batch", str(batch), "--out", str(out))
        runs.append(_files(out, "summary.json", "jobs/*/result.json", "jobs/*/output/*.json",
                           "jobs/*/output/scan_*/*.json", "jobs/*/output/reconstruction/*.json"))
    _assert_same(*runs)
    summary = runs[0]["summary.json"]
    assert [j["status"] for j in summary["jobs"]] == ["passed"]
    assert runs[0]["jobs/autoscan/output/autoscan_report.json"]["scans"] == 2


@pytest.mark.slow
def test_planner_bench_twice_with_one_seed(tmp_path):
    runs = []
    for k in (1, 2):
        out = tmp_path / f"bench{k}"
        _invoke("bench", "planners", "--planners", "RRTConnect,BITstar", "--requests", "20", "--seed", "3",
                "--out", str(out))
        runs.append(_files(out, "bench_planners.json"))
    _assert_same(*runs)
    requests = runs[0]["bench_planners.json"]["requests"]
    assert len(requests) == 40 and len({r["seed"] for r in requests}) == 20  # a seed per request
    lengths = {r["path_length"] for r in requests if r["planner"] == "RRTConnect"}
    assert len(lengths) > 1  # the requests differ from each other
