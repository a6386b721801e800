"""The commands a batch's jobs run, read from the typer app itself: ``recon batch`` hands
them to :mod:`recon_cli.batch` (:class:`recon_cli.batch.spec.Commands`), so a batch file's
options are checked by the same parser that will read them in the job."""

from __future__ import annotations

from functools import cache

import typer

from recon_cli.batch.spec import CommandOption, JobKind
from recon_cli.cli.app import app


@cache
def _command(name: str):
    return typer.main.get_group(app).commands[name]


@cache
def _options(name: str) -> dict[str, CommandOption]:
    out = {}
    for p in _command(name).params:
        longs = [o for o in getattr(p, "opts", ()) if o.startswith("--")]
        if not longs or type(p).__name__.endswith("Argument"):
            continue
        off = next(iter(getattr(p, "secondary_opts", ()) or ()), None)
        for long in longs:  # every long name of an option is a key (autoscan's scans: and n:)
            key = long[2:].replace("-", "_")
            out[key] = CommandOption(key, long, off, bool(getattr(p, "is_flag", False)))
    return out


@cache
def _check(name: str, args: tuple[str, ...]) -> str | None:
    try:
        _command(name).make_context(f"recon {name}", list(args))
    except Exception as exc:  # the parser's BadParameter / UsageError
        fmt = getattr(exc, "format_message", None)
        message = fmt() if callable(fmt) else str(exc)
        return message.replace(": Value error, ", ": ")  # a bad choice, as the type check words it
    return None


class AppCommands:
    """recon's commands as the typer app defines them (:class:`recon_cli.batch.spec.Commands`)."""

    def options(self, kind: JobKind) -> dict[str, CommandOption]:
        return _options(kind.value)

    def check(self, kind: JobKind, args: tuple[str, ...]) -> str | None:
        return _check(kind.value, tuple(args))
