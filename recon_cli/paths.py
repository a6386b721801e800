"""Where the project's data folders are (robot/, schemas/, scripts_xml/).

recon is installed in editable mode from its checkout (README), so the folders are found
beside the package. ``RECON_HOME`` overrides the checkout root.
"""

from __future__ import annotations

import os
from pathlib import Path

ROOT = Path(os.environ.get("RECON_HOME", Path(__file__).resolve().parents[1]))
ROBOT_DIR = ROOT / "robot"
SCHEMA_DIR = ROOT / "schemas"
SCRIPTS_DIR = ROOT / "scripts_xml"
SHARED_DATA_DIR = ROOT.parent / "shared" / "data"
