"""The ``robot.ads`` section of a station file: how to reach the PLC, the names of the
symbol contract (recon_cli/backends/hardware/ads.py) and the safety values, every one of
them finite and inside its documented range (:data:`RANGES`; docs/hardware.md shows the
same table), so that no value can switch a safety check off."""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field, fields

from recon_cli.errors import InputError
from recon_cli.inputs.numbers import described, in_range, integer, range_text, real
from recon_cli.inputs.yamlfile import shown_key, unknown_key_text

SYMBOL_KEYS = ("chunk", "chunk_offset", "chunk_count", "chunk_seq", "chunk_ack", "count", "period", "job",
               "job_ack", "stop", "heartbeat", "watchdog", "state", "index", "measured", "error", "error_id")

#: poll is at most watchdog / POLLS_PER_WATCHDOG: the PLC sees several beats per watchdog window
POLLS_PER_WATCHDOG = 5
#: settled: every joint within settle_tolerance of the goal on this many consecutive polls,
#: spanning at least SETTLE_HOLD seconds, across which each joint moved less than
#: SETTLE_SPREAD x its tolerance (at rest: an axis swinging through the goal is not settled)
SETTLE_POLLS = 3
SETTLE_HOLD = 0.05  # [s]
SETTLE_SPREAD = 0.5
#: [rad, m] one count of the finest joint encoders: a 32-bit count per turn of the joint
#: (2π / 2^32 rad) and 1 nm on a linear axis; no drive reports its position finer. The default
#: of ``encoder_resolution``
ENCODER_FLOOR = (2 * math.pi / 2**32, 1e-9)
#: a settle tolerance is at least this many encoder counts: a drive at rest reads ±1 count,
#: and settling asks it to move less than SETTLE_SPREAD x the tolerance
SETTLE_COUNTS = 4


def default_symbols(prefix: str = "MAIN.recon") -> dict[str, str]:
    return {k: f"{prefix}.{k}" for k in SYMBOL_KEYS}


# --------------------------------------------------------------------- the safety values' ranges
@dataclass(frozen=True)
class Range:
    """The documented range of one numeric value of ``robot.ads``."""

    lo: float
    hi: float
    lo_open: bool = False
    unit: str = ""
    whole: bool = False  # a whole number

    def text(self) -> str:
        return range_text(self.lo, self.hi, lo_open=self.lo_open, unit=self.unit)

    def check(self, value: object, where: str) -> float | int:
        """``value`` if it is a (whole) number in the range, else InputError naming ``where``."""
        if self.whole:
            return integer(value, where, int(self.lo), int(self.hi), hint=f"write a whole number in {self.text()}")
        real(value, where, hint=f"write a number in {self.text()}")
        return in_range(value, where, self.lo, self.hi, lo_open=self.lo_open, unit=self.unit,
                        hint="docs/hardware.md gives the range of every safety value")


