"""``recon view --web``: rerun's web viewer served on 127.0.0.1 unless --bind says otherwise,
its address printed by recon, and rerun's servers gone (ports free, no process of recon's
left) when recon is stopped by SIGINT, SIGTERM or SIGHUP, also when the kernel hands the
signal to another of recon's threads, and when recon's terminal is closed.

Each case starts ``python -m recon_cli view REC --web`` as its own process on a tiny
recording and talks to it over TCP like a browser would.
"""

from __future__ import annotations

import fcntl
import ipaddress
import os
import queue
import re
import select
import signal
import socket
import subprocess
import sys
import termios
import threading
import time
import urllib.request
from pathlib import Path

import pytest

pytest.importorskip("rerun", reason="recon view needs the viz extra (pip install 'recon-scan[viz]')")

from recon_cli.cli import main  # noqa: E402

URL = re.compile(r"^web viewer: (http://(\S+?):(\d+)/\?url=\S*?%3A(\d+)%2Fproxy) \(listening on (\S+);")


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> Path:
    from recon_cli.recording.recorder import Recorder

    path = tmp_path_factory.mktemp("view") / "recording.rrd"
    Recorder(path, "tiny").close()
    return path


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _answers(host: str, port: int) -> bool:
    try:
        with socket.create_connection((host, port), timeout=1.0):
            return True
    except OSError:
        return False


def _bindable(port: int) -> bool:
    """Nothing listens on the port any more (bound as servers bind, with SO_REUSEADDR)."""
    with socket.socket() as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind(("0.0.0.0", port))
            s.listen()
        except OSError:
            return False
    return True


def other_addresses() -> list[str]:
    """This machine's addresses besides loopback (``hostname -I``)."""
    try:
        words = subprocess.run(["hostname", "-I"], capture_output=True, text=True, timeout=10).stdout.split()
    except (OSError, subprocess.SubprocessError):
        return []
    found = []
    for w in words:
        try:
            a = ipaddress.ip_address(w)
        except ValueError:
            continue
        if a.version == 4 and not a.is_loopback:
            found.append(w)
    return found


def _children(pid: int) -> list[int]:
    kids = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            kids.append(int(stat.parent.name))
    return kids


def _descendants(pid: int) -> list[int]:
    """Every process below ``pid`` (psutil where it is installed, else /proc)."""
    try:
        import psutil
    except ImportError:
        found, todo = [], [pid]
        while todo:
            kids = _children(todo.pop())
            found += kids
            todo += kids
        return found
    try:
        return [p.pid for p in psutil.Process(pid).children(recursive=True)]
    except psutil.NoSuchProcess:
        return []


