"""Side by side with VAMP on the scan moves of a Franka cell (``recon bench planners --cell fr3
--peer vamp``).

VAMP (the Vector-Accelerated Motion Planner, Kavraki Lab) ships a compiled Panda: its
kinematic chain is the FR3's (the same Denavit-Hartenberg parameters), its collision model
59 spheres of the Panda's links, hand and fingers (where the FR3 cell carries the camera
bracket), its joint bounds the Panda's (narrower than the FR3's in joints 2, 6 and 7). VAMP
gets the same start/goal pairs as recon and the same obstacles as cuboids in the robot base
frame: every box of the cell's environment (table top, legs, board, ...) and the object box,
each inflated by the safety distance once more, since recon inflates both the robot's
shapes and the obstacles by it and VAMP's spheres are not inflated. A pair outside VAMP's
bounds or invalid in its model is left out and counted. VAMP plans with RRT-Connect
(``rrtc``) and simplifies with its defaults; times are wall clock around each call, one core.

VAMP is never a dependency of recon: it runs in its own virtual environment, built offline
by ``../shared/peers/vamp/build_vamp.sh VENV`` and named by ``RECON_VAMP_VENV``.
"""

from __future__ import annotations

import json
import os
import subprocess
import tempfile
from pathlib import Path

import numpy as np

from recon_cli.bench.scan_moves import ScanMoves
from recon_cli.errors import ReconError
from recon_cli.geometry.transforms import invert
from recon_cli.robot.cell import Cell
from recon_cli.robot.cell_file import descendant_links

PEER_SCRIPT = Path(__file__).with_name("peer_vamp.py")
VENV_VARIABLE = "RECON_VAMP_VENV"
BUILD_HINT = ("build it with ../shared/peers/vamp/build_vamp.sh VENV (2-15 minutes of compiling), then set "
              f"{VENV_VARIABLE}=VENV")


def vamp_python() -> Path:
    venv = os.environ.get(VENV_VARIABLE)
    if not venv:
        raise ReconError(f"the VAMP peer needs its own environment: {VENV_VARIABLE} is not set", hint=BUILD_HINT)
    python = Path(venv).expanduser() / "bin" / "python"
    check = subprocess.run([str(python), "-c", "import vamp"], capture_output=True, text=True) \
        if python.exists() else None
    if check is None or check.returncode != 0:
        raise ReconError(f"{venv} has no working VAMP", hint=BUILD_HINT)
    return python


#: [m] half width of the square left out of the surface the robot base stands on: VAMP checks
#: its base link's sphere (0.08 m around a point 0.05 m above the base) against the
#: environment, which recon never does (the base does not move)
BASE_HOLE = 0.1


def _robot_links(cell: Cell) -> set[str]:
    """The arm's base link and every link under it (their shapes are VAMP's spheres)."""
    base = cell.config.cell_file.base_link
    return {base, *descendant_links(cell.urdf, base)}


