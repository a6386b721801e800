"""The typer applications every command module registers itself with."""

from __future__ import annotations

import typer
from typer.core import TyperGroup

#: the order of the commands in ``recon --help``: from looking at the cell to benchmarks
ORDER = ("cell", "ik", "objects", "capture", "register", "evaluate", "validate", "run", "autoscan", "report", "view",
         "batch", "station", "replay", "calibrate", "bench")


class _Ordered(TyperGroup):
    def list_commands(self, ctx) -> list[str]:
        names = super().list_commands(ctx)
        return sorted(names, key=lambda n: (ORDER.index(n) if n in ORDER else len(ORDER), n))


app = typer.Typer(
    cls=_Ordered,
    name="recon",
    help="Robot-assisted 3D reconstruction of objects with a robot-held depth camera.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,  # help texts are plain: "[m]" and "[s]" are units, not markup
)
bench_app = typer.Typer(help="Benchmarks with results tables and figures.", no_args_is_help=True,
                        rich_markup_mode=None)
app.add_typer(bench_app, name="bench")
