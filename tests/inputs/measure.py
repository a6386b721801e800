"""Run Python code or the recon CLI in a process of its own and measure its wall time and
peak memory.

The peak is the child's own high-water mark (``VmHWM`` of /proc/self/status, written by
the child as it exits): ``ru_maxrss`` from ``wait4`` would also count the parent's memory
at the time of the fork, which Linux charges to the child when it executes Python.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

_EPILOGUE = """
import os as _os, sys as _sys
def _peak():
    _sys.stdout.flush(); _sys.stderr.flush()
    with open("/proc/self/status") as f:
        kb = next(line for line in f if line.startswith("VmHWM:")).split()[1]
    with open(_os.environ["RECON_TEST_PEAK"], "w") as f:
        f.write(kb)
"""

_CLI = _EPILOGUE + """
from recon_cli.cli import main
_code = main(_sys.argv[1:])
_peak()
_os._exit(_code)
"""


@dataclass(frozen=True)
class Run:
    code: int
    out: str
    err: str
    seconds: float
    peak_gb: float


def run_python(code: str, args: list[str], cwd: Path) -> Run:
    """Run ``code`` (which must call ``_peak()`` before it exits) with ``args``."""
    return _run(["-c", _EPILOGUE + code, *args], cwd)


def run_cli(args: list[str], cwd: Path) -> Run:
    """Run ``recon ARGS``."""
    return _run(["-c", _CLI, *args], cwd)


def _run(argv: list[str], cwd: Path) -> Run:
    peak = cwd / "peak.txt"
    peak.unlink(missing_ok=True)
    env = {**os.environ, "MUJOCO_GL": "egl", "RECON_PROGRESS": "0", "RECON_TEST_PEAK": str(peak)}
    out_path, err_path = cwd / "stdout.txt", cwd / "stderr.txt"
    t0 = time.monotonic()
    with out_path.open("w") as out, err_path.open("w") as err:
        proc = subprocess.run([sys.executable, *argv], cwd=cwd, env=env, stdout=out, stderr=err, timeout=300)
    seconds = time.monotonic() - t0
    peak_gb = int(peak.read_text()) / 1e6 if peak.exists() else float("nan")
    return Run(proc.returncode, out_path.read_text(), err_path.read_text(), seconds, peak_gb)
