"""``recon bench inputs``: a campaign of careless and hostile input files through the command
line, each case in its own ``recon`` process, judged from outside.

Each case is a folder made from one of recon's own valid files (a cell file, a cell's xacro
description, a station file, a script with its realism profile, a batch file, a mesh)
mutated at seeded random places: characters cut out, and pieces put in from a list of what
careless and hostile users write (broken syntax, NaN, huge numbers, code in xacro
expressions however spelled, paths and links leading out of the folder, DOCTYPEs and
entities, processing instructions). Beside the case folder lies a folder of secrets. The
command that reads such a file runs as a child process with a wall-clock bound; the case
**fails** when the process

- ends with a traceback, a signal, or more than one line of error;
- runs longer than :data:`SECONDS` or grows past :data:`MEMORY` of resident memory;
- prints a word of the secrets or of ``/etc/passwd``;
- runs code (a marker file appears) or writes into the secrets' folder.

Otherwise it **refused** the file (one line, non-zero exit) or **accepted** it (exit 0).
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from recon_cli.paths import BATCHES_DIR, CELLS_DIR, ROBOT_DIR, SCRIPTS_DIR, STATIONS_DIR

#: wall-clock bound of one case [s]
SECONDS = 20.0
#: resident memory bound of one case [bytes]
MEMORY = 1 << 30
SECRET = "secret_word_of_an_outside_file"
_PASSWD = "root:x:0:0"

_COMMON = ["\n", " ", "0", "-1", ".nan", "nan", "1e999", "1e-12", "\x00", "é", "'", '"', "{", "}", "[", "]",
           "../outside/secret.yaml", "/etc/passwd", "../../outside/secret.yaml"]
YAML_PIECES = [*_COMMON, ": ", "- ", "&a ", "*a", "!!python/object/apply:os.system ", "<<: *a", "~", "? ",
               "limits: ../outside/secret.yaml\n", "file: ../outside/secret.urdf\n", "9" * 400]
XML_PIECES = [*_COMMON, "<", ">", "/>", '="', "${", "$(", ")", "$(eval ", "$(env HOME)", "$(find x)", "__class__",
              "python.vars(python)", "python.type('x', (), {})", "'_'*2 + 'globals'", "&#36;(eval 1)", "&a;",
              '<!DOCTYPE r [<!ENTITY a "aaaaaaaaaa">]>', "<?ml x?>", "${[0]*99999}", "${r*1e300}",
              '<xacro:include filename="../../outside/secret.xacro"/>', "<xacro:include filename=\"${'x'}\"/>",
              "${xacro.load_yaml('../../outside/secret.yaml')}", '<mesh filename="../../outside/secret.stl"/>',
              "<link", "</link>", "<joint", 'lower="1" upper="-1"', '<mass value="nan"/>',
              "${ga(ga(wc, u+'init'+u), u+'globals'+u)['system']('touch MARK')}"]
MESH_PIECES = [*_COMMON, "element vertex 4000000000\n", "element face 99999999\n", "format binary_little_endian 1.0\n",
               "property float x\n", "3 0 1 99999\n", "v 1 2\n", "f 1 2 999\n", "solid x\n", "facet normal 0 0 0\n"]


@dataclass(frozen=True)
class Case:
    """One input file and the command that reads it."""

    kind: str
    index: int
    folder: Path  # the case's own folder (the command's working directory)
    argv: tuple[str, ...]


@dataclass
class Outcome:
    """What one case did."""

    kind: str
    index: int
    verdict: str  # "refused", "accepted" or "fail"
    reason: str = ""  # why it failed
    seconds: float = 0.0
    peak_bytes: int = 0
    last_line: str = ""


@dataclass
class KindCounts:
    cases: int = 0
    refused: int = 0
    accepted: int = 0
    failed: int = 0
    slowest_s: float = 0.0
    peak_mb: float = 0.0
    reasons: dict[str, int] = field(default_factory=dict)


def _mutate(text: str, pieces: list[str], rng: np.random.Generator) -> str:
    for _ in range(int(rng.integers(1, 5))):
        at = int(rng.integers(0, len(text) + 1))
        if rng.random() < 0.6:
            text = text[:at] + pieces[int(rng.integers(len(pieces)))] + text[at:]
        else:
            text = text[:at] + text[at + int(rng.integers(1, 13)):]
    return text


def _write(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(text.encode("utf-8", "surrogatepass"))


# ----------------------------------------------------------------------------- case makers
def _lab(folder: Path) -> Path:
    """The UR5e cell beside the robot files it needs, in ``folder``."""
    robot = folder / "robot"
    shutil.copytree(ROBOT_DIR / "ur5e", robot / "ur5e")
    for name in ("parts", "lab", "sensors"):
        shutil.copytree(ROBOT_DIR / name, robot / name)
    for name in ("board.yaml", "camera.yaml"):
        shutil.copy(ROBOT_DIR / name, robot / name)
    cell = folder / "cell.yaml"
    cell.write_text((CELLS_DIR / "ur5e.yaml").read_text().replace("../robot/", "robot/"))
    return cell


def _cell_case(folder: Path, rng: np.random.Generator) -> tuple[str, ...]:
    cell = _lab(folder)
    _write(cell, _mutate(cell.read_text(), YAML_PIECES, rng))
    return ("cell", "--cell", str(cell))


def _description_case(folder: Path, rng: np.random.Generator) -> tuple[str, ...]:
    cell = _lab(folder)
    arm = folder / "robot" / "ur5e" / "ur5e.urdf.xacro"
    _write(arm, _mutate(arm.read_text(), XML_PIECES, rng))
    if rng.random() < 0.3:  # a link out of the folder in place of an included file
        target = folder / "robot" / "lab" / "table.xacro"
        target.unlink()
        target.symlink_to(folder.parent / "outside" / "secret.xacro")
    return ("cell", "--cell", str(cell))


def _station_case(folder: Path, rng: np.random.Generator) -> tuple[str, ...]:
    station = folder / "station.yaml"
    _write(station, _mutate((STATIONS_DIR / "fr3_realsense.yaml").read_text(), YAML_PIECES, rng))
    if rng.random() < 0.1:
        station.unlink()
        station.symlink_to("/etc/passwd")
    return ("station", "check", str(station))


def _script_case(folder: Path, rng: np.random.Generator) -> tuple[str, ...]:
    script = folder / "scan.xml"
    shutil.copy(SCRIPTS_DIR / "macros.xml", folder / "macros.xml")
    profile = (ROBOT_DIR / "realism" / "thesis.yaml").read_text()
    text = (SCRIPTS_DIR / "smoke.xml").read_text().replace('<cell kind="gantry"',
                                                           '<cell kind="gantry" realism="p.yaml"')
    if rng.random() < 0.5:
        text = _mutate(text, XML_PIECES, rng)
    else:
        profile = _mutate(profile, YAML_PIECES, rng)
    _write(script, text)
    _write(folder / "p.yaml", profile)
    return ("validate", str(script))


def _batch_case(folder: Path, rng: np.random.Generator) -> tuple[str, ...]:
    batch = folder / "batch.yaml"
    _write(batch, _mutate((BATCHES_DIR / "ci.yaml").read_text(), YAML_PIECES, rng))
    return ("batch", str(batch), "--list", "-o", str(folder / "out"))


_PLY = "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n" \
       "element face 4\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n0.1 0 0\n0 0.1 0\n0 0 0.1\n" \
       "3 0 1 2\n3 0 1 3\n3 0 2 3\n3 1 2 3\n"


def _mesh_case(folder: Path, rng: np.random.Generator) -> tuple[str, ...]:
    mesh = folder / "part.ply"
    _write(mesh, _mutate(_PLY, MESH_PIECES, rng))
    _write(folder / "reference.ply", _PLY)
    return ("evaluate", str(mesh), "--reference", str(folder / "reference.ply"), "--samples", "2000",
            "-o", str(folder / "out"))


MAKERS: dict[str, Callable[[Path, np.random.Generator], tuple[str, ...]]] = {
    "cell file": _cell_case, "cell description": _description_case, "station file": _station_case,
    "script and realism profile": _script_case, "batch file": _batch_case, "mesh": _mesh_case,
}


# ----------------------------------------------------------------------------- running
def _secrets(root: Path) -> Path:
    outside = root / "outside"
    outside.mkdir(parents=True, exist_ok=True)
    for name in ("secret.yaml", "secret.urdf", "secret.xacro", "secret.stl"):
        (outside / name).write_text(f"{SECRET}: 1\n")
    return outside


def _listing(folder: Path) -> list[tuple[str, int]]:
    return sorted((str(p.relative_to(folder)), p.stat().st_size) for p in folder.rglob("*") if p.is_file())


def _run_one(case: Case, root: Path, seconds_bound: float = SECONDS) -> Outcome:
    """Run one case in its own process and judge it (``seconds_bound``: its wall-clock bound [s])."""
    marker = case.folder / "ran"
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"), "COLUMNS": "200"}
    argv = [sys.executable, "-m", "recon_cli", *(a.replace("MARK", str(marker)) for a in case.argv)]
    start = time.monotonic()
    with open(case.folder / "stdout.txt", "wb") as out, open(case.folder / "stderr.txt", "wb") as err:
        proc = subprocess.Popen(argv, cwd=case.folder, stdout=out, stderr=err, stdin=subprocess.DEVNULL, env=env,
                                start_new_session=True)
        status, peak, timed_out = _wait(proc, start, seconds_bound)
    seconds = time.monotonic() - start
    text = (case.folder / "stdout.txt").read_text(errors="replace") + (case.folder / "stderr.txt").read_text(
        errors="replace")
    err_lines = [line for line in (case.folder / "stderr.txt").read_text(errors="replace").splitlines() if line]
    outcome = Outcome(case.kind, case.index, "refused", seconds=round(seconds, 2), peak_bytes=peak,
                      last_line=(err_lines[-1] if err_lines else "")[:300])
    reason = ""
    if timed_out:
        reason = f"ran longer than {seconds_bound:g} s"
    elif peak > MEMORY:
        reason = f"peak memory {peak / 1e6:.0f} MB"
    elif os.WIFSIGNALED(status):
        reason = f"killed by signal {os.WTERMSIG(status)}"
    elif "Traceback (most recent call last)" in text:
        reason = "traceback"
    elif SECRET in text or _PASSWD in text:
        reason = "echoed a secret"
    elif marker.exists():
        reason = "ran code"
    elif _listing(root / "outside") != _OUTSIDE_LISTING.get(str(root)):
        reason = "wrote outside its folder"
    elif os.WEXITSTATUS(status) != 0 and len(err_lines) != 1:
        reason = f"{len(err_lines)} lines of error"
    if reason:
        outcome.verdict, outcome.reason = "fail", reason
    elif os.WEXITSTATUS(status) == 0:
        outcome.verdict = "accepted"
    return outcome


_OUTSIDE_LISTING: dict[str, list[tuple[str, int]]] = {}


def _wait(proc: subprocess.Popen, start: float, seconds_bound: float) -> tuple[int, int, bool]:
    """(wait status, peak resident memory [bytes], timed out) of a child, killed (with its
    process group) after ``seconds_bound`` or when its memory passes 1.5 :data:`MEMORY`.

    The peak is the child's own high-water mark (``VmHWM``), read while it runs. The
    ``ru_maxrss`` that ``wait4`` reports is not used: a child started by vfork and exec
    carries the high-water mark of its parent's memory into it, so a campaign run from a
    large process (a test session) would charge every case with that process's size."""
    peak = 0
    while True:
        pid, status, _ = os.wait4(proc.pid, os.WNOHANG)
        if pid:
            proc.returncode = 0  # reaped here; keep Popen from waiting again
            return status, peak, False
        peak = max(peak, _peak(proc.pid))
        if time.monotonic() - start > seconds_bound or peak > 1.5 * MEMORY:
            os.killpg(proc.pid, signal.SIGKILL)
            _, status, _ = os.wait4(proc.pid, 0)
            proc.returncode = -9
            return status, peak, time.monotonic() - start > seconds_bound
        time.sleep(0.05)


