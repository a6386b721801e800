"""3D recordings of runs: a rerun recording (``recording.rrd``) beside each run's results.

``--record`` on ``recon run``, ``recon autoscan``, ``recon capture`` and ``recon register``
writes what happened in the cell as a rerun recording: the cell from the same URDF with
its joints animated along the executed trajectories (timeline ``robot_time``: the time the
robot spent moving and settling), the camera paths of the moves, a camera frustum with the
colour and depth images at each scan, each scan's cloud in the world, the ellipsoid and the
candidate views of every autoscan iteration, the board detections, the registered clouds
before and after local registration, the mesh and, in simulation, the signed distances to
the ground truth as colours. ``recon view RUN_FOLDER`` opens it.

rerun-sdk is an optional extra (``pip install 'recon-scan[viz]'``), pinned to one version
because its API moves between releases; :func:`require_rerun` says how to install it.

Modules: ``recorder`` (the recording stream, its clock and what each event logs),
``station`` (a station whose robot reports its motions to the recorder), ``scene``
(geometry helpers: camera paths, clouds from depth, colours), ``readback`` (what a
recording holds, read with rerun's own reader), ``viewer`` (opening a recording).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
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


def open_recorder(folder: Path, name: str):
    """A :class:`~recon_cli.recording.recorder.Recorder` writing ``folder/recording.rrd``."""
    from recon_cli.recording.recorder import Recorder

    return Recorder(recording_path(folder), name)


@contextmanager
def closing(recorder) -> Iterator[None]:
    """Close the recorder (when there is one) however the block ends: what was recorded up
    to an error or an interruption stays readable."""
    try:
        yield
    finally:
        if recorder is not None:
            recorder.close()
