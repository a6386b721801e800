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

The turn and the merge are those of a script's ``<turn_over/>`` too (recon_cli/both_sides.py).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from recon_cli.backends.station_file import load_station
from recon_cli.both_sides import (
    SIDES_VOXEL,
    Ask,
    SideModel,
    any_way_up_box,
    confidence_line,
    merge_sides,
    turn_object,
    turn_rng,
)
from recon_cli.errors import ReconError
from recon_cli.inputs.meshes import read_cloud
from recon_cli.objects import SceneObject, load_object
from recon_cli.reconstruction.sides import SideRegistration
from recon_cli.recording import closing, open_recorder
from recon_cli.recording.results import record_sides
from recon_cli.report import write_page_after_run
from recon_cli.runs import sides as sides_file
from recon_cli.session import resolve_object_name
from recon_cli.viewplan.policy import Status
from recon_cli.workflows.autoscan import Autoscan, AutoscanOptions, AutoscanResult, SidePrior


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
    page: Path | None = None  # report.html of both sides (None: not written)


class TwoSided:
    """Both sides of an object (see the module docstring)."""

    def __init__(self, opt: AutoscanOptions, progress: Callable[[str, int, int], None] | None = None,
                 ask: Ask | None = None) -> None:
        self.opt = opt
        self.progress = progress or (lambda *a: None)
        self.ask = ask  # the operator prompt of a real cell (None: a prompt in the terminal)
        self.rng = turn_rng(opt.config.seed)

    def _object(self) -> SceneObject:
        cfg = self.opt.config
        if self.opt.scene_object is not None:
            return self.opt.scene_object
        return load_object(resolve_object_name(cfg.scene.object_name), cfg.scene.object_scale,
                           cfg.cell.cell_file.object_position)

    def _simulated(self) -> bool:
        return self.opt.station is None or load_station(self.opt.station).capabilities.simulated

    def run(self) -> TwoSidedResult:
        """Both sides, merged; the page of the folder is written once the sides report is,
        however the merge ended."""
        try:
            result = self._run()
        except ReconError:
            self._page()
            raise
        if not result.interrupted:
            result.page = self._page()
        return result

    def _page(self) -> Path | None:
        if not (self.opt.page and (self.opt.out / sides_file.SIDES_REPORT).is_file()):
            return None
        written = write_page_after_run(self.opt.out)
        return None if written is None else written.path

    def _run(self) -> TwoSidedResult:
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
            turn = turn_object(first, self._simulated(), self.rng, self.ask, side1.cloud)
        except KeyboardInterrupt:
            return self._stopped((side1,), t0)
        box = None
        if turn.scene_object is None and side1.cloud is not None:  # a real cell: around what side 1 saw
            box = any_way_up_box(side1.cloud, opt.config.scene.box_margin)
        side2 = Autoscan(replace(side_opt, out=opt.out / "side_2", scene_object=turn.scene_object, box=box,
                                 prior=self._prior(side1)), self.progress).run()
        if side2.interrupted:
            return self._stopped((side1, side2), t0)
        return self._merge(first, turn.scene_object, (side1, side2), turn.record, t0)

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
        models = [SideModel(s.cloud, s.scans, s.seconds) for s in sides if s.cloud is not None]
        if len(models) != len(sides):
            raise ReconError("a side has no registered cloud: the sides cannot be merged",
                             hint="see side_1/autoscan_report.json and side_2/autoscan_report.json")
        merged = merge_sides(opt.out, (models[0], models[1]), first, second, turn, cfg.registration.surface,
                             cfg.seed, t0, mesh=opt.mesh, prior=sides[1].prior)
        if opt.record:  # the sides as registered onto each other, beside each side's own recording
            recorder = open_recorder(opt.out, f"{first.name}: two sides")
            with closing(recorder):
                record_sides(recorder, (models[0].cloud, models[1].cloud), merged.registration.side1_T_side2,
                             confidence_line(merged.registration))
        if merged.error is not None:
            raise merged.error
        return TwoSidedResult(opt.out, sides, merged.registration, merged.cloud, merged.mesh, merged.report,
                              time.perf_counter() - t0, merged.coverage)
