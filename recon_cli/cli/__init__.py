"""The ``recon`` command line. Commands only parse options, call the library and print.

    app.py       the typer applications
    options.py   options shared by several commands, their parsers; defaults from the configuration
    cell.py      recon cell, recon cell check, recon ik, recon objects
    scans.py     recon capture, recon register, recon evaluate
    scripts.py   recon validate, recon run
    autoscan.py  recon autoscan
    bench.py     recon bench ...
    station.py   recon station check
    replay.py    recon replay
    batch.py     recon batch
    report.py    recon report
    calibrate.py recon calibrate handeye, recon calibrate intrinsics
    view.py      recon view

Heavy libraries (pinocchio, coal, Open3D, MuJoCo, OMPL) are imported inside the commands
so that ``recon --help`` is instant. User errors (``ReconError`` and malformed options)
end as one line on stderr and a non-zero exit code, without a traceback (:func:`main`).
"""

from __future__ import annotations

import math
import os
import sys
import typing

import typer

from recon_cli.cli import (  # noqa: F401 (registers the commands)
    autoscan,
    batch,
    bench,
    calibrate,
    cell,
    replay,
    report,
    scans,
    scripts,
    station,
    view,
)
from recon_cli.cli.app import app, bench_app
from recon_cli.cli.options import parse_vector
from recon_cli.console import err_console
from recon_cli.errors import ReconError
from recon_cli.outputs import remove_empty_made

__all__ = ["app", "bench_app", "entry", "main", "parse_vector"]


def _non_finite(value) -> bool:
    if isinstance(value, float):
        return not math.isfinite(value)
    if isinstance(value, tuple | list):
        return any(_non_finite(v) for v in value)
    return False


def _non_finite_text(value) -> float | None:
    """The non-finite number a command-line text spells ('nan', 'inf', '1e999'), else None."""
    if not isinstance(value, str):
        return None
    try:
        number = float(value)
    except ValueError:
        return None
    return None if math.isfinite(number) else number


def _is_number(param) -> bool:
    annotation = getattr(getattr(param, "type_descriptor", None), "annotation", None)
    return annotation in (int, float) or bool(set(typing.get_args(annotation)) & {int, float})


def refuse_non_finite(command) -> None:
    """Every number option of ``command`` and its subcommands refuses NaN and infinity, named
    as such before its range is checked (a range such as ``min=1`` lets NaN through: every
    comparison with it is false)."""
    for param in getattr(command, "params", ()):
        if getattr(param, "_recon_finite", False):
            continue
        process = param.process_value
        number = _is_number(param)

        def process_value(ctx, value, _process=process, _param=param, _number=number):
            bad = _non_finite_text(value) if _number else None
            if bad is not None:
                raise typer.BadParameter(f"{bad!r} is not a finite number", ctx=ctx, param=_param)
            value = _process(ctx, value)
            if _non_finite(value):
                raise typer.BadParameter(f"{value!r} is not a finite number", ctx=ctx, param=_param)
            return value

        param.process_value = process_value
        param._recon_finite = True
    for sub in getattr(command, "commands", {}).values():
        refuse_non_finite(sub)


def main(argv: list[str] | None = None) -> int:
    """Run the app and return the exit code; user errors become one line on stderr."""
    command = typer.main.get_command(app)
    refuse_non_finite(command)

    try:
        code = _main(command, argv)
    except BaseException:
        remove_empty_made()
        raise
    if code != 0:
        remove_empty_made()  # a failed command leaves no empty output folder behind
    return code


def _main(command, argv: list[str] | None) -> int:

    try:
        result = command.main(args=argv, prog_name="recon", standalone_mode=False)
    except ReconError as exc:
        err_console.print(f"{exc.label}: {exc.one_line()}", markup=False, soft_wrap=True)
        return exc.exit_code
    except typer.Exit as exc:
        return exc.exit_code
    except SystemExit as exc:  # the completion options end the program themselves
        return exc.code if isinstance(exc.code, int) else 0
    except (typer.Abort, KeyboardInterrupt):
        err_console.print("interrupted", markup=False)
        return 130
    except typer.TyperException as exc:  # usage errors: bad option values, unknown options
        ctx = getattr(exc, "ctx", None)
        if type(exc).__name__ == "NoArgsIsHelpError":  # typer has printed the help already
            return 0
        where = f" (see '{ctx.command_path} --help')" if ctx is not None else ""
        message = exc.format_message() if hasattr(exc, "format_message") else str(exc)
        message = message.replace(": Value error, ", ": ")  # a bad choice, as the type check words it
        err_console.print(f"error: {message}{where}", markup=False, soft_wrap=True)
        return int(getattr(exc, "exit_code", 2))
    return result if isinstance(result, int) else 0


def entry() -> None:
    """Console-script entry point."""
    code = main()
    if "ompl" in sys.modules:
        # the OMPL wheel's nanobind bindings print spurious "leaked" reports at interpreter
        # teardown; everything is written and flushed by now, so leave without a teardown
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    sys.exit(code)