#: every numeric value of robot.ads: (range per element (rad, m for the pairs), also required, meaning).
#: docs/hardware.md carries the same table (tests/backends/test_ads_config.py compares them).
RANGES: dict[str, tuple[tuple[Range, ...], str, str]] = {
    "port": ((Range(1, 65535, whole=True),), "", "ADS port of the PLC runtime (851: TwinCAT 3 PLC 1)"),
    "period": ((Range(0.0005, 0.1, unit="s"),), "", "setpoint period"),
    "chunk_points": ((Range(1, 1000, whole=True),), "", "setpoint rows per download chunk"),
    "max_points": ((Range(2, 1_000_000, whole=True),), "", "size of the PLC's trajectory buffer"),
    "poll": ((Range(0.001, 0.1, unit="s"),), f"at most `watchdog` / {POLLS_PER_WATCHDOG}",
             "status polling and heartbeat period"),
    "watchdog": ((Range(0.01, 5.0, unit="s"),), f"at least {POLLS_PER_WATCHDOG} × `poll`",
                 "the PLC stops the axes when the heartbeat stalls this long; bound of a stop's confirmation"),
    "timeout": ((Range(0.01, 30.0, unit="s"),), "", "one ADS request, one chunk handshake"),
    "speed_override": ((Range(0.0, 1.0, lo_open=True),), "", "share of the planned speed"),
    "time_margin": ((Range(0.0, 600.0, lo_open=True, unit="s"),), "",
                    "beyond the duration before \"did not complete\""),
    "tracking_bound": ((Range(0.0, 0.2, lo_open=True, unit="rad"), Range(0.0, 0.05, lo_open=True, unit="m")), "",
                       "largest \\|measured − setpoint\\| in a motion; widens the joint limits for measurements"),
    "settle_tolerance": ((Range(0.0, 0.01, lo_open=True, unit="rad"), Range(0.0, 0.005, lo_open=True, unit="m")),
                         f"at most `tracking_bound`, at least {SETTLE_COUNTS} × `encoder_resolution`",
                         "\\|measured − goal\\| before a scan"),
    "encoder_resolution": ((Range(ENCODER_FLOOR[0], 0.001, unit="rad"), Range(ENCODER_FLOOR[1], 0.001, unit="m")),
                           "", "one count of the drives' position encoders (default: the lower bounds, the finest "
                               "any encoder resolves)"),
    "settle_timeout": ((Range(0.0, 60.0, lo_open=True, unit="s"),), "", "longest wait for settling"),
    "limit_tolerance": ((Range(0.0, 0.2),), "", "relative slack of the velocity re-check"),
    "scale": ((Range(1e-6, 1e6),), "one per axis; of \\|scale\\|, the sign is the axis direction",
              "PLC unit per recon unit"),
}
PAIRS = ("tracking_bound", "settle_tolerance", "encoder_resolution")


def range_rows() -> list[str]:
    """The rows of the ranges table of docs/hardware.md."""
    rows = []
    for key, (ranges, also, meaning) in RANGES.items():
        text = " and ".join(r.text() for r in ranges)
        rows.append(f"| `{key}` | {text} | {also} | {meaning} |")
    return rows


_AMS_NET_ID = re.compile(r"\d{1,3}(\.\d{1,3}){5}")
_HOST = re.compile(r"[A-Za-z0-9.:\-]{1,253}")
_SYMBOL = re.compile(r"[^\s]{1,255}")
_WHERE = re.compile(r"(.*?)(?::\d+)?: (.*)")


def key_where(d: object, key: str, where: str) -> str:
    """``where.key``, as ``file:line: where.key`` when the mapping knows the key's line."""
    lines = getattr(d, "lines", None)
    line = lines.get(key) if isinstance(lines, dict) else None
    m = _WHERE.fullmatch(where)
    if line and m:
        return f"{m.group(1)}:{line}: {m.group(2)}.{key}"
    return f"{where}.{key}"


def _number(key: str, value: object, where: str) -> float | int | tuple[float, ...]:
    ranges, _, _ = RANGES[key]
    if key in PAIRS:
        if isinstance(value, str | bytes) or not isinstance(value, list | tuple) or len(value) != 2:
            raise InputError(f"{where} is {described(value)}, not a pair [rad, m]", hint=f"e.g. {key}: [0.02, 0.005]")
        return tuple(float(ranges[i].check(v, f"{where}[{i}]")) for i, v in enumerate(value))
    if key == "scale":
        if isinstance(value, str | bytes) or not isinstance(value, list | tuple) or len(value) > 64:
            raise InputError(f"{where} is not a list of numbers", hint="one per axis, e.g. [1000, 57.29578, ...]")
        out = []
        r = ranges[0]
        for i, v in enumerate(value):
            x = real(v, f"{where}[{i}]", hint="PLC unit per recon unit, e.g. 1000 for mm")
            if not r.lo <= abs(x) <= r.hi:
                raise InputError(f"{where}[{i}] = {x:g} is outside ±{r.text()}",
                                 hint="PLC unit per recon unit, e.g. 1000 for mm; the sign is the axis direction")
            out.append(x)
        return tuple(out)
    return ranges[0].check(value, where)


