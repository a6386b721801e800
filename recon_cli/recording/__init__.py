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

Modules: ``sdk`` (the pinned rerun release, :func:`require_rerun`), ``recorder`` (the
recording stream, its clock and what each event logs), ``station`` (a station whose robot
reports its motions to the recorder), ``scene`` (geometry helpers: camera paths, clouds from
depth, colours), ``readback`` (what a recording holds, read with rerun's own reader),
``viewer`` (opening a recording).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from recon_cli.recording.recorder import Recorder
from recon_cli.recording.sdk import (  # noqa: F401 (the package's names)
    EXTRA,
    RECORDING_FILE,
    RERUN_VERSION,
    recording_path,
    require_rerun,
)


def open_recorder(folder: Path, name: str):
    """A :class:`~recon_cli.recording.recorder.Recorder` writing ``folder/recording.rrd``."""

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
