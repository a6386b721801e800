"""``recon capture``: move the robot through views and take one scan at each.

Views that cannot be reached (IK or planning fails) are reported and skipped; scans already
written stay. ``cover_board`` lists views (1-based) at which a plain sheet lies over the
ChArUco board (simulation), so registration must fall back to kinematics there.

Beside the scan store: ``capture_report.json`` (views, scans, the skipped views and why,
how the capture ended) and the report page ``report.html``, written also when a capture
ends early (Ctrl-C, a fault).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path

import numpy as np

from recon_cli.acquisition import MoveReport, view_record
from recon_cli.config import DEFAULTS, Config
from recon_cli.errors import ReconError
from recon_cli.geometry.view import View
from recon_cli.objects import SceneObject
from recon_cli.outputs import keep_earlier, refuse_links
from recon_cli.reconstruction.scan_store import Scan
from recon_cli.recording import closing, open_recorder
from recon_cli.report import write_page_after_run
from recon_cli.runs import capture as capture_file
from recon_cli.runs.capture import CAPTURE_REPORT, ViewFailure
from recon_cli.session import Backend, Mode, SessionSpec, open_session


@dataclass(frozen=True)
class CaptureOptions:
    views: tuple[View, ...]
    out: Path
    config: Config = DEFAULTS
    backend: Backend = Backend.SIM
    cover_board: frozenset[int] = frozenset()  # 1-based views with the board covered (simulation)
    run: dict = field(default_factory=dict)  # recorded in config.yaml
    station: Path | None = None  # a station file (robot and camera adapters)
    record: bool = False  # write a 3D recording of the run (recording.rrd in ``out``)
    page: bool = True  # write the report page (report.html) at the end
    append: bool = False  # add to the scan store in ``out`` (same cell and object); earlier reports kept as NAME-1


class CaptureStatus(StrEnum):
    DONE = "done"  # every view scanned
    INCOMPLETE = "incomplete"  # some views skipped (unreachable, no path)
    FAILED = "failed"  # no scan, or an error ended the capture
    INTERRUPTED = "interrupted"  # Ctrl-C or SIGTERM


@dataclass(frozen=True)
class CaptureResult:
    folder: Path
    scans: list[Scan]
    moves: list[MoveReport]
    failures: list[ViewFailure]
    capture_seconds: list[float]
    total_seconds: float
    scene_object: SceneObject
    report: Path | None = None  # capture_report.json
    page: Path | None = None  # report.html (None: not written)

    @property
    def points(self) -> list[int]:
        return [int(np.count_nonzero(s.depth > 0)) for s in self.scans]


def run_capture(opt: CaptureOptions, progress: Callable[[str, int, int], None] | None = None
                ) -> CaptureResult:
    t0 = time.perf_counter()
    n = len(opt.views)
    step = (lambda k: progress("capture", k, n)) if progress else (lambda k: None)
    scans, moves, failures, capture_seconds = [], [], [], []
    if opt.append:

        refuse_links(opt.out)
        keep_earlier(opt.out, CAPTURE_REPORT, "config.yaml", "recording.rrd")
    recorder = open_recorder(opt.out, "recon capture") if opt.record else None
    spec = SessionSpec(opt.out, opt.config, Mode.CAPTURE, opt.backend, run=opt.run, station=opt.station,
                       recorder=recorder, append=opt.append)
    ended: CaptureStatus | None = None
    error: str | None = None
    report: Path | None = None
    page: Path | None = None
    scene_object: SceneObject | None = None  # set when the session is open
    try:
        with closing(recorder), open_session(spec) as session:
            cell, acq, station, scene_object = session.cell, session.acquisition, session.station, session.scene_object
            assert acq is not None and station is not None and scene_object is not None  # an open session of an object
            for k, view in enumerate(opt.views, start=1):
                try:
                    T = cell.view_pose(view)
                    move = acq.move_to_pose(T, what=f"view {k}")
                except ReconError as exc:  # unreachable or unplannable view: report, go on
                    failures.append(ViewFailure(k, str(exc)))
                    step(k)
                    continue
                if station.capabilities.cover_board:
                    station.cover_board(k in opt.cover_board)
                t_cap = time.perf_counter()
                scans.append(acq.scan(view_record(view, T), move))
                capture_seconds.append(time.perf_counter() - t_cap)
                moves.append(move)
                step(k)
    except KeyboardInterrupt:
        ended = CaptureStatus.INTERRUPTED
        raise
    except ReconError as exc:
        ended, error = CaptureStatus.FAILED, exc.one_line()
        raise
    finally:
        seconds = time.perf_counter() - t0
        if scene_object is not None:  # the session was opened: report what it did
            if ended is None:
                ended = CaptureStatus.DONE if len(scans) == n else \
                    CaptureStatus.INCOMPLETE if scans else CaptureStatus.FAILED
            report, page = _write_report(opt, ended, len(scans), failures, seconds, error)
    assert scene_object is not None  # no error: the session was opened
    return CaptureResult(opt.out, scans, moves, failures, capture_seconds, seconds, scene_object, report, page)


def _write_report(opt: CaptureOptions, status: CaptureStatus, scans: int, failures: list[ViewFailure],
                  seconds: float, error: str | None) -> tuple[Path, Path | None]:
    """capture_report.json and (when asked) the report page."""

    report = capture_file.write(opt.out, capture_file.CaptureReport(
        status=status.value, views=len(opt.views), scans=scans, seconds=seconds, error=error,
        failures=tuple(failures)))
    page = None
    if opt.page:

        written = write_page_after_run(opt.out)
        page = None if written is None else written.path
    return report, page