def _symbols(value: object, where: str) -> dict[str, str]:
    """``symbols`` of the station file ({prefix, key: name}) as the full symbol table."""
    if not isinstance(value, dict):
        raise InputError(f"{where} is not a mapping", hint="e.g. symbols: {prefix: MAIN.recon}")
    prefix = value.get("prefix", "MAIN.recon")
    if not isinstance(prefix, str) or not _SYMBOL.fullmatch(prefix):
        raise InputError(f"{where}.prefix is not a symbol name (1 to 255 characters, no spaces)",
                         hint="e.g. prefix: MAIN.recon")
    merged = default_symbols(prefix)
    for key, name in value.items():
        if key == "prefix":
            continue
        if not isinstance(key, str) or key not in SYMBOL_KEYS:
            shown = shown_key(key)
            raise InputError(f"{where}.{shown} is not a symbol of the contract" if shown
                             else f"{where} has a key that is not a symbol of the contract",
                             hint=f"symbols: prefix, {', '.join(SYMBOL_KEYS)}")
        if not isinstance(name, str) or not _SYMBOL.fullmatch(name):
            raise InputError(f"{where}.{key} is not a symbol name (1 to 255 characters, no spaces)",
                             hint="e.g. GVL.cell.stop")
        merged[key] = name
    return merged


def _field(key: str, value: object, where: str):
    """One value of robot.ads, checked and converted (InputError naming ``where``)."""
    if key == "ams_net_id":
        ok = isinstance(value, str) and _AMS_NET_ID.fullmatch(value) and all(int(p) <= 255 for p in value.split("."))
        if not ok:
            raise InputError(f"{where} is not an AMS Net ID", hint="six numbers 0-255 with dots, "
                             "e.g. 5.80.201.232.1.1 (TwinCAT shows it under System > Routes)")
        return value
    if key == "ip":
        if not isinstance(value, str) or not _HOST.fullmatch(value):
            raise InputError(f"{where} is not an address (a host name or an IP address)",
                             hint="the PLC's IP address, e.g. 192.168.10.2")
        return value
    if key == "symbols":
        return _symbols(value, where)
    if key == "axes":
        if isinstance(value, str | bytes) or not isinstance(value, list | tuple) or len(value) > 64 \
                or not all(isinstance(a, str) for a in value):
            raise InputError(f"{where} is not a list of joint names", hint="e.g. [base_joint_1, arm_joint_1, ...]")
        if len(set(value)) != len(value):
            raise InputError(f"{where} names a joint twice", hint="list each joint once, in the PLC's axis order")
        return tuple(value)
    return _number(key, value, where)


def _together(values: dict, at) -> None:
    """The checks between values (``at(key)`` names a key)."""
    poll, watchdog = values["poll"], values["watchdog"]
    if poll * POLLS_PER_WATCHDOG > watchdog * (1 + 1e-9):
        raise InputError(f"{at('poll')} = {poll:g} s is more than watchdog / {POLLS_PER_WATCHDOG} "
                         f"= {watchdog / POLLS_PER_WATCHDOG:g} s",
                         hint="the PLC must see several heartbeats per watchdog window: lower poll or raise watchdog")
    for k, unit in enumerate(("rad", "m")):
        if values["settle_tolerance"][k] > values["tracking_bound"][k]:
            raise InputError(f"{at('settle_tolerance')}[{k}] = {values['settle_tolerance'][k]:g} {unit} is more "
                             f"than tracking_bound[{k}] = {values['tracking_bound'][k]:g} {unit}",
                             hint="settling is the tighter bound; lower settle_tolerance")
        tolerance, count = values["settle_tolerance"][k], values["encoder_resolution"][k]
        if tolerance < SETTLE_COUNTS * count * (1 - 1e-9):
            raise InputError(f"{at('settle_tolerance')}[{k}] = {tolerance:g} {unit} is below {SETTLE_COUNTS} counts "
                             f"of the encoder resolution encoder_resolution[{k}] = {count:g} {unit}: a drive at "
                             f"rest reads ±1 count, so no drive could ever settle within it",
                             hint=f"give a settle_tolerance of at least {SETTLE_COUNTS * count:g} {unit} "
                                  f"(docs/hardware.md)")
    axes, scale = values["axes"], values["scale"]
    if axes and scale and len(axes) != len(scale):
        raise InputError(f"{at('scale')} has {len(scale)} numbers for {len(axes)} axes",
                         hint="one scale per axis, in the order of axes")


