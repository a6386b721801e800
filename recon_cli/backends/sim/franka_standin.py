"""franka-sim as a stand-in for a Franka robot: libfranka's own network protocol on loopback.

franka-sim (PyPI, Apache-2.0) is a MuJoCo server that speaks libfranka's robot protocol
(version 10, the FR3's) on TCP port 1337 plus its 1 kHz UDP state and command stream, and
checks commanded motions against the FCI's limits as the real controller does. recon's
Franka adapter is tested against it through pylibfranka, the real client library.

franka-sim pins numpy 1.26 and MuJoCo < 3.3, so it runs in its own virtual environment
(``bash install.sh --franka-sim`` builds ``.venvs/franka-sim`` beside the checkout;
``RECON_FRANKA_SIM_VENV`` names another). It would download its FR3 model on first use; it
is given the cell's own description instead (:func:`standin_mjcf`: the expanded URDF
compiled by MuJoCo with the drives file's armature and friction, no meshes), so the
stand-in moves the same kinematics and inertias recon plans with.

The stand-in runs in a session (and process group) of its own. :meth:`FrankaStandin.stop`
and :meth:`FrankaStandin.kill` end the whole group, reap the server and return only when no
process of the group is left and its port refuses connections (a ReconError otherwise);
a start that fails or is interrupted (Ctrl-C) ends what it started before the error
leaves; and a stand-in whose parent ends without stopping it ends within 0.5 s by itself.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from recon_cli.backends.sim.scene import drives, mujoco_urdf
from recon_cli.errors import ReconError
from recon_cli.interrupts import held_signals
from recon_cli.lazy import lazy_module
from recon_cli.paths import ROOT
from recon_cli.robot.cell import Cell
from recon_cli.robot.cell_file import descendant_links
from recon_cli.robot.description import CellConfig
from recon_cli.robot.poses import named_configuration

if TYPE_CHECKING:
    import mujoco
else:
    mujoco = lazy_module("mujoco")

#: franka-sim's physics step [s] (its DEFAULT_DT, the FCI's 1 kHz cycle)
SIM_STEP = 0.001
#: share of the explicit-damping stability bound (KD dt / M < 2) the stand-in's position servo
#: may use: with KD dt / M <= 1 each step shrinks a velocity error without changing its sign
DAMPING_SHARE = 0.5

#: libfranka's command port (fixed in libfranka: a robot is reached by its address alone)
COMMAND_PORT = 1337
#: [s] after SIGKILL, until the stand-in's group is empty and its port refuses connections
GONE_TIMEOUT_S = 10.0
VENV_ENV = "RECON_FRANKA_SIM_VENV"
DEFAULT_VENV = ROOT / ".venvs" / "franka-sim"

#: run inside franka-sim's environment: the server bound to one address, the gripper off,
#: motions checked against the FCI's limits and aborted on a violation as the robot does, and
#: a late answer dropped as the FCI drops it
_LAUNCHER = """
import logging, os, signal, sys, threading, time
logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
# A controller runs on its own real-time computer; on a shared machine the stand-in's threads
# get real-time round-robin priority where the system permits it (inherited by the server's
# threads, below the client's 1 kHz loop), else a higher nice level, and hand the interpreter
# lock over within 0.2 ms instead of Python's 5 ms
try:
    os.sched_setscheduler(0, os.SCHED_RR, os.sched_param(40))
except (AttributeError, OSError):
    try:
        os.nice(-10)
    except OSError:
        pass
sys.setswitchinterval(0.0002)
import franka_sim.mujoco_franka_sim as arm
from franka_sim import FrankaSimServer
# An answer that reaches the controller after it published the next state is dropped, as the
# FCI drops it ("If the <1 ms constraint is violated for a cycle, the packet is dropped by FCI",
# libfranka's network requirements): the cycle stays lost and its extrapolation stands.
# franka-sim applies it instead, for scripted clients, and rewrites the reference it already
# published for the next state, which a 1 kHz client answering that state cannot see.
_absorb = FrankaSimServer._absorb_within_motion_limits
def _absorb_in_time(self, command, *, fresh):
    if not fresh and self.comm._motion and int(command["message_id"]) < self.comm._published_id:
        return False
    return _absorb(self, command, fresh=fresh)
FrankaSimServer._absorb_within_motion_limits = _absorb_in_time
host, port = sys.argv[1], int(sys.argv[2])
if len(sys.argv) > 3:  # where the arm stands at start-up (the module's start pose, changed in place)
    arm.ARM_INITIAL_Q[:] = [float(v) for v in sys.argv[3].split(",")]
if len(sys.argv) > 4:  # the position servo's damping gains, bounded for this arm (changed in place)
    arm.ARM_POSITION_KD[:] = [min(float(b), k) for b, k in zip(sys.argv[4].split(","), arm.ARM_POSITION_KD)]
server = FrankaSimServer(host=host, port=port, enable_gripper=False, enforce_motion_limits=True)
def _quit(*_):
    raise KeyboardInterrupt
