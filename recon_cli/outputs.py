"""Output folders: one owner for every folder recon writes; nothing lands outside it,
nothing is half-written, nothing is written, replaced or deleted through a link.

* :func:`claim_output` is how every command takes its output folder (``--out``) before it
  does any work: a new or empty folder (:attr:`OutputMode.NEW`), a folder the command adds
  to (:attr:`OutputMode.APPEND`: ``recon run --append``, ``recon capture --append``,
  ``recon batch --resume``, the page ``recon report`` writes into a run folder), or one
  whose earlier recon results are removed first (:attr:`OutputMode.FORCE`: ``--force``).
  What FORCE removes is the table :data:`WRITTEN`: the names recon writes at the top of an
  output folder, whichever command wrote them; links among them are removed as links
  (never followed), folders without following the links inside them, and every other
  entry stays;
* :func:`inside` turns a relative name from a script into a path inside the output folder
  and refuses names that leave it, directly (``..``, absolute paths) or through links
  already in the folder;
* :func:`refuse_links` checks a folder that is being added to for links, so that no later
  write can follow one out of it; :func:`refuse_leaving` refuses an output folder inside a
  run folder that a link leads out of (``recon evaluate RUN`` into ``RUN/reconstruction``);
* :func:`remove_inside` removes an entry of an output folder without following a link;
* :func:`keep_earlier` renames an earlier run's report (``NAME-1``, ``NAME-2``, ...)
  before an appending run writes its own;
* :func:`atomic_write` writes to a fresh temporary file beside the target (created
  exclusively, so never through a link) and renames it into place: a reader sees the old
  file or the new one, never a part, and a crash leaves no broken file.
"""

from __future__ import annotations

import contextlib
import fnmatch
import os
import shutil
import tempfile
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from datetime import datetime
from enum import StrEnum
from pathlib import Path

from recon_cli.errors import FileError, InputError, ReconError
from recon_cli.inputs.files import link_out_of
from recon_cli.inputs.jsonfile import load_json


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


_MODE = 0o666 & ~_umask()  # what open() would give a new file

#: the folder that holds the default output folders (``runs/<command>-<time>``)
RUNS = Path("runs")

#: What recon writes at the top of an output folder, by writer (glob patterns). ``--force``
#: removes exactly the entries that match one of them, and recon's hidden temporary files
#: of them (``.NAME.*``), whichever command wrote them, so that a forced run never mixes
#: its results with an earlier one's; everything else in the folder stays.
WRITTEN: dict[str, tuple[str, ...]] = {
    "scan store (capture, autoscan, calibrate handeye, run's scans/)": (
        "session.json", "scan_[0-9][0-9][0-9][0-9]*", "ground_truth", "config.yaml", "config-[0-9]*.yaml"),
    "report page": ("report.html", "report_files"),
    "3D recording (--record)": ("recording.rrd", "recording-[0-9]*.rrd"),
    "recon capture": ("capture_report.json", "capture_report-[0-9]*.json"),
    "recon run": ("scans", "reconstruction", "run_report.json", "run_report-[0-9]*.json", "script.expanded.xml",
                  "script.expanded-[0-9]*.xml"),
    "recon autoscan": ("reconstruction", "autoscan_report.json", "iterations"),
    "two sides (autoscan --sides 2, <turn_over/>)": ("side_1", "side_2", "sides_report.json"),
    "recon register": ("cloud.ply", "cloud_global.ply", "mesh.ply", "report.json"),
    "recon evaluate": ("*_evaluation.json", "*_distances.png"),
    "recon replay": ("store", "reconstruction", "consistency.json", "cloud.png"),
    "recon calibrate": ("scans", "handeye.json", "hand_eye.yaml", "handeye_residuals.png", "intrinsics.yaml",
                        "intrinsics.json", "intrinsics_reprojection.png", "realism.yaml"),
    "recon batch": ("batch.json", "jobs", "junit.xml", "summary.json", "summary.md", "index.html", ".lock"),
    "recon bench": ("bench_*.json", "requests.csv", "plan_times.png", "peer", "eq_4_1_views.png", "scans",
                    "case_[0-9]*", "distances.png", "t_p_ecdf.png", "tour_gap.png", "coverage.png",
                    "*_ellipsoid", "*_ellipsoid_face_on", "*_sphere", "*_random", "stage_profile.png",
                    "profiled_autoscan", "profiled_autoscan.pstats"),
    "every command": (".write-test*",),
}
_PATTERNS = tuple(dict.fromkeys(p for names in WRITTEN.values() for p in names))


