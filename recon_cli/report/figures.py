"""The page's own pictures: charts drawn with matplotlib where a run has the numbers but no
figure (plan times, coverage and accuracy, ICP residuals, the two sides of an object as
registered onto each other), and thumbnails of the scans' colour images. Each function writes
one file and returns its path."""

from __future__ import annotations

import contextlib
from pathlib import Path

import numpy as np

from recon_cli.errors import ReconError
from recon_cli.inputs.images import read_color, read_depth
from recon_cli.inputs.jsonschemas import check_pose
from recon_cli.reconstruction.assessment import registered_sides
from recon_cli.report.model import Edge, Evaluation, Move, Scan, TwoSides

_BLUE, _ORANGE, _GREEN, _GREY = "#1f77b4", "#ff7f0e", "#2ca02c", "#7f7f7f"


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    _pyplot().close(fig)
    return path


def _short(label: str, limit: int = 28) -> str:
    return label if len(label) <= limit else label[: limit - 1] + "…"


def _band_mm(label: str) -> float:
    """"±0.5 mm" -> 0.5 (unknown labels last)."""
    try:
        return float(label.replace("±", "").replace("mm", "").strip())
    except ValueError:
        return float("inf")


def plan_times_png(path: Path, moves: tuple[Move, ...]) -> Path:
    """Planning time and trajectory duration [s] of every move, in the order of the run
    (two panels: planning takes a fraction of the time the robot moves)."""
    plt = _pyplot()
    x = np.arange(len(moves))
    plan = np.array([m.plan_s if m.plan_s is not None else np.nan for m in moves])
    traj = np.array([m.trajectory_s if m.trajectory_s is not None else np.nan for m in moves])
    fig, axes = plt.subplots(2, 1, figsize=(max(5.0, 0.35 * len(moves) + 2.5), 4.6), sharex=True)
    axes[0].bar(x, plan, color=_BLUE)
    axes[0].set_ylabel("planning [s]")
    axes[1].bar(x, traj, color=_ORANGE)
    axes[1].set_ylabel("trajectory [s]")
    axes[1].set_xticks(x, [_short(f"{k + 1}: {m.label}") for k, m in enumerate(moves)], rotation=60, ha="right",
                       fontsize=7)
    axes[0].set_title(f"{len(moves)} move{'s' if len(moves) != 1 else ''}: planning {np.nansum(plan):.2f} s, "
                      f"trajectories {np.nansum(traj):.1f} s", fontsize=10)
    return _save(fig, path)


def coverage_png(path: Path, evaluations: tuple[Evaluation, ...]) -> Path:
    """Per evaluation: the share of points within each distance band, and the coverage of the
    reference surface (and of its visible part)."""
    plt = _pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(9.0, 3.4))
    bands = sorted({k for e in evaluations for k in e.within}, key=_band_mm)
    width = 0.8 / max(1, len(evaluations))
    for k, e in enumerate(evaluations):
        offset = (k - (len(evaluations) - 1) / 2) * width
        axes[0].bar(np.arange(len(bands)) + offset, [100 * e.within.get(b, np.nan) for b in bands], width,
                    label=e.name)
        labels, values = ["surface"], [100 * (e.coverage or 0.0)]
        if e.coverage_visible is not None:
            labels.append("visible surface")
            values.append(100 * e.coverage_visible)
        axes[1].bar(np.arange(len(values)) + offset, values, width, label=e.name)
        axes[1].set_xticks(np.arange(len(labels)), labels)
    axes[0].set_xticks(np.arange(len(bands)), bands)
    axes[0].set_ylabel("points within [%]")
    axes[0].set_title("accuracy: |signed distance| within", fontsize=10)
    tol = evaluations[0].tolerance_mm
    axes[1].set_ylabel("covered [%]")
    axes[1].set_title("coverage" + (f" (tolerance {tol:g} mm)" if tol is not None else ""), fontsize=10)
    for ax in axes:
        ax.set_ylim(0, 100)
        ax.legend(fontsize=8)
    return _save(fig, path)


