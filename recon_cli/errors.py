"""The one exception family for errors a user can cause.

Every message says what went wrong, where, and what to do about it; the CLI prints it as
one line and exits non-zero (see :func:`recon_cli.cli.main`). Internal bugs are ordinary
exceptions and keep their traceback.
"""

from __future__ import annotations


class ReconError(Exception):
    """An error the user can fix (bad input, unreachable goal, missing file, ...)."""

    exit_code = 1
    label = "error"  # how the CLI introduces the message

    def __init__(self, message: str, *, hint: str | None = None) -> None:
        self.message = message
        self.hint = hint
        super().__init__(self.one_line())

    def one_line(self) -> str:
        text = self.message.rstrip(".")
        if self.hint:
            text += f"; {self.hint.rstrip('.')}"
        return text.replace("\n", " ")


class InputError(ReconError):
    """A malformed value on the command line or in a file."""


class UnknownNameError(InputError):
    """A name (cell, planner, object, ...) that is not one of the valid choices."""

    def __init__(self, kind: str, name: str, choices: list[str] | tuple[str, ...]) -> None:
        self.kind = kind
        self.name = name
        self.choices = tuple(choices)
        super().__init__(
            f"unknown {kind} '{name}'", hint=f"choose one of: {', '.join(self.choices)}"
        )


class UnreachableViewError(ReconError):
    """No collision-free inverse-kinematics solution within the soft limits."""


class InvalidViewError(ReconError):
    """A view that cannot be taken at all (camera inside an obstacle, bad radius, ...)."""


class FileError(ReconError):
    """A file or folder that is missing, unreadable or not writable."""
