"""The rerun SDK recordings are written with: its pinned release, how to get it, where a run
folder keeps its recording, and the check before a recording is read."""

from __future__ import annotations

import stat
from pathlib import Path

from recon_cli.errors import FileError, OptionalPackageMissing

#: the rerun-sdk release recon's recordings are written with (``recon-scan[viz]`` pins it)
RERUN_VERSION = "0.41.0"
#: the recording's file name inside a run folder
RECORDING_FILE = "recording.rrd"
EXTRA = "viz"


def require_rerun():
    """The ``rerun`` module of the pinned release, or a one-line error saying how to get it."""
    try:
        import rerun
    except ImportError:
        raise OptionalPackageMissing("rerun-sdk", EXTRA, "recordings (--record, recon view)") from None
    if rerun.__version__.split(".")[:2] != RERUN_VERSION.split(".")[:2]:
        raise OptionalPackageMissing("rerun-sdk", EXTRA, "recordings (--record, recon view)",
                                     found=rerun.__version__, wanted=RERUN_VERSION)
    return rerun


def recording_path(folder: Path) -> Path:
    """Where a run folder keeps its recording."""
    return Path(folder) / RECORDING_FILE


#: what to give where a recording cannot be read
RECORDING_HINT = "give the recording.rrd a run wrote with --record (recon run, autoscan, capture, register)"


def recording_file(path: Path) -> int:
    """The size of ``path``, a regular file (a FIFO would block the reader), else a
    FileError."""
    try:
        st = Path(path).stat()
    except OSError as exc:
        raise FileError(f"{path} cannot be read ({exc.strerror})", hint=RECORDING_HINT) from None
    if not stat.S_ISREG(st.st_mode):
        raise FileError(f"{path} is not a regular file", hint=RECORDING_HINT)
    return st.st_size
