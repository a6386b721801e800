"""Lower bound on the duration of a joint motion (thesis 2.3.4, eqs. 2.16-2.21).

A single joint travelling Δs from rest to rest with |a| <= a_max and |v| <= v_max needs at
least 2 sqrt(Δs / a_max) when the velocity limit is not reached (Δs < v_max² / a_max), and
Δs / v_max + v_max / a_max otherwise (eq. 2.20). The slowest joint bounds the whole motion
(eq. 2.21). Any trajectory that respects the limits, along any path, takes at least this
long; the sequence optimizer uses it for edges it has not planned yet.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt


def joint_time_lower_bound(distance: npt.ArrayLike, v_max: npt.ArrayLike,
                           a_max: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Eq. 2.20 for every joint: minimum rest-to-rest time [s] for strokes ``distance``."""
    ds = np.abs(np.asarray(distance, dtype=float))
    v = np.asarray(v_max, dtype=float)
    a = np.asarray(a_max, dtype=float)
    bound: npt.NDArray[np.float64] = np.where(ds < v * v / a, 2.0 * np.sqrt(ds / a), ds / v + v / a)
    return bound


def duration_lower_bound(q_a: npt.ArrayLike, q_b: npt.ArrayLike, v_max: npt.ArrayLike, a_max: npt.ArrayLike,
                         velocity_scale: float = 1.0, acceleration_scale: float = 1.0) -> float:
    """Eq. 2.21: the largest single-joint bound for the motion q_a -> q_b [s]."""
    t = joint_time_lower_bound(np.asarray(q_b) - np.asarray(q_a), np.asarray(v_max) * velocity_scale,
                               np.asarray(a_max) * acceleration_scale)
    return float(np.max(t, axis=-1))