def written_by_recon(name: str) -> bool:
    """Whether recon writes an entry of this name at the top of an output folder (or it is
    one of recon's hidden temporary files of such an entry)."""
    if any(fnmatch.fnmatchcase(name, p) for p in _PATTERNS):
        return True
    return name.startswith(".") and any(fnmatch.fnmatchcase(name[1:], f"{p}.*") for p in _PATTERNS)


class OutputMode(StrEnum):
    """How a command takes its output folder."""

    NEW = "new"  #: the folder must be new or empty
    APPEND = "append"  #: add to what is there (no link anywhere in the folder)
    FORCE = "force"  #: remove what recon wrote there first (:data:`WRITTEN`), keep the rest

    @classmethod
    def of(cls, append: bool = False, force: bool = False, *, append_option: str = "--append",
           force_option: str = "--force") -> OutputMode:
        """The mode of a command's ``--append`` / ``--force`` flags."""
        if append and force:
            raise InputError(f"{append_option} and {force_option} exclude each other",
                             hint=f"{append_option} adds to the output folder, {force_option} replaces what recon "
                                  "wrote there; pass one of them")
        return cls.APPEND if append else cls.FORCE if force else cls.NEW


@dataclass
class OutputFolder:
    """An output folder a command has claimed (:func:`claim_output`); :meth:`make` makes it
    (and does what FORCE removes) when the command is about to write."""

    path: Path
    mode: OutputMode
    command: str  # who owns it, e.g. "capture"
    removed: tuple[str, ...] = ()  # what FORCE removed (entry names), once made
    pending: tuple[str, ...] = ()  # what FORCE removes when the folder is made
    made: bool = False

    def make(self) -> Path:
        """Remove what FORCE removes, make the folder and check that it is writable; the
        path. Only the first call does anything."""
        if not self.made:
            for name in self.pending:
                if name == ".":
                    _remove(self.path)  # a link where recon's folder goes: the link only
                else:
                    remove_inside(self.path, name)
            names = tuple(self.path.name if n == "." else n for n in self.pending)
            self.removed, self.pending = self.removed + names, ()
            _make(self.path)
            self.made = True
        return self.path

    def inside(self, name: str | Path, what: str = "output") -> Path:
        """``path / name``, refused unless it stays inside the folder (:func:`inside`)."""
        return inside(self.path, name, what)

    def keep_earlier(self, *names: str) -> list[Path]:
        """APPEND: an earlier run's files of these names stay, as NAME-1, NAME-2, ..."""
        return keep_earlier(self.path, *names)

    def __fspath__(self) -> str:
        return os.fspath(self.path)


