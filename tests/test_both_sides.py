"""The turn between two sides (recon_cli/both_sides.py) on a real cell: the operator is asked,
the pause recorded; Ctrl-C at the prompt reaches the caller; no terminal is one line; the box
of the turned object holds it however it lies."""

from __future__ import annotations

import builtins

import numpy as np
import pytest

from recon_cli.both_sides import OPERATOR_PROMPT, any_way_up_box, turn_object, turn_rng
from recon_cli.errors import ReconError
from recon_cli.geometry.transforms import pose, rot_x, rot_z
from recon_cli.objects import load_object


def test_the_operator_turns_the_object_on_a_real_cell():
    asked: list[str] = []
    turn = turn_object(load_object("bottle"), False, turn_rng(0), asked.append)
    assert asked == [OPERATOR_PROMPT] and "press Enter" in OPERATOR_PROMPT and "Ctrl-C" in OPERATOR_PROMPT
    assert turn.scene_object is None and turn.record["by"] == "operator" and turn.record["pause_s"] >= 0.0


def _input_raising(exc: type[BaseException]):
    def answer(prompt: str = "") -> str:
        raise exc

    return answer


def test_ctrl_c_at_the_prompt_reaches_the_caller(monkeypatch, capsys):
    monkeypatch.setattr(builtins, "input", _input_raising(KeyboardInterrupt))
    with pytest.raises(KeyboardInterrupt):
        turn_object(load_object("bottle"), False, turn_rng(0))
    assert "turn the object over" in capsys.readouterr().out


def test_no_terminal_to_ask_is_one_line(monkeypatch):
    monkeypatch.setattr(builtins, "input", _input_raising(EOFError))
    with pytest.raises(ReconError) as info:
        turn_object(load_object("bottle"), False, turn_rng(0))
    line = info.value.one_line()
    assert "\n" not in line and "the standard input is closed" in line and "first side's scans are kept" in line


def test_the_box_of_a_turned_object_holds_it_any_way_up(tmp_path):
    import open3d as o3d

    obj = load_object("toy_blocks")
    seen = obj.world_vertices()
    path = tmp_path / "side_1.ply"
    o3d.io.write_point_cloud(str(path), o3d.geometry.PointCloud(o3d.utility.Vector3dVector(seen)))
    centre, size = any_way_up_box(path, 0.01)
    lo, hi = seen.min(axis=0), seen.max(axis=0)
    assert size[0] == size[1] == size[2] == pytest.approx(np.linalg.norm(hi - lo) + 0.02)
    assert centre[2] - size[2] / 2 == pytest.approx(lo[2])  # standing on the table
    middle = (lo + hi) / 2
    for a, b in ((0.0, 0.0), (np.pi / 2, 0.3), (np.pi, 1.0), (2.0, 2.5)):
        # turned about its middle, lying on the table again, back on its spot
        T = pose(rot_z(b) @ rot_x(a), middle) @ pose(np.eye(3), -middle)
        moved = seen @ T[:3, :3].T + T[:3, 3]
        moved[:, 2] += lo[2] - moved[:, 2].min()
        assert np.all(np.abs(moved - np.asarray(centre)) <= np.asarray(size) / 2 + 1e-9)
