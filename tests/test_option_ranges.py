"""Every number option of every command has a range, the same as a script's where a script
takes the same value, stated in docs/commands.md; a value outside it is a usage error (exit 2,
one line) before anything runs, on the command line and in a batch file alike."""

from __future__ import annotations

import re
import typing
import warnings
from pathlib import Path

import numpy as np
import pytest

from recon_cli.cli import main
from recon_cli.errors import InputError, InvalidViewError, UnreachableViewError

from .cli_commands import all_commands

ROOT = Path(__file__).resolve().parents[1]
COMMANDS_MD = ROOT / "docs" / "commands.md"


def _is_number(param) -> bool:
    annotation = param.type_descriptor.annotation
    return annotation in (int, float) or bool(set(typing.get_args(annotation)) & {int, float})


NUMBER_OPTIONS = [(name, p) for name, cmd in all_commands() for p in cmd.params if _is_number(p)]
IDS = [f"{name} {p.opts[-1]}" for name, p in NUMBER_OPTIONS]


@pytest.mark.parametrize(("command", "param"), NUMBER_OPTIONS, ids=IDS)
def test_every_number_option_has_a_range(command, param):
    assert param.min is not None and param.max is not None, f"{command} {param.opts[-1]} has no range"
    assert param.min < param.max


def _row(text: str, command: str, option: str) -> str:
    start = re.search(rf"(?m)^#{{2,4}} `{re.escape(command)}`\s*$", text)
    assert start, f"docs/commands.md has no section for {command}"
    body = text[start.end():]
    nxt = re.search(r"(?m)^#{2,4} ", body)
    body = body[:nxt.start()] if nxt else body
    rows = [ln for ln in body.splitlines() if ln.startswith("|") and f"`{option}`" in ln.split("|")[1]]
    assert rows, f"docs/commands.md, {command}: no row for {option}"
    return rows[0]


@pytest.mark.parametrize(("command", "param"), NUMBER_OPTIONS, ids=IDS)
def test_commands_md_states_every_range(command, param):
    row = _row(COMMANDS_MD.read_text(encoding="utf-8"), command, param.opts[-1])
    kind = "integer" if int in (param.type_descriptor.annotation, *typing.get_args(param.type_descriptor.annotation)) \
        else "number"
    expected = f"{kind}, {param.min!r} ... {param.max!r}"
    assert expected in row, f"docs/commands.md, {command} {param.opts[-1]}: says {row.split('|')[2].strip()!r}, " \
                            f"the code {expected!r}"


def test_view_bounds_are_those_of_scripts():
    """The view options take what a script's <move>/<view> takes (README "limits")."""
    from recon_cli.cli import options
    from recon_cli.geometry import view
    from recon_cli.scripts.build import ANGLE_BOUNDS_DEG

    xsd = (ROOT / "schemas" / "recon_script.xsd").read_text()
    assert options.MAX_THETA == ANGLE_BOUNDS_DEG["theta"]
    assert options.MAX_TURN == ANGLE_BOUNDS_DEG["phi"] == ANGLE_BOUNDS_DEG["alpha"]
    assert f'<xs:maxInclusive value="{view.MAX_COORDINATE:g}"/>' in xsd.split('name="coordinate"')[1][:200]
    assert f'<xs:maxInclusive value="{view.MAX_RADIUS:g}"/>' in xsd.split('name="radius"')[1][:200]
    assert options.RADIUS_RANGE[1] == view.MAX_RADIUS
    assert options.PLANNING_TIME_RANGE[1] == 3600.0
    assert '<xs:maxInclusive value="3600"/>' in xsd.split('name="planner"')[1][:600]
    readme = (ROOT / "README.md").read_text()
    assert "coordinates ±100 m, radius (0, 10] m" in readme and "planner time (0, 3600] s" in readme


def _one_usage_error(capsys, argv: list[str], needle: str) -> str:
    code = main(argv)
    out, err = capsys.readouterr()
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert code == 2, (code, out, err)
    assert len(lines) == 1 and lines[0].startswith("error: ") and needle in lines[0], err
    assert "Traceback" not in out + err and "Warning" not in err
    return lines[0]


