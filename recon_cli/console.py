"""One shared rich console, progress bars and run folders for every command."""

from __future__ import annotations

import contextlib
import json
import os
import sys
from collections.abc import Callable, Iterator
from datetime import datetime
from pathlib import Path

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TaskID, TextColumn, TimeElapsedColumn
from rich.text import Text

from recon_cli.errors import FileError
from recon_cli.outputs import atomic_write_text
from recon_cli.serialization import to_jsonable

# piped output (logs, CI, tests) gets wide tables instead of rich's 80 columns
_WIDTH = None if sys.stdout.isatty() else int(os.environ.get("COLUMNS", "140"))
# text from scripts, file names and messages is printed literally: no rich markup, no
# emoji codes (a script named "[/oops]" or ":x:" is shown as written); styles are applied
# explicitly with ``styled``
# long lines are not broken (logs and greps see one line per message; terminals wrap them)
console = Console(highlight=False, markup=False, emoji=False, soft_wrap=True, width=_WIDTH)
err_console = Console(stderr=True, highlight=False, markup=False, emoji=False, soft_wrap=True, width=_WIDTH)


def styled(label: str, style: str, rest: str = ""):
    """``label`` in ``style`` followed by ``rest`` printed literally."""

    return Text.assemble((label, style), rest)


@contextlib.contextmanager
def progress_bar() -> Iterator[Callable[[str, int, int], None]]:
    """A progress bar; yields ``update(task_description, done, total)``."""
    with Progress(TextColumn("{task.description:<18}"), BarColumn(), MofNCompleteColumn(),
                  TimeElapsedColumn(), console=err_console, transient=False,
                  disable=not err_console.is_terminal and os.environ.get("RECON_PROGRESS") != "1",
                  ) as prog:
        tasks: dict[str, TaskID] = {}

        def update(what: str, done: int, total: int) -> None:
            if what not in tasks:
                tasks[what] = prog.add_task(what, total=total)
            prog.update(tasks[what], completed=done, total=total)

        yield update


def run_folder(base: Path | None, name: str, fresh: bool = False) -> Path:
    """A new output folder ``runs/name-YYYYmmdd-HHMMSS`` (or ``base`` itself when given).
    ``fresh``: a given ``base`` must be new or empty (so that a run never mixes its results
    with an earlier one's)."""
    if base is None:
        base = Path("runs") / f"{name}-{datetime.now():%Y%m%d-%H%M%S}"
    elif fresh and base.is_dir() and any(base.iterdir()):
        held = ", ".join(sorted(p.name for p in base.iterdir())[:4])
        raise FileError(f"output folder {base} is not empty (it holds {held}, ...)",
                        hint="choose a new folder with --out, or pass --append to add this run's scans to the "
                             "scan store in it")
    elif fresh and base.exists() and not base.is_dir():
        raise FileError(f"output folder {base} is a file", hint="choose a new folder with --out")
    try:
        base.mkdir(parents=True, exist_ok=True)
        probe = base / ".write-test"
        probe.write_text("")
        probe.unlink()
    except OSError as exc:
        raise FileError(f"output folder {base} is not writable ({exc.strerror})",
                        hint="choose another folder with --out") from None
    return base


def write_json(path: Path, data) -> None:
    """Write JSON atomically (temporary name, then rename)."""

    atomic_write_text(path, json.dumps(data, indent=2, default=to_jsonable) + "\n")
