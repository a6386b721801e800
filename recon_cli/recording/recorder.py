"""The recording stream of one run and what each event of the run logs into it.

Entities (all in the world frame; the cell's links in the frames of the URDF, which the
recording joins to the world):

    cell/recon_cell/...               the cell from the run's URDF (visual geometry)
    cell/joints/<joint>               joint transforms along the executed trajectories
    world/marker                      the marker frame; world/board the board's outline
    world/object_box                  the object's known bounding box
    world/ground_truth                the simulated object (simulation only)
    world/moves/move_NNN              the camera's path along each executed move
    world/camera                      the camera now: frustum, colour and depth images
    world/scans/scan_NNNN/camera      frustum, colour and depth image of each scan
    world/scans/scan_NNNN/cloud       the scan's points by forward kinematics
    world/scans/side_2/scan_NNNN/...  an object's second side (its scans numbered from 0 again)
    world/scans/scan_NNNN/camera/color/board   board corners found in the image
    viewplan/ellipsoid, viewplan/views/<status>   each autoscan iteration
    registration/before|after/scan_NNNN           cropped clouds, global vs final poses
    reconstruction/mesh, reconstruction/distances the surface and the cloud's signed distances
    sides/side_1, sides/side_2        an object's two sides as registered onto each other (side 1's frame)
    log                               one line per event

Timelines: ``robot_time`` (seconds the robot spent moving and settling; scans and
iterations sit at the time they happened, reconstruction results after the last motion)
and ``scan`` (the index of the scan an entity belongs to).
"""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from recon_cli.perception.charuco import cell_board
from recon_cli.recording import scene as S
from recon_cli.recording.sdk import require_rerun

if TYPE_CHECKING:
    from rerun.urdf import UrdfJoint

TIMELINE = "robot_time"