def icp_png(path: Path, edges: tuple[Edge, ...], max_bars: int = 30) -> Path:
    """Fitness and inlier RMSE [mm] of every pairwise ICP result of the pose graph: a bar
    per edge, or for larger graphs a scan-by-scan matrix of each."""
    plt = _pyplot()
    if len(edges) > max_bars:
        return _icp_matrix(plt, path, edges)
    fig, axes = plt.subplots(2, 1, figsize=(max(5.0, 0.3 * len(edges) + 2.5), 4.6), sharex=True)
    x = np.arange(len(edges))
    colors = [_GREY if e.rejected else _BLUE if e.kind == "odometry" else _GREEN for e in edges]
    axes[0].bar(x, [e.fitness if e.fitness is not None else np.nan for e in edges], color=colors)
    axes[0].set_ylabel("fitness")
    axes[0].set_ylim(0, 1)
    axes[1].bar(x, [e.rmse_mm if e.rmse_mm is not None else np.nan for e in edges], color=colors)
    axes[1].set_ylabel("inlier RMSE [mm]")
    labels = [f"{e.source.removeprefix('scan_')}-{e.target.removeprefix('scan_')}" for e in edges]
    axes[1].set_xticks(x, labels, rotation=90, fontsize=7)
    axes[1].set_xlabel("edge (scan - scan)")
    from matplotlib.patches import Patch

    axes[0].legend(handles=[Patch(color=_BLUE, label="odometry"), Patch(color=_GREEN, label="loop closure"),
                            Patch(color=_GREY, label="rejected")], fontsize=7, loc="lower right")
    axes[0].set_title(f"pose graph: {len(edges)} pairwise ICP result{'s' if len(edges) != 1 else ''}",
                      fontsize=10)
    return _save(fig, path)


