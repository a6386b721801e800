"""Opening a run's recording: rerun's viewer where there is a display, its web viewer served
from here on request, otherwise the commands that open it elsewhere.

The viewer is rerun's own program (the ``rerun`` binary of rerun-sdk), run as a child of
recon in a process group of its own: ``--bind`` goes to it (the web viewer's HTTP server and
the gRPC server that feeds it listen on 127.0.0.1 unless the user says otherwise), its
output is kept off the terminal (recon prints the address itself), and it ends with recon.
Ctrl-C, SIGTERM and SIGHUP (the terminal closed) make recon stop the group (SIGTERM, SIGKILL
after STOP_TIMEOUT_S), reap the child, wait until no process of the group is left and
check that neither port answers any more before it exits; a port that still answers is an
error. On Linux the child also gets SIGTERM should recon be killed without cleaning up
(SIGKILL).
"""

from __future__ import annotations

import ctypes
import errno
import ipaddress
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from urllib.parse import quote

from recon_cli.errors import FileError, InputError, ReconError
from recon_cli.interrupts import held_signals, signal_name, stop_signals
from recon_cli.recording.sdk import RECORDING_FILE, RERUN_VERSION, recording_file, require_rerun

#: where the web viewer listens unless ``--bind`` says otherwise: this machine only
DEFAULT_BIND = "127.0.0.1"
#: the web viewer's HTTP port unless ``--port`` says otherwise (rerun's default)
WEB_PORT = 9090
START_TIMEOUT_S = 30.0  # until the web viewer answers
STOP_TIMEOUT_S = 5.0  # after SIGTERM, before SIGKILL
WAIT_STEP_S = 0.2  # how soon a stop signal is acted on while rerun runs
GONE_TIMEOUT_S = 10.0  # after SIGKILL, until the group is empty and the ports are closed


def find_recording(target: Path) -> Path:
    """The recording of a run folder (``recording.rrd``, or ``reconstruction/recording.rrd``
    of ``recon register``), or the .rrd file itself."""
    target = Path(target)
    if target.suffix == ".rrd" and os.path.lexists(target):
        return _regular(target)
    if not target.exists():
        raise FileError(f"{target} does not exist", hint="give a run folder written with --record")
    for candidate in (target / RECORDING_FILE, target / "reconstruction" / RECORDING_FILE):
        if os.path.lexists(candidate):
            return _regular(candidate)
    raise FileError(f"{target} holds no recording ({RECORDING_FILE})",
                    hint="run the command again with --record (recon run, autoscan, capture, register)")


def _regular(path: Path) -> Path:
    """``path`` if it is a regular file (a FIFO would block the reader), else a FileError."""
    recording_file(path)
    return path