def _alive(pid: int) -> bool:
    """``pid`` runs (a zombie has ended: only its exit status is left)."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return False
    return state != "Z"


def _reset_signals() -> None:  # runs in the child: stop signals as in a terminal, whatever pytest inherited
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, signal.SIG_DFL)


def _wait_for_exit(proc: subprocess.Popen, timeout: float = 60.0) -> int | None:
    """The exit code, polled for up to ``timeout`` (generous: a loaded machine), else None."""
    try:
        return proc.wait(timeout)
    except subprocess.TimeoutExpired:
        return None


def _closed_and_gone(web_port: int, grpc_port: int, processes: list[int]) -> None:
    assert not _answers("127.0.0.1", web_port) and not _answers("127.0.0.1", grpc_port)
    assert _bindable(web_port) and _bindable(grpc_port)
    left = [pid for pid in processes if _alive(pid)]
    assert not left, f"processes of recon view outlived it: {left}"


class Viewer:
    """``recon view REC --web ...`` in its own process; stdout read line by line."""

    def __init__(self, recording: Path, *args: str) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "recon_cli", "view", str(recording), "--web", *args],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
            # Ctrl-C as in a terminal even where this test runs with SIGINT (or SIGHUP) ignored
            preexec_fn=_reset_signals)
        self.lines: queue.Queue[str] = queue.Queue()
        self.out: list[str] = []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        for line in self.proc.stdout:
            self.lines.put(line.rstrip("\n"))

    def address(self, timeout: float = 60.0) -> re.Match:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            try:
                line = self.lines.get(timeout=0.2)
            except queue.Empty:
                assert self.proc.poll() is None, f"recon view ended: {self.proc.stderr.read()}"
                continue
            self.out.append(line)
            m = URL.match(line)
            if m:
                return m
        raise AssertionError(f"no address printed: {self.out}")

    def stop(self, sig: int) -> tuple[int, list[str], str]:
        self.proc.send_signal(sig)
        t0 = time.monotonic()
        code = self.proc.wait(timeout=10)
        elapsed = time.monotonic() - t0
        time.sleep(0.2)
        while not self.lines.empty():
            self.out.append(self.lines.get())
        assert elapsed < 5, elapsed
        return code, self.out, self.proc.stderr.read()

    def kill(self) -> None:
        left = _descendants(self.proc.pid)
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()
        for pid in left + _children(self.proc.pid):
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass


@pytest.mark.parametrize("sig, name", [(signal.SIGINT, "SIGINT"), (signal.SIGTERM, "SIGTERM"),
                                       (signal.SIGHUP, "SIGHUP")])
def test_web_viewer_on_loopback_stops_with_recon(recording, sig, name):
    port = _free_port()
    v = Viewer(recording, "--port", str(port))
    try:
        m = v.address()
        url, host, web_port, grpc_port, bind = m.group(1), m.group(2), int(m.group(3)), int(m.group(4)), m.group(5)
        assert (host, web_port, bind) == ("127.0.0.1", port, "127.0.0.1")
        with urllib.request.urlopen(url, timeout=10) as r:  # the address as printed: the web viewer's page
            assert r.status == 200 and b"<html" in r.read().lower()
        assert _answers("127.0.0.1", grpc_port)
        for address in other_addresses():  # nobody else on the network reaches it
            assert not _answers(address, web_port), address
            assert not _answers(address, grpc_port), address
        servers = _children(v.proc.pid)
        assert servers, "rerun's server runs as recon's child"
        code, out, err = v.stop(sig)
    finally:
        v.kill()
    assert code == 0, err
    assert err == ""
    assert out[-1] == f"viewer stopped ({name})"
    assert not _answers("127.0.0.1", web_port) and not _answers("127.0.0.1", grpc_port)
    assert _bindable(web_port) and _bindable(grpc_port)
    for pid in servers:
        assert not Path(f"/proc/{pid}").exists(), "rerun's server outlived recon"


@pytest.mark.parametrize("sig, name", [(signal.SIGINT, "SIGINT"), (signal.SIGTERM, "SIGTERM"),
                                       (signal.SIGHUP, "SIGHUP")])
def test_a_stop_signal_taken_by_another_thread_stops_the_viewer(recording, sig, name):
    """The kernel hands a process's signal to any of its threads that can take it; sent to
    one of recon's other threads (kill(2) with that thread's id), it must still stop rerun."""
    port = _free_port()
    v = Viewer(recording, "--port", str(port))
    try:
        m = v.address()
        web_port, grpc_port = int(m.group(3)), int(m.group(4))
        processes = _descendants(v.proc.pid)
        assert processes, "rerun's server runs as recon's child"
        threads = sorted(int(t) for t in os.listdir(f"/proc/{v.proc.pid}/task") if int(t) != v.proc.pid)
        if not threads:
            pytest.skip("recon runs no other thread here: every signal reaches its main thread")
        os.kill(threads[0], sig)
        code = _wait_for_exit(v.proc)
    finally:
        v.kill()
    assert code == 0, f"recon view did not end after {name} (exit {code})"
    _closed_and_gone(web_port, grpc_port, processes)


def test_closing_the_terminal_stops_the_viewer(recording):
    """recon view in a terminal of its own (a pseudo-terminal, recon's controlling terminal);
    closing it hangs the terminal up (SIGHUP from the kernel): rerun's servers end with recon,
    which exits normally although it can no longer write to the terminal."""
    port = _free_port()
    master, slave = os.openpty()

    def session() -> None:  # runs in the child: a session whose controlling terminal is the pty
        _reset_signals()
        fcntl.ioctl(0, termios.TIOCSCTTY, 0)

    proc = subprocess.Popen([sys.executable, "-m", "recon_cli", "view", str(recording), "--web", "--port", str(port)],
                            stdin=slave, stdout=slave, stderr=slave, start_new_session=True, preexec_fn=session,
                            env={**os.environ, "TERM": "dumb", "NO_COLOR": "1"})
    os.close(slave)
    screen = b""
    try:
        deadline = time.monotonic() + 60
        while b"Ctrl-C stops it" not in screen and time.monotonic() < deadline and proc.poll() is None:
            if not select.select([master], [], [], 0.5)[0]:
                continue
            try:
                chunk = os.read(master, 4096)
            except OSError:  # the terminal's other side is gone: recon ended
                break
            screen += chunk
        text = re.sub(r"\x1b\[[0-9;?]*[A-Za-z]|\r", "", screen.decode(errors="replace"))
        m = next((URL.match(line) for line in text.splitlines() if URL.match(line)), None)
        assert m, text
        web_port, grpc_port = int(m.group(3)), int(m.group(4))
        assert _answers("127.0.0.1", web_port) and _answers("127.0.0.1", grpc_port)
        processes = _descendants(proc.pid)
        assert processes, "rerun's server runs as recon's child"
        os.close(master)  # the terminal is closed
        master = -1
        code = _wait_for_exit(proc)
    finally:
        if master >= 0:
            os.close(master)
        left = _descendants(proc.pid)
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        for pid in left:
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
    assert code == 0, f"recon view did not end normally when its terminal closed (exit {code})"
    _closed_and_gone(web_port, grpc_port, processes)


def test_bind_all_interfaces_when_asked(recording):
    port = _free_port()
    v = Viewer(recording, "--port", str(port), "--bind", "0.0.0.0")
    try:
        m = v.address()
        web_port, grpc_port = int(m.group(3)), int(m.group(4))
        assert m.group(5) == "0.0.0.0" and m.group(2) != "0.0.0.0"  # an address to open, not the wildcard
        assert _answers("127.0.0.1", web_port) and _answers("127.0.0.1", grpc_port)
        for address in other_addresses():
            assert _answers(address, web_port), address
        code, out, err = v.stop(signal.SIGTERM)
    finally:
        v.kill()
    assert code == 0 and out[-1] == "viewer stopped (SIGTERM)", err
    assert _bindable(web_port) and _bindable(grpc_port)


def test_port_in_use_is_one_line(recording, capsys):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        assert main(["view", str(recording), "--web", "--port", str(port)]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"port {port} is in use on 127.0.0.1" in err and "--port" in err


@pytest.mark.parametrize("bind", ["localhost", "1.2.3", "0.0.0.0; rm"])
def test_bind_must_be_an_address(recording, capsys, bind):
    assert main(["view", str(recording), "--web", "--bind", bind]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "is not an IP address" in err and "127.0.0.1" in err