def _icp_matrix(plt, path: Path, edges: tuple[Edge, ...]) -> Path:
    names = sorted({e.source for e in edges} | {e.target for e in edges})
    at = {n: k for k, n in enumerate(names)}
    fitness = np.full((len(names), len(names)), np.nan)
    rmse = np.full_like(fitness, np.nan)
    for e in edges:
        for i, j in ((at[e.source], at[e.target]), (at[e.target], at[e.source])):
            fitness[i, j] = np.nan if e.fitness is None else e.fitness
            rmse[i, j] = np.nan if e.rmse_mm is None else e.rmse_mm
    fig, axes = plt.subplots(1, 2, figsize=(10.0, 4.6))
    ticks = [n.removeprefix("scan_") for n in names]
    for ax, values, label, cmap in ((axes[0], fitness, "fitness", "viridis"),
                                    (axes[1], rmse, "inlier RMSE [mm]", "magma_r")):
        im = ax.imshow(values, cmap=cmap, interpolation="nearest")
        fig.colorbar(im, ax=ax, label=label, fraction=0.046, pad=0.04)
        step = max(1, len(names) // 12)
        ax.set_xticks(range(0, len(names), step), ticks[::step], rotation=90, fontsize=7)
        ax.set_yticks(range(0, len(names), step), ticks[::step], fontsize=7)
        ax.set_xlabel("scan")
        ax.set_title(label, fontsize=10)
        for e in edges:
            if e.rejected:
                ax.plot([at[e.source], at[e.target]], [at[e.target], at[e.source]], "x", color="red", ms=4)
    n_odo = sum(e.kind == "odometry" for e in edges)
    fig.suptitle(f"pose graph: {len(edges)} pairwise ICP results ({n_odo} odometry, {len(edges) - n_odo} loop "
                 f"closures; rejected: red x)", fontsize=10)
    return _save(fig, path)


def thumbnail(path: Path, scan: Scan, width: int) -> Path | None:
    """A JPEG of the scan's colour image (else its depth image, grey) ``width`` pixels wide;
    None when neither can be read."""
    import cv2


    image = depth = None
    if scan.color is not None:
        with contextlib.suppress(ReconError):
            image = read_color(scan.color)
    if image is None and scan.depth is not None:
        with contextlib.suppress(ReconError):
            depth = read_depth(scan.depth)
        if depth is not None:
            valid = depth > 0
            image = np.zeros(depth.shape, np.uint8)
            if valid.any():
                lo, hi = np.percentile(depth[valid], (1, 99))
                scaled = 255 - 205 * np.clip((depth.astype(float) - lo) / max(hi - lo, 1.0), 0, 1)
                image[valid] = scaled[valid].astype(np.uint8)
    if image is None:
        return None
    height = max(1, round(image.shape[0] * width / image.shape[1]))
    small = cv2.resize(image, (width, height), interpolation=cv2.INTER_AREA)
    path.parent.mkdir(parents=True, exist_ok=True)
    return path if cv2.imwrite(str(path), small, [cv2.IMWRITE_JPEG_QUALITY, 85]) else None


def sides_png(path: Path, sides: TwoSides, points_per_side: int = 12_000, seed: int = 0) -> Path | None:
    """Both sides' clouds as registered onto each other (side 1 blue, side 2 orange, side 2
    placed by the registration of the sides), seen from the front, the side and above, with
    the registration's confidence; None when a side's cloud or the pose cannot be read."""
    reg = sides.report.registration
    clouds = [side.cloud for side in sides.sides if side.cloud is not None]
    if len(clouds) != 2:
        return None
    try:
        check_pose(reg.get("side1_T_side2"), sides.sides[0].folder.parent / "sides_report.json", "sides report",
                   "registration.side1_T_side2")
        points = list(registered_sides((clouds[0], clouds[1]), np.asarray(reg["side1_T_side2"], dtype=float))
                      .values())
    except ReconError:
        return None
    rng = np.random.default_rng(seed)
    points = [p[rng.choice(len(p), points_per_side, replace=False)] if len(p) > points_per_side else p
              for p in points]
    plt = _pyplot()
    fig = plt.figure(figsize=(12, 4.4))
    everything = np.vstack(points)
    centre, half = (everything.min(axis=0) + everything.max(axis=0)) / 2.0, np.ptp(everything, axis=0).max() / 2.0
    colours = np.array([_BLUE] * len(points[0]) + [_ORANGE] * len(points[1]))
    order = rng.permutation(len(everything))
    for k, (name, elevation, azimuth) in enumerate((("front", 10, -90), ("side", 10, 0), ("above", 80, -90))):
        ax = fig.add_subplot(1, 3, k + 1, projection="3d")
        # one scatter in a shuffled order: neither side is drawn over the other as a whole
        ax.scatter(everything[order, 0], everything[order, 1], everything[order, 2], s=0.3, c=colours[order],
                   depthshade=False)
        for side, colour in zip(sides.sides, (_BLUE, _ORANGE), strict=True):
            ax.scatter([], [], [], s=0.3, c=colour, label=side.label)
        ax.set_xlim(centre[0] - half, centre[0] + half)
        ax.set_ylim(centre[1] - half, centre[1] + half)
        ax.set_zlim(centre[2] - half, centre[2] + half)
        ax.set_box_aspect((1, 1, 1))
        ax.view_init(elev=elevation, azim=azimuth)
        ax.set_axis_off()
        ax.set_title(name, fontsize=9)
        if k == 0:
            ax.legend(loc="upper left", markerscale=20, fontsize=8)
    fitness, reverse, rmse = (reg.get(key) for key in ("fitness", "fitness_reverse", "rmse_m"))
    confidence = ("not trusted: " + str(reg["reason"]) if reg.get("reason") else
                  "ambiguous in pose, not in shape" if reg.get("ambiguous") else "unique")
    numbers = ""
    if isinstance(fitness, (int, float)) and isinstance(reverse, (int, float)) and isinstance(rmse, (int, float)):
        numbers = f"fitness {fitness:.3f} / {reverse:.3f}, RMSE {rmse * 1e3:.3f} mm; "
    fig.suptitle(_short(f"the two sides registered by shape: {numbers}{confidence}", 150), fontsize=10)
    return _save(fig, path)