def claim_output(path: Path | None, mode: OutputMode = OutputMode.NEW, *, command: str,
                 append: str | None = None, force: str | None = "--force", nested_in: Path | None = None,
                 inputs: Iterable[Path | None] = (), names: tuple[str, ...] | None = None,
                 within: Path | None = None, make: bool = True, default: str | None = None) -> OutputFolder:
    """Take the output folder of ``command`` (see the module docstring); call it before any
    planning, robot or registration work, so that a refusal costs nothing.

    path: ``--out``; None: a new folder ``runs/<default>-<time>`` (default: the command's
        name, words joined by "-")
    append: how a refusal names the command's way to add to a folder, e.g. "--append to add
        this run's scans to the scan store in it"; None: the command cannot append
    force: the command's option for FORCE, named in a refusal; None: it has none
    nested_in: the folder is recon's choice inside this folder (``recon register DIR`` writes
        ``DIR/reconstruction``), so it may not be a link: refused, and FORCE replaces the
        link (not what it points to) by a folder
    inputs: what the command reads: FORCE never removes one, nor a folder that holds one,
        nor works in a folder that is one
    names: APPEND into an existing folder another command wrote: the names this command
        writes there (only they must not be links)
    within: the run folder the output folder is recon's choice in (``recon evaluate RUN``
        writes into ``RUN/reconstruction``): refused, before anything is written, when the
        folder is or lies behind a link leading out of it (the link is named, not where it
        leads)
    make: make the folder now (and remove what FORCE removes); False: everything is checked
        now, and :meth:`OutputFolder.make` does it when the command is about to write
    """
    if path is None:
        return OutputFolder(_new_default(default or command.replace(" ", "-")), OutputMode.NEW, command, made=True)
    path = Path(path)
    if within is not None:
        refuse_leaving(path, Path(within))
    pending: tuple[str, ...] = ()
    if nested_in is not None and path.is_symlink():
        if mode is not OutputMode.FORCE:
            replace = f", pass {force} to replace it by a folder" if force else ""
            raise FileError(f"output folder {path} is a link to {os.readlink(path)}; recon does not write through "
                            "links", hint=f"remove the link{replace} or choose another folder with --out")
        pending = (".",)  # the link, never what it points to
    elif path.is_symlink() and not path.exists():
        raise FileError(f"output folder {path} is a link to a missing folder ({os.readlink(path)})",
                        hint="make the folder it points to, or choose another folder with --out")
    elif path.exists() and not path.is_dir():
        raise FileError(f"output folder {path} is a file", hint="choose a new folder with --out")
    if names is not None:
        if not path.is_dir():
            what = "is not a folder" if path.exists() else "does not exist"
            raise FileError(f"{path} {what}", hint="give the folder a recon command wrote")
        for name in names:
            if (path / name).is_symlink():
                raise FileError(f"{path / name} is a link to {os.readlink(path / name)}; recon does not write "
                                "through links", hint="remove the link")
        return OutputFolder(path, OutputMode.APPEND, command, made=True)
    entries = sorted(os.listdir(path)) if not pending and path.is_dir() else []
    if entries and mode is OutputMode.NEW:
        shown = ", ".join(entries[:3]) + (f" and {len(entries) - 3} more" if len(entries) > 3 else "")
        ways = " or ".join(w for w in (append, force and f"{force} to replace what recon wrote there") if w)
        raise FileError(f"output folder {path} is not empty (it holds {shown})",
                        hint=(f"pass {ways}, or " if ways else "") + "choose a new folder with --out")
    if entries and mode is OutputMode.APPEND:
        refuse_links(path)
    if entries and mode is OutputMode.FORCE:
        pending = _written(path, [Path(p) for p in inputs if p is not None], force or "--force")
    folder = OutputFolder(path, mode, command, pending=pending)
    if make:
        folder.make()
    return folder


def _new_default(name: str) -> Path:
    """A new folder ``runs/<name>-<time>`` (``-2``, ``-3``, ... when that exists)."""
    stamp = f"{name}-{datetime.now():%Y%m%d-%H%M%S}"
    for k in range(1, 1000):
        path = RUNS / (stamp if k == 1 else f"{stamp}-{k}")
        try:
            path.mkdir(parents=True)
            _MADE.append(path)
        except FileExistsError:
            continue
        except OSError as exc:
            raise FileError(f"cannot make the output folder {path} ({exc.strerror})",
                            hint="choose a folder with --out") from None
        _make(path)
        return path
    raise FileError(f"too many output folders named {stamp}-N in {RUNS}", hint="choose a folder with --out")


#: output folders this process made; those still empty when a command fails are removed
_MADE: list[Path] = []


