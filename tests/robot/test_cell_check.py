"""``recon cell check``: a shipped lab cell is ready to scan (picture written); a cell whose
home pose collides or lies outside the soft limits, or whose object position is out of
reach, fails with ``problem:`` lines that say which joint, which directions and why, and
exit code 1."""

from __future__ import annotations

import math
import shutil
from pathlib import Path

import numpy as np

from recon_cli.cell_check import AT_LIMIT, COLLIDES, INSIDE, NO_IK, OUT_OF_REACH, check_cell
from recon_cli.cli import main
from recon_cli.paths import CELLS_DIR, ROBOT_DIR
from recon_cli.robot.cell import Cell
from recon_cli.robot.description import CellConfig


def test_the_fr3_cell_is_fit_to_scan_with(tmp_path, capsys):
    out = tmp_path / "check"
    assert main(["cell", "check", "fr3", "--step", "0.3", "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "home: collision-free" in text and "board from home: 5 of 5 points" in text
    assert "simulation: MuJoCo scene built, its camera at the cell's camera frame" in text
    assert text.rstrip().splitlines()[-1] == ("fr3: no problems found; the cell is ready to scan "
                                              "(recon autoscan --cell fr3)")
    assert (out / "reachability.png").stat().st_size > 10_000


def test_reachability_counts_the_directions_of_each_point():
    result = check_cell(Cell(CellConfig(kind="fr3")), np.random.default_rng(0), step=0.4)
    r = result.reach
    assert r.counts.shape == (len(r.ys), len(r.xs)) and r.directions == 24
    assert r.xs[0] > r.table[0] and r.xs[-1] < r.table[1]  # cells tile the table top
    assert r.object_count >= 20 and not result.problems
    # every direction not reached has its reason
    assert sum(n for _, n in r.failures) == r.counts.size * r.directions - r.counts.sum()
    assert {f for f, _ in r.failures} <= {INSIDE, COLLIDES, NO_IK}
    assert len(r.object_directions) == r.directions
    assert sum(d.reached for d in r.object_directions) == r.object_count
    assert [t for t, _ in r.by_theta] == [20.0, 40.0, 60.0]
    sim = result.simulation
    assert sim is not None and sim.camera_agrees and sim.depth_share > 0.5


def test_a_cell_whose_home_collides_fails_the_check(tmp_path, capsys):
    shutil.copytree(ROBOT_DIR, tmp_path / "robot", ignore=shutil.ignore_patterns("realism"))
    cell = tmp_path / "bent.yaml"
    text = (CELLS_DIR / "fr3.yaml").read_text().replace("../robot/", "robot/")
    home = next(line for line in text.splitlines() if line.strip().startswith("home:"))
    cell.write_text(text.replace(home, "  home: [0, 100, 0, -170, 0, 40, 0]"))
    assert main(["cell", "check", str(cell), "--step", "0.4", "-o", str(tmp_path / "out")]) == 1
    text = capsys.readouterr().out
    assert "problem: the home pose collides" in text
    assert (Path(tmp_path / "out") / "reachability.png").exists()


def test_home_outside_the_soft_limits_and_an_object_out_of_reach_say_which_and_why(tmp_path, capsys):
    shutil.copytree(ROBOT_DIR, tmp_path / "robot", ignore=shutil.ignore_patterns("realism"))
    cell = tmp_path / "far.yaml"
    text = (CELLS_DIR / "fr3.yaml").read_text().replace("../robot/", "robot/")
    home = next(line for line in text.splitlines() if line.strip().startswith("home:"))
    # joint 4 at -10 deg: inside its hard upper limit -8.6975 deg, 3.6975 deg above the soft one
    text = text.replace(home, "  home: [0, -10, 0, -10, 0, 110, 0]")
    position = next(line for line in text.splitlines() if line.strip().startswith("position:"))
    cell.write_text(text.replace(position, "  position: [0.55, 0.35, 0.753]"))  # 1 m from the base
    assert main(["cell", "check", str(cell), "--step", "0.5", "-o", str(tmp_path / "out")]) == 1
    out = capsys.readouterr().out
    problems = [line for line in out.splitlines() if line.startswith("problem: ")]
    assert ("problem: the home pose is outside the soft joint limits: fr3_joint4 at -10 deg is 3.698 deg above "
            "its soft upper limit -13.7 deg") in problems
    reach = next(p for p in problems if "the object position is reachable from" in p)
    assert "not reached: " in reach and any(w in reach for w in (OUT_OF_REACH, AT_LIMIT))
    assert "limit margin -3.698 deg (fr3_joint4, outside its soft limits)" in out
    listed = next(line for line in out.splitlines() if line.startswith("object position, not reached"))
    assert "theta/phi in deg" in listed and " 20/0," in listed  # the camera beyond the object, off the robot


def test_a_distance_fcl_leaves_without_depth_is_not_printed_as_a_value():
    import fcl

    from recon_cli.render import FCL_NO_DEPTH, distance_text

    # python-fcl's answer for a cylinder touching a box, which it does not call a collision
    a = fcl.CollisionObject(fcl.Cylinder(0.05, 0.1), fcl.Transform())
    b = fcl.CollisionObject(fcl.Box(0.1, 0.1, 0.1), fcl.Transform(np.array([0.1, 0.0, 0.0])))
    assert fcl.distance(a, b, fcl.DistanceRequest(), fcl.DistanceResult()) == FCL_NO_DEPTH
    assert not fcl.collide(a, b, fcl.CollisionRequest(), fcl.CollisionResult())
    pair = ("link_a/shape_a", "link_b/shape_b")
    assert distance_text(FCL_NO_DEPTH, pair, "self-collision") == \
        "touching or overlapping (shape_a ↔ shape_b; no depth computed for these shapes)"
    assert distance_text(math.inf, ("", ""), "self-collision") == "no self-collision pairs checked"
    assert distance_text(-0.004, pair, "self-collision") == "overlapping by 4.0 mm (shape_a ↔ shape_b)"
    assert distance_text(0.0252, pair, "self-collision") == "25.2 mm (shape_a ↔ shape_b)"
