"""One name for one thing: an option name means the same, with the same kind of value, in
every command that takes it, and docs/commands.md lists the shared names ("One name for one
thing"). An option with a fixed set of values shows them in --help, and a value outside them
is a usage error (exit 2, one line) before anything runs."""

from __future__ import annotations

import enum
import re
import typing
from pathlib import Path

import pytest
import typer

from recon_cli.cli import main

from .cli_commands import all_commands

ROOT = Path(__file__).resolve().parents[1]
COMMANDS_MD = ROOT / "docs" / "commands.md"
#: words in a choice list that stand for a file, not a name
FILE_WORDS = ("FILE", "FILE.yaml")


COMMANDS = all_commands()


def _is_option(param) -> bool:
    return not type(param).__name__.endswith("Argument") and param.name not in ("install_completion",
                                                                                 "show_completion")


def _choices(param) -> tuple[str, ...] | None:
    """The values an option takes from a fixed or registered set (None: not such an option)."""
    annotation = param.type_descriptor.annotation
    if isinstance(annotation, type) and issubclass(annotation, enum.Enum):
        return tuple(str(m.value) for m in annotation)
    if typing.get_origin(annotation) is typing.Literal:
        return tuple(str(a) for a in typing.get_args(annotation))
    metavar = getattr(param, "metavar", None)
    m = re.fullmatch(r"<([^>]+)>(?:,\.\.\.)?(?:\|(\w+))?", metavar or "")  # <a|b>  <a|b>,...  <a|b>,...|c
    if m:
        return (*m.group(1).split("|"), *([m.group(2)] if m.group(2) else []))
    return None


CHOICE_OPTIONS = [(name, p) for name, cmd in COMMANDS for p in cmd.params if _is_option(p) and _choices(p)]
IDS = [f"{name} {p.opts[0]}" for name, p in CHOICE_OPTIONS]


def test_the_choice_options_are_found():
    found = {(name, p.opts[0]) for name, p in CHOICE_OPTIONS}
    for expected in [("recon ik", "--cell"), ("recon ik", "--frame"), ("recon capture", "--planner"),
                     ("recon capture", "--views"), ("recon capture", "--object"), ("recon capture", "--realism"),
                     ("recon register", "--crop-frame"), ("recon register", "--loop-closures"),
                     ("recon evaluate", "--align"), ("recon run", "--backend"), ("recon run", "--sequence-method"),
                     ("recon batch", "--cluster"), ("recon calibrate handeye", "--method"),
                     ("recon calibrate intrinsics", "--model"), ("recon calibrate intrinsics", "--realism"),
                     ("recon bench sequence", "--cases"), ("recon bench viewplan", "--methods"),
                     ("recon bench viewplan", "--objects"), ("recon bench planners", "--planners"),
                     ("recon bench planners", "--peer"), ("recon bench planners", "--simplify")]:
        assert expected in found, expected
    assert len(found) >= 37


@pytest.mark.parametrize(("command", "param"), CHOICE_OPTIONS, ids=IDS)
def test_help_lists_the_choices(capsys, command, param):
    assert main([*command.split()[1:], "--help"]) == 0
    out = " ".join(capsys.readouterr().out.split())
    choices = _choices(param)
    shown = getattr(param, "metavar", None) or "<" + "|".join(choices) + ">"
    assert f"{param.opts[0]} {shown}" in out, f"{command} --help does not list {choices} for {param.opts[0]}"


def _required_args(cmd) -> list[str]:
    """Placeholders for the arguments and required options of ``cmd``."""
    args = []
    for p in cmd.params:
        if type(p).__name__.endswith("Argument"):
            args.append("x")
        elif getattr(p, "required", False):
            args += [p.opts[0], "x"]
    return args