@pytest.mark.parametrize(("argv", "needle"), [
    (["autoscan", "--m", "999999999999"], "Invalid value for '--candidates' / '-m' / '--m'"),
    (["autoscan", "-m", "100000000", "--n", "2"], "less than or equal to 1000"),
    (["autoscan", "--n", "201"], "Invalid value for '--scans' / '-n' / '--n'"),
    (["autoscan", "--scans", "1"], "Invalid value for '--scans' / '-n' / '--n'"),
    (["autoscan", "--sigma", "1e300"], "Invalid value for '--sigma'"),
    (["autoscan", "--scale", "1e300"], "Invalid value for '--scale'"),
    (["ik", "-r", "1e300"], "Invalid value for '--radius' / '-r'"),
    (["ik", "-r", "0"], "Invalid value for '--radius' / '-r'"),
    (["ik", "--radius", "1e999"], "inf is not a finite number"),
    (["ik", "--focus", "1e300,0,0.78"], "a coordinate of 1e+300 m is outside ±100 m"),
    (["ik", "--focus", "0,-100.5,0.78"], "outside ±100 m"),
    (["ik", "--alpha", "1e300"], "Invalid value for '--alpha'"),
    (["ik", "--alpha", "721"], "Invalid value for '--alpha'"),
    (["ik", "--phi", "-721"], "Invalid value for '--phi'"),
    (["ik", "--theta", "181"], "Invalid value for '--theta'"),
    (["ik", "--safety", "0.5"], "Invalid value for '--safety'"),
    (["ik", "--solutions", "33"], "Invalid value for '--solutions'"),
    (["capture", "--planning-time", "1e300"], "Invalid value for '--planning-time'"),
    (["capture", "--radius", "11"], "Invalid value for '--radius' / '-r'"),
    (["register", "x", "--voxel", "1e300"], "Invalid value for '--voxel'"),
    (["evaluate", "x", "--reference", "y", "--samples", "1000000000"], "Invalid value for '--samples'"),
    (["evaluate", "x", "--reference", "y", "--tolerance", "5"], "Invalid value for '--tolerance'"),
    (["replay", "x", "--depth-scale", "1e300"], "Invalid value for '--depth-scale'"),
    (["batch", "x.yaml", "--timeout", "1e300"], "Invalid value for '--timeout'"),
    (["calibrate", "intrinsics", "x", "--min-corners", "99999999"], "Invalid value for '--min-corners'"),
    (["bench", "ik", "--poses", "1000000000"], "Invalid value for '--poses'"),
    (["bench", "sequence", "--runs", "1000000000"], "Invalid value for '--runs'"),
    (["bench", "viewplan", "-n", "100000"], "Invalid value for '--scans' / '-n' / '--n'"),
    (["bench", "viewplan", "--dc", "1e300"], "Invalid value for '--dc'"),
    (["bench", "planners", "--requests", "1000000000"], "Invalid value for '--requests'"),
    (["bench", "planners", "--planning-time", "1e300"], "Invalid value for '--planning-time'"),
    (["bench", "planners", "--peer-requests", "1000000000"], "Invalid value for '--peer-requests'"),
    (["bench", "planners", "--shortcut-rounds", "1000000000"], "Invalid value for '--shortcut-rounds'"),
])
def test_values_beyond_the_range_are_usage_errors(capsys, tmp_path, argv, needle):
    line = _one_usage_error(capsys, argv + (["--out", str(tmp_path / "out")] if argv[0] in ("autoscan", "capture")
                                            else []), needle)
    assert not re.search(r"\d{30}", line)  # no 300-digit numbers
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("command", sorted({name for name, cmd in all_commands()
                                            if any("--focus" in p.opts for p in cmd.params)}))
