"""An object scanned on both sides: turned over between them, its two side models merged.

Shared by ``recon autoscan --sides 2`` (recon_cli/workflows/two_sided.py) and scripts with
``<turn_over/>`` (recon_cli/scripts/handlers/sides.py):

- :func:`turn_object`: in simulation MuJoCo turns the object over onto the stable face of its
  hull that :class:`MissedSurface` ranks first (the one that shows most of what side 1
  missed while side 1's surface still fixes the registration) and lets it settle
  (recon_cli/backends/sim/turnover.py); on a real cell the operator is asked in the terminal
  while the robot waits at its home posture (Ctrl-C at the prompt is a KeyboardInterrupt);
- :func:`any_way_up_box`: the crop and collision box of a turned object whose pose nobody
  measured (a real cell): a cube around what side 1 saw, large enough for any way up;
- :func:`merge_sides`: the two side models registered by shape
  (recon_cli/reconstruction/sides.py), merged into one cloud and Poisson mesh
  (``reconstruction/``), and ``sides_report.json`` with the registration's confidence and, in
  simulation, its error against the true turn (and against the pose that puts the two
  clouds onto each other as they are, each side's own errors removed), the coverage of the
  whole surface and the accuracy of the merged cloud;
- :func:`confidence_line`: the registration's confidence in one line for the terminal.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from recon_cli.backends.sim.resting import Rest
from recon_cli.backends.sim.turnover import turn_over, turned
from recon_cli.console import console
from recon_cli.errors import ReconError
from recon_cli.geometry.transforms import invert, transform_points
from recon_cli.inputs.meshes import read_cloud
from recon_cli.objects import SceneObject
from recon_cli.reconstruction.assessment import align_icp
from recon_cli.reconstruction.evaluation import signed_distances, within_shares
from recon_cli.reconstruction.options import COVERAGE_TOLERANCE, SurfaceOptions
from recon_cli.reconstruction.sides import SideRegistration, register_sides
from recon_cli.reconstruction.surface import poisson_mesh, write_cloud, write_mesh
from recon_cli.runs import sides as sides_file

#: [m] the side registration's voxel
SIDES_VOXEL = 0.003
#: samples of an object's true surface that each side's cloud is aligned to (simulation): a
#: point every millimetre or so on objects of 0.1-0.3 m
ALIGN_SAMPLES = 50_000
#: the turn's random draws come from the run's seed plus this (apart from the run's other draws)
TURN_SEED_OFFSET = 7919
#: samples of the whole surface that rank the faces a turned object can rest on
RANK_SAMPLES = 20_000
#: [m] surface closer than this to the face the object rests on is hidden by the table
HIDDEN_ABOVE = 0.003
#: surface whose normal is within 60 deg of straight down (cos) faces the table: not seen
FACING_DOWN = 0.5
#: side 1's surface still in view after the turn fixes the registration of the sides when its
#: normals spread in every direction: the smallest eigenvalue of their scatter matrix
#: (mean of n n^T; 1/3 for a sphere, 0 for flanks that are all vertical) at least this
CONSTRAINED = 0.05
OPERATOR_PROMPT = ("turn the object over onto another face and put it back on the same spot, then press Enter "
                   "(Ctrl-C stops; the first side's scans are kept)")

Ask = Callable[[str], None]
"""Asks the operator and returns when the object is turned (raises KeyboardInterrupt to stop)."""


def turn_rng(seed: int) -> np.random.Generator:
    """The generator of the physics turn for a run's seed."""
    return np.random.default_rng(seed + TURN_SEED_OFFSET)


@dataclass(frozen=True)
class Turn:
    """How the object was turned over."""

    scene_object: SceneObject | None  # where it lies now (simulation); None: turned by the operator, pose unknown
    record: dict[str, Any]  # by physics (tilt [deg], settle time [s], face down) or by the operator (pause [s])


def _ask_in_terminal(prompt: str) -> None:
    console.print(prompt)
    try:
        input()
    except EOFError:
        raise ReconError("nobody can be asked to turn the object over: the standard input is closed",
                         hint="run recon in a terminal on a real cell; the first side's scans are kept") from None


