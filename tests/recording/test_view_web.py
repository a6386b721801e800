"""``recon view --web``: rerun's web viewer served on 127.0.0.1 unless --bind says otherwise,
its address printed by recon, and rerun's servers gone (ports free) when recon is stopped by
SIGINT or SIGTERM.

Each case starts ``python -m recon_cli view REC --web`` as its own process on a tiny
recording and talks to it over TCP like a browser would.
"""

from __future__ import annotations

import ipaddress
import os
import queue
import re
import signal
import socket
import subprocess
import sys
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


class Viewer:
    """``recon view REC --web ...`` in its own process; stdout read line by line."""

    def __init__(self, recording: Path, *args: str) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "recon_cli", "view", str(recording), "--web", *args],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
            # Ctrl-C as in a terminal even where this test runs with SIGINT ignored
            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
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
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()
        for pid in _children(self.proc.pid):
            os.kill(pid, signal.SIGKILL)


@pytest.mark.parametrize("sig, name", [(signal.SIGINT, "SIGINT"), (signal.SIGTERM, "SIGTERM")])
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
