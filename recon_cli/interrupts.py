"""Stop requests (Ctrl-C, SIGTERM, SIGHUP) as one exception, so that a run can stop the robot,
keep what it completed and say what was interrupted.

SIGINT raises ``KeyboardInterrupt`` as usual; inside :func:`stop_signals` SIGTERM (what a
batch system or ``kill`` sends) raises :class:`Interrupted`, a ``KeyboardInterrupt`` too,
so every handler of Ctrl-C handles both. With ``hangup=True`` SIGHUP (the terminal was
closed) does the same, and what recon writes to that terminal from then on is dropped, so
that the cleanup after it cannot fail on a terminal that is gone.
"""

from __future__ import annotations

import contextlib
import os
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


def _terminals() -> tuple[int, ...]:
    """Which of standard output and error go to a terminal (asked before a hang-up: a
    terminal that is gone answers no more)."""
    found = []
    for fd in (1, 2):
        try:
            if os.isatty(fd):
                found.append(fd)
        except OSError:
            pass
    return tuple(found)


def _drop_output(fds: tuple[int, ...]) -> None:
    """``fds`` write to /dev/null from now on."""
    try:
        null = os.open(os.devnull, os.O_WRONLY)
    except OSError:
        return
    try:
        for fd in fds:
            try:
                os.dup2(null, fd)
            except OSError:
                pass
    finally:
        os.close(null)


@contextlib.contextmanager
def stop_signals(hangup: bool = False) -> Iterator[None]:
    """Turn SIGTERM (and with ``hangup`` SIGHUP, unless it is ignored, as under ``nohup``)
    into :class:`Interrupted` while the block runs (main thread only)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def on_term(signum, frame):
        raise Interrupted("SIGTERM")

    terminals = _terminals() if hangup else ()

    def on_hangup(signum, frame):
        _drop_output(terminals)
        raise Interrupted("SIGHUP")

    previous = {signal.SIGTERM: signal.signal(signal.SIGTERM, on_term)}
    if hangup and hasattr(signal, "SIGHUP") and signal.getsignal(signal.SIGHUP) is not signal.SIG_IGN:
        previous[signal.SIGHUP] = signal.signal(signal.SIGHUP, on_hangup)
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)


@contextlib.contextmanager
def held_signals() -> Iterator[None]:
    """Hold back Ctrl-C, SIGTERM and SIGHUP while the block runs and deliver them after it
    (main thread only; ignored signals stay ignored). For starting a child process: a stop
    signal then cannot fall between its start and the moment the caller knows it, whichever
    thread the kernel hands the signal to."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    pending: list[int] = []

    def hold(signum, frame):
        pending.append(signum)

    previous = {}
    for name in ("SIGINT", "SIGTERM", "SIGHUP"):
        signum = getattr(signal, name, None)
        if signum is not None and signal.getsignal(signum) not in (signal.SIG_IGN, None):
            previous[signum] = signal.signal(signum, hold)
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
        for signum in dict.fromkeys(pending):
            signal.raise_signal(signum)