class MissedSurface:
    """Ranks the faces a turned object can rest on (:mod:`recon_cli.backends.sim.resting`)
    by what side 1 missed: the share of the whole surface that side 1's cloud did not come
    within the coverage tolerance of and that faces up or sideways on that face (not within
    60 deg of straight down, more than 3 mm above the table). A face on which side 1's
    surface still in view spreads its normals in every direction (:data:`CONSTRAINED`: the
    two sides' shapes fix their registration; a box upside down shows side 1 only its
    vertical flanks, along which side 2 could slide) ranks before every face that does not."""

    def __init__(self, obj: SceneObject, side_1: Path) -> None:
        import open3d as o3d

        points, normals = obj.surface_samples(RANK_SAMPLES, np.random.default_rng(0), exclude_base=-np.inf)
        seen = read_cloud(side_1, "side 1 cloud", points=False)
        d = np.asarray(o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points)).compute_point_cloud_distance(seen))
        self.covered = d <= COVERAGE_TOLERANCE
        to_object = invert(obj.world_T_object)
        self.points = transform_points(to_object, points)
        self.normals = normals @ to_object[:3, :3].T
        self.vertices = obj.vertices

    def _in_view(self, face: Rest) -> np.ndarray:
        height = float(np.max(self.vertices @ face.down)) - self.points @ face.down
        return (height > HIDDEN_ABOVE) & (self.normals @ face.down < FACING_DOWN)

    def exposed(self, face: Rest) -> tuple[float, float]:
        """The share of the surface side 1 missed that is in view on ``face``, and the
        smallest eigenvalue of the normal scatter of side 1's surface still in view."""
        view = self._in_view(face)
        overlap = self.normals[view & self.covered]
        spread = float(np.linalg.eigvalsh(overlap.T @ overlap / len(overlap))[0]) if len(overlap) >= 100 else 0.0
        return float(np.mean(view & ~self.covered)), spread

    def __call__(self, face: Rest) -> float:
        gain, spread = self.exposed(face)
        return gain + (1.0 if spread >= CONSTRAINED else 0.0)

    def record(self, face: Rest) -> dict[str, float | bool]:
        gain, spread = self.exposed(face)
        return {"missed_by_side_1": float(np.mean(~self.covered)), "missed_in_view": gain,
                "side_1_normal_spread": spread, "registration_fixed": spread >= CONSTRAINED}


def turn_object(obj: SceneObject, simulated: bool, rng: np.random.Generator, ask: Ask | None = None,
                side_1: Path | None = None) -> Turn:
    """The object turned over: by physics in simulation (``obj`` as it lies, the yaw and drop
    drawn from ``rng``; with ``side_1``, side 1's cloud, onto the face :class:`MissedSurface`
    ranks first), by the operator on a real cell (``ask``, default: a prompt in the terminal)."""
    if simulated:
        rank = MissedSurface(obj, side_1) if side_1 is not None else None
        t = turn_over(obj, rng, rank=rank)
        record: dict[str, Any] = {"by": "physics", "tilt_deg": t.tilt_deg, "settle_s": t.settle_s,
                                  "down_object": [float(v) for v in t.down_object], "stable_faces": t.faces,
                                  "faces_tried": t.tried}
        if t.rest is not None:
            record["face"] = t.rest.to_dict() | (rank.record(t.rest) if rank is not None else {})
            # the face put down as a direction of side 1's world: what an operator is told ("upside down")
            record["down_world"] = [float(v) for v in obj.world_T_object[:3, :3] @ t.rest.down]
        return Turn(turned(obj, t), record)
    t0 = time.monotonic()
    (ask or _ask_in_terminal)(OPERATOR_PROMPT)
    return Turn(None, {"by": "operator", "pause_s": time.monotonic() - t0})


def any_way_up_box(side_1: Path, margin: float) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """(centre, size) [m] of a cube standing where the bounding box of side 1's cloud (world
    frame) stood, with edges of its diagonal plus twice ``margin`` [m]: it holds the object
    however it was turned over."""
    pts = np.asarray(read_cloud(side_1, "side 1 cloud", points=False).points)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    d = float(np.linalg.norm(hi - lo)) + 2 * margin
    c = (lo + hi) / 2.0
    return (float(c[0]), float(c[1]), float(lo[2] + d / 2.0)), (d, d, d)


@dataclass(frozen=True)
class SideModel:
    """One side's registered cloud (world frame) and what it took."""

    cloud: Path
    scans: int
    seconds: float  # wall clock of the side [s]


@dataclass(frozen=True)
class MergedSides:
    registration: SideRegistration
    cloud: Path | None  # the merged cloud (None: not merged)
    mesh: Path | None
    report: Path  # sides_report.json
    coverage: float | None  # of the whole surface, the resting faces included (simulation)
    truth: dict[str, float] | None  # the registration's error against the true turn (simulation)
    error: ReconError | None  # why the sides were not merged


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


