"""``recon bench planners --cell NAME``: recon's planners and the peers on a cell's scan moves.

One run asks every planner the same requests (:mod:`.scan_moves`): recon's OMPL planners
here, mplib (:mod:`.mplib_peer`) and VAMP (:mod:`.vamp_peer`) in their own environments.
Written to the output folder: ``bench_planners.json`` (summaries, every request, the
problem), ``requests.csv``, ``profile.txt`` (where recon's planning time goes, cProfile's
cumulative view), ``plan_times.png`` (plan time per request, each planner). Medians are over
the solved requests; the ratios compare the medians of the same requests in the same run.
"""

from __future__ import annotations

import csv
import json
from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path

import numpy as np

from recon_cli.bench.mplib_peer import run_mplib
from recon_cli.bench.planners import RequestRow, plan_time_boxes, summarize
from recon_cli.bench.scan_moves import ScanMoves, run_scan_moves
from recon_cli.bench.vamp_peer import run_vamp, vamp_valid
from recon_cli.planning.planner import PlanOptions
from recon_cli.robot.cell import Cell
from recon_cli.robot.description import CellConfig

PEERS = ("mplib", "vamp")


def run_cell_planners(folder: Path, config: CellConfig, planners: list[str], n: int, time_limit: float,
                      seed: int, peers: tuple[str, ...], options: PlanOptions,
                      progress: Callable[[str, int, int], None] | None = None,
                      status: Callable[[str], None] | None = None, distance: float | None = None) -> dict:
    # with VAMP, the goals are those its own Panda model takes as valid too (its hand and
    # fingers reach past the flange where the cell's camera sits): the same requests for all
    accept = vamp_valid if "vamp" in peers else None
    problem, rows, profile = run_scan_moves(config, planners, n, time_limit, seed, progress, options, accept,
                                            distance)
    (folder / "profile.txt").write_text(profile)
    peer_results = []
    cell = Cell(config, object_box=problem.object_box)
    for name in peers:
        if status:
            status(f"{name} on the same requests ...")
        if name == "mplib":
            peer_results.append(run_mplib(folder, n, time_limit, ranges=(0.1, 1.5), cell=cell,
                                          pairs=list(problem.pairs)))
        elif name == "vamp":
            peer_results.append(run_vamp(folder, cell, problem))
    summary = {name: summarize([r for r in rows if r.planner == name])
               for name in dict.fromkeys(r.planner for r in rows)}
    meta = {"cell": problem.cell, "requests": n, "time_limit": time_limit, "seed": seed, "planners": planners,
            "problem": "scan moves", "camera_distance": problem.distance,
            "object_box": {"center": list(problem.object_box.center), "size": list(problem.object_box.size)},
            "plan_time": "search + simplification, one core"}
    ratios = _ratios(rows, peer_results)
    data = {"meta": meta, "summary": summary, "peers": [{k: v for k, v in p.items() if k != "times"}
                                                         for p in peer_results],
            "ratios": ratios, "pairs": [[a.tolist(), b.tolist()] for a, b in problem.pairs],
            "requests": [asdict(r) for r in rows]}
    (folder / "bench_planners.json").write_text(json.dumps(data, indent=2, default=float) + "\n")
    with open(folder / "requests.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(asdict(rows[0]).keys()))
        writer.writeheader()
        for r in rows:
            writer.writerow(asdict(r))
    _plot(folder / "plan_times.png", problem, rows, peer_results)
    return {"meta": meta, "summary": summary, "peers": peer_results, "ratios": ratios,
            "profile": _profile_head(profile)}


def _ratios(rows: list[RequestRow], peers: list[dict]) -> dict:
    """recon's RRTConnect over each peer: medians over the requests both solved."""
    ours = {r.request: r.plan_time for r in rows if r.planner == "RRTConnect" and r.solved}
    out = {}
    for peer in peers:
        common = [i for i, t in enumerate(peer["per_request"]) if t is not None and i in ours]
        if not common:
            continue
        a = float(np.median([ours[i] for i in common]))
        b = float(np.median([peer["per_request"][i] for i in common]))
        out[peer["name"]] = {"requests": len(common), "recon_median": a, "peer_median": b, "ratio": a / b}
    return out


def _profile_head(profile: str, lines: int = 12) -> list[str]:
    """The first rows of cProfile's table (after its header)."""
    rows = profile.splitlines()
    start = next((i for i, line in enumerate(rows) if line.strip().startswith("ncalls")), 0)
    return [line for line in rows[start:start + 1 + lines] if line.strip()]


def _plot(path: Path, problem: ScanMoves, rows: list[RequestRow], peers: list[dict]) -> None:
    labels, data, colors = [], [], []
    for name in dict.fromkeys(r.planner for r in rows):
        t = [r.plan_time * 1e3 for r in rows if r.planner == name and r.solved]
        if t:
            labels.append(f"{name}\n(recon)")
            data.append(t)
            colors.append("#2b7bba")
    for peer in peers:
        if peer["times"]:
            labels.append(f"RRTConnect\n({peer['name']})")
            data.append([t * 1e3 for t in peer["times"]])
            colors.append("#3a9e4f" if peer["name"] == "mplib" else "#8e44ad")
    plan_time_boxes(path, labels, data, colors, "plan time (search + simplification) [ms]",
                    f"{problem.cell} cell: {len(problem.pairs)} scan moves at {problem.distance:g} m camera distance",
                    width=(5.0, 1.3), fontsize=8)
