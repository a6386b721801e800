"""The franka-sim stand-in the tests start is gone after them: stop() and kill() end its
whole process group and return when its port refuses connections, a start that is
interrupted ends what it started, and the ``standin`` fixture leaves nothing behind after
a test that fails.

Two cases use a stand-in program in place of franka-sim's Python (a shell script that
starts what a server might: a listener in a grandchild, or a Ctrl-C to the tests); the
last one runs the real franka-sim where its environment is built.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from recon_cli.backends.sim.franka_standin import standin_venv, start_standin
from recon_cli.robot.description import CellConfig, CellName

ROOT = Path(__file__).resolve().parents[2]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _refused(port: int) -> bool:
    with socket.socket() as s:
        s.settimeout(1.0)
        return s.connect_ex(("127.0.0.1", port)) != 0


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return False
    return state != "Z"


def _wait_for(path: Path, timeout: float = 60.0) -> int:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            return int(path.read_text())
        except (OSError, ValueError):
            time.sleep(0.05)
    raise AssertionError(f"{path} was not written")


def _fake_venv(folder: Path, script: str) -> Path:
    """A folder with bin/python: ``script`` (sh) in place of franka-sim's interpreter."""
    python = folder / "bin" / "python"
    python.parent.mkdir(parents=True)
    python.write_text("#!/bin/sh\n" + textwrap.dedent(script))
    python.chmod(0o755)
    return folder


@pytest.fixture(scope="module")
def fr3() -> CellConfig:
    return CellConfig(kind=CellName.parse("fr3"))


def _kill(*pids: int) -> None:
    for pid in pids:
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass


def test_stop_ends_the_standins_whole_group_and_its_port(fr3, tmp_path, monkeypatch):
    """The listener is a grandchild in the stand-in's group: ending the server's own process
    alone would leave the port open."""
    port = _free_port()
    monkeypatch.setenv("FAKE_PIDS", str(tmp_path / "listener.pid"))
    venv = _fake_venv(tmp_path / "venv", f"""\
        {sys.executable} -c "import os, socket, time
        s = socket.socket(); s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        s.bind(('127.0.0.1', {port})); s.listen()
        open(os.environ['FAKE_PIDS'], 'w').write(str(os.getpid()))
        time.sleep(300)" &
        exec sleep 300
        """)
    standin = start_standin(fr3, port=port, venv=venv)
    listener = _wait_for(tmp_path / "listener.pid")
    try:
        assert not _refused(port)
        standin.stop(grace=1.0)
        assert _refused(port), "the stand-in's port still accepts connections after stop()"
        assert not _alive(standin.process.pid) and not _alive(listener), "a process of the stand-in outlived stop()"
        assert not standin.workdir.exists()
    finally:
        _kill(standin.process.pid, listener)


def test_an_interrupted_start_leaves_no_standin(fr3, tmp_path, monkeypatch):
    """Ctrl-C while the stand-in starts (here the stand-in sends it to the tests at once):
    the KeyboardInterrupt leaves start_standin, the stand-in's process does not stay."""
    port = _free_port()
    monkeypatch.setenv("FAKE_PIDS", str(tmp_path / "standin.pid"))
    venv = _fake_venv(tmp_path / "venv", """\
        echo $$ > "$FAKE_PIDS"
        kill -INT $PPID
        exec sleep 300
        """)
    pid = None
    try:
        with pytest.raises(KeyboardInterrupt):
            start_standin(fr3, port=port, venv=venv)
        pid = _wait_for(tmp_path / "standin.pid")
        assert not _alive(pid), "the stand-in outlived its interrupted start"
    finally:
        if pid is not None:
            _kill(pid)


INNER = """\
import os
import socket
from pathlib import Path

from tests.backends.test_franka import fr3, standin  # noqa: F401 (the fixtures)


def _refused(port):
    with socket.socket() as s:
        s.settimeout(1.0)
        return s.connect_ex(("127.0.0.1", port)) != 0


def _standins():
    found = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
            cmd = (stat.parent / "cmdline").read_bytes()
        except OSError:
            continue
        if int(fields[1]) == os.getpid() and fields[0] != "Z" and b"FrankaSimServer" in cmd:
            found.append(int(stat.parent.name))
    return found


def test_fails_with_the_standin_running(standin):
    assert not _refused(standin.port) and _standins()
    Path(os.environ["STANDIN_PORT"]).write_text(str(standin.port))
    raise AssertionError("a test that fails")


def test_the_next_test_finds_it_gone():
    port = int(Path(os.environ["STANDIN_PORT"]).read_text())
    assert _refused(port), "franka-sim still listens after the failed test"
    assert not _standins(), "franka-sim outlived the failed test"
"""


def test_a_failing_test_leaves_no_standin(tmp_path):
    pytest.importorskip("pylibfranka", reason="the Franka tests need pylibfranka (pip install 'recon-scan[franka]')")
    if standin_venv() is None:
        pytest.skip("franka-sim's environment is not built (bash install.sh --franka-sim)")
    inner = tmp_path / "test_inner.py"
    inner.write_text(INNER)
    env = {**os.environ, "PYTHONPATH": str(ROOT), "STANDIN_PORT": str(tmp_path / "port"), "MUJOCO_GL": "egl"}
    run = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "no:randomly",
                          str(inner), "--rootdir", str(tmp_path)],
                         cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert "1 failed, 1 passed" in run.stdout, run.stdout[-3000:]
    assert "a test that fails" in run.stdout
