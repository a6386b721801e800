"""Where recon's data folders are: the shipped cell files (cells/), the robot description
(robot/), the schemas (schemas/), the shipped scripts (scripts_xml/) and the shipped batches
(batches/).

In a checkout (and an editable install) they are the folders beside the package; an
installed wheel carries them as package data (``recon_cli._data``). ``RECON_HOME`` points
to another checkout root. Public test data outside the repository (YCB meshes, the thesis'
benchmark results) is found only where a path or ``RECON_SHARED_DATA`` says, or beside a
checkout as ``../shared/data``.
"""

from __future__ import annotations

import os
from importlib import resources
from pathlib import Path

_CHECKOUT = Path(os.environ.get("RECON_HOME", Path(__file__).resolve().parents[1]))


def _data_dir(name: str) -> Path:
    folder = _CHECKOUT / name
    if folder.is_dir():
        return folder
    return Path(str(resources.files("recon_cli._data") / name))


#: the checkout root (or, installed, the folder that holds the package)
ROOT = _CHECKOUT
CELLS_DIR = _data_dir("cells")
ROBOT_DIR = _data_dir("robot")
SCHEMA_DIR = _data_dir("schemas")
SCRIPTS_DIR = _data_dir("scripts_xml")
BATCHES_DIR = _data_dir("batches")
STATIONS_DIR = _data_dir("stations")
SHARED_DATA_DIR = Path(os.environ.get("RECON_SHARED_DATA", _CHECKOUT.parent / "shared" / "data"))
