"""Per-iteration picture of the view planner, like thesis Figures 4.10 and 5.5-5.7: the
partial cloud, its bounding box, the ellipsoid and the views (infeasible red, completed
green, planned blue, active yellow)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

COLORS = {"infeasible": "#d62728", "completed": "#2ca02c", "planned": "#1f77b4", "active": "#ffbf00"}


def iteration_png(path: Path, iteration: int, points: np.ndarray, ellipsoid, views, planned: list[np.ndarray],
                  active: np.ndarray, seed: int) -> None:
    """``seed``: of the subset of a large partial object that is drawn (the run's seed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path.parent.mkdir(parents=True, exist_ok=True)
    fig = plt.figure(figsize=(6.5, 6))
    ax = fig.add_subplot(projection="3d")
    pts = np.asarray(points)
    if len(pts) > 4000:
        pts = pts[np.random.default_rng(seed).choice(len(pts), 4000, replace=False)]
    ax.scatter(pts[:, 0], pts[:, 1], pts[:, 2], s=0.5, c="0.35", alpha=0.6)
    # ellipsoid wireframe and its box (the box = ellipsoid axes / sqrt(3) * 2 / 2)
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, 30), np.linspace(0, np.pi, 15))
    local = np.stack([np.cos(u) * np.sin(v), np.sin(u) * np.sin(v), np.cos(v)], -1) * ellipsoid.axes
    w = ellipsoid.to_world(local.reshape(-1, 3)).reshape(local.shape)
    ax.plot_wireframe(w[..., 0], w[..., 1], w[..., 2], color="0.6", linewidth=0.3)
    half = ellipsoid.axes / np.sqrt(3.0)
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * half
    cw = ellipsoid.to_world(corners)
    for i in range(8):
        for j in range(i + 1, 8):
            if np.sum(np.abs(corners[i] - corners[j]) > 1e-12) == 1:
                ax.plot(*cw[[i, j]].T, color="k", linewidth=0.8)

    def draw(T, status, size=18):
        p, z = T[:3, 3], T[:3, 2]
        ax.scatter(*p, color=COLORS[status], s=size, depthshade=False)
        ax.plot(*np.stack([p, p + 0.08 * z]).T, color=COLORS[status], linewidth=1.0)

    for view in views:
        if view.status in ("infeasible", "completed"):
            draw(view.world_T_camera, view.status)
    for T in planned:
        draw(T, "planned")
    draw(active, "active", size=60)
    allp = np.vstack([pts, [v.world_T_camera[:3, 3] for v in views], [active[:3, 3]]])
    mid, span = allp.mean(0), (allp.max(0) - allp.min(0)).max() / 2 + 0.02
    ax.set_xlim(mid[0] - span, mid[0] + span)
    ax.set_ylim(mid[1] - span, mid[1] + span)
    ax.set_zlim(mid[2] - span, mid[2] + span)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_zlabel("z [m]")
    counts = {s: sum(v.status == s for v in views) for s in ("completed", "infeasible")}
    ax.set_title(f"iteration {iteration}: {counts['completed']} completed, {len(planned) + 1} planned, "
                 f"{counts['infeasible']} infeasible", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