def test_every_command_taking_a_view_bounds_it(capsys, command):
    words = command.split()[1:]
    for option, value in (("--focus", "0,0,1e300"), ("--radius", "1e300"), ("--theta", "1e300"), ("--phi", "1e300"),
                          ("--alpha", "1e300")):
        _one_usage_error(capsys, [*words, option, value], f"Invalid value for '{option}")


def test_a_batch_file_checks_the_same_ranges(tmp_path, capsys):
    batch = tmp_path / "b.yaml"
    batch.write_text("name: t\njobs:\n  - name: a\n    autoscan: {scans: 2, candidates: 999999999999}\n"
                     "  - name: b\n    capture: {alpha: 1e300}\n")
    assert main(["batch", str(batch), "--list"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "autoscan.candidates: Invalid value for '--candidates' / '-m' / '--m'" in err, err


def test_the_view_planner_refuses_more_samples_than_its_bound():
    from recon_cli.config import VIEWPLAN_M, ViewPlanConfig
    from recon_cli.viewplan.ellipsoid import Ellipsoid
    from recon_cli.viewplan.views import next_sample

    with pytest.raises(InputError, match="view planner m = 1e\\+12 is outside 1 ... 1000"):
        ViewPlanConfig(m=10**12)
    with pytest.raises(InputError, match="view planner n = 1 is outside 2 ... 200"):
        ViewPlanConfig(n=1)
    ell = Ellipsoid(np.eye(4), np.array([0.1, 0.1, 0.1]))
    with pytest.raises(InputError, match="preliminary samples per view"):
        next_sample(ell, np.zeros((0, 3)), VIEWPLAN_M[1] + 1, 1e-5, np.random.default_rng(0))
    assert next_sample(ell, np.zeros((0, 3)), VIEWPLAN_M[1], 1e-5, np.random.default_rng(0)).shape == (3,)


def test_a_view_and_ik_refuse_absurd_values_without_numpy_warnings():
    from recon_cli.cli.options import make_cell
    from recon_cli.geometry.view import View

    with pytest.raises(InvalidViewError, match=r"radius r = 1e\+300 m is beyond 10 m"):
        View((0.0, 0.0, 0.78), 1e300, 1.0, 0.0)
    with pytest.raises(InvalidViewError, match=r"coordinate of 1e\+300 m, beyond ±100 m"):
        View((1e300, 0.0, 0.78), 0.6, 1.0, 0.0)
    cell = make_cell("gantry", 0.03)
    T = np.eye(4)
    T[:3, 3] = (1e300, 0.0, 2.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # an overflow in the descent would be a RuntimeWarning
        result = cell.ik.solve(T, np.random.default_rng(0))
        assert result.status.value == "unreachable" and result.attempts == 0
        T[:3, 3] = (np.nan, 0.0, 2.0)
        assert cell.ik.solve(T, np.random.default_rng(0)).status.value == "unreachable"
        T[:3, 3] = (0.0, 0.0, 1e300)
        with pytest.raises((UnreachableViewError, InvalidViewError)):
            cell.solve_pose(T, np.random.default_rng(0))


@pytest.mark.parametrize(("argv", "needle"), [
    (["ik", "--object-box", "1e300,0.3,0.3"], "--object-box '1e300,0.3,0.3' has an edge beyond 10 m"),
    (["autoscan", "--initial", "1e300,0"], "--initial '1e300,0' is outside theta ±180°, phi ±720°"),
    (["register", "x", "--crop-box", "0,0,1e300,0.3,0.3,0.3"], "the centre must lie within ±100 m"),
    (["register", "x", "--crop-box", "0,0,0.8,11,0.3,0.3"], "sizes be at most 10 m"),
])
def test_numbers_in_text_options_are_bounded_too(capsys, tmp_path, argv, needle):
    code = main(argv + (["--out", str(tmp_path / "out")] if argv[0] == "autoscan" else []))
    out, err = capsys.readouterr()
    assert code == 1 and err.count("\n") == 1 and needle in err, (code, out, err)
    assert "Traceback" not in out + err and not (tmp_path / "out").exists()
