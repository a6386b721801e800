"""Stop requests (Ctrl-C, SIGTERM) as one exception, so that a run can stop the robot,
keep what it completed and say what was interrupted.

SIGINT raises ``KeyboardInterrupt`` as usual; inside :func:`stop_signals` SIGTERM (what a
batch system or ``kill`` sends) raises :class:`Interrupted`, a ``KeyboardInterrupt`` too,
so every handler of Ctrl-C handles both.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator


class Interrupted(KeyboardInterrupt):
    """A stop request by a signal other than SIGINT."""

    def __init__(self, signal_name: str) -> None:
        super().__init__(signal_name)
        self.signal_name = signal_name


def signal_name(exc: BaseException) -> str:
    """SIGINT for Ctrl-C, else the name of the signal that asked to stop."""
    return exc.signal_name if isinstance(exc, Interrupted) else "SIGINT"


def exit_code(name: str) -> int:
    """Shell convention: 128 + signal number (130 for SIGINT, 143 for SIGTERM)."""
    return 128 + int(getattr(signal, name, signal.SIGINT))


@contextlib.contextmanager
def stop_signals() -> Iterator[None]:
    """Turn SIGTERM into :class:`Interrupted` while the block runs (main thread only)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def on_term(signum, frame):
        raise Interrupted("SIGTERM")

    previous = signal.signal(signal.SIGTERM, on_term)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)
