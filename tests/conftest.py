"""Shared fixtures: the two cells (built once per session) and seeded generators."""

from __future__ import annotations

import os
import signal
from pathlib import Path

import numpy as np
import pytest

from recon_cli.robot.cell import Cell
from recon_cli.robot.description import CellConfig, CellKind
from recon_cli.thesis import BENCH_CUBE

# A job started with & by a non-interactive shell inherits SIGINT ignored, and Python then
# keeps ignoring it: the tests of Ctrl-C need Python's own handler whatever started the run.
if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)

ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = ROOT.parent / "shared" / "data"


def _scheduling() -> tuple[int, int]:
    return os.sched_getscheduler(0), os.sched_getparam(0).sched_priority


@pytest.fixture(autouse=True)
def _scheduling_unchanged():
    """No test leaves the test process under another scheduler: a thread left at real-time
    FIFO 99 (libfranka's Robot constructor does that to its caller) starves every process
    of its core, and the jobs a later test starts inherit it and run a hundred times slower."""
    before = _scheduling()
    yield
    assert _scheduling() == before, f"the test process's scheduling changed from {before} to {_scheduling()}"


@pytest.fixture(scope="session")
def gantry() -> Cell:
    """The 9-DoF cell with the 0.3 m benchmark cube on the table (thesis 4.1)."""
    return Cell(CellConfig(kind=CellKind.GANTRY), object_box=BENCH_CUBE)


@pytest.fixture(scope="session")
def ceiling() -> Cell:
    """The 7-DoF ceiling cell of thesis section 5.1."""
    return Cell(CellConfig(kind=CellKind.CEILING))


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(12345)


_EXIT_STATUS: list[int] = []


def pytest_sessionfinish(session, exitstatus):
    _EXIT_STATUS.append(int(exitstatus))


def pytest_unconfigure(config):
    """The OMPL wheel's nanobind bindings print spurious "leaked" reports at interpreter
    teardown, after pytest's summary line; the summary is printed and flushed by now."""
    import os
    import sys

    if "ompl" in sys.modules and _EXIT_STATUS:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(_EXIT_STATUS[-1])


@pytest.fixture(scope="session", autouse=True)
def _ads_port_held():
    """ADS clients connect to TCP port 48898, which lies in Linux's ephemeral range: a client
    that connects while no stand-in listens can be given 48898 as its own port and connect to
    itself, and the TIME-WAIT of that connection keeps every stand-in from binding the port
    for a minute. A socket bound to the port (SO_REUSEADDR, never listening) for the whole
    session keeps the port out of the ephemeral range: such a connect is refused at once, and
    the stand-ins (SO_REUSEADDR too) still bind and listen on it."""
    import socket

    holder = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    holder.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        holder.bind(("127.0.0.1", 48898))
    except OSError:  # held already (another test session): it is out of the ephemeral range then too
        holder.close()
        yield
        return
    yield
    holder.close()
