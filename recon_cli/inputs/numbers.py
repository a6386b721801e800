"""Number checks shared by every reader of user input: a value is a real number, finite,
and inside its documented range, or the read fails with one line naming where it came from.

NaN compares false with everything, so a check written ``if not value > 0`` lets nothing
through, but ``if value < lo`` lets NaN through: every check here tests finiteness first.

A refusal shows a number as the number it was read as; anything else (a text, a list) is
described, never quoted (:func:`described`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from recon_cli.errors import InputError


def _fmt(x: float) -> str:
    return f"{x:g}"


def described(value: object) -> str:
    """What ``value`` is, without its content (``a text``, ``true``, ``a list of 3 items``)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if value is None:
        return "empty"
    if isinstance(value, str | bytes):
        return "a text"
    if isinstance(value, dict):
        return "a mapping"
    if isinstance(value, list | tuple):
        return f"a list of {len(value)} item{'s' if len(value) != 1 else ''}"
    return "not a plain value"


def real(value: object, where: str, *, hint: str | None = None) -> float:
    """``value`` as a finite float (bools and strings are refused, ints accepted)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise InputError(f"{where} is {described(value)}, not a number", hint=hint or "write a plain number, e.g. 0.5")
    try:
        x = float(value)
    except OverflowError:
        raise InputError(f"{where} = {value} is too large", hint=hint or "write a number of sensible size") from None
    if not math.isfinite(x):
        raise InputError(f"{where} = {value} is not a finite number",
                         hint=hint or "NaN and infinity are not accepted; write a number")
    return x


def in_range(value: object, where: str, lo: float | None = None, hi: float | None = None, *,
             lo_open: bool = False, hi_open: bool = False, unit: str = "", hint: str | None = None) -> float:
    """A finite float inside ``[lo, hi]`` (``(lo`` / ``hi)`` when open; None: unbounded)."""
    x = real(value, where, hint=hint)
    low_bad = lo is not None and (x <= lo if lo_open else x < lo)
    high_bad = hi is not None and (x >= hi if hi_open else x > hi)
    if low_bad or high_bad:
        raise InputError(f"{where} = {_fmt(x)}{(' ' + unit) if unit else ''} is outside "
                         f"{range_text(lo, hi, lo_open=lo_open, hi_open=hi_open, unit=unit)}",
                         hint=hint or "give a value inside the range")
    return x


def range_text(lo: float | None, hi: float | None, *, lo_open: bool = False, hi_open: bool = False,
               unit: str = "") -> str:
    """``(0, 10] m``-style text of a range."""
    left = "(" if lo_open or lo is None else "["
    right = ")" if hi_open or hi is None else "]"
    text = f"{left}{'-inf' if lo is None else _fmt(lo)}, {'inf' if hi is None else _fmt(hi)}{right}"
    return f"{text} {unit}".rstrip()


def integer(value: object, where: str, lo: int | None = None, hi: int | None = None, *,
            hint: str | None = None) -> int:
    """An int inside ``[lo, hi]`` (a float with an integral value is accepted)."""
    if isinstance(value, bool):
        raise InputError(f"{where} is {described(value)}, not a whole number", hint=hint or "e.g. 40")
    if isinstance(value, float) and math.isfinite(value) and value.is_integer():
        value = int(value)
    if not isinstance(value, int):
        text = f"= {value:g} is" if isinstance(value, float) else f"is {described(value)},"
        raise InputError(f"{where} {text} not a whole number", hint=hint or "e.g. 40")
    if (lo is not None and value < lo) or (hi is not None and value > hi):
        raise InputError(f"{where} = {value} is outside {range_text(lo, hi)}",
                         hint=hint or "give a value inside the range")
    return value


def vector(value: object, where: str, n: int | None = None, lo: float | None = None, hi: float | None = None, *,
           lo_open: bool = False, hi_open: bool = False, unit: str = "", max_len: int = 10_000,
           hint: str | None = None) -> tuple[float, ...]:
    """A list of ``n`` finite floats, each inside the range."""
    if isinstance(value, str | bytes) or not isinstance(value, Sequence):
        raise InputError(f"{where} is not a list of numbers", hint=hint or "write [a, b, ...]")
    if len(value) > max_len or (n is not None and len(value) != n):
        want = f"{n}" if n is not None else f"at most {max_len}"
        raise InputError(f"{where} has {len(value)} numbers, {want} expected", hint=hint or "write [a, b, ...]")
    return tuple(in_range(v, f"{where}[{i}]", lo, hi, lo_open=lo_open, hi_open=hi_open, unit=unit, hint=hint)
                 for i, v in enumerate(value))
