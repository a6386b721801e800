"""What a recording holds, read back with rerun's own reader (``rerun.chunk.RrdReader``):
the entities, how many scans, moves, clouds and iterations, the joints' samples over the
robot's time. ``recon view`` prints it; the tests check recordings with it."""

from __future__ import annotations

import re
import warnings
from dataclasses import dataclass, field
from pathlib import Path

from recon_cli.errors import FileError
from recon_cli.inputs.images import native_output_captured
from recon_cli.recording.recorder import TIMELINE
from recon_cli.recording.sdk import recording_file, require_rerun


@dataclass
class RecordingSummary:
    path: Path
    size_bytes: int
    entities: set[str] = field(default_factory=set)
    joint_samples: dict[str, int] = field(default_factory=dict)  # joint -> rows on the robot_time timeline
    time_range_s: tuple[float, float] = (0.0, 0.0)  # robot time covered [s]
    camera_poses: int = 0  # scan frustums (pinhole + pose)
    clouds: int = 0  # scans' clouds in the world
    moves: int = 0  # executed moves (camera paths)
    iterations: int = 0  # autoscan iterations (ellipsoids logged)
    mesh: bool = False
    registered: int = 0  # scans with clouds before and after registration
    distances: bool = False  # signed distances to the ground truth
    sides: int = 0  # an object's sides, registered onto each other

    @property
    def scans(self) -> list[str]:
        return sorted({m.group(1) for e in self.entities
                       if (m := re.match(r"/world/scans/((?:side_\d+/)?scan_\d+)/", e))})

    def describe(self) -> str:
        t0, t1 = self.time_range_s
        parts = [f"{len(self.scans)} scans", f"{self.moves} moves", f"robot time {t0:.1f} ... {t1:.1f} s"]
        if self.iterations:
            parts.append(f"{self.iterations} view-planning iterations")
        if self.registered:
            parts.append(f"{self.registered} registered clouds")
        if self.mesh:
            parts.append("mesh")
        if self.distances:
            parts.append("signed distances")
        if self.sides:
            parts.append(f"{self.sides} sides registered onto each other")
        return f"{self.path.name}: " + ", ".join(parts) + f" ({self.size_bytes / 1e6:.1f} MB)"


def summarize(path: Path) -> RecordingSummary:
    """Read every chunk of the recording and count what it holds; a file rerun cannot read
    is one :class:`~recon_cli.errors.FileError` line (rerun's warnings kept off the terminal)."""
    require_rerun()
    path = Path(path)
    size = recording_file(path)
    from pyarrow import ArrowException  # rerun's chunks are Arrow record batches


    failure: BaseException | None = None
    with native_output_captured((1, 2), opencv=False) as log, warnings.catch_warnings():
        warnings.simplefilter("ignore")  # e.g. "RRD file has no footer" before a truncated file fails
        try:
            out = _summarize(path, size)
        except (RuntimeError, ValueError, OSError, EOFError, ArrowException) as exc:
            failure = exc
        except BaseException as exc:  # a panic of rerun's reader (pyo3's PanicException is no Exception)
            if type(exc).__name__ != "PanicException":
                raise
            failure = exc
    if failure is not None:
        raise _unreadable(path, " ".join(str(failure).split()) or type(failure).__name__)
    logged = re.findall(r"\bERROR \S+: ([^\n]*)", re.sub(r"\x1b\[[0-9;]*m", "", "".join(log)))
    if logged:  # rerun's decoder logs what it cannot decode (a damaged header, bytes after the last message)
        raise _unreadable(path, logged[0].strip())  # and ends the stream there, as if the file ended
    return out




def _unreadable(path: Path, reason: str) -> FileError:
    reason = re.sub(r"^Failed to read RRD file at .*?: ", "", reason)
    reason = re.sub(r': b"(?:[^"\\]|\\.)*"', "", reason)  # the bytes it could not decode
    return FileError(f"{path} is not a readable rerun recording ({reason[:160]})",
                     hint="it is truncated or damaged; record the run again")


def _summarize(path: Path, size: int) -> RecordingSummary:
    from rerun.chunk import RrdReader

    out = RecordingSummary(path, size)
    times: list[int] = []
    ellipsoid_rows = 0
    for chunk in RrdReader(path).stream():
        entity = chunk.entity_path
        out.entities.add(entity)
        batch = None
        if not chunk.is_static and TIMELINE in chunk.timeline_names:
            batch = chunk.to_record_batch()
            column = batch.column(TIMELINE).cast("int64").to_pylist()
            times += [t for t in column if t is not None]
        if entity.startswith("/cell/joints/"):
            name = entity.rsplit("/", 1)[1]
            out.joint_samples[name] = out.joint_samples.get(name, 0) + chunk.num_rows
        elif entity.startswith("/world/moves/"):
            out.moves += 1
        elif entity == "/viewplan/ellipsoid":
            ellipsoid_rows += chunk.num_rows
        elif entity == "/reconstruction/mesh":
            out.mesh = True
        elif entity == "/reconstruction/distances":
            out.distances = True
    out.camera_poses = sum(1 for e in out.entities if re.fullmatch(r"/world/scans/(side_\d+/)?scan_\d+/camera", e))
    out.clouds = sum(1 for e in out.entities if re.fullmatch(r"/world/scans/(side_\d+/)?scan_\d+/cloud", e))
    out.registered = sum(1 for e in out.entities if e.startswith("/registration/after/"))
    out.iterations = ellipsoid_rows
    out.sides = sum(1 for e in out.entities if re.fullmatch(r"/sides/side_\d", e))
    if times:
        out.time_range_s = (min(times) * 1e-9, max(times) * 1e-9)
    return out
