"""Writing a calibration into the configuration that uses it.

``hand_eye`` of a station file (docs/hardware.md) is the flange_T_camera every command run
with ``--station`` plans and computes forward kinematics with (it becomes arguments of the
one cell description). The file is edited as text: only the ``hand_eye`` block is replaced
(or appended), comments and the rest stay as the user wrote them; the edited file must load
before it replaces the old one, which is kept as ``FILE.bak``. A station file reached through
a link is updated where the link points (the file, its backup beside it, atomically); the
link stays a link.
"""

from __future__ import annotations

import os
import re
import shutil
from pathlib import Path

import numpy as np

from recon_cli.backends.station_file import load_station
from recon_cli.errors import FileError, InputError
from recon_cli.outputs import atomic_write, atomic_write_text

_KEY = re.compile(r"^hand_eye\s*:")


def hand_eye_block(flange_T_camera: np.ndarray, comment: str = "") -> str:
    """The ``hand_eye:`` block of a station file (4 rows, [m])."""
    note = f"   # {comment}" if comment else ""
    rows = "".join("  - [" + ", ".join(f"{v: .9f}" for v in row) + "]\n"
                   for row in np.asarray(flange_T_camera, dtype=float)[:3])
    return f"hand_eye:{note}\n{rows}  - [0, 0, 0, 1]\n"


def replace_hand_eye(text: str, block: str) -> str:
    """Station file text with its top-level ``hand_eye`` value replaced by ``block`` (appended
    when there is none)."""
    lines = text.splitlines(keepends=True)
    start = next((i for i, line in enumerate(lines) if _KEY.match(line)), None)
    if start is None:
        sep = "" if not text or text.endswith("\n") else "\n"
        return text + sep + block
    end = start + 1
    while end < len(lines) and (lines[end][:1] in (" ", "\t", "-") or not lines[end].strip()):
        end += 1
    while end > start + 1 and not lines[end - 1].strip():  # blank lines before the next key stay
        end -= 1
    return "".join(lines[:start]) + block + "".join(lines[end:])


def write_station_hand_eye(path: Path, flange_T_camera: np.ndarray, comment: str = "") -> Path:
    """Put flange_T_camera into a station file (see the module docstring); returns the backup."""

    path = Path(path)
    try:
        real = path.resolve(strict=True)  # a link: the file it points to is updated, the link stays
        text = real.read_text(encoding="utf-8")
        mode = real.stat().st_mode & 0o7777
    except (OSError, RuntimeError, UnicodeDecodeError) as exc:
        raise FileError(f"cannot read the station file {path} ({getattr(exc, 'strerror', None) or exc})",
                        hint="check the path given with --station") from None
    new = replace_hand_eye(text, hand_eye_block(flange_T_camera, comment))
    probe = real.with_name(f".{real.name}.calibrated")
    try:
        atomic_write_text(probe, new)
        try:
            load_station(probe)  # the edited file must be a valid station file
        except InputError as exc:
            raise InputError(exc.message.replace(str(probe), str(path)), hint=exc.hint) from None
        backup = atomic_write(real.with_name(real.name + ".bak"), lambda tmp: shutil.copyfile(real, tmp), mode)
        os.chmod(probe, mode)
        os.replace(probe, real)
    except OSError as exc:
        raise FileError(f"cannot write the station file {path} ({exc.strerror})",
                        hint="make the file writable or pass --no-write and copy hand_eye.yaml by hand") from None
    finally:
        probe.unlink(missing_ok=True)
    return backup
