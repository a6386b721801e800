"""``recon cell check``: a shipped lab cell is fit to scan with (picture written); a cell whose
home pose collides fails with one ``problem:`` line and exit code 1."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np

from recon_cli.cell_check import check_cell
from recon_cli.cli import main
from recon_cli.paths import CELLS_DIR, ROBOT_DIR
from recon_cli.robot.cell import Cell
from recon_cli.robot.description import CellConfig


def test_the_fr3_cell_is_fit_to_scan_with(tmp_path, capsys):
    out = tmp_path / "check"
    assert main(["cell", "check", "fr3", "--step", "0.3", "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "home: collision-free" in text and "board from home: 5 of 5 points" in text
    assert "fr3: fit to scan with" in text
    assert (out / "reachability.png").stat().st_size > 10_000


def test_reachability_counts_the_directions_of_each_point():
    result = check_cell(Cell(CellConfig(kind="fr3")), np.random.default_rng(0), step=0.4)
    r = result.reach
    assert r.counts.shape == (len(r.ys), len(r.xs)) and r.directions == 24
    assert r.xs[0] > r.table[0] and r.xs[-1] < r.table[1]  # cells tile the table top
    assert r.object_count >= 20 and not result.problems


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
