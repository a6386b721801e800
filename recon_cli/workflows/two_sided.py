"""``recon autoscan --sides 2``: scan an object, turn it over, scan it again, merge both sides.

With the object resting on the table the camera never sees its resting face. Two sides
make the model complete:

1. side 1: the autoscan of ``recon autoscan`` (``side_1/``: its scans, registration, report);
2. the object is turned over: in simulation by physics (MuJoCo lays it on another face and
   lets it settle, recon_cli/backends/sim/turnover.py); on a real cell the robot waits at
   its home posture while the operator turns it over and puts it back on the spot (Enter
   to go on; the pause is recorded);
3. side 2: the same autoscan of the turned object (``side_2/``);
4. the sides registered by shape alone (the board no longer relates them,
   recon_cli/reconstruction/sides.py), with its confidence; a pose the shape cannot fix is
   said, not merged;
5. one merged cloud and Poisson mesh (``reconstruction/``), with the scans' colours; in
   simulation the coverage of the whole surface (the resting faces included), each side's
   share, the accuracy, and the side-to-side registration against the truth
   (``sides_report.json``).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from recon_cli.backends.sim.turnover import turn_over, turned
from recon_cli.backends.station_file import load_station
from recon_cli.console import console
from recon_cli.errors import ReconError
from recon_cli.geometry.transforms import invert
from recon_cli.inputs.meshes import read_cloud
from recon_cli.objects import SceneObject, load_object
from recon_cli.reconstruction.evaluation import signed_distances, within_shares
from recon_cli.reconstruction.options import COVERAGE_TOLERANCE
from recon_cli.reconstruction.sides import SideRegistration, register_sides
from recon_cli.reconstruction.surface import poisson_mesh, write_cloud, write_mesh
from recon_cli.runs import sides as sides_file
from recon_cli.session import resolve_object_name
from recon_cli.viewplan.policy import Status
from recon_cli.workflows.autoscan import Autoscan, AutoscanOptions, AutoscanResult, SidePrior

#: [m] the side registration's voxel
SIDES_VOXEL = 0.003


@dataclass
class TwoSidedResult:
    folder: Path
    sides: tuple[AutoscanResult, ...]
    registration: SideRegistration | None
    cloud: Path | None
    mesh: Path | None
    report: Path
    seconds: float
    coverage: float | None  # of the whole surface (simulation)
    error: ReconError | None = None
    interrupted: bool = False  # Ctrl-C in a side or at the turn: what was scanned is kept


def _coverages(obj: SceneObject, clouds: dict[str, np.ndarray], rng: np.random.Generator,
               samples: int = 100_000) -> dict[str, float]:
    """Share of the object's whole surface (the resting faces included) with a point of each
    cloud within the coverage tolerance (one sample of the surface for all)."""
    import open3d as o3d

    truth = obj.surface_points(samples, rng, exclude_base=-np.inf)
    ref = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(truth))
    out = {}
    for name, points in clouds.items():
        rec = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(points, float)))
        out[name] = float(np.mean(np.asarray(ref.compute_point_cloud_distance(rec)) <= COVERAGE_TOLERANCE))
    return out


def _angle_deg(R: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0))))


class TwoSided:
    """Both sides of an object (see the module docstring)."""

    def __init__(self, opt: AutoscanOptions, progress: Callable[[str, int, int], None] | None = None,
                 ask: Callable[[str], None] | None = None) -> None:
        self.opt = opt
        self.progress = progress or (lambda *a: None)
        self.ask = ask  # the operator prompt of a real cell (None: input())
        self.rng = np.random.default_rng(opt.config.seed + 7919)

    def _object(self) -> SceneObject:
        cfg = self.opt.config
        if self.opt.scene_object is not None:
            return self.opt.scene_object
        return load_object(resolve_object_name(cfg.scene.object_name), cfg.scene.object_scale,
                           cfg.cell.cell_file.object_position)

    def _simulated(self) -> bool:
        return self.opt.station is None or load_station(self.opt.station).capabilities.simulated

    def _turn(self, first: SceneObject, side1: AutoscanResult) -> tuple[SceneObject | None, dict]:
        """The object turned over: by physics in simulation, by the operator on a real cell."""
        if self._simulated():
            t = turn_over(first, self.rng)
            return turned(first, t), {"by": "physics", "tilt_deg": t.tilt_deg, "settle_s": t.settle_s,
                                      "down_object": [float(v) for v in t.down_object]}
        t0 = time.monotonic()
        prompt = ("turn the object over onto another face and put it back on the same spot, then press Enter "
                  "(Ctrl-C stops; the first side's scans are kept)")
        if self.ask is not None:
            self.ask(prompt)
        else:
            console.print(prompt)
            input()
        return None, {"by": "operator", "pause_s": time.monotonic() - t0}

    def run(self) -> TwoSidedResult:
        opt = self.opt
        t0 = time.perf_counter()
        first = self._object()
        # each side a complete autoscan folder with its registered cloud; the mesh and the page
        # are the merged model's
        side_opt = replace(opt, scene_object=first, mesh=False, page=False)
        # on a real cell the robot waits at its home posture while the operator turns the object
        side1 = Autoscan(replace(side_opt, out=opt.out / "side_1", park=not self._simulated()), self.progress).run()
        if side1.interrupted:
            return self._stopped((side1,), t0)
        try:
            second, turn = self._turn(first, side1)
        except KeyboardInterrupt:
            return self._stopped((side1,), t0)
        box = None
        if second is None and side1.cloud is not None:  # a real cell: the box of what side 1 saw, any way up
            pts = np.asarray(read_cloud(side1.cloud, "side 1 cloud", points=False).points)
            lo, hi = pts.min(axis=0), pts.max(axis=0)
            d = float(np.linalg.norm(hi - lo)) + 2 * opt.config.scene.box_margin
            c = (lo + hi) / 2.0
            box = ((float(c[0]), float(c[1]), float(lo[2] + d / 2.0)), (d, d, d))
        side2 = Autoscan(replace(side_opt, out=opt.out / "side_2", scene_object=second, box=box,
                                 prior=self._prior(side1)), self.progress).run()
        if side2.interrupted:
            return self._stopped((side1, side2), t0)
        return self._merge(first, second, (side1, side2), turn, t0)

    @staticmethod
    def _prior(side1: AutoscanResult) -> SidePrior | None:
        """What side 1 saw, for side 2's view planning (None without a registered cloud)."""
        if side1.cloud is None:
            return None
        cloud = read_cloud(side1.cloud, "side 1 cloud", points=False).voxel_down_sample(SIDES_VOXEL / 2)
        cameras = np.array([v.world_T_camera[:3, 3] for v in side1.views if v.status is Status.COMPLETED])
        return SidePrior(np.asarray(cloud.points), cameras.reshape(-1, 3), SIDES_VOXEL)

    def _stopped(self, sides: tuple[AutoscanResult, ...], t0: float) -> TwoSidedResult:
        """Interrupted: the sides scanned so far stay (each a complete autoscan folder)."""
        return TwoSidedResult(self.opt.out, sides, None, None, None, self.opt.out, time.perf_counter() - t0, None,
                              interrupted=True)

    def _merge(self, first: SceneObject, second: SceneObject | None, sides: tuple[AutoscanResult, ...], turn: dict,
               t0: float) -> TwoSidedResult:
        opt, cfg = self.opt, self.opt.config
        import open3d as o3d

        paths = [s.cloud for s in sides if s.cloud is not None]
        if len(paths) != len(sides):
            raise ReconError("a side has no registered cloud: the sides cannot be merged",
                             hint="see side_1/autoscan_report.json and side_2/autoscan_report.json")
        clouds = [read_cloud(p, f"side {i + 1} cloud", points=False) for i, p in enumerate(paths)]
        reg = register_sides(clouds[0], clouds[1], SIDES_VOXEL, seed=cfg.seed)
        truth = None
        if second is not None:  # side-2 world points onto side 1: W1 inv(W2)
            true_T = first.world_T_object @ invert(second.world_T_object)
            dT = reg.side1_T_side2 @ invert(true_T)
            centre = first.world_vertices().mean(axis=0)
            truth = {"rotation_deg": _angle_deg(dT[:3, :3]),
                     "translation_mm": float(np.linalg.norm(dT[:3, :3] @ centre + dT[:3, 3] - centre) * 1e3)}
        out = opt.out / "reconstruction"
        cloud = mesh = None
        coverage = accuracy = None
        contributions: dict[str, float] = {}
        error = None
        if reg.reason is not None:
            error = ReconError(f"the two sides cannot be registered by their shape: {reg.reason}; nothing was merged",
                               hint="each side's model is in side_1/ and side_2/; turn the object onto a face that "
                                    "shows more of the first side's shape and scan the second side again")
        else:
            second_cloud = o3d.geometry.PointCloud(clouds[1])
            second_cloud.transform(reg.side1_T_side2)
            merged = clouds[0] + second_cloud
            merged = merged.voxel_down_sample(cfg.registration.surface.voxel)
            cloud = write_cloud(out / "cloud.ply", merged)
            if opt.mesh:
                m, _ = poisson_mesh(merged, cfg.registration.surface)
                mesh = write_mesh(out / "mesh.ply", m)
            if second is not None:
                pts = np.asarray(merged.points)
                shares = _coverages(first, {"merged": pts, "side_1": np.asarray(clouds[0].points),
                                            "side_2": np.asarray(second_cloud.points)},
                                    np.random.default_rng(cfg.seed))
                coverage = shares.pop("merged")
                contributions = shares
                d = signed_distances(pts, first.mesh_world())
                accuracy = {"mean_mm": float(d.mean() * 1e3), "std_mm": float(d.std() * 1e3),
                            "within": within_shares(d)}
        seconds = time.perf_counter() - t0
        report = sides_file.write(opt.out, sides_file.SidesReport(
            object=first.name, sides=2, turn=turn, seconds=seconds,
            side_seconds=[float(s.seconds) for s in sides], side_scans=[s.scans for s in sides],
            side_2_prior=sides[1].prior,
            registration=sides_file.registration_entry(reg.to_dict(), truth),
            coverage_whole=coverage, contributions=contributions, accuracy=accuracy,
            error=None if error is None else error.one_line(),
            cloud=None if cloud is None else str(cloud), mesh=None if mesh is None else str(mesh)))
        result = TwoSidedResult(opt.out, sides, reg, cloud, mesh, report, seconds, coverage, error)
        if error is not None:
            raise error
        return result
