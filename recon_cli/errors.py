"""The one exception family for errors a user can cause, each carrying its data.

Every message says what went wrong, where, and what to do about it; the CLI prints it as
one line (``label: message; hint``) and exits with the error's ``exit_code``. The data
(file:line, joint and bounds, limit and value, signal, ...) stays on the exception for
callers that handle it. Internal bugs are ordinary exceptions and keep their traceback.
"""

from __future__ import annotations

import signal as _signal

from recon_cli import install_hint


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


# --------------------------------------------------------------------- input
class InputError(ReconError):
    """A malformed value on the command line or in a file."""


class UnknownNameError(InputError):
    """A name (cell, planner, object, ...) that is not one of the valid choices."""

    def __init__(self, kind: str, name: str, choices: list[str] | tuple[str, ...]) -> None:
        self.kind = kind
        self.name = name
        self.choices = tuple(choices)
        super().__init__(f"unknown {kind} '{name}'", hint=f"choose one of: {', '.join(self.choices)}")


class FileError(ReconError):
    """A file or folder that is missing, unreadable, malformed or not writable."""


class MetadataError(FileError):
    """A metadata file of a scan store (scan.json, session.json) or a scan's image that is
    broken, malformed or inconsistent; ``path`` is the file, ``where`` the line or the key."""

    def __init__(self, message: str, *, path: str, where: str | None = None, hint: str | None = None) -> None:
        self.path = path
        self.where = where
        super().__init__(message, hint=hint)


class ScriptError(InputError):
    """A script that cannot be loaded, validated or run as written; ``source`` is the
    file:line of what the user wrote (when known)."""

    def __init__(self, message: str, *, hint: str | None = None, source: str | None = None) -> None:
        self.source = source
        super().__init__(message, hint=hint)


class LimitError(ScriptError):
    """A script asked for something a script may not do, or exceeded a hard limit of its
    expansion; ``limit`` names it (e.g. "max_int_bits"), ``bound`` is its value."""

    def __init__(self, message: str, *, hint: str | None = None, limit: str | None = None,
                 bound: float | None = None) -> None:
        self.limit = limit
        self.bound = bound
        super().__init__(message, hint=hint)


class JointLimitError(ScriptError):
    """A joint goal outside a joint's soft limits: the joint, the value and the bounds (in
    the unit the user wrote)."""

    def __init__(self, message: str, *, joint: str, value: float, lower: float, upper: float, unit: str,
                 hint: str | None = None, source: str | None = None) -> None:
        self.joint, self.value, self.lower, self.upper, self.unit = joint, value, lower, upper, unit
        super().__init__(message, hint=hint, source=source)


# --------------------------------------------------------------------- views and motion
class InvalidViewError(ReconError):
    """A view that cannot be taken at all (camera inside an obstacle, bad radius, ...)."""


class UnreachableViewError(ReconError):
    """No collision-free inverse-kinematics solution within the soft limits."""


class PlanningError(ReconError):
    """A move that could not be planned (no path, invalid start or goal); ``status`` is the
    planner's PlanStatus when there was a request."""

    def __init__(self, message: str, *, hint: str | None = None, status=None) -> None:
        self.status = status
        super().__init__(message, hint=hint)


class TrajectoryError(ReconError):
    """A trajectory that may not be executed (limits or collisions)."""


# --------------------------------------------------------------------- stations and runs
class HardwareUnavailable(ReconError):
    """The hardware backend was asked for, but no station adapters are configured here."""


class OptionalPackageMissing(ReconError):
    """A feature needs an optional extra that is not installed (or not the pinned release)."""

    def __init__(self, package: str, extra: str, what: str, *, found: str | None = None,
                 wanted: str | None = None) -> None:
        self.package = package
        self.extra = extra
        self.found = found
        self.wanted = wanted
        if found is None:
            message = f"{what} need the Python package '{package}', which is not installed"
        else:
            message = f"{what} need {package} {wanted}, installed is {found}"
        super().__init__(message, hint=install_hint(extra))


class RobotFault(ReconError):
    """The robot was stopped by recon or reported a fault: the run cannot go on safely.

    kind: "connection" (lost or refused), "plc_fault" (the PLC's error flag, ``code`` its
    error id), "timeout" (no completion within the time bound), "tracking" (measured joints
    too far from the setpoints, ``joint``/``value``/``bound``), "limit" (a setpoint outside
    a joint or velocity limit, refused before anything was sent), "start" (the robot is not
    where the trajectory starts), "measurement" (NaN, infinite, out-of-range or malformed
    values read from the controller), "settle" (the robot did not settle at the goal: no scan
    is taken). ``stopped``: the controller confirmed the stop.
    """

    exit_code = 4
    label = "robot stopped"

    def __init__(self, message: str, *, kind: str, hint: str | None = None, code: int | None = None,
                 joint: str | None = None, value: float | None = None, bound: float | None = None,
                 stopped: bool = True) -> None:
        self.kind, self.code, self.joint = kind, code, joint
        self.value, self.bound, self.stopped = value, bound, stopped
        super().__init__(message, hint=hint)


class CameraFault(ReconError):
    """The camera gave no usable frame: not found, time-out, lost, data it cannot convert, or
    a replay with no frame left. ``adapter`` names the camera adapter (genicam, realsense,
    replay)."""

    label = "camera"

    def __init__(self, message: str, *, adapter: str, hint: str | None = None) -> None:
        self.adapter = adapter
        super().__init__(message, hint=hint)


class ScriptAborted(ReconError):
    """A failed command under on_failure="abort"; ``source`` is its file:line."""

    exit_code = 4
    label = "aborted"

    def __init__(self, message: str, *, hint: str | None = None, source: str | None = None) -> None:
        self.source = source
        super().__init__(message, hint=hint)


class RunInterrupted(ReconError):
    """Ctrl-C or SIGTERM during a run: the robot is stopped, completed scans are kept. The
    exit code is the shell's 128 + signal number (130, 143)."""

    label = "interrupted"

    def __init__(self, message: str, *, signal: str, scans_kept: int = 0, hint: str | None = None) -> None:
        self.signal = signal
        self.scans_kept = scans_kept
        self.exit_code = 128 + int(getattr(_signal, signal, _signal.SIGINT))
        super().__init__(message, hint=hint)
