"""Side by side with a peer: the Table 4.1 problem in mplib 0.2.1 (``recon bench planners
--peer mplib``).

mplib gets the same problem: the same expanded URDF (safety distance 0.03 m), an SRDF whose
disabled pairs are recon's allowed link pairs (plus every pair of two fixed environment
links, which never move), the same 0.3 m cube inflated by the safety distance, the same
start, goal and time limit. Differences that remain: mplib plans within the URDF's hard
joint limits (recon within the soft limits, 10 deg tighter), checks the few shape pairs
recon proved separated (carriage/rails, link 6/camera housing), and checks motions at
OMPL's default resolution instead of recon's 5 mm bound.

The peer runs in its own virtual environment (mplib pins numpy < 2), created on first use
under ``~/.cache/recon/venv-mplib`` with pip from PyPI.
"""

from __future__ import annotations

import itertools
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
from lxml import etree

from recon_cli.errors import ReconError
from recon_cli.robot.cell import Cell
from recon_cli.robot.collision import allowed_link_pairs
from recon_cli.robot.description import CellConfig
from recon_cli.thesis import BENCH_CUBE, TABLE_4_1_GOAL, TABLE_4_1_START

VENV = Path(os.environ.get("RECON_MPLIB_VENV", Path.home() / ".cache" / "recon" / "venv-mplib"))
PEER_SCRIPT = Path(__file__).with_name("peer_mplib.py")


def ensure_venv() -> Path:
    python = VENV / "bin" / "python"
    if python.exists():
        check = subprocess.run([str(python), "-c", "import mplib"], capture_output=True)
        if check.returncode == 0:
            return python
    VENV.parent.mkdir(parents=True, exist_ok=True)
    steps = [[sys.executable, "-m", "venv", str(VENV)],
             [str(python), "-m", "pip", "install", "-q", "--disable-pip-version-check", "mplib==0.2.1"]]
    for cmd in steps:
        proc = subprocess.run(cmd, capture_output=True, text=True)
        if proc.returncode != 0:
            last = (proc.stderr or proc.stdout).strip().splitlines()[-1:] or ["?"]
            raise ReconError(f"cannot set up the mplib peer environment ({last[0]})",
                             hint=f"check network access to PyPI or remove {VENV}")
    return python


def srdf_for(urdf: str, cell: Cell) -> str:
    root = etree.fromstring(urdf.encode())
    links = [link.attrib["name"] for link in root.iterfind("link")]
    body = {name: cell.kin.model.frames[cell.kin.model.getFrameId(name)].parentJoint for name in links}
    allowed = allowed_link_pairs(urdf, cell.kin)
    robot = etree.Element("robot", name="recon_cell")
    group = etree.SubElement(robot, "group", name="camera")
    etree.SubElement(group, "chain", base_link="world", tip_link=cell.config.cell_file.camera_frame)
    for a, b in itertools.combinations(links, 2):
        if frozenset((a, b)) in allowed or (body[a] == 0 and body[b] == 0):
            etree.SubElement(robot, "disable_collisions", link1=a, link2=b, reason="recon")
    return etree.tostring(robot, pretty_print=True).decode()


def run_mplib(folder: Path, n: int, time_limit: float, ranges=(0.1, 1.5), cell: Cell | None = None,
              pairs: list[tuple[np.ndarray, np.ndarray]] | None = None) -> dict:
    """mplib on the Table 4.1 problem (``n`` requests), or on ``pairs`` of ``cell`` (once each)."""
    python = ensure_venv()
    cell = cell if cell is not None else Cell(CellConfig(), object_box=BENCH_CUBE)
    box = cell.collision.object_box if pairs is not None else BENCH_CUBE
    assert box is not None  # both problems have an object box
    (folder / "peer").mkdir(exist_ok=True)
    urdf_path = folder / "peer" / "cell.urdf"
    srdf_path = folder / "peer" / "cell.srdf"
    urdf_path.write_text(cell.urdf)
    srdf_path.write_text(srdf_for(cell.urdf, cell))
    sd = cell.config.safety_distance
    problem = {
        "urdf": str(urdf_path), "srdf": str(srdf_path), "move_group": "camera",
        **({"start": TABLE_4_1_START.tolist(), "goal": TABLE_4_1_GOAL.tolist()} if pairs is None
           else {"pairs": [[a.tolist(), b.tolist()] for a, b in pairs]}),
        "box_center": list(box.center), "box_size": [s + 2 * sd for s in box.size],
        "time_limit": time_limit, "n": n, "ranges": list(ranges),
        "velocity": cell.limits.velocity.tolist(), "acceleration": cell.limits.acceleration.tolist(),
        "velocity_scale": 0.15, "acceleration_scale": 0.3,
        "environment_links": sorted({s.link for s in cell.collision.env_shapes} - {"object"}),
    }
    (folder / "peer" / "problem.json").write_text(json.dumps(problem, indent=2))
    proc = subprocess.run([str(python), str(PEER_SCRIPT), str(folder / "peer" / "problem.json")],
                          capture_output=True, text=True, env={**os.environ, "OMP_NUM_THREADS": "1"})
    if proc.returncode != 0:
        tail = proc.stderr.strip().splitlines()[-1:] or ["?"]
        raise ReconError(f"the mplib peer failed ({tail[0]})", hint=f"see {folder / 'peer'}")
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    best_key = min(out["results"], key=lambda k: float(np.median(out["results"][k]["planning"])))
    best = out["results"][best_key]
    solved = np.array(best["solved"])
    times = np.array(best["planning"])
    summary = {
        "version": out["mplib"], "range": float(best_key),
        "success_rate": float(solved.mean()),
        "time_median": float(np.median(times[solved])) if solved.any() else float("nan"),
        "total_median": float(np.median(best["total"])),
        "path_length_median": float(np.median(best["path_lengths"])) if best["path_lengths"] else float("nan"),
        "start_collisions": out["start_collisions"], "goal_collisions": out["goal_collisions"],
        "all_ranges": {k: {"time_median": float(np.median(v["planning"])),
                           "success_rate": float(np.mean(v["solved"]))} for k, v in out["results"].items()},
        "times": times[solved].tolist(), "name": "mplib", "requests": len(solved),
        "solved": int(solved.sum()),
        "per_request": [float(t) if ok else None for t, ok in zip(times, solved, strict=True)],
    }
    (folder / "peer" / "mplib_results.json").write_text(json.dumps(out, indent=1))
    return summary