def has_display() -> bool:
    """A screen the native viewer can open a window on."""
    if sys.platform in ("darwin", "win32"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def elsewhere(path: Path) -> str:
    """How to open a recording on a machine with a screen, or from here in a browser."""
    return (f"no display here. On a machine with one: pip install rerun-sdk=={RERUN_VERSION} && rerun {path}; "
            f"or serve it from here: recon view {path} --web (then open the printed address)")


# ------------------------------------------------------------------ addresses and ports
def check_bind(address: str) -> str:
    """``--bind``: an IPv4 or IPv6 address (normalized), or a one-line error."""
    try:
        return str(ipaddress.ip_address(address.strip().strip("[]")))
    except ValueError:
        raise InputError(f"--bind {address!r} is not an IP address",
                         hint="give 127.0.0.1 (this machine only, the default), 0.0.0.0 (every IPv4 interface), "
                              ":: (every interface) or one address of this machine") from None


def _family(address: str) -> socket.AddressFamily:
    return socket.AF_INET6 if ipaddress.ip_address(address).version == 6 else socket.AF_INET


def _wildcard(address: str) -> bool:
    return ipaddress.ip_address(address).is_unspecified


def _bind_problem(address: str, port: int) -> InputError | None:
    """Why a server cannot listen on ``address:port`` (bound the way rerun binds, with
    SO_REUSEADDR), or None when it can."""
    with socket.socket(_family(address), socket.SOCK_STREAM) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind((address, port))
        except OSError as exc:
            if exc.errno == errno.EADDRINUSE:
                return InputError(f"port {port} is in use on {address}", hint="choose another --port")
            if exc.errno == errno.EADDRNOTAVAIL:
                return InputError(f"--bind {address} is not an address of this machine",
                                  hint="give 127.0.0.1 (this machine only, the default), 0.0.0.0 (every IPv4 "
                                       "interface), :: (every interface) or one address of this machine")
            if exc.errno == errno.EACCES:
                return InputError(f"port {port} on {address} needs privileges recon does not have",
                                  hint="choose a --port of 1024 or above")
            return InputError(f"cannot listen on {address} port {port} ({exc.strerror or exc})",
                              hint="choose another --bind or --port")
    return None


def _free_port(address: str) -> int:
    """A port nothing listens on at ``address`` (for the gRPC server behind the web viewer)."""
    with socket.socket(_family(address), socket.SOCK_STREAM) as s:
        s.bind((address, 0))
        return s.getsockname()[1]


def _local_address(address: str) -> str:
    """Where this machine reaches a server listening on ``address``."""
    if not _wildcard(address):
        return address
    return "::1" if _family(address) == socket.AF_INET6 else "127.0.0.1"


def _outward_address() -> str:
    """This machine's address toward the network (no packet is sent), else its name."""
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.connect(("192.0.2.1", 9))  # TEST-NET-1: only selects the outgoing interface
            return s.getsockname()[0]
    except OSError:
        return socket.gethostname()


def viewer_url(address: str, web_port: int, grpc_port: int) -> str:
    """The address to open: rerun's web viewer, told where its data comes from."""
    host = _outward_address() if _wildcard(address) else address
    if ":" in host:
        host = f"[{host}]"
    return f"http://{host}:{web_port}/?url=" + quote(f"rerun+http://{host}:{grpc_port}/proxy", safe="")


def _answers(address: str, port: int) -> bool:
    try:
        with socket.create_connection((address, port), timeout=0.5):
            return True
    except OSError:
        return False


# ------------------------------------------------------------------ rerun's program
def _rerun_command() -> list[str]:
    """rerun's own program (rerun-sdk's ``rerun_cli/rerun``), started directly so that
    stopping it stops the server (``python -m rerun`` would be one more process between)."""
    try:
        import rerun_cli
    except ImportError:
        return [sys.executable, "-m", "rerun"]
    folder = Path(rerun_cli.__file__).parent
    name = "rerun.exe" if sys.platform.startswith("win") else "rerun"
    candidates = [Path(os.environ["RERUN_CLI_PATH"])] if os.environ.get("RERUN_CLI_PATH") else []
    candidates += [folder / "Rerun.app" / "Contents" / "MacOS" / "Rerun", folder / name]
    for c in candidates:
        if c.is_file():
            return [str(c)]
    return [sys.executable, "-m", "rerun"]


def _child_setup() -> Callable[[], None]:
    """What the child does between fork and exec: on Linux, ask for SIGTERM when recon ends
    without stopping it. Everything it needs is looked up here, in the parent."""
    prctl = None
    if sys.platform.startswith("linux"):

        try:
            prctl = ctypes.CDLL(None, use_errno=True).prctl
        except (OSError, AttributeError):
            prctl = None
    term = int(signal.SIGTERM)

    def setup() -> None:  # pragma: no cover - runs in the child
        if prctl is not None:
            prctl(1, term)  # PR_SET_PDEATHSIG

    return setup


def _start(command: list[str], log, started: list[subprocess.Popen]) -> None:
    """Start rerun in a process group of its own and append it to ``started``, with stop
    signals held back until it is there, so that a Ctrl-C cannot fall between the start and
    the moment recon knows the child it has to stop."""
    if sys.platform == "win32":  # pragma: no cover
        started.append(subprocess.Popen(command, stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT))
        return
    setup = _child_setup()
    with held_signals():
        started.append(subprocess.Popen(command, stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT,
                                        preexec_fn=setup, process_group=0))


def _signal_group(child: subprocess.Popen, sig: int) -> bool:
    """Send ``sig`` to the child's process group (its pid); False when no process is left in it."""
    if sys.platform == "win32":  # pragma: no cover
        if child.poll() is None:
            child.kill()
        return child.poll() is None
    try:
        os.killpg(child.pid, sig)
    except ProcessLookupError:
        return False
    except PermissionError:  # a member that is not ours any more: it is there all the same
        return True
    return True


def _stop(child: subprocess.Popen) -> None:
    """SIGTERM to the child's group, SIGKILL after STOP_TIMEOUT_S; always reaps the child
    and waits until no process of its group is left (a second Ctrl-C only hurries it)."""
    if child.poll() is None:
        _signal_group(child, signal.SIGTERM)
        try:
            child.wait(STOP_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            pass
        except KeyboardInterrupt:
            pass
    deadline = time.monotonic() + GONE_TIMEOUT_S
    while True:
        try:
            _signal_group(child, signal.SIGKILL)  # whatever is still in the group
            child.wait()
            while _signal_group(child, 0) and time.monotonic() < deadline:  # grandchildren, reaped by init
                time.sleep(0.05)
            return
        except KeyboardInterrupt:  # a second Ctrl-C: keep waiting for the child, it is ending
            continue


def _closed(address: str, ports: tuple[int, ...]) -> None:
    """Wait until none of ``ports`` answers on ``address`` (after rerun's processes are
    gone), else a ReconError naming the port."""
    deadline = time.monotonic() + GONE_TIMEOUT_S
    while True:
        try:
            still = [p for p in ports if _answers(address, p)]
            if not still:
                return
            if time.monotonic() > deadline:
                raise ReconError(f"port {still[0]} on {address} still answers after rerun's viewer ended",
                                 hint=f"another program listens there: ss -ltnp 'sport = :{still[0]}' names it")
            time.sleep(0.1)
        except KeyboardInterrupt:  # a second Ctrl-C: the check goes on, it is bounded
            continue


def _wait(child: subprocess.Popen) -> int:
    """The child's exit code, waited for in short steps: a stop signal that the kernel hands
    to another of recon's threads (rerun's SDK runs some) only sets a flag, and a blocking
    wait for the child would never return to the main thread to raise it."""
    while True:
        try:
            return child.wait(WAIT_STEP_S)
        except subprocess.TimeoutExpired:
            continue


def _last_line(log) -> str:
    log.flush()
    log.seek(0)
    lines = [ln.strip() for ln in log.read().decode("utf-8", "replace").splitlines() if ln.strip()]
    return lines[-1] if lines else "no output"


def _wait_until_listening(child: subprocess.Popen, address: str, ports: tuple[int, ...], log) -> None:
    deadline = time.monotonic() + START_TIMEOUT_S
    while not all(_answers(address, p) for p in ports):
        if child.poll() is not None:
            raise ReconError(f"rerun's web viewer ended at its start (exit code {child.returncode}): "
                             f"{_last_line(log)}", hint="try another --port, or run rerun --serve-web yourself")
        if time.monotonic() > deadline:
            raise ReconError(f"rerun's web viewer did not answer on {address} within {START_TIMEOUT_S:g} s",
                             hint="try another --port")
        time.sleep(0.1)


def open_viewer(path: Path, web: bool = False, port: int | None = None, bind: str = DEFAULT_BIND,
                say: Callable[[str], None] = print) -> int:
    """Open the recording in rerun's viewer (until its window is closed), or serve the web
    viewer on ``bind`` (until Ctrl-C, SIGTERM or SIGHUP; ``say`` gets the address to open).
    Either way rerun's processes are gone and the web viewer's ports closed before this
    returns; rerun's viewer analytics are switched off first. Returns 0 (also after a stop
    signal)."""
    require_rerun()
    bind = check_bind(bind)
    with stop_signals(hangup=True):
        return _open_viewer(path, web, port, bind, say)


def _open_viewer(path: Path, web: bool, port: int | None, bind: str, say: Callable[[str], None]) -> int:
    command = _rerun_command()
    subprocess.run([*command, "analytics", "disable"], check=False, capture_output=True, timeout=60)
    ports: tuple[int, ...] = ()
    if web:
        web_port = port or WEB_PORT
        problem = _bind_problem(bind, web_port)
        if problem is not None:
            raise problem
        grpc_port = _free_port(bind)
        ports = (web_port, grpc_port)
        args = ["--serve-web", "--bind", bind, "--web-viewer-port", str(web_port), "--port", str(grpc_port)]
    else:
        args = ["--bind", bind]
    stopped_by = None
    started: list[subprocess.Popen] = []
    served = False  # the ports answered: rerun's own, to be closed when it ends
    with tempfile.TemporaryFile() as log:
        try:
            try:
                _start([*command, *args, str(path)], log, started)
            except OSError as exc:
                raise ReconError(f"cannot start rerun's viewer ({exc.strerror or exc})",
                                 hint=f"pip install rerun-sdk=={RERUN_VERSION}") from None
            child = started[0]
            if web:
                _wait_until_listening(child, _local_address(bind), ports, log)
                served = True
                say(f"web viewer: {viewer_url(bind, web_port, grpc_port)} (listening on {bind}; Ctrl-C stops it)")
            code = _wait(child)
        except KeyboardInterrupt as exc:
            stopped_by = signal_name(exc)
        finally:
            for child in started:
                _stop(child)
            if served:
                _closed(_local_address(bind), ports)
        if stopped_by is not None:
            say(f"viewer stopped ({stopped_by})")
            return 0
        if code != 0:
            raise ReconError(f"rerun's viewer ended with exit code {code}: {_last_line(log)}",
                             hint="recon view --web serves it to a browser instead")
    return 0
