"""Vectorized broad phase for the collision model: bounding capsules against bounding boxes.

Every robot shape is enclosed in a capsule (segment + radius) and every environment shape
in an oriented box. Two numpy tests, evaluated for many configurations at once, decide
which shape pairs *may* touch; only those go to FCL for the exact answer. Both tests are
conservative (the bounding volumes contain the shapes), so a pair they clear is free.

- capsule vs box: the capsule's segment against the box grown by the radius (slab test);
  the grown box contains the capsule-box Minkowski sum, so no contact is missed.
- capsule vs capsule: exact segment-segment distance against the sum of the radii.
"""

from __future__ import annotations

import numpy as np


def bounding_capsule(kind: str, dims: tuple[float, ...]) -> tuple[np.ndarray, np.ndarray, float]:
    """Segment end points (shape frame) and radius of a capsule containing the shape."""
    if kind == "capsule":
        r, length = dims
        return np.array([0.0, 0.0, -length / 2]), np.array([0.0, 0.0, length / 2]), float(r)
    if kind == "cylinder":
        r, length = dims
        return np.array([0.0, 0.0, -length / 2]), np.array([0.0, 0.0, length / 2]), float(r)
    if kind == "sphere":
        return np.zeros(3), np.zeros(3), float(dims[0])
    if kind == "box":
        half = np.asarray(dims, dtype=float) / 2.0
        k = int(np.argmax(half))
        a, b = np.zeros(3), np.zeros(3)
        a[k], b[k] = -half[k], half[k]
        others = np.delete(half, k)
        return a, b, float(np.linalg.norm(others))
    raise ValueError(kind)


def bounding_box(kind: str, dims: tuple[float, ...]) -> np.ndarray:
    """Half extents (shape frame) of a box containing the shape."""
    if kind == "box":
        return np.asarray(dims, dtype=float) / 2.0
    if kind in ("capsule", "cylinder"):
        r, length = dims
        return np.array([r, r, length / 2 + (r if kind == "capsule" else 0.0)])
    if kind == "sphere":
        return np.full(3, float(dims[0]))
    raise ValueError(kind)


def world_aabbs(box_R: np.ndarray, box_c: np.ndarray, box_h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World-axis-aligned boxes (centres, half extents) containing oriented boxes (E)."""
    return box_c, np.einsum("eij,ej->ei", np.abs(box_R), box_h)


def segments_hit_boxes(p0: np.ndarray, p1: np.ndarray, radius: np.ndarray,
                       box_c: np.ndarray, box_h: np.ndarray) -> np.ndarray:
    """May capsules (segments p0-p1 (..., R, 3), radii (R,) or (..., R)) touch world-aligned
    boxes (E, centres box_c (E, 3), half extents box_h (E, 3))? -> (..., R, E).

    First the capsules' own axis-aligned boxes against the boxes (cheap, dense), then, for
    the overlapping pairs only, a slab test of the segment against its box grown by the
    capsule radius."""
    lo = np.minimum(p0, p1) - radius[..., None]  # (..., R, 3)
    hi = np.maximum(p0, p1) + radius[..., None]
    box_lo, box_hi = box_c - box_h, box_c + box_h  # (E, 3)
    near = np.all((lo[..., :, None, :] <= box_hi) & (hi[..., :, None, :] >= box_lo), axis=-1)
    idx = np.nonzero(near)
    if len(idx[0]) == 0:
        return near
    e = idx[-1]
    rs = idx[:-1]
    a = p0[rs] - box_c[e]  # (M, 3)
    d = p1[rs] - p0[rs]
    r = np.broadcast_to(radius, p0.shape[:-1])[rs]
    H = box_h[e] + r[:, None]
    small = np.abs(d) < 1e-12
    inv = 1.0 / np.where(small, 1.0, d)
    t1 = (-H - a) * inv
    t2 = (H - a) * inv
    tlo = np.where(small, np.where(np.abs(a) <= H, -np.inf, np.inf), np.minimum(t1, t2))
    thi = np.where(small, np.inf, np.maximum(t1, t2))
    hit = np.maximum(tlo.max(axis=-1), 0.0) <= np.minimum(thi.min(axis=-1), 1.0)
    near[idx] = hit
    return near


def segment_distance(p1: np.ndarray, q1: np.ndarray, p2: np.ndarray, q2: np.ndarray) -> np.ndarray:
    """Distance between segments p1-q1 and p2-q2 (arrays (..., 3)) -> (...)."""
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    a = np.einsum("...i,...i", d1, d1)
    e = np.einsum("...i,...i", d2, d2)
    f = np.einsum("...i,...i", d2, r)
    c = np.einsum("...i,...i", d1, r)
    b = np.einsum("...i,...i", d1, d2)
    eps = 1e-15
    a_ok, e_ok = a > eps, e > eps
    denom = a * e - b * b
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(denom > eps * np.maximum(a * e, eps), np.clip((b * f - c * e) / denom, 0, 1), 0.0)
        t = np.where(e_ok, (b * s + f) / np.where(e_ok, e, 1.0), 0.0)
        s = np.where(t < 0.0, np.clip(-c / np.where(a_ok, a, 1.0), 0, 1),
                     np.where(t > 1.0, np.clip((b - c) / np.where(a_ok, a, 1.0), 0, 1), s))
        t = np.clip(t, 0.0, 1.0)
        # degenerate segments (points)
        s = np.where(a_ok, s, 0.0)
        t = np.where(a_ok, t, np.where(e_ok, np.clip(f / np.where(e_ok, e, 1.0), 0, 1), 0.0))
        s = np.where(e_ok | ~a_ok, s, np.clip(-c / np.where(a_ok, a, 1.0), 0, 1))
    c1 = p1 + d1 * s[..., None]
    c2 = p2 + d2 * t[..., None]
    return np.linalg.norm(c1 - c2, axis=-1)
