"""Planner benchmark of thesis section 4.1 (``recon bench planners``).

The problem of Table 4.1: 9-DoF gantry cell, start and goal as given, the 0.3 m cube on the
table (inflated by the 3 cm safety distance like every other shape), 5 s per request. Every
request is independent (a fresh search from the start state) with a seed of its own, the
k-th drawn from --seed; every planner gets the same N seeds, and a request gives the same
path again with its seed (``plan_to_joints``). Measured per request: success,
plan time (search + simplification, the figure MoveIt's benchmark reports as "time"),
post-processing time (toppra timing + the dense final check), path length (sum of absolute
joint differences, rad and m mixed, as MoveIt) and trajectory duration (velocity and
acceleration scaling 0.15 / 0.3, as the thesis' benchmark requests).
"""

from __future__ import annotations

import csv
import json
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from recon_cli.paths import SHARED_DATA_DIR
from recon_cli.planning.planner import MotionPlanner, PlanOptions
from recon_cli.robot.cell import Cell
from recon_cli.robot.description import CellConfig
from recon_cli.thesis import BENCH_CUBE, TABLE_4_1_GOAL, TABLE_4_1_START

#: planners that stop at a first solution by design; the optimizing ones are asked for
#: their first exact solution too (PlanOptions), so all of them answer the same request
DEFAULT_PLANNERS = ("RRTConnect", "RRT", "KPIECE1", "BKPIECE1", "LBKPIECE1", "PRM", "RRTstar",
                    "BITstar", "AORRTC")
THESIS_PLANNERS = ("RRTConnect", "BiEST", "RRT", "ProjEST")


@dataclass(frozen=True)
class RequestRow:
    planner: str
    request: int
    solved: bool
    status: str
    plan_time: float  # search + simplification [s]
    search_time: float
    simplify_time: float
    post_time: float  # toppra + final check [s]
    path_length: float
    trajectory_duration: float
    seed: int  # of the request (MotionPlanner.plan_to_joints: the same seed gives the same path)


def summarize(rows: list[RequestRow]) -> dict:
    t = np.array([r.plan_time for r in rows])
    ok = np.array([r.solved for r in rows])
    ts = t[ok] if ok.any() else np.array([np.nan])
    pl = np.array([r.path_length for r in rows if r.solved] or [np.nan])
    td = np.array([r.trajectory_duration for r in rows if r.solved] or [np.nan])
    return {
        "requests": len(rows), "solved": int(ok.sum()), "success_rate": float(ok.mean()),
        "time_min": float(np.min(ts)), "time_median": float(np.median(ts)),
        "time_p90": float(np.percentile(ts, 90)), "time_max": float(np.max(ts)),
        "time_median_all": float(np.median(t)),
        "path_length_median": float(np.median(pl)), "trajectory_duration_median": float(np.median(td)),
        "post_time_median": float(np.median([r.post_time for r in rows if r.solved] or [np.nan])),
    }


def request_seeds(seed: int, n: int) -> list[int]:
    """The seeds of the N requests of a benchmark run with ``seed``."""
    return [int(s) for s in np.random.default_rng(seed).integers(1 << 30, size=n)]


def run_planner_bench(planners: list[str], n: int, time_limit: float, seed: int,
                      progress: Callable[[str, int, int], None] | None = None,
                      options: PlanOptions = PlanOptions()) -> list[RequestRow]:  # noqa: B008
    """N requests of the Table 4.1 problem per planner; ``options`` gives everything but the
    planner and the time limit (simplification, scaling)."""
    cell = Cell(CellConfig(), object_box=BENCH_CUBE)
    seeds = request_seeds(seed, n)
    rows: list[RequestRow] = []
    for name in planners:
        planner = MotionPlanner(cell, replace(options, planner=name, time_limit=time_limit))
        for k, request_seed in enumerate(seeds):
            t0 = time.perf_counter()
            r = planner.plan_to_joints(TABLE_4_1_START, TABLE_4_1_GOAL, seed=request_seed)
            trajectory = r.trajectory if r.ok else None
            total = time.perf_counter() - t0
            plan_time = r.plan_time + r.simplify_time
            rows.append(RequestRow(
                name, k, r.ok, r.status.value, plan_time, r.plan_time, r.simplify_time,
                max(total - plan_time, 0.0) if r.ok else 0.0, r.path_length if r.ok else float("nan"),
                float("nan") if trajectory is None else trajectory.duration, request_seed))
            if progress:
                progress(name, k + 1, n)
    return rows


def thesis_times() -> dict[str, np.ndarray]:
    """Per-request total planning times of the thesis' MoveIt benchmark (benchmark4 CSVs,
    solved runs only), when ../shared/data/thesis is present."""
    out = {}
    folder = SHARED_DATA_DIR / "thesis" / "benchmark4"
    for name in THESIS_PLANNERS:
        path = folder / f"{name}.csv"
        if path.exists():
            with open(path) as f:
                out[name] = np.array([float(row["time"]) for row in csv.DictReader(f)])
    return out


def write_results(folder: Path, rows: list[RequestRow], meta: dict, peer: dict | None = None) -> dict:
    summary = {name: summarize([r for r in rows if r.planner == name])
               for name in dict.fromkeys(r.planner for r in rows)}
    with open(folder / "requests.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(asdict(rows[0]).keys()))
        writer.writeheader()
        for r in rows:
            writer.writerow(asdict(r))
    data = {"meta": meta, "summary": summary, "requests": [asdict(r) for r in rows]}
    if peer is not None:
        data["peer"] = peer
    (folder / "bench_planners.json").write_text(json.dumps(data, indent=2, default=float) + "\n")
    _box_plot(folder / "plan_times.png", rows, thesis_times(), peer)
    return summary


def _box_plot(path: Path, rows: list[RequestRow], thesis: dict[str, np.ndarray], peer: dict | None) -> None:
    labels: list[str] = []
    data: list[list[float] | np.ndarray] = []
    colors: list[str] = []
    for name in dict.fromkeys(r.planner for r in rows):
        t = [r.plan_time for r in rows if r.planner == name and r.solved]
        if t:
            labels.append(f"{name}\n(recon)")
            data.append(t)
            colors.append("#2b7bba")
    if peer and peer.get("times"):
        labels.append("RRTConnect\n(mplib)")
        data.append(peer["times"])
        colors.append("#3a9e4f")
    for name, times in thesis.items():
        labels.append(f"{name}\n(thesis, MoveIt)")
        data.append(times)
        colors.append("#c0504d")
    plan_time_boxes(path, labels, data, colors, "plan time (search + simplification) [s]",
                    "Table 4.1 problem: plan time per request (cf. thesis Figure 4.2)", width=(6.0, 1.1), fontsize=7)


def plan_time_boxes(path: Path, labels: list[str], data: list, colors: list[str], ylabel: str, title: str,
                    width: tuple[float, float], fontsize: int) -> None:
    """Box plots of plan times on a log axis, one box per planner (``width``: the figure's
    least width and its width per box [in])."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(max(width[0], width[1] * len(labels)), 4.5))
    box = ax.boxplot(data, patch_artist=True, showfliers=True)
    for patch, c in zip(box["boxes"], colors, strict=True):
        patch.set_facecolor(c)
        patch.set_alpha(0.6)
    ax.set_xticks(range(1, len(labels) + 1), labels, fontsize=fontsize)
    ax.set_yscale("log")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(True, which="both", axis="y", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)
