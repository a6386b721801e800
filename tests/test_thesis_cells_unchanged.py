"""The thesis' cells give the numbers they gave before cells became data files.

The expected values are the reports of ``recon bench ik --poses 40`` (both cells) and
``recon bench planners --quick`` (Table 4.1, RRTConnect) as the tool printed them when the
gantry and ceiling cells were the only ones, on the same seeds: a generalisation below the
cell (the IK's seeds, the collision model, the limits, the planner) that changes a number
shows here. Wall-clock times are not compared. The README tour (tests/test_readme.py)
compares ``recon ik``, ``validate``, ``run``, ``autoscan`` and the eq. 4.1 capture and
registration the same way.
"""

from __future__ import annotations

import pytest

from recon_cli.bench.ik import IKBenchConfig, run_ik_bench
from recon_cli.bench.planners import run_planner_bench
from recon_cli.robot.cell import Cell
from recon_cli.robot.description import CellConfig

#: (samples drawn, first-solution success, mean distinct solutions, smallest separation [rad or m])
IK_BEFORE = {
    "gantry": (66056, 1.0, 4.0, 0.13281088923074158),
    "ceiling": (49999, 1.0, 4.0, 0.10220932538250713),
}
#: Table 4.1, RRTConnect, seed 0, 10 requests: path lengths and trajectory durations [s]
PATHS_BEFORE = [17.683810515, 23.553073963, 18.16613342, 16.934837411, 17.901470323, 16.907168219, 18.383886661,
                16.746933801, 14.350888113, 14.601737243]
DURATIONS_BEFORE = [21.515698408, 24.161811791, 17.52309829, 22.560431657, 24.217417423, 17.670120136,
                    17.110786658, 25.603135746, 16.034630002, 19.937023101]


@pytest.mark.parametrize("kind", ["gantry", "ceiling"])
def test_the_ik_benchmark_reports_what_it_did(kind):
    result = run_ik_bench(Cell(CellConfig(kind=kind)), IKBenchConfig(n_poses=40, seed=0))
    drawn, success, solutions, separation = IK_BEFORE[kind]
    assert result.samples_drawn == drawn
    assert result.success_first == success and result.success_multi == success
    assert result.mean_solutions == solutions
    assert result.min_pairwise_separation == pytest.approx(separation, abs=1e-12)
    assert result.all_within_soft_limits and result.all_collision_free


def test_the_table_4_1_paths_are_what_they_were():
    rows = run_planner_bench(["RRTConnect"], 10, 5.0, 0)
    assert all(r.solved for r in rows)
    assert [round(r.path_length, 9) for r in rows] == pytest.approx(PATHS_BEFORE, abs=1e-8)
    assert [round(r.trajectory_duration, 9) for r in rows] == pytest.approx(DURATIONS_BEFORE, abs=1e-8)
