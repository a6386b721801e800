"""The geometry checks: finite values, coordinates and extent within the limits, non-zero
total area; on arrays Open3D loaded, or (:class:`_Scan`) over records read in chunks."""

from __future__ import annotations

import numpy as np

from .limits import MAX_COORDINATE_M, MAX_EXTENT_M
from .refused import _count, _Refused, _Units

_PLURAL = {"vertex": "vertices", "point": "points", "normal": "normals", "colour": "colours"}


def _fmt_point(p: np.ndarray) -> str:
    return "(" + ", ".join(f"{v:.6g}" for v in p) + ")"


def _not_finite(noun: str, count: int, index: int, row: np.ndarray) -> str:
    return (f"has {count} {noun if count == 1 else _PLURAL[noun]} with NaN or infinite values "
            f"({noun} {index}: {_fmt_point(row)})")


def _check_arrays(named: dict[str, np.ndarray]) -> None:
    """Every row finite; ``named``: singular noun -> (N, 3) array."""
    for noun, a in named.items():
        if a.size and not np.isfinite(a).all():
            rows = np.flatnonzero(~np.isfinite(a).all(axis=1))
            raise _Refused(_not_finite(noun, len(rows), int(rows[0]), a[rows[0]]))


def _check_geometry(lo: np.ndarray, hi: np.ndarray, scale: float) -> None:
    """Coordinates and extent of points whose per-axis minimum and maximum are ``lo``, ``hi``."""
    worst = float(max(np.abs(lo).max(), np.abs(hi).max())) * scale
    if worst > MAX_COORDINATE_M:
        raise _Units(f"has a coordinate of {worst:.4g} m (after scale {scale:g}), outside ±{MAX_COORDINATE_M:g} m "
                     "(is the file in metres?)")
    extent = float((hi - lo).max()) * scale
    if extent > MAX_EXTENT_M:
        raise _Units(f"is {extent:.4g} m across (after scale {scale:g}), more than the {MAX_EXTENT_M:g} m recon reads "
                     "(is the file in metres?)")


def _check_area(area: float, lo: np.ndarray, hi: np.ndarray, triangles: int) -> None:
    extent = float((hi - lo).max())
    if not area > 1e-12 * extent**2:
        raise _Refused(f"is degenerate: the total area of its {_count(triangles, 'triangle')} is {area:.3g} "
                       "(every triangle is a point or a line)")


def _area(points: np.ndarray, index: np.ndarray) -> float:
    a, b, c = (points[index[:, k]].astype(np.float64) for k in range(3))
    return float(np.linalg.norm(np.cross(b - a, c - a), axis=1).sum()) / 2.0


def _total_area(vertices: np.ndarray, triangles: np.ndarray) -> float:
    return sum(_area(vertices, triangles[at:at + 1_000_000]) for at in range(0, len(triangles), 1_000_000))


class _Scan:
    """The checks after loading, run over the records of a file read in chunks before
    loading: NaN or infinite rows, coordinates and extent (after ``scale``), total area.
    ``noun`` names a row of coordinates ("vertex" or "point")."""

    def __init__(self, noun: str, scale: float = 1.0) -> None:
        self.noun = noun
        self.scale = scale
        self.bad: dict[str, list] = {}  # noun -> [rows, first row's index, first row]
        self.lo = np.full(3, np.inf)
        self.hi = np.full(3, -np.inf)

    def finite(self, noun: str, columns: list[np.ndarray], first: int) -> None:
        """Rows ``first``, ``first`` + 1, ... given as one array per axis."""
        ok = np.isfinite(columns[0])
        for c in columns[1:]:
            ok &= np.isfinite(c)
        if not ok.all():
            bad = np.flatnonzero(~ok)
            row = np.array([float(c[bad[0]]) for c in columns])
            entry = self.bad.setdefault(noun, [0, first + int(bad[0]), row])
            entry[0] += len(bad)

    def coordinates(self, xyz: list[np.ndarray], first: int) -> None:
        self.finite(self.noun, xyz, first)
        if len(xyz[0]) and self.noun not in self.bad:
            self.lo = np.minimum(self.lo, [c.min() for c in xyz])
            self.hi = np.maximum(self.hi, [c.max() for c in xyz])

    def check(self) -> None:
        for noun in (self.noun, "normal", "colour"):
            if noun in self.bad:
                raise _Refused(_not_finite(noun, *self.bad[noun]))
        if np.isfinite(self.lo).all():
            _check_geometry(self.lo, self.hi, self.scale)

    def area(self, area: float, triangles: int) -> None:
        _check_area(area, self.lo, self.hi, triangles)
