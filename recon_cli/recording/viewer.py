"""Opening a run's recording: rerun's viewer where there is a display, its web viewer served
from here on request, otherwise the commands that open it elsewhere."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from recon_cli.errors import FileError
from recon_cli.recording import RECORDING_FILE, RERUN_VERSION, require_rerun


def find_recording(target: Path) -> Path:
    """The recording of a run folder (``recording.rrd``, or ``reconstruction/recording.rrd``
    of ``recon register``), or the .rrd file itself."""
    target = Path(target)
    if target.is_file() and target.suffix == ".rrd":
        return target
    if not target.exists():
        raise FileError(f"{target} does not exist", hint="give a run folder written with --record")
    for candidate in (target / RECORDING_FILE, target / "reconstruction" / RECORDING_FILE):
        if candidate.is_file():
            return candidate
    raise FileError(f"{target} holds no recording ({RECORDING_FILE})",
                    hint="run the command again with --record (recon run, autoscan, capture, register)")


def has_display() -> bool:
    """A screen the native viewer can open a window on."""
    if sys.platform in ("darwin", "win32"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def elsewhere(path: Path) -> str:
    """How to open a recording on a machine with a screen, or from here in a browser."""
    return (f"no display here. On a machine with one: pip install rerun-sdk=={RERUN_VERSION} && rerun {path}; "
            f"or serve it from here: recon view {path} --web (then open the printed address)")


def _rerun(*args: str) -> list[str]:
    return [sys.executable, "-m", "rerun", *args]


def open_viewer(path: Path, web: bool = False, port: int | None = None) -> int:
    """Open the recording in rerun's viewer (blocks until it is closed) or serve the web
    viewer (blocks until Ctrl-C); rerun's viewer analytics are switched off first."""
    require_rerun()
    subprocess.run(_rerun("analytics", "disable"), check=False, capture_output=True)
    if web:
        args = ["--serve-web", *(["--web-viewer-port", str(port)] if port else []), str(path)]
    else:
        args = [str(path)]
    return subprocess.run(_rerun(*args), check=False).returncode