def remove_empty_made() -> None:
    """Remove the output folders this process made that are still empty (a command that
    failed before writing anything leaves no trace); a folder with anything in it stays."""
    while _MADE:
        with contextlib.suppress(OSError):
            os.rmdir(_MADE.pop())


def _make(path: Path) -> None:
    """Make the folder (and its parents) and check that a file can be made in it."""
    try:
        missing = [p for p in (path, *path.parents) if not p.exists()]
        path.mkdir(parents=True, exist_ok=True)
        _MADE.extend(reversed(missing))  # the deepest is removed first
        fd, probe = tempfile.mkstemp(prefix=".write-test", dir=path)  # created exclusively: never through a link
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise FileError(f"output folder {path} is not writable ({exc.strerror})",
                        hint="choose another folder with --out") from None


def _written(folder: Path, inputs: list[Path], force: str) -> tuple[str, ...]:
    """FORCE: what recon wrote in ``folder`` (:data:`WRITTEN`, and the exports an earlier
    script run's reports list), refused when an input of the command goes with it."""
    real_inputs = [p.resolve() for p in inputs]
    if folder.resolve() in real_inputs:
        raise FileError(f"{force} would remove recon's files from {folder}, which this command reads",
                        hint="choose another output folder with --out")
    victims = [name for name in sorted(os.listdir(folder)) if written_by_recon(name)]
    victims += [e for e in _recorded_exports(folder) if e not in victims]
    for name in victims:
        p = folder / name
        if p.is_symlink():
            continue  # only the link goes
        real = p.resolve()
        for i in real_inputs:
            if i == real or i.is_relative_to(real):
                raise FileError(f"{force} would remove {p}, which this command reads ({i})",
                                hint="choose another output folder with --out")
    return tuple(victims)


def _recorded_exports(folder: Path) -> list[str]:
    """The exports (relative paths) that earlier script runs in ``folder`` wrote, as their
    ``run_report*.json`` list them."""
    out: list[str] = []
    base = Path(os.path.abspath(folder))
    for report in sorted(folder.glob("run_report*.json")):
        if report.is_symlink() or not report.is_file():
            continue

        try:
            outputs = load_json(report, "run report").get("outputs") or {}
        except (ReconError, AttributeError):
            continue
        for value in outputs.values() if isinstance(outputs, dict) else ():
            if not isinstance(value, str):
                continue
            p = Path(value)
            for candidate in (Path(os.path.abspath(p)), Path(os.path.abspath(folder.parent / p))):
                if candidate.is_relative_to(base) and candidate != base:
                    rel = candidate.relative_to(base)
                    if ".." not in rel.parts and ((folder / rel).is_file() or (folder / rel).is_symlink()):
                        out.append(str(rel))
                    break
    return list(dict.fromkeys(out))


def remove_inside(root: Path, name: str | Path) -> bool:
    """Remove ``root / name`` without following a link: a link is removed as a link, a
    folder with everything in it (links in it removed as links, never followed); refused
    when a folder on the way to it is a link. False when there was nothing to remove."""
    root, rel = Path(root), Path(name)
    if rel.is_absolute() or ".." in rel.parts or not rel.parts:
        raise FileError(f"{name} is not a name inside {root}", hint="give a path relative to the folder")
    probe = root
    for part in rel.parts[:-1]:
        probe = probe / part
        if probe.is_symlink():
            raise FileError(f"{root / rel} lies behind the link {probe} -> {os.readlink(probe)}; recon does not "
                            "delete through links", hint="remove the link")
    target = root / rel
    if not (target.is_symlink() or target.exists()):
        return False
    _remove(target)
    return True


def _remove(path: Path) -> None:
    try:
        if path.is_symlink() or not path.is_dir():
            path.unlink()
        elif shutil.rmtree.avoids_symlink_attacks:
            shutil.rmtree(path)
        else:  # no descriptor-based rmtree here: remove bottom-up, links as links
            for dirpath, dirnames, filenames in os.walk(path, topdown=False):
                for n in filenames:
                    os.unlink(os.path.join(dirpath, n))
                for n in dirnames:
                    p = os.path.join(dirpath, n)
                    if os.path.islink(p):
                        os.unlink(p)
                    else:
                        os.rmdir(p)
            os.rmdir(path)
    except OSError as exc:
        raise FileError(f"cannot remove {path} ({exc.strerror})",
                        hint="check the permissions of the output folder") from None


