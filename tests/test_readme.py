"""The README's tour shows real output: the commands it shows that run in seconds are run here
and their output compared with the README's, line by line.

Rules of the comparison: ``...`` in the README stands for any number of lines left out (also
at the end); wall-clock durations (``in 1.0 ms``, ``in 4.2 s``) are compared as durations,
not as numbers, and a table's padding at any width; ``/tmp/NAME`` is a fresh folder of the test. Every other
character must be the same.
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = ROOT.parent / "shared" / "data"

#: wall-clock durations: "in 1.0 ms", "in 8.2 s", a run's "..., 3 scans, 4.2 s" and a benchmark
#: table's last column ("wall / run"); durations of robot time (trajectories) are compared
_DURATION = re.compile(r"(?<=\bin )\d+(?:\.\d+)? ?(?:ms|s)\b|(?<=, )\d+(?:\.\d+)? s$|(?<=│ )\s*\d+(?:\.\d+)? s(?= │$)")
_TMP = re.compile(r"/tmp/[\w.-]+")


@dataclass(frozen=True)
class Step:
    command: str
    expected: tuple[str, ...]


def tour_steps() -> list[Step]:
    """The ``$ command`` lines of the tour's code blocks with the output the README shows."""
    text = (ROOT / "README.md").read_text()
    tour = text.split("## A five-minute tour", 1)[1].split("\n## ", 1)[0]
    steps: list[Step] = []
    for block in re.findall(r"```\n(.*?)```", tour, flags=re.S):
        command, lines = None, []
        for line in block.splitlines():
            if line.startswith("$ "):
                if command is not None:
                    steps.append(Step(command, tuple(lines)))
                command, lines = line[2:], []
            elif command is not None:
                lines.append(line.rstrip())
        if command is not None:
            steps.append(Step(command, tuple(lines)))
    return steps


def _normal(line: str) -> str:
    """Durations as durations; a table's padding and rules at any width (a duration's digits
    may widen a column)."""
    line = _DURATION.sub("<duration>", line.rstrip())
    return re.sub(r"([━─])\1+", r"\1", re.sub(r" +", " ", line))


def differences(expected: tuple[str, ...], actual: list[str]) -> str | None:
    """None where ``actual`` shows every expected line in order, ``...`` standing for any
    number of lines; else the first expected line not found."""
    i, skipping = 0, False
    for line in expected:
        if line == "...":
            skipping = True
            continue
        want = _normal(line)
        if skipping:
            while i < len(actual) and _normal(actual[i]) != want:
                i += 1
        if i >= len(actual) or _normal(actual[i]) != want:
            got = actual[i] if i < len(actual) else "(no more output)"
            return f"README line {line!r} not in the output (at: {got!r})"
        i += 1
        skipping = False
    if not skipping and i < len(actual):
        return f"the output goes on where the README stops without '...': {actual[i]!r}"
    return None


def _run(step: Step, folders: dict[str, Path], tmp_path: Path) -> list[str]:
    def local(match: re.Match) -> str:
        return str(folders.setdefault(match.group(0), tmp_path / Path(match.group(0)).name))

    argv = shlex.split(_TMP.sub(local, step.command))
    assert argv[0] == "recon"
    env = {**os.environ, "COLUMNS": "120", "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"), "NO_COLOR": "1"}
    proc = subprocess.run([sys.executable, "-m", "recon_cli", *argv[1:]], cwd=ROOT, env=env, capture_output=True,
                          text=True, timeout=900)
    out = proc.stdout + proc.stderr
    back = {str(v): k for k, v in folders.items()}
    for path, name in back.items():
        out = out.replace(path, name)
    return out.splitlines()


#: the tour's commands that finish in seconds (not: the full 16-view autoscan with its
#: recording)
QUICK = ("recon ik ", "recon validate ", "recon run scripts_xml/smoke.xml", "recon autoscan --n 4 ",
         "recon capture --views eq-4.1 ", "recon register /tmp/scans", "recon evaluate /tmp/scans/")
#: those of them that scan the YCB drill ('auto' where the shared test data is beside the checkout)
DRILL = ("recon capture --views eq-4.1 ", "recon register /tmp/scans", "recon evaluate /tmp/scans/")


def test_the_tour_lists_its_commands():
    commands = [s.command for s in tour_steps()]
    assert len(commands) >= 8
    assert all(c.startswith("recon ") for c in commands)
    assert sum(c.startswith(QUICK) for c in commands) >= 5


@pytest.mark.slow
def test_the_tour_shows_what_its_quick_commands_print(tmp_path):
    folders: dict[str, Path] = {}
    problems = []
    for step in tour_steps():
        if not step.command.startswith(QUICK):
            continue
        if step.command.startswith(DRILL) and not SHARED_DATA.is_dir():
            continue  # the tour scans the YCB drill of the shared test data there
        problem = differences(step.expected, _run(step, folders, tmp_path))
        if problem:
            problems.append(f"$ {step.command}: {problem}")
    assert not problems, "\n".join(problems)


def test_the_comparison_rules():
    assert differences(("a", "...", "d"), ["a", "b", "c", "d"]) is None
    assert differences(("a", "d"), ["a", "b", "c", "d"]) is not None  # lines left out need '...'
    assert differences(("a", "..."), ["a", "b"]) is None
    assert differences(("a",), ["a", "b"]) is not None
    assert differences(("done in 7.1 s",), ["done in 12.0 s"]) is None
    assert differences(("1 of 2",), ["1 of 3"]) is not None
    assert differences(("│ A │ 124.40 s │  1.1 s │", "└──┘"), ["│ A │ 124.40 s │ 12.1 s │", "└───┘"]) is None
    assert differences(("trajectory 24.42 s",), ["trajectory 24.43 s"]) is not None
    assert differences(("│ A │ 124.40 s │ 1.1 s │",), ["│ A │ 82.17 s │ 1.1 s │"]) is not None