@pytest.mark.parametrize(("command", "param"), CHOICE_OPTIONS, ids=IDS)
def test_a_value_outside_the_choices_is_a_usage_error(capsys, tmp_path, command, param):
    cmd = dict(COMMANDS)[command]
    argv = [*command.split()[1:], *_required_args(cmd), param.opts[0], "no-such-choice"]
    out_folder = tmp_path / "out"
    if any("--out" in p.opts for p in cmd.params):
        argv += ["--out", str(out_folder)]
    code = main(argv)
    out, err = capsys.readouterr()
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert code == 2, (argv, code, out, err)
    assert len(lines) == 1 and lines[0].startswith(f"error: Invalid value for '{param.opts[0]}'"), err
    assert "'no-such-choice' is not one of" in lines[0] and "Value error" not in lines[0], err
    named = [c for c in _choices(param) if c not in FILE_WORDS]
    assert all(c in lines[0] for c in named), f"the message does not name every choice: {lines[0]}"
    assert "Traceback" not in out + err and not out_folder.exists()


@pytest.mark.parametrize(("command", "param"), CHOICE_OPTIONS, ids=IDS)
def test_commands_md_lists_the_choices(command, param):
    text = COMMANDS_MD.read_text(encoding="utf-8")
    start = re.search(rf"(?m)^#{{2,4}} `{re.escape(command)}`\s*$", text)
    assert start, f"docs/commands.md has no section for {command}"
    body = text[start.end():]
    nxt = re.search(r"(?m)^#{2,4} ", body)
    body = body[:nxt.start()] if nxt else body
    rows = [ln for ln in body.splitlines() if ln.startswith("|") and f"`{param.opts[0]}`" in ln.split("|")[1]]
    assert rows, f"docs/commands.md, {command}: no row for {param.opts[0]}"
    value = rows[0].split("|")[2]
    for choice in _choices(param):
        if choice not in FILE_WORDS:
            assert f"`{choice}`" in value, f"docs/commands.md, {command} {param.opts[0]}: {choice} is not listed"


def test_the_choices_are_those_of_the_registries():
    from recon_cli.bench.sequence import CASES
    from recon_cli.calibration.handeye import HandEyeMethod
    from recon_cli.cli.bench import SEQUENCE_CASES
    from recon_cli.objects import BUILTIN, ycb_names
    from recon_cli.planning.options import PLANNERS, SIMPLIFICATIONS
    from recon_cli.realism import BUILT_IN
    from recon_cli.viewplan.policy import Method

    assert SEQUENCE_CASES == CASES
    got = {(name, p.opts[0]): _choices(p) for name, p in CHOICE_OPTIONS}
    assert got[("recon bench sequence", "--cases")] == CASES
    assert got[("recon bench planners", "--planners")] == (*PLANNERS, "default")
    assert got[("recon capture", "--planner")] == PLANNERS
    assert got[("recon bench planners", "--simplify")] == SIMPLIFICATIONS
    assert got[("recon bench viewplan", "--methods")] == tuple(m.value for m in Method)
    assert got[("recon calibrate handeye", "--method")] == tuple(m.value for m in HandEyeMethod)
    assert got[("recon capture", "--object")] == (*BUILTIN, *ycb_names(), "auto", "FILE")
    assert got[("recon bench viewplan", "--objects")] == (*BUILTIN, *ycb_names(), "FILE")
    assert got[("recon capture", "--realism")] == (*BUILT_IN, "FILE.yaml")


@pytest.mark.parametrize(("argv", "needle"), [
    (["bench", "sequence", "--cases", "A,E"], "'E' is not one of A, B, C, D or A0"),
    (["bench", "sequence", "--cases", ","], "names nothing"),
    (["bench", "viewplan", "--methods", "ellipsoid,cube"], "'cube' is not one of ellipsoid, sphere or random"),
    (["bench", "planners", "--planners", "RRT,default"], "'default' is not one of RRTConnect"),
    (["autoscan", "--object", "bottle,mug"], "is more than one object"),
])
def test_name_lists_are_checked_when_parsed(capsys, argv, needle):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and needle in err, err


def test_names_and_files_pass_the_parser(tmp_path):
    """A known name, 'auto' where taken, a mesh file and a profile file are all accepted by the parser."""
    from recon_cli.cli.options import _realism, object_option

    assert object_option(True)("auto") == "auto" and object_option(False)("mug") == "mug"
    assert object_option(False)("parts/bracket.stl") == "parts/bracket.stl"
    assert _realism("thesis") == "thesis" and _realism(str(tmp_path / "mine.yml")).endswith("mine.yml")
    with pytest.raises(typer.BadParameter, match="'auto' is not one of"):
        object_option(False)("auto")


