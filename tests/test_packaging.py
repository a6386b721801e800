"""A normal (non-editable) install works from any folder: the cell description, the schemas
and the shipped scripts travel as package data."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from recon_cli.paths import ROOT


@pytest.mark.slow
def test_wheel_install_runs_the_smoke_script_from_anywhere(tmp_path):
    venv = tmp_path / "v"
    # the dependencies come from this interpreter's site-packages; recon itself is built
    # and installed as a wheel into the venv
    subprocess.run([sys.executable, "-m", "venv", "--system-site-packages", str(venv)], check=True)
    pip = subprocess.run([str(venv / "bin" / "pip"), "install", "-q", "--no-deps", "--disable-pip-version-check",
                          str(ROOT)], capture_output=True, text=True)
    assert pip.returncode == 0, pip.stderr[-2000:]
    env = {k: v for k, v in os.environ.items() if k not in ("RECON_HOME", "PYTHONPATH")}
    env["MUJOCO_GL"] = os.environ.get("MUJOCO_GL", "egl")
    where = subprocess.run([str(venv / "bin" / "python"), "-c",
                            "import recon_cli, recon_cli.paths as p; print(recon_cli.__file__); print(p.ROBOT_DIR); "
                            "print(p.BATCHES_DIR / 'ci.yaml')"],
                           capture_output=True, text=True, cwd="/", env=env, check=True).stdout.split()
    assert all(Path(w).is_relative_to(venv) for w in where), where  # the installed copy, not the checkout
    assert Path(where[-1]).is_file()  # the shipped batches travel too
    from recon_cli import DISTRIBUTION, __version__

    version = subprocess.run([str(venv / "bin" / "python"), "-c",
                              f"import importlib.metadata as m; print(m.version({DISTRIBUTION!r}))"],
                             capture_output=True, text=True, cwd="/", env=env, check=True).stdout.strip()
    assert version == __version__
    shown = subprocess.run([str(venv / "bin" / "recon"), "--version"], capture_output=True, text=True, cwd="/",
                           env=env, check=True).stdout.strip()
    assert shown == f"recon {__version__}"
    listed = subprocess.run([str(venv / "bin" / "recon"), "batch", "ci.yaml", "--list"], capture_output=True,
                            text=True, cwd="/", env=env, timeout=300)
    assert listed.returncode == 0 and "jobs in batch 'ci'" in listed.stdout, listed.stdout[-2000:] + listed.stderr
    out = tmp_path / "run"
    run = subprocess.run([str(venv / "bin" / "recon"), "run", "scripts_xml/smoke.xml", "--out", str(out)],
                         capture_output=True, text=True, cwd="/", env=env, timeout=600)
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-2000:]
    assert (out / "reconstruction" / "mesh.ply").is_file() and (out / "config.yaml").is_file()