def _around_base(center: np.ndarray, half: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """An axis-aligned box the base stands on, as up to four boxes around a square hole of
    half width :data:`BASE_HOLE` at the base (x = y = 0 of the base frame)."""
    lo, hi = center - half, center + half
    if not (lo[0] < 0 < hi[0] and lo[1] < 0 < hi[1] and abs(hi[2]) < 0.1):
        return [(center, half)]
    h = BASE_HOLE
    pieces = [((lo[0], -h), (lo[1], hi[1])), ((h, hi[0]), (lo[1], hi[1])),
              ((-h, h), (lo[1], -h)), ((-h, h), (h, hi[1]))]
    out = []
    for (x0, x1), (y0, y1) in pieces:
        if x1 > x0 and y1 > y0:
            a, b = np.array([x0, y0, lo[2]]), np.array([x1, y1, hi[2]])
            out.append(((a + b) / 2.0, (b - a) / 2.0))
    return out


def cuboids(cell: Cell, extra: float) -> list[list[list[float]]]:
    """The cell's environment boxes (and the object box) as VAMP cuboids (centre, Euler XYZ,
    half extents) in the robot base frame, each grown by ``extra`` [m] on every face; the
    robot's own fixed links left out, the surface under the base with a hole for VAMP's base
    sphere (:data:`BASE_HOLE`)."""
    from scipy.spatial.transform import Rotation

    cf = cell.config.cell_file
    home = cf.pose("home", cell.joint_names)
    base_T_world = invert(cell.kin.frame_pose(home, cf.base_link))
    robot = _robot_links(cell)
    out = []
    for shape in cell.collision.env_shapes:
        if shape.link in robot:
            continue
        T = base_T_world @ shape.joint_T_shape
        if shape.kind == "box":
            half = np.asarray(shape.dims) / 2.0 + extra
        elif shape.kind in ("cylinder", "capsule"):  # the bounding box: conservative
            r, length = shape.dims
            half = np.array([r, r, length / 2.0 + (r if shape.kind == "capsule" else 0.0)]) + extra
        else:  # sphere
            half = np.full(3, shape.dims[0] + extra)
        euler = Rotation.from_matrix(T[:3, :3]).as_euler("xyz")  # R = Rz(e2) Ry(e1) Rx(e0), as VAMP's
        aligned = shape.kind == "box" and np.allclose(np.abs(T[:3, :3]), np.eye(3), atol=1e-9)
        if aligned:  # the table top under the base: around the base
            half = np.abs(T[:3, :3]) @ half
            for c, h in _around_base(T[:3, 3], half):
                out.append([c.tolist(), [0.0, 0.0, 0.0], h.tolist()])
            continue
        out.append([T[:3, 3].tolist(), euler.tolist(), half.tolist()])
    return out


def vamp_valid(cell: Cell, configurations: list[np.ndarray]) -> list[bool]:
    """Which configurations VAMP's Panda takes as valid among the cell's obstacles."""
    python = vamp_python()
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "validate.json"
        path.write_text(json.dumps({"robot": "panda", "planner": "rrtc",
                                    "validate": [q.tolist() for q in configurations],
                                    "cuboids": cuboids(cell, cell.config.safety_distance)}))
        proc = subprocess.run([str(python), str(PEER_SCRIPT), str(path)], capture_output=True, text=True)
    if proc.returncode != 0:
        tail = proc.stderr.strip().splitlines()[-1:] or ["?"]
        raise ReconError(f"the VAMP peer failed ({tail[0]})", hint="check RECON_VAMP_VENV")
    return [bool(v) for v in json.loads(proc.stdout.strip().splitlines()[-1])["valid"]]


def run_vamp(folder: Path, cell: Cell, problem: ScanMoves) -> dict:
    """VAMP on the pairs of ``problem``; a summary like mplib's (times of solved requests)."""
    if cell.kin.nq != 7:
        raise ReconError(f"VAMP plans for its compiled Panda (7 joints); the {problem.cell} cell has {cell.kin.nq}",
                         hint="use --peer vamp on a Franka cell (fr3)")
    python = vamp_python()
    peer = folder / "peer"
    peer.mkdir(exist_ok=True)
    spec = {"robot": "panda", "planner": "rrtc",
            "pairs": [[a.tolist(), b.tolist()] for a, b in problem.pairs],
            "cuboids": cuboids(cell, cell.config.safety_distance)}
    path = peer / "vamp_problem.json"
    path.write_text(json.dumps(spec, indent=1))
    proc = subprocess.run([str(python), str(PEER_SCRIPT), str(path)], capture_output=True, text=True,
                          env={**os.environ, "OMP_NUM_THREADS": "1"})
    if proc.returncode != 0:
        tail = proc.stderr.strip().splitlines()[-1:] or ["?"]
        raise ReconError(f"the VAMP peer failed ({tail[0]})", hint=f"see {peer}")
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    (peer / "vamp_results.json").write_text(json.dumps(out, indent=1))
    rows = out["rows"]
    asked = [r for r in rows if r["start_valid"] and r["goal_valid"]]
    solved = [r for r in asked if r["solved"]]
    times = [r["total"] for r in solved]
    return {
        "name": "VAMP", "version": out["vamp"], "planner": "RRTConnect (rrtc)",
        "requests": len(rows), "asked": len(asked), "solved": len(solved),
        "invalid_start_or_goal": len(rows) - len(asked),
        "outside_bounds": sum(not r["within_bounds"] for r in rows),
        "success_rate": len(solved) / len(asked) if asked else float("nan"),
        "time_median": float(np.median(times)) if times else float("nan"),
        "plan_median": float(np.median([r["plan"] for r in solved])) if solved else float("nan"),
        "path_length_median": float(np.median([r["path_length"] for r in solved])) if solved else float("nan"),
        "times": times,
        "per_request": [r["total"] if r["start_valid"] and r["goal_valid"] and r["solved"] else None for r in rows],
    }
