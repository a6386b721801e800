"""Forward kinematics of many configurations at once (distance tables of the collision model).

pinocchio computes one configuration per call; tabulating a pair's distance needs the poses
of all links at thousands of configurations, where the per-call overhead from Python
dominates.
``BatchFK`` evaluates pinocchio's own model (joint placements and joint types, nothing
re-described) for a (K, n) batch with a handful of numpy operations per joint. Supported
joints: revolute and prismatic about/along a coordinate axis (the thesis cells use RZ, PX,
PY) or any other axis (pinocchio's RevoluteUnaligned and PrismaticUnaligned: a URDF axis
such as 0 0 -1).
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
        self.axes: dict[int, npt.NDArray[np.float64]] = {}  # unaligned joints: their unit axis
        for j in range(1, model.njoints):
            short = model.joints[j].shortname()  # e.g. JointModelRZ, JointModelPY
            kind = short.replace("JointModel", "")
            iq = int(model.joints[j].idx_q)
            if kind in ("RevoluteUnaligned", "PrismaticUnaligned"):
                axis = np.asarray(model.joints[j].extract().axis, dtype=float)
                self.axes[j] = axis / np.linalg.norm(axis)
                self.kinds.append((kind[0] + "U", -1, iq))
                continue
            if len(kind) != 2 or kind[0] not in "RP" or kind[1] not in _AXES:
                raise NotImplementedError(f"joint {model.names[j]} of type {short} is not supported")
            self.kinds.append((kind[0], _AXES[kind[1]], iq))

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
            if kind in ("RU", "PU"):
                u = self.axes[j]
                if kind == "PU":
                    M[:, :3, 3] += (M[:, :3, :3] @ u) * q[:, None]
                else:  # Rodrigues: R(q) = I + sin q [u]x + (1 - cos q) [u]x^2
                    ux = np.array([[0.0, -u[2], u[1]], [u[2], 0.0, -u[0]], [-u[1], u[0], 0.0]])
                    R = (np.eye(3)[None] + np.sin(q)[:, None, None] * ux[None]
                         + (1.0 - np.cos(q))[:, None, None] * (ux @ ux)[None])
                    M[:, :3, :3] = M[:, :3, :3] @ R
                out[:, j] = M
                continue
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
