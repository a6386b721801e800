"""``recon bench profile``: the main job's wall clock by stage. The stage arithmetic on a
made-up profile (the innermost stage owns the time), then ``--quick`` through the command
line: every stage in the JSON, the rows adding up to the total, the plot and the autoscan's
own outputs written."""

from __future__ import annotations

import importlib
import json
from dataclasses import replace

import pytest

from recon_cli.bench import profile
from recon_cli.bench.profile import (
    OTHER,
    STAGES,
    START_UP,
    SUBFOLDER,
    function_key,
    main_job_options,
    stage_names,
    stage_rows,
)
from recon_cli.cli import main
from recon_cli.errors import ReconError


def _key(stage: str) -> tuple:
    module, qualname = next((m, q) for s, m, q in STAGES if s == stage)
    key = function_key(module, qualname)
    assert key is not None, (module, qualname)
    return key


def test_every_stage_function_exists():
    missing = [f"{m}.{q}" for _, m, q in STAGES if function_key(m, q) is None]
    assert missing == []
    assert len(stage_names()) == len(set(stage_names())) and START_UP not in stage_names()


class _Given(ReconError):
    """Raised by a stand-in workflow once it has its options."""


def test_the_workflow_gets_what_recon_autoscan_gives_it(monkeypatch, tmp_path):
    given = []

    def workflow(opts, progress=None):
        given.append(opts)
        raise _Given("options taken")

    monkeypatch.setattr(importlib.import_module("recon_cli.cli.autoscan"), "Autoscan", workflow)
    assert main(["autoscan", "--dc", "0.55", "--n", "16", "--object", "bottle", "--seed", "0",
                 "--out", str(tmp_path / "a")]) == 1
    ours = main_job_options(tmp_path / "a")
    assert given and replace(given[0], out=ours.out) == ours


def test_the_innermost_stage_owns_the_time(monkeypatch):
    """run (10 s) calls select_view (4 s, its own planning request 1 s inside) and a helper
    (3 s), which calls render_rgbd (2 s), which calls apply (0.5 s); apply also recurses."""
    run, helper = ("w.py", 1, "run"), ("w.py", 9, "helper")
    select, plan = _key("view selection and motion planning"), function_key(
        "recon_cli.planning.planner", "MotionPlanner.plan_to_joints")
    render, sensor = _key("rendering"), _key("sensor model")
    raw = {  # key: (cc, nc, tt, ct, callers: {caller: (cc, nc, tt, ct)})
        run: (1, 1, 1.0, 10.0, {}),
        select: (1, 1, 3.0, 4.0, {run: (1, 1, 3.0, 4.0)}),
        plan: (1, 1, 1.0, 1.0, {select: (1, 1, 1.0, 1.0)}),
        helper: (1, 1, 1.0, 3.0, {run: (1, 1, 1.0, 3.0)}),
        render: (1, 1, 1.5, 2.0, {helper: (1, 1, 1.5, 2.0)}),
        sensor: (1, 2, 0.5, 0.5, {render: (1, 1, 0.4, 0.5), sensor: (0, 1, 0.1, 0.1)}),
    }
    rows = {r.stage: r.seconds for r in stage_rows(raw, 0.5, 11.0)}
    assert rows["view selection and motion planning"] == pytest.approx(4.0)  # the request not twice
    assert rows["rendering"] == pytest.approx(1.5) and rows["sensor model"] == pytest.approx(0.5)
    assert rows[START_UP] == 0.5 and rows[OTHER] == pytest.approx(11.0 - 0.5 - 4.0 - 2.0)
    assert sum(rows.values()) == pytest.approx(11.0)
    assert list(rows) == [START_UP, *stage_names(), OTHER]


def test_an_import_inside_an_import_is_counted_once():
    """scan_cloud (3 s) imports a library (2 s), whose module imports another (0.5 s): the
    imports are 2 s (cProfile's cumulative time counts the outermost call), taken from the
    scan clouds."""
    cloud, load = _key("scan clouds"), _key("imports (libraries loaded on first use)")
    run, body = ("w.py", 1, "run"), ("lib/__init__.py", 1, "<module>")
    raw = {
        run: (1, 1, 0.0, 3.0, {}),
        cloud: (1, 1, 1.0, 3.0, {run: (1, 1, 1.0, 3.0)}),
        load: (1, 2, 0.1, 2.0, {cloud: (1, 1, 0.05, 2.0), body: (0, 1, 0.05, 0.5)}),
        body: (1, 1, 1.4, 1.9, {load: (1, 1, 1.4, 1.9)}),
    }
    rows = {r.stage: r.seconds for r in stage_rows(raw, 0.0, 3.0)}
    assert rows["imports (libraries loaded on first use)"] == pytest.approx(2.0)
    assert rows["scan clouds"] == pytest.approx(1.0) and rows[OTHER] == pytest.approx(0.0)


@pytest.mark.slow
def test_bench_profile_quick(capsys, tmp_path):
    out = tmp_path / "profile"
    assert main(["bench", "profile", "--quick", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    data = json.loads((out / "bench_profile.json").read_text())
    assert (out / "stage_profile.png").stat().st_size > 0 and (out / profile.PSTATS_FILE).stat().st_size > 0
    assert data["quick"] and data["settings"]["n"] == profile.QUICK_N and data["scans"] == profile.QUICK_N
    assert (out / SUBFOLDER / "autoscan_report.json").is_file() and (out / SUBFOLDER / "report.html").is_file()
    stages = {s["stage"]: s for s in data["stages"]}
    assert list(stages) == [START_UP, *stage_names(), OTHER]
    total = data["total_s"]
    assert total > 0 and abs(sum(s["seconds"] for s in stages.values()) - total) <= 0.01 * total
    for name in ("session set-up", "rendering", "sensor model", "scan storage", "scan clouds",
                 "ellipsoid fits", "view selection and motion planning", "robot execution", "registration",
                 "report page", "pictures (hand-over, final wait)"):
        assert stages[name]["seconds"] > 0, (name, {k: v["seconds"] for k, v in stages.items()})
        assert all(f["found"] for f in stages[name]["functions"]), name
    assert stages[OTHER]["seconds"] >= -0.01 * total  # nothing counted twice
    assert "bench_profile.json" in printed and "rendering" in printed and f"{total:.2f} s" in printed