signal.signal(signal.SIGTERM, _quit)
def _orphaned(parent=os.getppid()):  # the process that started the stand-in has ended: end too
    while os.getppid() == parent:
        time.sleep(0.5)
    os.kill(os.getpid(), signal.SIGTERM)
threading.Thread(target=_orphaned, daemon=True).start()
try:
    server.start()
except KeyboardInterrupt:
    pass
finally:
    server.stop()
"""


def standin_venv() -> Path | None:
    """franka-sim's virtual environment, None when it is not built."""
    root = Path(os.environ.get(VENV_ENV) or DEFAULT_VENV).expanduser()
    python = root / "bin" / "python"
    return root if python.exists() else None


def standin_mjcf(config: CellConfig) -> str:
    """MJCF text of the cell's robot for franka-sim: the description's bodies, joints,
    inertias and (real-size) collision primitives, the drives file's armature and friction.
    The robot's links make contact with the table and the board, not with each other: their
    collision primitives enclose the real links loosely (a real gap of 3 cm between the
    camera bracket and link 6 is an overlap of theirs), and the FR3 keeps its links apart by
    its controller, not by contact. franka-sim finds the arm by its ``*joint1`` ..
    ``*joint7`` and ``*link7`` names."""
    urdf = mujoco_urdf(config)
    spec = mujoco.MjSpec.from_string(urdf)
    d = drives(config.cell_file)
    for joint in spec.joints:
        joint.armature = d.armature_of(joint.name)
        joint.damping = [d.friction_of(joint.name), 0.0, 0.0]
    base = config.cell_file.base_link
    robot = [name for name in (base, *descendant_links(urdf, base)) if spec.body(name) is not None]
    for i, a in enumerate(robot):
        for b in robot[i + 1:]:
            exclude = spec.add_exclude()
            exclude.bodyname1, exclude.bodyname2 = a, b
    spec.compile()
    return spec.to_xml()


def servo_damping_bound(mjcf: str, samples: int = 64, seed: int = 0) -> list[float]:
    """Upper bounds [N m s/rad] on franka-sim's position-servo damping gains for this arm.

    franka-sim's servo applies ``KD (dq_c - dq)`` as an applied force, which MuJoCo integrates
    explicitly: the velocity error is multiplied by ``1 - KD dt / M`` every step, stable only
    while ``KD dt / M < 2`` for the joint's inertia ``M``. Its gains are tuned for its own
    FR3 with the Franka Hand; on an arm whose wrist carries a lighter camera, joints 5-7 sit
    near the reflected rotor inertia alone and the wrist servo rings at the actuator's torque
    limit (the arm at rest drifts 2 mrad and chatters at 0.08 rad/s). The bound is
    ``2 DAMPING_SHARE M_min / dt`` with ``M_min`` the smallest diagonal of the joint-space
    inertia over seeded configurations within the joint ranges (and the zero pose)."""
    model = mujoco.MjModel.from_xml_string(mjcf)
    data = mujoco.MjData(model)
    joints = [j for j in range(model.njnt) if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE]
    qpos = model.jnt_qposadr[joints]
    dofs = model.jnt_dofadr[joints]
    low, high = model.jnt_range[joints].T
    rng = np.random.default_rng(seed)
    m_min = np.full(len(joints), np.inf)
    dense = np.zeros((model.nv, model.nv))
    for k in range(samples + 1):
        data.qpos[:] = 0.0
        if k:
            data.qpos[qpos] = rng.uniform(low, high)
        mujoco.mj_forward(model, data)
        try:
            mujoco.mj_fullM(model, data, dense)
        except TypeError:  # MuJoCo before 3.3.6: mj_fullM(m, dst, qM)
            mujoco.mj_fullM(model, dense, data.qM)
        m_min = np.minimum(m_min, np.diag(dense)[dofs])
    return [float(v) for v in 2.0 * DAMPING_SHARE * m_min / SIM_STEP]