def _apart(a: np.ndarray, b: np.ndarray, centre: np.ndarray) -> dict[str, float]:
    """Rotation [deg] between two poses, and how far apart [mm] they put ``centre``."""
    dT = a @ invert(b)
    return {"rotation_deg": _angle_deg(dT[:3, :3]),
            "translation_mm": float(np.linalg.norm(dT[:3, :3] @ centre + dT[:3, 3] - centre) * 1e3)}


def merge_sides(out: Path, sides: tuple[SideModel, SideModel], first: SceneObject, second: SceneObject | None,
                turn: dict[str, Any], surface: SurfaceOptions, seed: int, t0: float, *, mesh: bool = True,
                prior: dict | None = None) -> MergedSides:
    """Register side 2 onto side 1 by shape, merge them into ``out/reconstruction/`` (cloud,
    and with ``mesh`` the Poisson mesh of ``surface``) and write ``out/sides_report.json``.

    ``first``: the object as side 1 saw it; ``second``: as side 2 saw it in simulation (then
    the report has the registration's error against the truth, the coverage of the whole
    surface and the accuracy), None on a real cell. ``t0``: ``time.perf_counter()`` at the
    start of side 1. A registration the shape cannot fix is not merged: ``error`` says why
    (the report is written all the same)."""
    import open3d as o3d

    clouds = [read_cloud(s.cloud, f"side {i + 1} cloud", points=False) for i, s in enumerate(sides)]
    down = turn.get("down_world")
    reg = register_sides(clouds[0], clouds[1], SIDES_VOXEL, seed=seed,
                         down_world=None if down is None else np.asarray(down, dtype=float))
    truth = None
    if second is not None:  # side-2 world points onto side 1: W1 inv(W2)
        true_T = first.world_T_object @ invert(second.world_T_object)
        centre = first.world_vertices().mean(axis=0)
        truth = _apart(reg.side1_T_side2, true_T, centre)
        # each side's cloud lies off its true surface by that side's own errors (a realism
        # profile's calibration and kinematic errors); the pose that puts side 2's cloud onto
        # side 1's as they are: inv(D1) true_T D2, with D_k aligning side k's cloud to its truth
        D1, D2 = (align_icp(np.asarray(c.points), obj.mesh_world(), samples=ALIGN_SAMPLES)
                  for c, obj in zip(clouds, (first, second), strict=True))
        clouds_T = invert(D1) @ true_T @ D2
        truth |= {f"clouds_{k}": v for k, v in _apart(reg.side1_T_side2, clouds_T, centre).items()}
    folder = Path(out) / "reconstruction"
    cloud = mesh_path = None
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
        merged = (clouds[0] + second_cloud).voxel_down_sample(surface.voxel)
        cloud = write_cloud(folder / "cloud.ply", merged)
        if mesh:
            m, _ = poisson_mesh(merged, surface)
            mesh_path = write_mesh(folder / "mesh.ply", m)
        if second is not None:
            pts = np.asarray(merged.points)
            shares = _coverages(first, {"merged": pts, "side_1": np.asarray(clouds[0].points),
                                        "side_2": np.asarray(second_cloud.points)}, np.random.default_rng(seed))
            coverage = shares.pop("merged")
            contributions = shares
            d = signed_distances(pts, first.mesh_world())
            accuracy = {"mean_mm": float(d.mean() * 1e3), "std_mm": float(d.std() * 1e3), "within": within_shares(d)}
    report = sides_file.write(out, sides_file.SidesReport(
        object=first.name, sides=2, turn=turn, seconds=time.perf_counter() - t0,
        side_seconds=[float(s.seconds) for s in sides], side_scans=[s.scans for s in sides], side_2_prior=prior,
        registration=sides_file.registration_entry(reg.to_dict(), truth),
        coverage_whole=coverage, contributions=contributions, accuracy=accuracy,
        error=None if error is None else error.one_line(),
        cloud=None if cloud is None else str(cloud), mesh=None if mesh_path is None else str(mesh_path)))
    return MergedSides(reg, cloud, mesh_path, report, coverage, truth, error)


def confidence_line(reg: SideRegistration) -> str:
    """The registration of the sides in one line (fitness, RMSE, overlap, symmetry)."""
    return (f"sides registered by shape: fitness {reg.fitness:.3f}, rmse {reg.rmse * 1e3:.3f} mm, overlap "
            f"{reg.overlap:.2f}" + (", ambiguous (symmetric shape)" if reg.ambiguous else ""))