def keep_earlier(folder: Path, *names: str) -> list[Path]:
    """An earlier run's files of these names stay, renamed to NAME-1, NAME-2, ... (the
    stem numbered, the suffix kept); returns the new names."""
    kept = []
    folder = Path(folder)
    for name in names:
        path = folder / name
        if path.is_symlink() or path.exists():
            k = 1
            while (folder / f"{path.stem}-{k}{path.suffix}").exists():
                k += 1
            target = folder / f"{path.stem}-{k}{path.suffix}"
            path.rename(target)
            kept.append(target)
    return kept


def _within(path: Path, root: Path) -> bool:
    return path == root or path.is_relative_to(root)


def inside(root: Path, name: str | Path, what: str = "output") -> Path:
    """``root / name``, refused unless it stays inside ``root`` after resolving links."""
    root = Path(root)
    real_root = root.resolve()
    rel = Path(name)
    if rel.is_absolute() or str(name).startswith("~"):
        raise FileError(f"{what} {name} is an absolute path", hint="give a path relative to the output folder")
    target = root / rel
    # every part that exists already must resolve inside the folder
    probe = root
    for part in rel.parts:
        probe = probe / part
        if probe.is_symlink() or probe.exists():
            real = probe.resolve()
            if not _within(real, real_root):
                raise FileError(f"{what} {name} would be written outside the output folder {root} "
                                f"({probe} leads to {real})",
                                hint="remove the link or choose an empty output folder")
        elif part == "..":
            raise FileError(f"{what} {name} leaves the output folder", hint="give a path inside the output folder")
    if not _within(target.resolve(), real_root):
        raise FileError(f"{what} {name} leaves the output folder {root}", hint="give a path inside the output folder")
    if target.is_symlink():
        raise FileError(f"{what} {target} is a link; recon does not write through links",
                        hint="remove the link or choose an empty output folder")
    return target


def refuse_leaving(path: Path, run: Path) -> None:
    """Refuse (FileError) an output folder that is, or lies behind, a link leading out of the
    run folder ``run`` it belongs to: nothing is written through it. The message names the
    link inside the run, never where it leads."""
    link = link_out_of(path, run)
    if link is None:
        return
    where = (f"lies behind the link {link}, which leads out of" if link != path
             else "is a link leading out of" if path.is_symlink() else "lies outside")
    raise FileError(f"output folder {path} {where} the run folder {run}; recon does not write through links",
                    hint="remove the link, or choose an output folder with --out")


def refuse_links(root: Path) -> None:
    """Refuse a folder that holds a link anywhere in it (a later write could follow it out)."""
    root = Path(root)
    if root.is_symlink():
        return  # the folder itself may be reached through a link; what is inside counts
    for dirpath, dirnames, filenames in os.walk(root):
        for name in (*dirnames, *filenames):
            p = Path(dirpath) / name
            if p.is_symlink():
                raise FileError(f"output folder {root} holds a link {p} -> {os.readlink(p)}; recon does not write "
                                "through links", hint="remove the link or choose an empty output folder")


def atomic_write(path: Path, write: Callable[[Path], object], mode: int | None = None) -> Path:
    """Call ``write(tmp)`` for a fresh temporary file beside ``path``, then rename it to
    ``path`` (replacing a file, never following a link); ``mode``: its permission bits
    (default: those of a new file)."""
    path = Path(path)
    fd, tmp_name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=path.suffix or ".tmp", dir=path.parent)
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        write(tmp)
        os.chmod(tmp, _MODE if mode is None else mode)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise
    return path


def atomic_write_text(path: Path, text: str) -> Path:
    return atomic_write(path, lambda tmp: tmp.write_text(text))
