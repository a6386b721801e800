"""The ``robot.franka`` section of a station file: how to reach the Franka's controller (FCI)
and the values of the adapter's checks, each finite and inside its documented range
(:data:`RANGES`; docs/hardware.md shows the same table), so that no value switches a check
off."""

from __future__ import annotations

import re
from dataclasses import dataclass, fields

from recon_cli.backends.hardware.ads_config import ENCODER_FLOOR, SETTLE_COUNTS, Range, key_where
from recon_cli.errors import InputError
from recon_cli.inputs.yamlfile import unknown_key_text

#: at rest: every joint moved less than REST_SPREAD over this many consecutive states (1 ms
#: apart); settled: at rest within settle_tolerance of the goal
SETTLE_STATES = 50
REST_SPREAD = 5e-4  # [rad]

#: every numeric value of robot.franka: (range, meaning); docs/hardware.md carries the same table
RANGES: dict[str, tuple[Range, str]] = {
    "tracking_bound": (Range(0.0, 0.2, lo_open=True, unit="rad"),
                       "largest \\|measured − commanded\\| in a motion; widens the joint limits for measurements"),
    "settle_tolerance": (Range(SETTLE_COUNTS * ENCODER_FLOOR[0], 0.01, unit="rad"),
                         f"\\|measured − goal\\| before a scan; at least {SETTLE_COUNTS} counts of the finest joint "
                         "encoder (2π/2³² rad)"),
    "settle_timeout": (Range(0.0, 60.0, lo_open=True, unit="s"), "longest wait for settling"),
    "time_margin": (Range(0.0, 600.0, lo_open=True, unit="s"), "beyond the duration before \"did not complete\""),
    "lost_cycles": (Range(0, 5, whole=True),
                    "consecutive controller cycles the 1 kHz stream may miss anywhere and stay within the jerk limit "
                    "(its smoothing)"),
    "deviation_bound": (Range(0.0, 0.01, lo_open=True, unit="rad"),
                        "largest distance of the smoothed setpoints from the checked path"),
}
REALTIME = ("enforce", "ignore")
_HOST = re.compile(r"[A-Za-z0-9.\-]{1,253}")


def range_rows() -> list[str]:
    """The rows of the ranges table of docs/hardware.md."""
    return [f"| `{key}` | {r.text()} | {meaning} |" for key, (r, meaning) in RANGES.items()]


def _field(key: str, value: object, where: str):
    if key == "ip":
        if not isinstance(value, str) or not _HOST.fullmatch(value):
            raise InputError(f"{where} is not an address (a host name or an IP address)",
                             hint="the controller's address (Franka's default is 172.16.0.2)")
        return value
    if key == "realtime":
        if value not in REALTIME:
            raise InputError(f"{where} is not one of {', '.join(REALTIME)}",
                             hint="enforce on a real-time kernel (the robot); ignore for a simulated robot")
        return value
    if key == "settle_tolerance":
        _settle_floor(value, where)
    return RANGES[key][0].check(value, where)


def _settle_floor(value: object, where: str) -> None:
    """A settle tolerance below SETTLE_COUNTS counts of the finest encoder: no drive meets it."""
    floor = SETTLE_COUNTS * ENCODER_FLOOR[0]
    if isinstance(value, int | float) and not isinstance(value, bool) and 0 < value < floor:
        raise InputError(f"{where} = {value:g} rad is below {SETTLE_COUNTS} counts of the finest joint encoder "
                         f"(resolution {ENCODER_FLOOR[0]:g} rad: a 32-bit count per turn): a drive at rest reads "
                         f"±1 count, so the arm could never settle within it",
                         hint=f"give a settle_tolerance of at least {floor:g} rad (docs/hardware.md)")


@dataclass(frozen=True)
class FrankaConfig:
    """The ``robot.franka`` section of a station file (ranges: :data:`RANGES`)."""

    ip: str = "172.16.0.2"  # the controller's (FCI) address; libfranka's port 1337 is fixed
    realtime: str = "enforce"  # libfranka's RealtimeConfig: enforce (a real-time kernel) or ignore
    tracking_bound: float = 0.05  # [rad] largest |measured - commanded| in a motion
    settle_tolerance: float = 0.005  # [rad] at the goal (the impedance controller holds a static error)
    settle_timeout: float = 3.0  # [s]
    time_margin: float = 3.0  # [s] beyond the duration before "timeout"
    lost_cycles: int = 3  # consecutive missed cycles the smoothing absorbs (the check is at the limit)
    deviation_bound: float = 0.001  # [rad] of the smoothed setpoints from the checked path

    def __post_init__(self) -> None:
        for f in fields(self):
            object.__setattr__(self, f.name, _field(f.name, getattr(self, f.name), f"robot.franka.{f.name}"))
        if self.settle_tolerance > self.tracking_bound:
            raise InputError(f"robot.franka.settle_tolerance = {self.settle_tolerance:g} rad is more than "
                             f"tracking_bound = {self.tracking_bound:g} rad", hint="settling is the tighter bound")

    @classmethod
    def from_mapping(cls, d: dict, where: str = "robot.franka") -> FrankaConfig:
        if not isinstance(d, dict):
            raise InputError(f"{where} is not a mapping", hint="write key: value lines under it, e.g. ip: 172.16.0.2")
        known = [f.name for f in fields(cls)]
        for key in d:
            if key not in known:
                raise InputError(unknown_key_text(where, key), hint=f"known keys: {', '.join(sorted(known))}")
        if "ip" not in d:
            raise InputError(f"{where} has no ip", hint="ip: the controller's address, e.g. 172.16.0.2")
        kw = {key: _field(key, value, key_where(d, key, where)) for key, value in d.items()}
        if kw.get("settle_tolerance", cls.settle_tolerance) > kw.get("tracking_bound", cls.tracking_bound):
            raise InputError(f"{key_where(d, 'settle_tolerance', where)} is more than tracking_bound",
                             hint="settling is the tighter bound; lower settle_tolerance")
        return cls(**kw)
