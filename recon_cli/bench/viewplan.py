"""View-planning benchmark (``recon bench viewplan``, thesis 4.4 and 5.3): the ellipsoid
planner against N views evenly spread on a sphere and N random feasible views, for every
built-in object, same N, same d_c, same initial view; plus the wood block seen face-on."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from recon_cli.config import DEFAULTS, SceneConfig, SensorConfig
from recon_cli.errors import ReconError
from recon_cli.geometry.view import View
from recon_cli.objects import load_object
from recon_cli.realism import IDEAL, RealismProfile
from recon_cli.robot.description import CellConfig
from recon_cli.viewplan.policy import Method
from recon_cli.workflows.autoscan import METHODS, Autoscan, AutoscanOptions

BUILT_IN = ("wood_block", "toy_blocks", "bottle", "mug")


@dataclass(frozen=True)
class ViewplanRow:
    object_name: str
    method: str
    initial: str
    scans: int
    coverage: float
    mean_mm: float
    std_mm: float
    infeasible: int
    requests: int
    trajectory_s: float
    seconds: float
    error: str = ""


def face_on_view(name: str, d_c: float, position: tuple[float, float, float] | None = None) -> View:
    """The initial view straight at the largest vertical face (thesis 5.3.3), as low as the
    cell allows: 80 deg from the vertical (at 90 deg the camera bracket meets the table);
    ``position``: where the cell's objects stand (None: the thesis cell's board centre)."""
    obj = load_object(name, position=position)
    center, size = obj.crop_box(0.01)
    phi = 90.0 if size[0] >= size[1] else 0.0  # look along the shorter horizontal axis
    return View.from_degrees(center, d_c + 0.1, 80.0, phi)


def run_viewplan_bench(out: Path, objects=BUILT_IN, methods=METHODS, n: int = 16, d_c: float = 0.55,
                       seed: int = DEFAULTS.seed, resolution: float = DEFAULTS.sensor.resolution,
                       cell: CellConfig | None = None,
                       progress: Callable[[str, int, int], None] | None = None,
                       realism: RealismProfile = IDEAL) -> list[ViewplanRow]:
    rows = []
    runs = [(o, m, "default") for o in objects for m in methods]
    if "wood_block" in objects and "ellipsoid" in methods:
        runs.append(("wood_block", "ellipsoid", "face-on"))
    for k, (name, method, initial) in enumerate(runs):
        folder = out / (f"{name}_{method}" + ("_face_on" if initial == "face-on" else ""))
        config = DEFAULTS.replace(cell=cell or DEFAULTS.cell, scene=SceneConfig(name), seed=seed,
                                  sensor=SensorConfig(DEFAULTS.sensor.noise, resolution),
                                  viewplan=replace(DEFAULTS.viewplan, n=n, d_c=d_c), realism=realism)
        face_on = face_on_view(name, d_c, config.cell.cell_file.object_position) if initial == "face-on" else None
        opts = AutoscanOptions(folder, config, face_on,
                               Method(method), pictures=method == "ellipsoid", run={"command": "bench viewplan"},
                               page=False)
        try:
            r = Autoscan(opts).run()
        except ReconError as exc:  # reported as a failed run, the others go on
            rows.append(ViewplanRow(name, method, initial, 0, 0.0, float("nan"), float("nan"), 0, 0, 0.0, 0.0,
                                    exc.one_line()))
            continue
        rows.append(ViewplanRow(name, method, initial, r.scans, r.coverage or 0.0,
                                r.accuracy.mean_mm if r.accuracy else float("nan"),
                                r.accuracy.std_mm if r.accuracy else float("nan"), r.infeasible, r.requests,
                                r.trajectory_s, r.seconds))
        if progress:
            progress("autoscans", k + 1, len(runs))
    return rows


def coverage_png(path: Path, rows: list[ViewplanRow]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    objects = list(dict.fromkeys(r.object_name for r in rows if r.initial == "default"))
    methods = list(dict.fromkeys(r.method for r in rows))
    fig, ax = plt.subplots(figsize=(7, 3.8))
    width = 0.8 / len(methods)
    for k, m in enumerate(methods):
        vals = [next((r.coverage for r in rows if r.object_name == o and r.method == m and r.initial == "default"),
                     np.nan) * 100 for o in objects]
        ax.bar(np.arange(len(objects)) + (k - (len(methods) - 1) / 2) * width, vals, width, label=m)
    ax.axhline(95, color="k", linewidth=0.8, linestyle="--")
    ax.set_xticks(range(len(objects)), objects)
    ax.set_ylabel("coverage of the ground truth [%] (1 mm)")
    ax.set_ylim(50, 100.5)
    ax.legend(fontsize=8)
    ax.set_title("N = 16 scans, d_c = 0.55 m")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
