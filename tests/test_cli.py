"""The command line: commands run, user errors are one line with a non-zero exit."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from recon_cli.cli import main


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_help_lists_commands(capsys):
    code, out, _ = run(capsys, "--help")
    assert code == 0
    for command in ("cell", "ik", "bench"):
        assert command in out


def test_help_shows_units(capsys):
    """Units in brackets are text, not terminal markup."""
    code, out, _ = run(capsys, "ik", "--help")
    assert code == 0 and "Camera distance r from f [m]" in out and "Polar angle from the vertical [deg]" in out
    code, out, _ = run(capsys, "bench", "planners", "--help")
    assert code == 0 and "Planning time limit per request [s]" in out


def test_help_is_fast_and_light():
    """`recon --help` must not load the heavy libraries (a module of recon_cli.lazy stands in
    sys.modules unloaded until first used)."""
    code = ("import sys; from recon_cli.cli import main; main(['--help']); "
            "heavy = [m for m in ('pinocchio', 'fcl', 'coal', 'open3d', 'mujoco', 'ompl', 'cv2', 'scipy', 'toppra', "
            "'matplotlib') if m in sys.modules and type(sys.modules[m]).__name__ != '_LazyModule']; "
            "print('HEAVY', heavy)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert "HEAVY []" in out.stdout


def test_open3d_loads_without_its_plotly_viewer_until_it_is_used():
    """Open3D imported after recon_cli leaves its Plotly/Dash viewer (and Dash, Flask,
    IPython) unloaded; the viewer's functions still work and load it on first call."""
    code = ("import sys, recon_cli, open3d as o3d; print('DASH', 'dash' in sys.modules); "
            "cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector([[0.0, 0, 0], [1, 1, 1]])); "
            "figure = o3d.visualization.get_plotly_fig([cloud]); "
            "print('FIGURE', type(figure).__name__, 'dash' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert "DASH False" in out.stdout and "FIGURE Figure True" in out.stdout


def test_cell_prints_joints_shapes_camera(capsys, tmp_path):
    code, out, _ = run(capsys, "cell", "--urdf", str(tmp_path / "cell.urdf"))
    assert code == 0
    for text in ("base_joint_1", "arm_joint_7", "capsule", "table_top", "camera in flange", "marker"):
        assert text in out
    assert (tmp_path / "cell.urdf").read_text().startswith("<?xml")


def test_cell_ceiling(capsys):
    code, out, _ = run(capsys, "cell", "--cell", "ceiling")
    assert code == 0 and "7 DoF" in out and "base_joint_1" not in out


def test_ik_prints_solutions(capsys):
    code, out, _ = run(capsys, "ik", "--focus", "0,0,0.78", "-r", "0.6", "--theta", "70",
                       "--phi", "30", "--solutions", "3")
    assert code == 0
    assert "3 IK solution(s)" in out and "clearance" in out and "limit margin" in out


def test_ik_marker_frame(capsys):
    code, out, _ = run(capsys, "ik", "--frame", "marker", "--focus", "0.1925,0.1225,0.1",
                       "--theta", "50", "--solutions", "1")
    assert code == 0 and "1 IK solution(s)" in out


@pytest.mark.parametrize("argv, code, needle", [
    (["ik", "--focus", "0.7,1.2,-0.2", "-r", "0.3", "--theta", "90"], 1, "out of reach"),
    (["ik", "--theta", "170", "-r", "0.2"], 1, "under the table top"),
    (["ik", "--focus", "0,0,0.9", "--theta", "0", "-r", "0.05"], 1, "inside object"),
    (["ik", "--cell", "scara"], 2, "Invalid value for '--cell': 'scara' is not one of 'gantry', 'ceiling'"),
    (["cell", "--cell", "12dof"], 2, "Invalid value for '--cell'"),
    (["ik", "--radius", "abc"], 2, "Invalid value for '--radius'"),
    (["ik", "--focus", "1,2,x"], 2, "Invalid value for '--focus': '1,2,x' is not 3 numbers"),
    (["ik", "--focus", "1,2"], 2, "is not 3 numbers"),
    (["ik", "--radius", "-0.5"], 2, "Invalid value for '--radius' / '-r'"),
    (["ik", "--theta", "nan"], 2, "Invalid value for '--theta': nan is not a finite number"),
    (["ik", "--radius", "inf"], 2, "inf is not a finite number"),
    (["ik", "--frame", "tool"], 2, "Invalid value for '--frame': 'tool' is not one of 'world', 'marker'"),
    (["ik", "--object-box", "0.3,-1,0.3"], 1, "non-positive edge"),
    (["cell", "--safety", "-1"], 2, "Invalid value for '--safety'"),
    (["ik", "--nonsense"], 2, "No such option"),
])
def test_bad_input_is_one_line(capsys, argv, code, needle):
    got, out, err = run(capsys, *argv)
    assert got == code
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, err
    assert lines[0].startswith("error: ")
    assert needle in lines[0]
    assert "Traceback" not in err + out


def test_console_script_exit_code():
    """The installed entry point exits non-zero without a traceback."""
    proc = subprocess.run([sys.executable, "-m", "recon_cli", "ik", "--cell", "nope"],
                          capture_output=True, text=True)
    assert proc.returncode == 2
    assert proc.stderr.strip().startswith("error: Invalid value for '--cell'")
    assert "Traceback" not in proc.stderr


def test_bench_ik_quick(capsys, tmp_path):
    code, out, _ = run(capsys, "bench", "ik", "--poses", "10", "--out", str(tmp_path))
    assert code == 0
    data = json.loads((tmp_path / "bench_ik.json").read_text())
    res = data["result"]
    assert res["n_poses"] == 10 and res["success_first"] == 1.0
    assert res["all_within_soft_limits"] and res["all_collision_free"]


def test_bench_output_folder_not_writable(capsys, tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    code, _, err = run(capsys, "bench", "ik", "--poses", "1", "--out", str(blocker / "sub"))
    assert code == 1 and "not writable" in err


def test_bench_planners_small(capsys, tmp_path):
    code, out, _ = run(capsys, "bench", "planners", "--planners", "RRTConnect", "--requests", "3",
                       "--out", str(tmp_path))
    assert code == 0
    data = json.loads((tmp_path / "bench_planners.json").read_text())
    assert data["summary"]["RRTConnect"]["requests"] == 3
    assert (tmp_path / "plan_times.png").stat().st_size > 0
    assert (tmp_path / "requests.csv").read_text().startswith("planner,request,solved")


def test_bench_planners_bad_names(capsys):
    code, _, err = run(capsys, "bench", "planners", "--planners", "RRT,EST", "--requests", "1")
    assert code == 2 and "Invalid value for '--planners': 'EST' is not one of RRTConnect, RRT," in err
    code, _, err = run(capsys, "bench", "planners", "--peer", "moveit", "--requests", "1")
    assert code == 2 and "Invalid value for '--peer': 'moveit' is not one of 'none', 'mplib'" in err


def test_version_short_help_and_completion(capsys, monkeypatch):
    import typer.completion

    from recon_cli import __version__

    # typer takes the shell from the process tree (the test runner's parent may be any shell)
    monkeypatch.setattr(typer.completion, "_get_shell_name", lambda: "bash")

    code, out, _ = run(capsys, "--version")
    assert code == 0 and out.strip() == f"recon {__version__}"
    for argv in (["-h"], ["ik", "-h"], ["bench", "planners", "-h"], ["calibrate", "handeye", "-h"],
                 ["station", "check", "-h"]):
        code, out, _ = run(capsys, *argv)
        assert code == 0 and out.startswith("Usage: recon"), argv
    code, out, err = run(capsys, "--show-completion", "bash")
    assert code == 0 and "_RECON_COMPLETE=complete_bash" in out, err


def test_completion_offers_commands_and_options():
    import os
    import subprocess
    import sys

    env = {**os.environ, "_RECON_COMPLETE": "complete_bash", "COMP_WORDS": "recon ca", "COMP_CWORD": "1"}
    code = "from recon_cli.cli import entry; entry()"
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=60).stdout
    assert out.split() == ["capture", "calibrate"]
    env.update(COMP_WORDS="recon autoscan --se", COMP_CWORD="2")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=60).stdout
    assert "--seed" in out.split()