# ----------------------------------------------------------------------------- one name for one thing
def _signature(param) -> tuple:
    """What must agree between two commands' options of the same name."""
    return (tuple(param.opts), tuple(param.secondary_opts), bool(getattr(param, "is_flag", False)),
            param.type_descriptor.annotation, _choices(param))


def _options_by_name() -> dict[str, list[tuple[str, object]]]:
    out: dict[str, list[tuple[str, object]]] = {}
    for name, cmd in COMMANDS:
        for p in cmd.params:
            if _is_option(p):
                out.setdefault(p.opts[0], []).append((name, p))
    return out


def test_an_option_name_has_one_meaning():
    """The same name: the same declarations (long, short, the negative of a switch), the same
    kind of value and the same choices in every command; and no name of one option is another
    option's alias."""
    names = _options_by_name()
    errors = []
    for option, uses in names.items():
        first_command, first = uses[0]
        for command, p in uses[1:]:
            if _signature(p) != _signature(first):
                errors.append(f"{option}: {command} {_signature(p)} but {first_command} {_signature(first)}")
    declared: dict[str, str] = {}
    for option, uses in names.items():
        for _, p in uses:
            for alias in (*p.opts, *p.secondary_opts):
                if declared.setdefault(alias, option) != option:
                    errors.append(f"{alias} is a name of both {declared[alias]} and {option}")
    assert not errors, "\n".join(errors)


def _table() -> list[tuple[list[str], set[str]]]:
    """(options, commands) of every row of "One name for one thing" in docs/commands.md."""
    text = COMMANDS_MD.read_text(encoding="utf-8")
    start = text.index("## One name for one thing")
    body = text[start:text.index("\n## ", start + 1)]
    rows = []
    for line in body.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) != 3 or cells[0] in ("concept", "---"):
            continue
        options = re.findall(r"`(-[\w-]+)`", cells[1])
        commands = {f"recon {c.strip()}" for c in cells[2].split(",")}
        rows.append((options, commands))
    return rows


def test_commands_md_lists_every_shared_option_name():
    table = _table()
    assert len(table) >= 25
    listed = {o for options, _ in table for o in options}
    names = _options_by_name()
    errors = []
    for option, uses in names.items():
        if len({c for c, _ in uses}) > 1 and option not in listed:
            errors.append(f"{option} (used by {', '.join(c for c, _ in uses)}) is not in the table")
    every = {alias: option for option, uses in names.items() for _, p in uses
             for alias in (*p.opts, *p.secondary_opts)}
    for options, commands in table:
        for o in options:
            if o not in every:
                errors.append(f"the table names {o}, which no command has")
                continue
            having = {c for c, _ in names[every[o]]}
            if having != commands:
                errors.append(f"the table says {o} is in {sorted(commands)}; it is in {sorted(having)}")
    assert not errors, "\n".join(errors)


def test_frequent_options_have_their_short_form():
    for name, cmd in COMMANDS:
        for p in cmd.params:
            if "--out" in p.opts:
                assert "-o" in p.opts, f"{name} --out has no -o"
            if "--scans" in p.opts:
                assert p.opts == ["--scans", "-n", "--n"], f"{name}: {p.opts}"
    autoscan = dict(COMMANDS)["recon autoscan"]
    assert {"--dc", "--n", "-n", "--m", "-m", "--candidates"} <= {o for p in autoscan.params for o in p.opts}


def test_the_documented_autoscan_usage_parses():
    """recon autoscan --dc 0.55 --n 16 (the thesis' symbols) and its short and long forms."""
    cmd = dict(COMMANDS)["recon autoscan"]
    for argv in (["--dc", "0.55", "--n", "16", "--m", "50"], ["--dc", "0.55", "-n", "16", "-m", "50"],
                 ["--dc", "0.55", "--scans", "16", "--candidates", "50"]):
        ctx = cmd.make_context("recon autoscan", list(argv))
        assert (ctx.params["dc"], ctx.params["n"], ctx.params["m"]) == (0.55, 16, 50)
