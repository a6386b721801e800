"""Forward kinematics of many configurations at once (distance tables of the collision model).

pinocchio computes one configuration per call; tabulating a pair's distance needs the poses
of all links at thousands of configurations, where the per-call overhead from Python
dominates.
``BatchFK`` evaluates pinocchio's own model (joint placements and joint types, nothing
re-described) for a (K, n) batch with a handful of numpy operations per joint. Supported
joints: revolute and prismatic about/along a coordinate axis (the cells use RZ, PX, PY).
tests/robot/test_batch_fk.py checks it against pinocchio to 1e-12.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from recon_cli.lazy import lazy_module

if TYPE_CHECKING:
    import pinocchio as pin
else:
    pin = lazy_module("pinocchio")


_AXES = {"X": 0, "Y": 1, "Z": 2}


class BatchFK:
    def __init__(self, model: pin.Model) -> None:
        self.njoints = model.njoints
        self.parents = [int(p) for p in model.parents]
        self.placements = [model.jointPlacements[j].homogeneous for j in range(model.njoints)]
        self.kinds: list[tuple[str, int, int]] = [("fixed", -1, -1)]
        for j in range(1, model.njoints):
            short = model.joints[j].shortname()  # e.g. JointModelRZ, JointModelPY
            kind = short.replace("JointModel", "")
            if len(kind) != 2 or kind[0] not in "RP" or kind[1] not in _AXES:
                raise NotImplementedError(f"joint {model.names[j]} of type {short} is not supported")
            self.kinds.append((kind[0], _AXES[kind[1]], int(model.joints[j].idx_q)))

    def joint_poses(self, Q: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """World poses of every joint frame (oMi), shape (K, njoints, 4, 4)."""
        Q = np.atleast_2d(np.asarray(Q, dtype=float))
        K = Q.shape[0]
        out = np.empty((K, self.njoints, 4, 4))
        out[:, 0] = np.eye(4)
        for j in range(1, self.njoints):
            kind, axis, iq = self.kinds[j]
            q = Q[:, iq]
            M = np.broadcast_to(out[:, self.parents[j]] @ self.placements[j], (K, 4, 4)).copy()
            if kind == "P":
                M[:, :3, 3] += M[:, :3, axis] * q[:, None]
            else:
                c, s = np.cos(q)[:, None], np.sin(q)[:, None]
                a, b = [(1, 2), (2, 0), (0, 1)][axis]  # the two axes turned into each other
                col_a, col_b = M[:, :3, a].copy(), M[:, :3, b].copy()
                M[:, :3, a] = c * col_a + s * col_b
                M[:, :3, b] = -s * col_a + c * col_b
            out[:, j] = M
        return out