@dataclass(frozen=True)
class AdsConfig:
    """The ``robot.ads`` section of a station file (ranges: :data:`RANGES`)."""

    ams_net_id: str = "127.0.0.1.1.1"  # the PLC's AMS Net ID
    port: int = 851  # TwinCAT 3 PLC runtime 1
    ip: str = "127.0.0.1"  # the PLC's address (a route to it must exist on the PLC side)
    symbols: dict[str, str] = field(default_factory=default_symbols)
    axes: tuple[str, ...] = ()  # recon joint names in the PLC's axis order (default: recon's order)
    scale: tuple[float, ...] = ()  # PLC unit per recon unit, per axis (default 1: rad and m)
    period: float = 0.01  # [s] setpoint period
    chunk_points: int = 40  # setpoint rows per download chunk
    max_points: int = 20000  # size of the PLC's trajectory buffer
    poll: float = 0.02  # [s] status polling and heartbeat period
    watchdog: float = 0.5  # [s] the PLC stops the axes when the heartbeat stalls this long
    timeout: float = 2.0  # [s] for one ADS request and one chunk handshake
    speed_override: float = 1.0  # of the planned speed (<= 1 slows the trajectory down)
    time_margin: float = 5.0  # [s] beyond the (overridden) duration before "timeout"
    tracking_bound: tuple[float, float] = (0.02, 0.005)  # [rad, m] largest |measured - setpoint|
    settle_tolerance: tuple[float, float] = (2e-4, 5e-5)  # [rad, m] at the goal
    settle_timeout: float = 3.0  # [s]
    limit_tolerance: float = 0.02  # relative slack of the velocity re-check (sampling)
    encoder_resolution: tuple[float, float] = ENCODER_FLOOR  # [rad, m] one count of the drives' encoders

    def __post_init__(self) -> None:
        """Every value in its range, whoever built the config."""
        where = "robot.ads"
        for f in fields(self):
            if f.name == "symbols":
                value = self.symbols
                if not isinstance(value, dict) or set(value) != set(SYMBOL_KEYS) or \
                        not all(isinstance(v, str) and _SYMBOL.fullmatch(v) for v in value.values()):
                    raise InputError(f"{where}.symbols is not a table of the contract's symbols",
                                     hint="build it with default_symbols() or AdsConfig.from_mapping")
                continue
            object.__setattr__(self, f.name, _field(f.name, getattr(self, f.name), f"{where}.{f.name}"))
        _together({f.name: getattr(self, f.name) for f in fields(self)}, lambda key: f"{where}.{key}")

    @classmethod
    def from_mapping(cls, d: dict, where: str = "robot.ads") -> AdsConfig:
        if not isinstance(d, dict):
            raise InputError(f"{where} is not a mapping", hint="write key: value lines under it")
        known = [f.name for f in fields(cls)]
        for key in d:
            if key not in known:
                raise InputError(unknown_key_text(where, key), hint=f"known keys: {', '.join(sorted(known))}")
        kw = {key: _field(key, value, key_where(d, key, where)) for key, value in d.items()}
        values = {f.name: f.default_factory() if callable(f.default_factory) else f.default for f in fields(cls)}
        _together({**values, **kw}, lambda key: key_where(d, key, where))
        return cls(**kw)
