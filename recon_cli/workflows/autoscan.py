"""``recon autoscan``: autonomous scanning of an unknown object (thesis 2.1.3, Table 2.1).

Initial scan, then until N scans: estimate the ellipsoid from the oriented bounding box of
the partial object (registered by the board, cropped to the known bounding volume),
re-project the completed and infeasible views onto it (nearest points, Eberly), sample
views by the potential field until enough feasible ones are planned, go to the one whose
planned trajectory is shortest (view selection, Table 2.4), scan. Finally the full
registration and Poisson surface of ``recon register``, and in simulation the coverage and
signed distances of the fused cloud against the true surface (with their histogram). The
same loop runs two baselines for ``recon bench viewplan``: views evenly spread on a sphere,
and random feasible views.
Every scan is written atomically on the way: an interrupted run keeps them all, and its
report (``autoscan_report.json``) and page (``report.html``) are written with what exists.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from recon_cli.acquisition import view_record
from recon_cli.config import DEFAULTS, Config
from recon_cli.errors import ReconError, UnknownNameError
from recon_cli.geometry.transforms import transform_points
from recon_cli.geometry.view import View
from recon_cli.inputs.meshes import read_cloud
from recon_cli.objects import SceneObject
from recon_cli.perception.charuco import cell_board
from recon_cli.planning.lower_bound import duration_lower_bound
from recon_cli.planning.planner import MotionPlanner
from recon_cli.reconstruction.crop import CropBox
from recon_cli.reconstruction.evaluation import histogram_png, signed_distances, within_shares
from recon_cli.reconstruction.options import COVERAGE_TOLERANCE
from recon_cli.reconstruction.pipeline import CloudMemo, run_register, scan_points
from recon_cli.reconstruction.sides import register_sides
from recon_cli.recording import open_recorder
from recon_cli.recording.results import record_registration
from recon_cli.report import write_page_after_run
from recon_cli.runs import autoscan as autoscan_file
from recon_cli.runs.autoscan import Accuracy
from recon_cli.runs.codec import matrix
from recon_cli.sequence.view_selection import select_view
from recon_cli.session import Backend, Mode, SessionSpec, open_session
from recon_cli.viewplan.ellipsoid import Ellipsoid
from recon_cli.viewplan.picture import PictureWorker
from recon_cli.viewplan.policy import Feasibility, Method, Status, baseline_views, lifted
from recon_cli.viewplan.views import camera_pose, next_sample

METHODS = tuple(m.value for m in Method)


@dataclass(frozen=True)
class AutoscanOptions:
    out: Path
    config: Config = DEFAULTS  # viewplan: N, d_c, M, sigma, ...; scene: the object; sensor, planner, cell
    initial: View | None = None  # default: the first reachable of a few views above the object
    method: Method = Method.ELLIPSOID  # the thesis' planner, or a baseline
    backend: Backend = Backend.SIM
    pictures: bool = True
    mesh: bool = True
    run: dict = field(default_factory=dict)  # recorded in config.yaml
    station: Path | None = None  # a station file (robot and camera adapters)
    record: bool = False  # write a 3D recording of the run (recording.rrd in ``out``)
    page: bool = True  # write the report page (report.html) at the end
    scene_object: SceneObject | None = None  # the object as it lies (a turned-over side); default: the config's
    box: tuple[tuple[float, float, float], tuple[float, float, float]] | None = None  # crop box (centre, size)
    park: bool = False  # end at the cell's home posture (clear of the table: someone reaches in next)
    prior: SidePrior | None = None  # what an earlier side of the object saw (a second side)


@dataclass(frozen=True)
class SidePrior:
    """What the first side of a turned-over object saw: its partial model and its camera
    positions, in that side's world frame. Once the second side's own partial model shows
    enough of the shape, the first side is registered onto it (by shape) and its points join
    the partial model (the ellipsoid covers the whole object) and its cameras repel the
    potential field (the views aim at what is still unseen)."""

    points: np.ndarray  # (N, 3) [m], down-sampled
    cameras: np.ndarray  # (K, 3) [m] camera positions of its completed views
    voxel: float = 0.003  # [m] of the registration
    attempts: tuple[int, ...] = (2, 4, 6)  # after so many scans of this side (at most once each)


@dataclass
class ViewRecord:
    world_T_camera: np.ndarray
    status: Status
    iteration: int
    planning_s: float | None = None  # completed views: planning of the move to it (view selection) [s]
    trajectory_s: float | None = None  # completed views: duration of that move [s]


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
    accuracy: Accuracy | None
    cloud: Path | None
    mesh: Path | None
    report: Path
    pictures: list[Path]
    interrupted: bool = False
    page: Path | None = None  # report.html (None: not written)
    prior: dict | None = None  # an earlier side registered onto this one: after how many scans, how well


class Autoscan:
    def __init__(self, opt: AutoscanOptions, progress: Callable[[str, int, int], None] | None = None) -> None:
        try:
            method = Method(opt.method)
        except ValueError:

            raise UnknownNameError("view planning method", str(opt.method), METHODS) from None
        if opt.config.viewplan.n < 2:
            raise ReconError(f"--n {opt.config.viewplan.n}: at least two scans are needed", hint="e.g. --n 16")
        self.opt = opt
        self.method = method
        self.vp = opt.config.viewplan
        self.progress = progress or (lambda *a: None)
        self.rng = np.random.default_rng(opt.config.seed)
        self.recorder = None
        self.drawing = PictureWorker()  # the iteration pictures, off the critical path
        self.memo = CloudMemo()  # each scan's cloud, made once for the planner and the registration

    # ------------------------------------------------------------------ set-up
    def _setup(self) -> None:

        opt, cfg = self.opt, self.opt.config
        if opt.record:

            self.recorder = open_recorder(opt.out, f"recon autoscan ({self.method.value})")
        spec = SessionSpec(opt.out, cfg, Mode.AUTOSCAN, opt.backend, run={"method": self.method.value, **opt.run},
                           station=opt.station, recorder=self.recorder, scene_object=opt.scene_object, box=opt.box)
        self.session = open_session(spec, self.rng)
        obj, store, station, acq = (self.session.scene_object, self.session.store, self.session.station,
                                    self.session.acquisition)
        assert obj is not None and store is not None and station is not None and acq is not None  # an open session
        self.obj, self.cell, self.store, self.station, self.acq = obj, self.session.cell, store, station, acq
        center, size = self.obj.crop_box(cfg.scene.box_margin) if opt.box is None else opt.box
        T = np.eye(4)
        T[:3, 3] = center
        self.feasible = Feasibility(self.cell, self.rng, self.vp.min_height)
        self.marker_T_world = self.feasible.marker_T_world
        self.crop_marker = CropBox(self.marker_T_world @ T, size)
        self.board = cell_board(self.cell.config.cell_file)
        self.motion = MotionPlanner(self.cell, cfg.planner)
        lim, plan = self.cell.limits, cfg.planner
        self.lower = lambda a, b: duration_lower_bound(a, b, lim.velocity, lim.acceleration,
                                                       plan.velocity_scale, plan.acceleration_scale)
        self.center = np.asarray(center, float)
        self.partial: list[np.ndarray] = []
        self.prior_cameras = np.zeros((0, 3))  # the first side's cameras, once registered onto this side
        self.prior_placed: dict | None = None  # how the prior was registered (fitness, rmse, scans)
        self.requests = 0
        self.trajectory_s = 0.0

    # ------------------------------------------------------------------ helpers
    def _plan_edge(self, a, b):
        self.requests += 1
        r = self.motion.plan_to_joints(a, b, seed=int(self.rng.integers(1 << 30)))
        return r.trajectory if r.ok else None

    def _scan(self, view_T: np.ndarray) -> None:
        """Scan where the robot is; add the registered, cropped points to the partial object."""

        scan = self.acq.scan(view_record(None, view_T), written=False)  # written while its cloud is made
        assert scan.path is not None  # a stored scan knows its folder
        try:
            registration = self.opt.config.registration
            pose = self.memo.pose(scan.path.name, scan, registration.board or self.board, self.cell.world_T_marker,
                                  registration)
            assert pose is not None  # the kinematics place every scan (world_T_marker is known)
            cloud = scan_points(scan, pose, self.crop_marker)
            self.memo.put(scan.path.name, pose.marker_T_camera, self.crop_marker, cloud)
            cloud.transform(self.cell.world_T_marker)
            pts = np.asarray(cloud.voxel_down_sample(self.vp.partial_voxel).points)
            if len(pts):
                self.partial.append(pts)
        finally:
            self.acq.settle()
        self._place_prior()

    def _place_prior(self) -> None:
        """Register the earlier side onto this side's partial model (see SidePrior)."""
        import open3d as o3d

        prior = self.opt.prior
        if prior is None or self.prior_placed is not None or len(self.store) not in prior.attempts:
            return
        mine = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.vstack(self.partial)))
        theirs = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(prior.points))
        try:
            reg = register_sides(mine, theirs, prior.voxel, seed=self.opt.config.seed)
        except ReconError:
            return
        if reg.reason is not None or reg.shape_ambiguous:
            return
        T = reg.side1_T_side2
        self.partial.append(transform_points(T, prior.points))
        self.prior_cameras = transform_points(T, prior.cameras)
        self.prior_placed = {"after_scans": len(self.store), "fitness": reg.fitness, "rmse_m": reg.rmse}

    def _partial_points(self) -> np.ndarray:
        return np.vstack(self.partial) if self.partial else self.center[None, :]

    def _default_initial(self) -> np.ndarray:
        """The first reachable of a few views around the box centre at r = d_c + 0.1
        (45 deg above it first, from +x; then other angles: the 7-DoF cell reaches less)."""
        q = self.station.robot.measured_joints()
        for theta in (45.0, 30.0, 60.0, 20.0):
            for phi in (0.0, 90.0, 180.0, 270.0):
                T = self.cell.view_pose(View(tuple(self.center), self.vp.d_c + 0.1, np.radians(theta),
                                             np.radians(phi)))
                if self.feasible(T, q) is not None:
                    return T
        raise ReconError("no initial view around the object is reachable",
                         hint="give one with --initial theta,phi or a smaller --dc")

    # ------------------------------------------------------------------ candidates
    def _ellipsoid_candidates(self, ell, views: list[ViewRecord], needed: int, q: np.ndarray, it: int):

        A = [ell.nearest_point(ell.to_local(v.world_T_camera[:3, 3])) for v in views
             if v.status in (Status.COMPLETED, Status.INFEASIBLE)]
        A += [ell.nearest_point(ell.to_local(c)) for c in self.prior_cameras]
        planned: list[tuple[np.ndarray, np.ndarray]] = []
        tries = 0
        while len(planned) < needed and tries < 20 * needed + 50:
            tries += 1
            p = next_sample(ell, np.array(A).reshape(-1, 3), self.vp.m, self.vp.sigma, self.rng)
            A.append(p)
            T = camera_pose(ell, p, self.vp.d_c)
            config = self.feasible(T, q)
            if config is None and self.vp.lift:
                T, config = lifted(T, ell.to_world(p), q, self.feasible)
                if config is not None:  # the view is where the lifted camera is
                    A.append(ell.nearest_point(ell.to_local(T[:3, 3])))
            if config is None:
                views.append(ViewRecord(T, Status.INFEASIBLE, it))
            else:
                planned.append((T, config))
        return planned

    def _fixed_candidates(self, ell, views: list[ViewRecord], q: np.ndarray) -> list:
        """Baselines: all views at once, at the ellipsoid planner's typical distance from the
        box centre (d_c + the mean semi-axis of the first ellipsoid)."""
        radius = self.vp.d_c + float(np.mean(ell.axes))
        out, infeasible = baseline_views(self.method, self.center, radius, self.vp.n - 1, q, self.feasible, self.rng)
        views.extend(ViewRecord(T, Status.INFEASIBLE, 0) for T in infeasible)
        return out

    # ------------------------------------------------------------------ run
    def run(self) -> AutoscanResult:

        opt, vp, ellipsoid = self.opt, self.vp, self.method is Method.ELLIPSOID
        t0 = time.perf_counter()
        try:
            self._setup()
        except BaseException:
            self._close_recorder()
            raise
        views: list[ViewRecord] = []
        pictures: list[Path] = []
        interrupted = False
        error: ReconError | None = None
        queue: list = []
        try:
            T0 = self.cell.view_pose(opt.initial) if opt.initial is not None else self._default_initial()
            move = self.acq.move_to_pose(T0, what="initial view")
            self.requests += move.plan.attempts
            self.trajectory_s += move.execution.duration
            self._scan(T0)
            views.append(ViewRecord(T0, Status.COMPLETED, 0, move.plan.total_time, move.execution.duration))
            if len(self._partial_points()) < 4:
                raise ReconError("the initial view saw no point of the object inside its box",
                                 hint="check that the object stands where the cell's objects stand, or give "
                                      "--initial and --dc within the camera's range")
            self.progress("scans", 1, vp.n)
            it, stuck = 0, 0
            while len(self.store) < vp.n and stuck < 3:
                it += 1
                ell = Ellipsoid.from_cloud(self._partial_points()).with_min_ratio(vp.min_axis_ratio)
                q = self.station.robot.measured_joints()
                if ellipsoid:
                    planned = self._ellipsoid_candidates(ell, views, vp.n - len(self.store), q, it)
                else:
                    if not queue and it == 1:
                        queue = self._fixed_candidates(ell, views, q)
                    planned = queue
                if not planned:
                    break
                t_select = time.perf_counter()
                sel = select_view(q, [c for _, c in planned], self.lower, self._plan_edge)
                planning = time.perf_counter() - t_select
                if sel.index is None or sel.trajectory is None:  # nothing reachable: those views are infeasible
                    views.extend(ViewRecord(T, Status.INFEASIBLE, it) for T, _ in planned)
                    stuck += 1
                    if not ellipsoid:
                        break
                    continue
                stuck = 0
                T, _ = planned[sel.index]
                others = [p for k, (p, _) in enumerate(planned) if k != sel.index]
                if opt.pictures and ellipsoid:
                    pictures.append(self._picture(it, ell, views, others, T))
                if self.recorder is not None:
                    self.recorder.iteration(it, ell, [(v.world_T_camera, v.status.value) for v in views], others, T)
                if not ellipsoid:
                    queue.pop(sel.index)
                self.station.robot.execute(sel.trajectory)
                self.trajectory_s += sel.trajectory.duration
                self._scan(T)
                views.append(ViewRecord(T, Status.COMPLETED, it, planning, sel.trajectory.duration))
                self.progress("scans", len(self.store), vp.n)
            if opt.park:
                self.acq.move_to_joints(self.session.start, what="home posture")
        except KeyboardInterrupt:
            interrupted = True
        except ReconError as exc:  # a fault, no reachable view: reported below, then raised
            error = exc
        except BaseException:
            self.drawing.close()
            self._close_recorder()
            raise
        finally:
            self.session.close()  # stops the robot first
        try:
            result, error = self._finish(views, pictures, t0, interrupted, error)
        finally:
            self.drawing.close()
            self._close_recorder()
        if opt.page:  # with the recording complete

            written = write_page_after_run(opt.out)
            result.page = None if written is None else written.path
        if error is not None:
            raise error
        return result

    def _close_recorder(self) -> None:
        if self.recorder is not None:
            self.recorder.close()

    # ------------------------------------------------------------------ results
    def _finish(self, views, pictures, t0: float, interrupted: bool, error: ReconError | None
                ) -> tuple[AutoscanResult, ReconError | None]:
        """Register and evaluate what was scanned (unless the run ended early) and write the
        report; the result and the error that ended the run (None when it did not)."""
        opt, cfg, vp = self.opt, self.opt.config, self.vp
        scanning = time.perf_counter() - t0
        cloud = mesh = None
        coverage = accuracy = None
        if not interrupted and error is None and len(self.store) > 0:


            try:
                reg = run_register(opt.out, opt.out / "reconstruction", replace(cfg.registration, mesh=opt.mesh),
                                   seed=cfg.seed, memo=self.memo)
            except ReconError as exc:
                error = exc
            else:
                cloud, mesh = reg.cloud, reg.mesh
            if error is None and self.station.capabilities.ground_truth:  # the true surface is known

                fused = reg.cloud
                pts = np.asarray(read_cloud(fused, "fused cloud", points=False).points)
                coverage = surface_coverage(self.obj, pts, COVERAGE_TOLERANCE, np.random.default_rng(cfg.seed))
                d = signed_distances(pts, self.obj.mesh_world())
                if self.recorder is not None:

                    record_registration(self.recorder, reg, opt.out, distances=(pts, d))
                accuracy = Accuracy(float(d.mean() * 1e3), float(d.std() * 1e3), len(pts), within_shares(d))
                histogram_png(fused.parent / f"{fused.stem}_distances.png", {fused.stem: d},
                              f"{fused.name} vs the true {self.obj.name}")
            elif error is None and self.recorder is not None:

                record_registration(self.recorder, reg, opt.out)
        seconds_total = time.perf_counter() - t0
        infeasible = sum(v.status is Status.INFEASIBLE for v in views)

        report = autoscan_file.write(opt.out, autoscan_file.AutoscanReport(
            method=self.method.value, object=self.obj.name, cell=cfg.cell.kind.value, n=vp.n, d_c=vp.d_c, m=vp.m,
            sigma=vp.sigma, seed=cfg.seed, scans=len(self.store), interrupted=interrupted,
            error=None if error is None else error.one_line(), infeasible_views=infeasible,
            planning_requests=self.requests, trajectory_s=float(self.trajectory_s), coverage_1mm=coverage,
            accuracy=accuracy, seconds_scanning=scanning, seconds_total=seconds_total,
            views=tuple(autoscan_file.ViewOutcome(v.status.value, v.iteration, matrix(v.world_T_camera), v.planning_s,
                                                  v.trajectory_s) for v in views),
            outputs=autoscan_file.AutoscanOutputs(None if cloud is None else str(cloud),
                                                  None if mesh is None else str(mesh),
                                                  tuple(str(p) for p in pictures))))
        return AutoscanResult(opt.out, len(self.store), views, infeasible, self.requests, self.trajectory_s,
                              seconds_total, coverage, accuracy, cloud, mesh, report, pictures, interrupted,
                              prior=self.prior_placed), error

    def _picture(self, it: int, ell, views: list[ViewRecord], planned: list[np.ndarray], active: np.ndarray) -> Path:

        path = self.opt.out / "iterations" / f"iteration_{it:02d}.png"
        return self.drawing.draw(path, it, self._partial_points(), ell, views, planned, active, self.opt.config.seed)


def surface_coverage(obj, points: np.ndarray, tolerance: float, rng: np.random.Generator,
                     samples: int = 100_000) -> float:
    """Share of the object's ground-truth surface (without the face on the table and faces
    hidden inside it) with a reconstructed point within ``tolerance``."""
    import open3d as o3d

    truth = obj.surface_points(samples, rng)
    ref = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(truth))
    rec = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(points, float)))
    return float(np.mean(np.asarray(ref.compute_point_cloud_distance(rec)) <= tolerance))
