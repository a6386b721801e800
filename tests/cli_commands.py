"""Every command of the typer app, for the tests that walk the command line."""

from __future__ import annotations

import typer

from recon_cli.cli import app


def all_commands() -> list[tuple[str, object]]:
    """(name, command) of every command of the app ("recon bench ik", ...)."""
    out: list[tuple[str, object]] = []

    def walk(cmd, path):
        if hasattr(cmd, "list_commands"):
            if getattr(cmd, "invoke_without_command", False):  # a group that is a command too (recon cell)
                out.append((" ".join(path), cmd))
            for name in cmd.list_commands(None):
                walk(cmd.get_command(None, name), (*path, name))
        else:
            out.append((" ".join(path), cmd))

    walk(typer.main.get_command(app), ("recon",))
    return out