@dataclass
class FrankaStandin:
    """A running franka-sim server (``start_standin``); ``stop`` ends it, ``kill`` cuts it off
    as a pulled network cable or a crashed controller would."""

    host: str
    port: int
    process: subprocess.Popen = field(repr=False)
    log_path: Path
    workdir: Path
    _ended: bool = field(default=False, init=False, repr=False)

    def log_tail(self, lines: int = 30) -> str:
        try:
            return "\n".join(self.log_path.read_text(errors="replace").splitlines()[-lines:])
        except OSError:
            return ""

    def alive(self) -> bool:
        return self.process.poll() is None

    def _signal_group(self, sig: int) -> bool:
        """``sig`` to the stand-in's process group (its own session); False when the group is empty."""
        try:
            os.killpg(self.process.pid, sig)
        except ProcessLookupError:
            return False
        except PermissionError:
            return True
        return True

    def _gone(self) -> None:
        """SIGKILL to whatever is left of the group, the server reaped, then wait until the
        group is empty and the port refuses connections; a ReconError if it does not. Once
        that is seen, nothing is signalled again (the pid may be another process's by then)."""
        if self._ended:
            return
        self._signal_group(signal.SIGKILL)
        self.process.wait()
        deadline = time.monotonic() + GONE_TIMEOUT_S
        while self._signal_group(0) or _port_open(self.host, self.port):
            if time.monotonic() > deadline:
                what = "a process of its group is still running" if self._signal_group(0) else \
                    f"{self.host}:{self.port} still accepts connections"
                raise ReconError(f"franka-sim (pid {self.process.pid}) was stopped, but {what}",
                                 hint=f"find it with: ss -ltnp 'sport = :{self.port}'")
            time.sleep(0.05)
        self._ended = True

    def kill(self) -> None:
        """End the stand-in at once (SIGKILL), as a crashed controller or a pulled cable would."""
        self._gone()

    def stop(self, grace: float = 20.0) -> None:
        """End the stand-in: SIGTERM (it closes its server), SIGKILL after ``grace``; returns
        when its processes are gone and its port is closed."""
        try:
            if self.alive() and not self._ended:
                self.process.send_signal(signal.SIGTERM)
                try:
                    self.process.wait(grace)
                except subprocess.TimeoutExpired:
                    pass
            self._gone()
        finally:
            shutil.rmtree(self.workdir, ignore_errors=True)

    def __enter__(self) -> FrankaStandin:
        return self

    def __exit__(self, *exc) -> None:
        self.stop()


def _port_open(host: str, port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.settimeout(0.2)
        return s.connect_ex((host, port)) == 0


def start_standin(config: CellConfig, host: str = "127.0.0.1", port: int = COMMAND_PORT,
                  start: Sequence[float] | None = None, venv: Path | None = None,
                  timeout: float = 120.0) -> FrankaStandin:
    """Start franka-sim on ``host:port`` with the cell's robot standing at ``start`` [rad]
    (default: the cell's home pose) and wait until it accepts connections. Raises ReconError
    when its environment is missing, the port is taken or it does not come up (with the tail
    of its log)."""
    venv = venv or standin_venv()
    if venv is None:
        raise ReconError("franka-sim's environment is not built",
                         hint=f"bash install.sh --franka-sim (or set {VENV_ENV} to a venv with franka-sim)")
    if _port_open(host, port):
        raise ReconError(f"{host}:{port} is taken: a robot or another franka-sim already listens there",
                         hint="stop it first")
    workdir = Path(tempfile.mkdtemp(prefix="recon-franka-sim-"))
    model = workdir / "fr3.xml"
    mjcf = standin_mjcf(config)
    model.write_text(mjcf)
    damping = servo_damping_bound(mjcf)
    if start is None:
        start = [float(v) for v in named_configuration(config.kind, "home", Cell(config).joint_names)]
    log_path = workdir / "server.log"
    env = dict(os.environ, FR3_MJCF=str(model), MUJOCO_GL="egl", PYTHONUNBUFFERED="1")
    env.pop("PYTHONPATH", None)
    standin = None
    try:
        with held_signals():  # no Ctrl-C between the start and the moment the stand-in can be stopped
            with log_path.open("wb") as log:
                process = subprocess.Popen([str(venv / "bin" / "python"), "-c", _LAUNCHER, host, str(port),
                                            ",".join(repr(float(v)) for v in start), ",".join(map(repr, damping))],
                                           stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, env=env,
                                           cwd=workdir, start_new_session=True)
            standin = FrankaStandin(host, port, process, log_path, workdir)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if not standin.alive():
                raise ReconError(f"franka-sim ended at start-up:\n{standin.log_tail()}", hint="see its log above")
            if _port_open(host, port):
                return standin
            time.sleep(0.1)
        raise ReconError(f"franka-sim did not listen on {host}:{port} within {timeout:g} s:\n{standin.log_tail()}")
    except BaseException:  # also Ctrl-C: nothing started here outlives the failed start
        if standin is None:
            shutil.rmtree(workdir, ignore_errors=True)
        else:
            try:
                standin.kill()
            finally:
                shutil.rmtree(workdir, ignore_errors=True)
        raise


@contextlib.contextmanager
def running_standin(config: CellConfig, **kwargs):
    """``start_standin`` as a context manager (stopped on leaving)."""
    standin = start_standin(config, **kwargs)
    try:
        yield standin
    finally:
        standin.stop()


if __name__ == "__main__":  # pragma: no cover (a manual check: python -m recon_cli.backends.sim.franka_standin)
    from recon_cli.robot.description import CellName

    with running_standin(CellConfig(kind=CellName.parse(sys.argv[1] if len(sys.argv) > 1 else "fr3"))) as s:
        print(f"franka-sim on {s.host}:{s.port}, log {s.log_path}; Ctrl-C ends it")
        with contextlib.suppress(KeyboardInterrupt):
            s.process.wait()