class Recorder:
    """A run's rerun recording, written to ``path`` as the run goes (use as a context
    manager, or call :meth:`close`)."""

    def __init__(self, path: Path, name: str) -> None:
        self.rr = require_rerun()
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.rec = self.rr.RecordingStream("recon", send_properties=True)
        self.rec.save(str(self.path))
        self.rec.send_recording_name(name)
        self.clock = 0.0  # [s] robot time
        self.moves = 0
        self.joints: dict[str, UrdfJoint | None] = {}  # recon joint name -> its joint in the URDF tree
        self.kin = None
        self.depth_scale = 20000.0
        self.scans: list[str] = []  # entities of the scans recorded (world/scans/[group]scan_NNNN)
        self.group = ""  # scans from here on: world/scans/<group>scan_NNNN (e.g. "side_2/")
        self._offset = 0  # added to a scan's index on the scan timeline (scans of earlier groups)
        self._closed = False
        self.rec.send_blueprint(self._layout())
        self._at(0.0)

    def _layout(self):
        """The viewer's layout: the cell in 3D (collision shapes, the clouds before
        registration and the depth images, which the 3D view would draw as clouds of their
        own, hidden), the current camera image, the event log."""
        import rerun.blueprint as rrb

        hidden = rrb.EntityBehavior(visible=False)
        depth = {f"/{name}/camera/depth": hidden for name in self.scans}
        cell = rrb.Spatial3DView(
            name="cell", origin="/", contents=["+ /cell/**", "+ /world/**", "+ /viewplan/**",
                                               "+ /registration/**", "+ /reconstruction/**", "+ /sides/**"],
            overrides={"/cell/recon_cell/collision_geometries": hidden, "/registration/before": hidden,
                       "/world/camera": hidden, **depth},
            eye_controls=rrb.EyeControls3D(position=(2.3, -2.6, 2.0), look_target=(0.0, 0.0, 0.85),
                                           eye_up=(0.0, 0.0, 1.0)))
        camera = rrb.Spatial2DView(name="camera", origin="/world/camera",
                                   overrides={"/world/camera/depth": hidden})
        return rrb.Blueprint(rrb.Horizontal(cell, rrb.Vertical(camera, rrb.TextLogView(name="log", origin="/log")),
                                            column_shares=[3, 1]),
                             rrb.TimePanel(timeline=TIMELINE))

    # ------------------------------------------------------------------ time
    def _at(self, t: float, scan: int | None = None) -> None:
        self.rec.reset_time()
        self.rec.set_time(TIMELINE, duration=float(t))
        if scan is not None:
            self.rec.set_time("scan", sequence=int(scan))

    def note(self, text: str, level: str = "INFO") -> None:
        self._at(self.clock)
        self._line(text, level)

    def _line(self, text: str, level: str = "INFO") -> None:
        """One line of the event log at the current time."""
        self.rec.log("log", self.rr.TextLog(text, level=level))

    # ------------------------------------------------------------------ the cell
    def cell(self, cell, start: np.ndarray | None = None, object_box=None, truth_mesh=None) -> None:
        """The cell from the URDF the run uses, the marker frame and board, the object box,
        the simulated object, and the robot at ``start``."""

        rr = self.rr
        with tempfile.TemporaryDirectory() as tmp:
            urdf = Path(tmp) / "cell.urdf"
            urdf.write_text(cell.urdf)
            tree = rr.urdf.UrdfTree.from_file_path(urdf, entity_path_prefix="cell")
            tree.log_urdf_to_recording(self.rec)
        self.joints = {name: tree.get_joint_by_name(name) for name in cell.joint_names}
        self.kin = cell.kin
        # the URDF's frames hang below its root link "world"; the entities below hang below
        # the recording's root: one tree for the viewer
        self.rec.log("world_link", rr.Transform3D(parent_frame="tf#/", child_frame="world"), static=True)
        M = cell.world_T_marker
        self.rec.log("world/marker", rr.Transform3D(translation=M[:3, 3], mat3x3=M[:3, :3]),
                     rr.TransformAxes3D(0.1), static=True)
        self.rec.log("world/board", rr.LineStrips3D([S.board_corners_world(cell_board(cell.config.cell_file), M)],
                                                    colors=[(230, 230, 230)], radii=0.0015), static=True)
        if object_box is not None:
            self.rec.log("world/object_box", rr.Boxes3D(centers=[object_box.center],
                                                        half_sizes=[np.asarray(object_box.size) / 2],
                                                        colors=[(255, 191, 0)], radii=0.001), static=True)
        if truth_mesh is not None:
            self.mesh("world/ground_truth", truth_mesh, color=(150, 150, 160), static=True)
        if start is not None:
            self.configuration(start)

    def configuration(self, q: np.ndarray) -> None:
        """The robot at q now (a scan's joint readings when no motion was recorded)."""
        self._joints(np.array([self.clock]), np.asarray(q, float)[None, :])

    def _joints(self, times: np.ndarray, q: np.ndarray) -> None:
        idx = [self.rr.TimeColumn(TIMELINE, duration=times)]
        for k, (name, joint) in enumerate(self.joints.items()):
            if joint is None or joint.joint_type == "fixed":
                continue
            self.rec.send_columns(f"cell/joints/{name}", indexes=idx,
                                  columns=joint.compute_transform_columns(q[:, k].tolist(), clamp=False))

    # ------------------------------------------------------------------ motion
    def move(self, trajectory, settle_s: float = 0.0) -> None:
        """An executed trajectory: the joints along it, the camera's path; the clock moves on
        by its duration and the settling time."""
        t, q = S.trajectory_samples(trajectory)
        self._joints(self.clock + t, q)
        self._at(self.clock)
        self.moves += 1
        if self.kin is not None:
            path = S.camera_path(self.kin, q)
            self.rec.log(f"world/moves/move_{self.moves:03d}",
                         self.rr.LineStrips3D([path], colors=[S.STATUS_RGB["planned"]], radii=0.002))
        self._line(f"move {self.moves}: {trajectory.duration:.2f} s trajectory, "
                   f"settled after {settle_s:.3f} s")
        self.clock += float(trajectory.duration) + float(settle_s)

    # ------------------------------------------------------------------ scans
    def begin_group(self, group: str) -> None:
        """The scans from here on are another store's (an object's second side, numbered from
        0 again): recorded under ``world/scans/<group>/`` and after the earlier ones on the scan
        timeline."""
        self._offset = len(self.scans)
        self.group = f"{group.strip('/')}/"

    def _scan_entity(self, index: int) -> str:
        return f"world/scans/{self.group}scan_{index:04d}"

    def scan(self, scan) -> None:
        """A scan at the current time: frustum and images at the pose by forward kinematics,
        and its points in the world."""
        rr = self.rr
        T = scan.world_T_camera_fk
        self._at(self.clock, self._offset + scan.index)
        name = self._scan_entity(scan.index)
        self.scans.append(name)
        K = scan.intrinsics
        colour, depth_m = scan.pinhole_images()  # undistorted where the scan has a lens distortion
        pose = rr.Transform3D(translation=T[:3, 3], mat3x3=T[:3, :3])
        # each scan's frustum keeps its images at full size; the current camera (the 2D view
        # beside the cell) shows a preview of the latest scan
        for entity, scale in ((f"{name}/camera", 1.0), ("world/camera", S.PREVIEW_SCALE)):
            color, depth, Ks = S.scaled_images(colour, depth_m, K, scale)
            self.rec.log(entity, pose, rr.Pinhole(image_from_camera=Ks.matrix(), resolution=[Ks.width, Ks.height],
                                                  camera_xyz=rr.ViewCoordinates.RDF, image_plane_distance=0.08))
            if color is not None:
                self.rec.log(f"{entity}/color", rr.EncodedImage(contents=S.jpeg(color), media_type="image/jpeg"))
            self.rec.log(f"{entity}/depth", rr.EncodedDepthImage(S.depth_png(depth, self.depth_scale),
                                                                 media_type="image/png", meter=self.depth_scale))
        points, rgb = S.scan_points(depth_m, colour, K, T)
        self.rec.log(f"{name}/cloud", rr.Points3D(points, colors=rgb, radii=0.001))
        self._line(f"scan {scan.index}: {len(points)} points shown")

    def board(self, index: int, image_points: np.ndarray, marker_outlines: np.ndarray, text: str) -> None:
        """Board corners (N, 2) and marker outlines (M, 4, 2) found in a scan's colour image."""
        rr = self.rr
        self._at(self.clock, self._offset + index)
        entity = f"{self._scan_entity(index)}/camera/color/board"
        self.rec.log(f"{entity}/corners", rr.Points2D(image_points, colors=[(44, 160, 44)], radii=3.0))
        if len(marker_outlines):
            strips = [np.vstack([m, m[:1]]) for m in marker_outlines]
            self.rec.log(f"{entity}/markers", rr.LineStrips2D(strips, colors=[(31, 119, 180)], radii=1.5))
        self._line(f"scan {index}: {text}")

    # ------------------------------------------------------------------ view planning
    def iteration(self, it: int, ellipsoid, views: list[tuple[np.ndarray, str]],
                  candidates: list[np.ndarray], selected: np.ndarray | None) -> None:
        """One autoscan iteration: the ellipsoid, the views so far (completed, infeasible),
        the planned candidates and the one chosen, in the colours of the iteration pictures."""
        from scipy.spatial.transform import Rotation

        rr = self.rr
        self._at(self.clock)
        q = Rotation.from_matrix(ellipsoid.world_T_E[:3, :3]).as_quat()
        self.rec.log("viewplan/ellipsoid", rr.Ellipsoids3D(
            centers=[ellipsoid.world_T_E[:3, 3]], half_sizes=[ellipsoid.axes], quaternions=[q],
            colors=[(160, 160, 160)], line_radii=0.0008, labels=[f"iteration {it}"]))
        groups = {"completed": [T for T, s in views if s == "completed"],
                  "infeasible": [T for T, s in views if s == "infeasible"],
                  "planned": list(candidates), "active": [] if selected is None else [selected]}
        for status, poses in groups.items():
            origins, vectors = S.view_arrows(poses)
            self.rec.log(f"viewplan/views/{status}",
                         rr.Arrows3D(origins=origins, vectors=vectors, colors=[S.STATUS_RGB[status]], radii=0.003))
        self._line(f"iteration {it}: {len(candidates)} candidate views planned, "
                   f"{len(groups['infeasible'])} infeasible so far")

    # ------------------------------------------------------------------ results
    def registration(self, result) -> None:
        """The cropped clouds of every registered scan at their global poses (before) and at
        their final poses (after local registration), in the output frame."""
        rr = self.rr
        self._at(self.clock)
        out_T_marker = result.out_T_marker
        for rec, cloud in zip(result.used, result.clouds, strict=True):
            after = np.asarray(cloud.points)
            before = after
            if rec.final_marker_T_camera is not None and rec.pose is not None:
                move = rec.pose.marker_T_camera @ np.linalg.inv(rec.final_marker_T_camera)
                before = after @ move[:3, :3].T + move[:3, 3]
            sub = slice(None, None, max(1, len(after) // 20_000))
            for stage, pts in (("before", before), ("after", after)):
                w = pts[sub] @ out_T_marker[:3, :3].T + out_T_marker[:3, 3]
                self.rec.log(f"registration/{stage}/{self.group}scan_{rec.index:04d}", rr.Points3D(w.astype(np.float32),
                                                                                      radii=0.0006))
            source = rec.pose.source.value if rec.pose is not None else "-"
            self._line(f"scan {rec.index}: pose from {source}")

    def mesh(self, entity: str, mesh, color=(200, 200, 205), static: bool = False) -> None:
        """An Open3D triangle mesh (normals computed when missing)."""
        if not mesh.has_vertex_normals():
            mesh.compute_vertex_normals()
        if not static:
            self._at(self.clock)
        self.rec.log(entity, self.rr.Mesh3D(vertex_positions=np.asarray(mesh.vertices, np.float32),
                                            triangle_indices=np.asarray(mesh.triangles, np.uint32),
                                            vertex_normals=np.asarray(mesh.vertex_normals, np.float32),
                                            albedo_factor=[*color, 255]), static=static)

    def distances(self, points: np.ndarray, d: np.ndarray) -> None:
        """Points of the fused cloud coloured by their signed distance to the ground truth."""
        self._at(self.clock)
        self.rec.log("reconstruction/distances",
                     self.rr.Points3D(np.asarray(points, np.float32), colors=S.distance_colors(d), radii=0.0006))
        self._line(
            f"signed distances to the ground truth: mean {np.mean(d) * 1e3:+.3f} mm, std {np.std(d) * 1e3:.3f} mm "
            f"(colours: blue -{S.DISTANCE_RANGE_M * 1e3:.1f} mm, white 0, red +{S.DISTANCE_RANGE_M * 1e3:.1f} mm)")

    def sides(self, clouds: dict[str, np.ndarray], text: str) -> None:
        """Both sides' clouds (N, 3) as registered onto each other (side 1 blue, side 2
        orange), and a line with the registration's confidence."""
        self._at(self.clock)
        for (name, points), color in zip(clouds.items(), ((31, 119, 180), (255, 127, 14)), strict=False):
            sub = slice(None, None, max(1, len(points) // 50_000))
            self.rec.log(f"sides/{name}", self.rr.Points3D(np.asarray(points[sub], np.float32), colors=[color],
                                                           radii=0.0006))
        self._line(text)

    # ------------------------------------------------------------------ end
    def close(self) -> None:
        """Flush and close the file (idempotent)."""
        if not self._closed:
            self._closed = True
            if self.scans:  # the layout again, now that the scans' depth images are known
                self.rec.send_blueprint(self._layout())
            self.rec.flush()
            self.rec.disconnect()

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