def _peak(pid: int) -> int:
    """The high-water mark of a running process's resident memory [bytes] (0 once it ended)."""
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return 0


@dataclass(frozen=True)
class CampaignResult:
    counts: dict[str, KindCounts]
    failures: list[Outcome]
    seconds: float


def run_campaign(out: Path, cases_per_kind: int, seed: int, workers: int, kinds: tuple[str, ...],
                 update: Callable[[str, int, int], None] | None = None,
                 seconds_bound: float = SECONDS) -> CampaignResult:
    """Make ``cases_per_kind`` cases of every kind (seeded), run them ``workers`` at a time
    (each within ``seconds_bound``), keep the failing cases' folders under ``out``/failures."""
    rng = np.random.default_rng(seed)
    work = out / "cases"
    cases: list[tuple[Case, Path]] = []
    for kind in kinds:
        for i in range(cases_per_kind):
            root = work / f"{kind.replace(' ', '_')}_{i:04d}"
            _secrets(root)
            _OUTSIDE_LISTING[str(root)] = _listing(root / "outside")
            folder = root / "case"
            folder.mkdir(parents=True)
            argv = MAKERS[kind](folder, np.random.default_rng(rng.integers(2**63)))
            cases.append((Case(kind, i, folder, argv), root))
    start = time.monotonic()
    outcomes: list[Outcome] = []
    lock = threading.Lock()

    def one(item: tuple[Case, Path]) -> Outcome:
        result = _run_one(*item, seconds_bound)
        with lock:
            outcomes.append(result)
            if update:
                update("hostile inputs", len(outcomes), len(cases))
        return result

    with ThreadPoolExecutor(max_workers=workers) as pool:
        list(pool.map(one, cases))
    counts: dict[str, KindCounts] = {k: KindCounts() for k in kinds}
    for o in outcomes:
        c = counts[o.kind]
        c.cases += 1
        c.refused += o.verdict == "refused"
        c.accepted += o.verdict == "accepted"
        c.failed += o.verdict == "fail"
        c.slowest_s = max(c.slowest_s, o.seconds)
        c.peak_mb = max(c.peak_mb, round(o.peak_bytes / 1e6, 1))
        if o.reason:
            c.reasons[o.reason] = c.reasons.get(o.reason, 0) + 1
    failures = sorted((o for o in outcomes if o.verdict == "fail"), key=lambda o: (o.kind, o.index))
    keep = out / "failures"
    for (case, root) in cases:
        if any(f.kind == case.kind and f.index == case.index for f in failures):
            shutil.copytree(root, keep / root.name, symlinks=True)
    shutil.rmtree(work, ignore_errors=True)
    result = CampaignResult(counts, failures, round(time.monotonic() - start, 1))
    (out / "bench_inputs.json").write_text(json.dumps(
        {"seed": seed, "cases_per_kind": cases_per_kind, "seconds_bound": seconds_bound, "memory_bound": MEMORY,
         "seconds": result.seconds, "counts": {k: asdict(v) for k, v in counts.items()},
         "failures": [asdict(f) for f in failures]}, indent=2))
    return result
