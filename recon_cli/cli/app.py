"""The typer applications every command module registers itself with."""

from __future__ import annotations

import typer
from typer.core import TyperGroup

from recon_cli import __version__

#: the order of the commands in ``recon --help``: from looking at the cell to benchmarks
ORDER = ("cell", "ik", "objects", "capture", "register", "evaluate", "validate", "run", "autoscan", "report", "view",
         "batch", "station", "replay", "calibrate", "bench")


class _Ordered(TyperGroup):
    def list_commands(self, ctx) -> list[str]:
        names = super().list_commands(ctx)
        return sorted(names, key=lambda n: (ORDER.index(n) if n in ORDER else len(ORDER), n))


#: -h is --help everywhere (subcommands inherit it from the root context)
HELP = {"help_option_names": ["-h", "--help"]}

app = typer.Typer(
    cls=_Ordered,
    name="recon",
    help="Robot-assisted 3D reconstruction of objects with a robot-held depth camera.",
    no_args_is_help=True,
    add_completion=True,  # --install-completion / --show-completion for bash, zsh, fish
    pretty_exceptions_enable=False,
    rich_markup_mode=None,  # help texts are plain: "[m]" and "[s]" are units, not markup
    context_settings=HELP,
)
bench_app = typer.Typer(help="Benchmarks with results tables and figures.", no_args_is_help=True,
                        rich_markup_mode=None, context_settings=HELP)


def _version(value: bool) -> None:
    if value:

        typer.echo(f"recon {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: bool = typer.Option(False, "--version", "-V", is_eager=True, callback=_version,
                                 help="Print recon's version and exit."),
) -> None:
    """Robot-assisted 3D reconstruction of objects with a robot-held depth camera."""
app.add_typer(bench_app, name="bench")
