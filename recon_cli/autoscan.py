"""``recon autoscan``: autonomous scanning of an unknown object (thesis 2.1.3, Table 2.1).

Initial scan, then until N scans: estimate the ellipsoid from the oriented bounding box of
the partial object (registered by the board, cropped to the known bounding volume),
re-project the completed and infeasible views onto it (nearest points, Eberly), sample
views by the potential field until enough feasible ones are planned, go to the one whose
planned trajectory is shortest (view selection, Table 2.4), scan. Finally the full
registration and Poisson surface of ``recon register``. The same loop runs two baselines
for ``recon bench viewplan``: views evenly spread on a sphere, and random feasible views.
Every scan is written atomically on the way: an interrupted run keeps them all.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from recon_cli.errors import ReconError
from recon_cli.geometry.view import View
from recon_cli.planning.planner import PlanOptions
from recon_cli.robot.description import CellConfig

METHODS = ("ellipsoid", "sphere", "random")


@dataclass(frozen=True)
class AutoscanOptions:
    out: Path
    object_name: str = "bottle"
    object_scale: float = 1.0
    cell: CellConfig = field(default_factory=CellConfig)
    n: int = 16  # scans in total, the initial one included
    d_c: float = 0.55  # [m] camera distance to the ellipsoid
    m: int = 200  # preliminary samples per view (thesis: 200)
    sigma: float = 1e-5  # regularization of the potential field (thesis: 1e-5)
    initial: View | None = None  # default: 45 deg above the object, from +x
    method: str = "ellipsoid"  # ellipsoid | sphere | random (baselines)
    seed: int = 0
    resolution: float = 1.0
    noise: bool = True
    box_margin: float = 0.01
    plan: PlanOptions = field(default_factory=PlanOptions)
    pictures: bool = True
    mesh: bool = True
    lift: bool = True  # raise infeasible views toward the vertical (ours; False: as the thesis)
    min_height: float = 0.05  # [m] lowest camera height above the board plane (thesis: above it)
    min_axis_ratio: float = 0.3  # ours: no semi-axis below this share of the largest (0: the thesis)


@dataclass
class ViewRecord:
    world_T_camera: np.ndarray
    status: str  # completed | infeasible | planned | active
    iteration: int


@dataclass
class AutoscanResult:
    folder: Path
    scans: int
    views: list[ViewRecord]
    infeasible: int
    requests: int
    trajectory_s: float
    seconds: float
    coverage: float | None
    accuracy: dict | None
    cloud: Path | None
    mesh: Path | None
    report: Path
    pictures: list[Path]
    interrupted: bool = False


class Autoscan:
    def __init__(self, opt: AutoscanOptions, progress: Callable[[str, int, int], None] | None = None) -> None:
        if opt.method not in METHODS:
            from recon_cli.errors import UnknownNameError

            raise UnknownNameError("view planning method", opt.method, METHODS)
        if opt.n < 2:
            raise ReconError(f"--n {opt.n}: at least two scans are needed", hint="e.g. --n 16")
        self.opt = opt
        self.progress = progress or (lambda *a: None)
        self.rng = np.random.default_rng(opt.seed)

    # ------------------------------------------------------------------ set-up
    def _setup(self) -> None:
        from recon_cli.acquisition import Acquisition
        from recon_cli.backends.sim.station import SimStation
        from recon_cli.capture import write_ground_truth_mesh
        from recon_cli.objects import load_object
        from recon_cli.perception.sensor import motioncam_3d_m
        from recon_cli.planning.lower_bound import duration_lower_bound
        from recon_cli.planning.planner import MotionPlanner, seed_ompl
        from recon_cli.reconstruction.crop import CropBox
        from recon_cli.reconstruction.scan_store import ScanStore
        from recon_cli.robot.cell import Cell
        from recon_cli.robot.poses import named_configuration

        opt = self.opt
        seed_ompl(opt.seed)
        self.obj = load_object(opt.object_name, opt.object_scale)
        box = self.obj.bounding_box(opt.box_margin)  # the known bounding volume
        self.cell = Cell(opt.cell, object_box=box)
        center, size = self.obj.crop_box(opt.box_margin)
        self.sensor = motioncam_3d_m()
        self.store = ScanStore.create(opt.out, {
            "backend": "sim", "mode": f"autoscan ({opt.method})",
            "cell": {"kind": opt.cell.kind.value, "safety_distance": opt.cell.safety_distance},
            "sensor": self.sensor.name, "noise": opt.noise, "seed": opt.seed,
            "object": {"name": self.obj.name, "world_T_object": self.obj.world_T_object},
            "object_box": {"frame": "world", "center": list(box.center), "size": list(box.size)},
            "crop_box": {"frame": "world", "center": list(center), "size": list(size)},
            "world_T_marker": self.cell.world_T_marker,
        })
        write_ground_truth_mesh(opt.out, self.obj)
        T = np.eye(4)
        T[:3, 3] = center
        self.marker_T_world = np.linalg.inv(self.cell.world_T_marker)
        self.crop_marker = CropBox(self.marker_T_world @ T, tuple(size))
        start = named_configuration(opt.cell.kind, "home", self.cell.joint_names)
        self.station = SimStation(self.cell, self.obj, start, self.rng, noise=opt.noise, resolution=opt.resolution)
        self.acq = Acquisition(self.cell, self.station.robot, self.station.camera, self.store, self.rng, opt.plan,
                               depth_scale=self.sensor.depth_scale, ground_truth=self.station.ground_truth)
        self.motion = MotionPlanner(self.cell, opt.plan)
        lim = self.cell.limits
        self.lower = lambda a, b: duration_lower_bound(a, b, lim.velocity, lim.acceleration,
                                                       opt.plan.velocity_scale, opt.plan.acceleration_scale)
        self.center = np.asarray(center, float)
        self.partial: list[np.ndarray] = []
        self.requests = 0
        self.trajectory_s = 0.0

    # ------------------------------------------------------------------ helpers
    def _plan_edge(self, a, b):
        self.requests += 1
        r = self.motion.plan_to_joints(a, b, seed=int(self.rng.integers(1 << 30)))
        return r.trajectory if r.ok else None

    def _feasible(self, T: np.ndarray, seed: np.ndarray) -> np.ndarray | None:
        """An IK solution of the camera pose (collision-free, soft limits), or None."""
        from recon_cli.robot.ik import IKOptions

        marker_z = (self.marker_T_world @ T)[2, 3]
        if marker_z < self.opt.min_height:  # the thesis' rule: the camera stays above the board
            return None
        try:
            r = self.cell.solve_pose(T, self.rng, seed=seed, options=IKOptions(max_solutions=1, max_attempts=20))
        except ReconError:
            return None
        return r.solutions[0].q

    def _scan(self, view_T: np.ndarray) -> None:
        """Scan where the robot is; add the registered, cropped points to the partial object."""
        from recon_cli.acquisition import view_record
        from recon_cli.perception.charuco import thesis_board
        from recon_cli.reconstruction.global_registration import global_pose
        from recon_cli.reconstruction.pipeline import scan_cloud
        from recon_cli.reconstruction.surface import SurfaceOptions

        scan = self.acq.scan(view_record(None, view_T))
        pose = global_pose(scan, thesis_board(), self.cell.world_T_marker)
        cloud = scan_cloud(scan, pose, self.crop_marker, SurfaceOptions())
        cloud.transform(self.cell.world_T_marker)
        pts = np.asarray(cloud.voxel_down_sample(0.002).points)
        if len(pts):
            self.partial.append(pts)

    def _partial_points(self) -> np.ndarray:
        return np.vstack(self.partial) if self.partial else self.center[None, :]

    def _default_initial(self) -> np.ndarray:
        """The first reachable of a few views around the box centre at r = d_c + 0.1
        (45 deg above it first, from +x; then other angles: the 7-DoF cell reaches less)."""
        q = self.station.robot.measured_joints()
        for theta in (45.0, 30.0, 60.0, 20.0):
            for phi in (0.0, 90.0, 180.0, 270.0):
                T = self.cell.view_pose(View(tuple(self.center), self.opt.d_c + 0.1, np.radians(theta),
                                             np.radians(phi)))
                if self._feasible(T, q) is not None:
                    return T
        raise ReconError("no initial view around the object is reachable",
                         hint="give one with --initial theta,phi or a smaller --dc")

    # ------------------------------------------------------------------ candidates
    def _ellipsoid_candidates(self, ell, views: list[ViewRecord], needed: int, q: np.ndarray, it: int):
        from recon_cli.viewplan.views import camera_pose, next_sample

        A = [ell.nearest_point(ell.to_local(v.world_T_camera[:3, 3])) for v in views
             if v.status in ("completed", "infeasible")]
        planned = []
        tries = 0
        while len(planned) < needed and tries < 20 * needed + 50:
            tries += 1
            p = next_sample(ell, np.array(A).reshape(-1, 3), self.opt.m, self.opt.sigma, self.rng)
            A.append(p)
            T = camera_pose(ell, p, self.opt.d_c)
            config = self._feasible(T, q)
            if config is None and self.opt.lift:
                T, config = self._lifted(T, ell.to_world(p), q)
                if config is not None:  # the view is where the lifted camera is
                    A.append(ell.nearest_point(ell.to_local(T[:3, 3])))
            if config is None:
                views.append(ViewRecord(T, "infeasible", it))
            else:
                planned.append((T, config))
        return planned

    def _lifted(self, T: np.ndarray, target: np.ndarray, q: np.ndarray):
        """Ours, beyond the thesis: a view that is infeasible (under or against the table,
        out of reach) is raised in steps of 15 deg toward the vertical, still looking at the
        same surface point from the same distance; the first feasible one replaces it. A
        region next to the table is then seen from above instead of being left out (the
        thesis marks such samples infeasible, and they repel later samples)."""
        from recon_cli.geometry.view import look_at_pose

        d = T[:3, 3] - target
        dist = float(np.linalg.norm(d))
        d /= dist
        horizontal = np.hypot(d[0], d[1])
        elevation = np.arctan2(d[2], horizontal)
        azimuth = np.arctan2(d[1], d[0])
        for step in (15.0, 30.0, 45.0, 60.0):
            e = min(elevation + np.radians(step), np.radians(85.0))
            direction = np.array([np.cos(e) * np.cos(azimuth), np.cos(e) * np.sin(azimuth), np.sin(e)])
            lifted = look_at_pose(target + dist * direction, target)
            config = self._feasible(lifted, q)
            if config is not None:
                return lifted, config
        return T, None

    def _fixed_candidates(self, ell, views: list[ViewRecord], q: np.ndarray) -> list:
        """Baselines: all views at once, at the ellipsoid planner's typical distance from the
        box centre (d_c + the mean semi-axis of the first ellipsoid)."""
        from recon_cli.geometry.view import look_at_pose

        radius = self.opt.d_c + float(np.mean(ell.axes))
        need = self.opt.n - 1
        out = []
        if self.opt.method == "sphere":  # Fibonacci spiral over the upper hemisphere
            k = np.arange(need) + 0.5
            z = 1.0 - k / need * 0.95  # cos(theta) from ~1 down to 0.05
            phi = np.pi * (3.0 - np.sqrt(5.0)) * k
            dirs = np.stack([np.sqrt(1 - z * z) * np.cos(phi), np.sqrt(1 - z * z) * np.sin(phi), z], 1)
        else:
            dirs = None
        tries = 0
        while len(out) < need and tries < 40 * need:
            if dirs is not None:
                if tries >= len(dirs):
                    break
                d = dirs[tries]
            else:
                d = self.rng.normal(size=3)
                d[2] = abs(d[2])
                d /= np.linalg.norm(d)
            tries += 1
            T = look_at_pose(self.center + radius * d, self.center)
            config = self._feasible(T, q)
            if config is None:
                views.append(ViewRecord(T, "infeasible", 0))
            else:
                out.append((T, config))
        return out

    # ------------------------------------------------------------------ run
    def run(self) -> AutoscanResult:
        from recon_cli.sequence.view_selection import select_view
        from recon_cli.viewplan.ellipsoid import Ellipsoid

        opt = self.opt
        t0 = time.perf_counter()
        self._setup()
        views: list[ViewRecord] = []
        pictures: list[Path] = []
        interrupted = False
        queue: list = []
        try:
            T0 = self.cell.view_pose(opt.initial) if opt.initial is not None else self._default_initial()
            move = self.acq.move_to_pose(T0, what="initial view")
            self.requests += move.plan.attempts
            self.trajectory_s += move.execution.duration
            self._scan(T0)
            views.append(ViewRecord(T0, "completed", 0))
            self.progress("scans", 1, opt.n)
            it, stuck = 0, 0
            while len(self.store) < opt.n and stuck < 3:
                it += 1
                ell = Ellipsoid.from_cloud(self._partial_points()).with_min_ratio(opt.min_axis_ratio)
                q = self.station.robot.measured_joints()
                if opt.method == "ellipsoid":
                    planned = self._ellipsoid_candidates(ell, views, opt.n - len(self.store), q, it)
                else:
                    if not queue and it == 1:
                        queue = self._fixed_candidates(ell, views, q)
                    planned = queue
                if not planned:
                    break
                sel = select_view(q, [c for _, c in planned], self.lower, self._plan_edge)
                if sel.index is None:  # nothing reachable: those views are infeasible
                    for T, _ in planned:
                        views.append(ViewRecord(T, "infeasible", it))
                    stuck += 1
                    if opt.method != "ellipsoid":
                        break
                    continue
                stuck = 0
                T, _ = planned[sel.index]
                if opt.pictures and opt.method == "ellipsoid":
                    pictures.append(self._picture(it, ell, views, [p for k, (p, _) in enumerate(planned)
                                                                   if k != sel.index], T))
                if opt.method != "ellipsoid":
                    queue.pop(sel.index)
                self.station.robot.execute(sel.trajectory)
                self.trajectory_s += sel.trajectory.duration
                self._scan(T)
                views.append(ViewRecord(T, "completed", it))
                self.progress("scans", len(self.store), opt.n)
        except KeyboardInterrupt:
            interrupted = True
        finally:
            self.station.close()
        return self._finish(views, pictures, t0, interrupted)

    # ------------------------------------------------------------------ results
    def _finish(self, views, pictures, t0: float, interrupted) -> AutoscanResult:
        from recon_cli.console import write_json

        opt = self.opt
        scanning = time.perf_counter() - t0
        cloud = mesh = None
        coverage = accuracy = None
        if not interrupted and len(self.store) > 0:
            from recon_cli.reconstruction.evaluation import signed_distances
            from recon_cli.reconstruction.pipeline import RegisterOptions, run_register

            reg = run_register(opt.out, opt.out / "reconstruction", RegisterOptions(mesh=opt.mesh, seed=opt.seed))
            cloud, mesh = reg.cloud, reg.mesh
            import open3d as o3d

            pts = np.asarray(o3d.io.read_point_cloud(str(cloud)).points)
            coverage = surface_coverage(self.obj, pts, 0.001, np.random.default_rng(opt.seed))
            d = signed_distances(pts, self.obj.mesh_world())
            accuracy = {"mean_mm": float(d.mean() * 1e3), "std_mm": float(d.std() * 1e3), "points": len(pts)}
        seconds_total = time.perf_counter() - t0
        report = opt.out / "autoscan_report.json"
        write_json(report, {
            "method": opt.method, "object": self.obj.name, "cell": opt.cell.kind.value, "n": opt.n, "d_c": opt.d_c,
            "m": opt.m, "sigma": opt.sigma, "seed": opt.seed, "scans": len(self.store),
            "interrupted": interrupted, "infeasible_views": sum(v.status == "infeasible" for v in views),
            "planning_requests": self.requests, "trajectory_s": self.trajectory_s,
            "coverage_1mm": coverage, "accuracy": accuracy, "seconds_scanning": scanning,
            "seconds_total": seconds_total,
            "views": [{"status": v.status, "iteration": v.iteration, "world_T_camera": v.world_T_camera}
                      for v in views],
            "outputs": {"cloud": None if cloud is None else str(cloud), "mesh": None if mesh is None else str(mesh),
                        "pictures": [str(p) for p in pictures]},
        })
        return AutoscanResult(opt.out, len(self.store), views, sum(v.status == "infeasible" for v in views),
                              self.requests, self.trajectory_s, seconds_total, coverage, accuracy, cloud, mesh,
                              report, pictures, interrupted)

    def _picture(self, it: int, ell, views: list[ViewRecord], planned: list[np.ndarray], active: np.ndarray) -> Path:
        from recon_cli.viewplan.picture import iteration_png

        path = self.opt.out / "iterations" / f"iteration_{it:02d}.png"
        iteration_png(path, it, self._partial_points(), ell, views, planned, active)
        return path


def surface_coverage(obj, points: np.ndarray, tolerance: float, rng: np.random.Generator,
                     samples: int = 100_000) -> float:
    """Share of the object's ground-truth surface (without the face on the table and faces
    hidden inside it) with a reconstructed point within ``tolerance``."""
    import open3d as o3d

    truth = obj.surface_points(samples, rng)
    ref = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(truth))
    rec = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(points, float)))
    return float(np.mean(np.asarray(ref.compute_point_cloud_distance(rec)) <= tolerance))
