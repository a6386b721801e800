"""Per-iteration picture of the view planner, like thesis Figures 4.10 and 5.5-5.7: the
partial cloud, its bounding box, the ellipsoid and the views (infeasible red, completed
green, planned blue, active yellow)."""

from __future__ import annotations

import multiprocessing
import signal
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from pathlib import Path

import numpy as np

COLORS = {"infeasible": "#d62728", "completed": "#2ca02c", "planned": "#1f77b4", "active": "#ffbf00"}


#: points of the partial object drawn at most (a seeded subset)
DRAWN_POINTS = 4000


@dataclass(frozen=True)
class DrawnView:
    """A view as the picture draws it."""

    world_T_camera: np.ndarray
    status: str  # infeasible, completed


def drawn_points(points: np.ndarray, seed: int) -> np.ndarray:
    """The points a picture draws: all, or a subset of DRAWN_POINTS seeded by ``seed``."""
    pts = np.asarray(points)
    if len(pts) > DRAWN_POINTS:
        pts = pts[np.random.default_rng(seed).choice(len(pts), DRAWN_POINTS, replace=False)]
    return pts


class PictureWorker:
    """Draws the iteration pictures in one worker process, so that drawing never holds up
    the scanning: :meth:`draw` hands a picture over and returns its path at once,
    :meth:`close` waits for every picture (and raises the first drawing error)."""

    def __init__(self) -> None:
        self._pool: ProcessPoolExecutor | None = None
        self._pending: list[tuple[Future, tuple]] = []

    def draw(self, path: Path, iteration: int, points: np.ndarray, ellipsoid, views, planned: list[np.ndarray],
             active: np.ndarray, seed: int) -> Path:
        drawn = [DrawnView(np.asarray(v.world_T_camera, float), str(getattr(v.status, "value", v.status)))
                 for v in views]
        args = (path, iteration, drawn_points(points, seed), ellipsoid, drawn, [np.asarray(T, float) for T in planned],
                np.asarray(active, float), seed)
        if self._pool is None:  # a fresh interpreter: nothing of this process (threads, GL contexts) is copied
            self._pool = ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn"),
                                             initializer=_leave_interrupts_to_the_run)
        try:
            self._pending.append((self._pool.submit(iteration_png, *args), args))
        except (BrokenProcessPool, RuntimeError):  # the worker could not start or has died: draw here
            iteration_png(*args)
        return path

    def close(self) -> None:
        """Wait for the pictures handed over (drawn here instead when the worker could not
        start or has died); the worker ends."""
        pending, self._pending = self._pending, []
        try:
            for future, args in pending:
                try:
                    future.result()
                except (BrokenProcessPool, OSError):
                    iteration_png(*args)
        finally:
            if self._pool is not None:
                self._pool.shutdown(wait=True, cancel_futures=True)
                self._pool = None


def _leave_interrupts_to_the_run() -> None:
    """In the worker: Ctrl-C reaches the whole process group; the run decides what ends."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def iteration_png(path: Path, iteration: int, points: np.ndarray, ellipsoid, views, planned: list[np.ndarray],
                  active: np.ndarray, seed: int) -> None:
    """``seed``: of the subset of a large partial object that is drawn (the run's seed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path.parent.mkdir(parents=True, exist_ok=True)
    fig = plt.figure(figsize=(6.5, 6))
    ax = fig.add_subplot(projection="3d")
    pts = drawn_points(points, seed)
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
