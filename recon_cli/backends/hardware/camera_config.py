"""Reading the ``camera.<adapter>`` section of a station file: checked key by key, every
problem one line naming ``where.key``; and the one-line hint for a driver that is missing.

Shared by the camera adapters (genicam.py, realsense.py, replay.py); each builds its own
frozen config dataclass with these.
"""

from __future__ import annotations

import importlib
from dataclasses import fields
from typing import Any

from recon_cli import install_hint
from recon_cli.errors import HardwareUnavailable, InputError
from recon_cli.inputs.numbers import described
from recon_cli.inputs.yamlfile import unknown_key_text

#: intrinsics keys a station file may give (width and height come from the images)
INTRINSICS_KEYS = ("fx", "fy", "cx", "cy")


def require_driver(module: str, extra: str, what: str):
    """Import an optional driver module, or raise HardwareUnavailable with the install hint."""
    try:
        return importlib.import_module(module)
    except ImportError as exc:
        raise HardwareUnavailable(f"the {what} camera adapter needs the Python package '{module.split('.')[0]}' "
                                  f"({exc})",
                                  hint=install_hint(extra)) from None


def check_keys(d: Any, where: str, cls) -> dict:
    """``d`` as a dict whose keys are all fields of the dataclass ``cls`` (except ``where``)."""
    known = sorted(f.name for f in fields(cls) if f.name != "where")
    if d is None:
        return {}
    if not isinstance(d, dict):
        raise InputError(f"{where} is not a mapping", hint="write 'key: value' lines under it")
    for key in d:
        if key not in known:
            raise InputError(unknown_key_text(where, key), hint=f"known keys: {', '.join(known)}")
    return dict(d)


def number(d: dict, key: str, where: str, default, *, integer: bool = False, minimum: float | None = None,
           positive: bool = False, optional: bool = False):
    """``d[key]`` as a number (``default`` when absent; None allowed with ``optional``)."""
    value = d.get(key, default)
    if value is None and optional:
        return None
    kind = "an integer" if integer else "a number"
    if isinstance(value, bool) or not isinstance(value, (int, float)) or (integer and not float(value).is_integer()):
        shown = f"= {value:g} is" if isinstance(value, float) else f"is {described(value)},"
        raise InputError(f"{where}.{key} {shown} not {kind}", hint=f"give {kind}")
    value = int(value) if integer else float(value)
    if positive and not value > 0:
        raise InputError(f"{where}.{key} = {value} is not positive", hint="give a positive number")
    if minimum is not None and value < minimum:
        raise InputError(f"{where}.{key} = {value} is below {minimum:g}", hint=f"give at least {minimum:g}")
    return value


def choice(d: dict, key: str, where: str, default: str, choices: tuple[str, ...]) -> str:
    value = d.get(key, default)
    if value not in choices:
        raise InputError(f"{where}.{key} is not one of {', '.join(choices)}",
                         hint=f"choose one of: {', '.join(choices)}")
    return str(value)


def text(d: dict, key: str, where: str, default: str | None) -> str | None:
    value = d.get(key, default)
    if value is None:
        return None
    if isinstance(value, (dict, list, bool)):
        raise InputError(f"{where}.{key} is {described(value)}, not a text", hint="give a name or a path")
    return str(value)


def intrinsics_values(value: Any, where: str) -> tuple[float, float, float, float]:
    """A mapping {fx, fy, cx, cy} [px] as a tuple (fx, fy, cx, cy)."""
    if not isinstance(value, dict):
        raise InputError(f"{where} is not a mapping of fx, fy, cx, cy", hint="e.g. {fx: 518.0, fy: 519.0, "
                                                                             "cx: 325.5, cy: 253.5} [px]")
    for key in value:
        if key not in INTRINSICS_KEYS:
            raise InputError(unknown_key_text(where, key), hint=f"known keys: {', '.join(INTRINSICS_KEYS)}")
    missing = [k for k in INTRINSICS_KEYS if k not in value]
    if missing:
        raise InputError(f"{where} lacks {', '.join(missing)}", hint="give fx, fy, cx, cy [px]")
    out = tuple(number(value, k, where, None) for k in INTRINSICS_KEYS)
    if not (out[0] > 0 and out[1] > 0):
        raise InputError(f"{where}: focal lengths must be positive", hint="fx, fy in pixels")
    return out  # type: ignore[return-value]


def distortion_values(value: Any, where: str) -> tuple[float, ...] | None:
    """OpenCV k1, k2, p1, p2[, k3] or None."""
    if value is None:
        return None
    if not isinstance(value, (list, tuple)) or len(value) not in (4, 5) or not all(
            isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
        raise InputError(f"{where} is not a list of 4 or 5 numbers", hint="OpenCV k1, k2, p1, p2[, k3]")
    return tuple(float(v) for v in value)
