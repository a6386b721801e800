"""The rerun SDK recordings are written with: its pinned release, how to get it, and where a
run folder keeps its recording."""

from __future__ import annotations

from pathlib import Path

from recon_cli.errors import OptionalPackageMissing

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
