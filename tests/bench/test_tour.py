"""``recon bench tour --quick`` through the command line: the optimal tour on the planned
matrix is never longer than ours, and the files say the same as the table."""

from __future__ import annotations

import json

import numpy as np
import pytest

from recon_cli.bench.sequence import SequenceProblem, run_case
from recon_cli.bench.tour import QUICK_VIEW_STEP
from recon_cli.cli import main
from recon_cli.sequence.exact import path_cost


@pytest.mark.slow
def test_bench_tour_quick(capsys, tmp_path):
    out = tmp_path / "tour"
    assert main(["bench", "tour", "--quick", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    data = json.loads((out / "bench_tour.json").read_text())
    assert (out / "tour_gap.png").stat().st_size > 0
    assert data["seeds"] == 1 and data["views_step"] == 2 and len(data["runs"]) == 1
    run = data["runs"][0]
    views = run["views"]
    assert views == 12
    matrix = np.array(run["matrix"])
    assert matrix.shape == (views + 1, views + 1) and np.allclose(matrix, matrix.T)
    for key in ("order_ours", "order_optimal"):
        assert run[key][0] == 0 and sorted(run[key]) == list(range(views + 1))
    # the durations are those of the orders on the one planned matrix
    assert run["ours"] == pytest.approx(path_cost(matrix, run["order_ours"]))
    assert run["optimal"] == pytest.approx(path_cost(matrix, run["order_optimal"]))
    assert run["proven_optimal"] and run["lower_bound"] == pytest.approx(run["optimal"])
    assert np.isfinite(run["optimal"]) and run["optimal"] <= run["ours"] + 1e-9
    assert run["optimal"] <= run["case_c"] + 1e-9
    assert run["optimal"] - 1e-9 <= run["search_full"] <= run["ours"] + 1e-9
    assert run["gap_s"] >= -1e-9 and run["gap_pct"] >= -1e-9
    assert run["gap_s"] == pytest.approx(run["ours"] - run["optimal"])
    assert run["gap_pct"] == pytest.approx(100.0 * run["gap_s"] / run["optimal"])
    assert run["requests_ours"] <= run["requests_matrix"] == views * (views + 1) // 2
    # ours is case D as ``recon bench sequence`` runs it on the same seed and views
    problem = SequenceProblem()
    problem.poses = problem.poses[::QUICK_VIEW_STEP]
    assert run_case(problem, "D", run["seed"]).duration == pytest.approx(run["ours"])
    summary = data["summary"]
    assert summary["all_proven_optimal"] and summary["gap_s_mean"] == pytest.approx(run["gap_s"])
    assert "optimal" in printed and f"{run['optimal']:.2f} s" in printed and "bench_tour.json" in printed
