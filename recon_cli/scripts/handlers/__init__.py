"""Command handlers of script runs, one module per area, found by command type.

    setup            <cell>, <object>, <box>, <planner>
    motion           moves (views, poses, joints, home), scans, waits
    reconstruction   <register>, <reconstruct>, <export>, <evaluate>
    sides            <turn_over/>, and the merge of the two sides at the end of the run
    fragments        the thesis dialect's named fragments and display commands

A handler is ``handle(state, command, report)``: it changes the run state, fills the
command's report and raises a ReconError when the command fails.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar

from recon_cli.scripts import commands as C
from recon_cli.scripts.state import CommandReport, RunState

#: a handler takes the command type it is registered for (the registry dispatches by type)
Handler = Callable[[RunState, Any, CommandReport], None]
_HANDLERS: dict[type[C.Command], Handler] = {}
_CommandT = TypeVar("_CommandT", bound=C.Command)


def handles(*types: type[_CommandT]) -> Callable[[Callable[[RunState, _CommandT, CommandReport], None]],
                                                 Callable[[RunState, _CommandT, CommandReport], None]]:
    def register(fn: Callable[[RunState, _CommandT, CommandReport], None]
                 ) -> Callable[[RunState, _CommandT, CommandReport], None]:
        for t in types:
            _HANDLERS[t] = fn
        return fn

    return register


def handler_for(cmd: C.Command) -> Handler:
    """The handler of a command's type (or of its nearest base type)."""
    for t in type(cmd).__mro__:
        if t in _HANDLERS:
            return _HANDLERS[t]
    raise TypeError(f"no handler for {type(cmd).__name__}")  # every command class has one


from recon_cli.scripts.handlers import fragments, motion, reconstruction, setup, sides  # noqa: E402,F401  (registration)
