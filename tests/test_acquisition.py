"""Taking scans: a scan written beside its caller (``written=False``) is in the store once
settled, exactly as one written at once; the next scan waits for it; a failed write is
raised by the settle, with nothing of the store lost."""

from __future__ import annotations

import numpy as np
import pytest

from recon_cli.acquisition import Acquisition
from recon_cli.backends.base import RGBDFrame
from recon_cli.backends.sim.robot import SimRobot
from recon_cli.backends.sim.scene import build_scene, mujoco
from recon_cli.errors import FileError
from recon_cli.perception.camera_model import Intrinsics
from recon_cli.reconstruction.scan_store import ScanStore, read_scan
from recon_cli.robot.poses import named_configuration


class _Camera:
    """A camera backend of recon's own interface: a fixed random frame."""

    def __init__(self) -> None:
        rng = np.random.default_rng(3)
        self.frame = RGBDFrame(rng.integers(0, 256, (120, 160, 3), dtype=np.uint8),
                               rng.uniform(0.3, 0.9, (120, 160)), Intrinsics(160, 120, 150.0, 150.0, 80.0, 60.0), 0.0)

    def capture(self) -> RGBDFrame:
        return self.frame


@pytest.fixture()
def acquisition(gantry, tmp_path):
    scene = build_scene(gantry.config, None)
    robot = SimRobot(scene, mujoco.MjData(scene.model), gantry.kin)
    robot.reset(named_configuration(gantry.config.kind, "home", gantry.joint_names))
    return Acquisition(gantry, robot, _Camera(), ScanStore.create(tmp_path / "scans", {}),
                       np.random.default_rng(0))


def test_a_scan_written_beside_its_caller_is_the_scan_written_at_once(acquisition):
    first = acquisition.scan({}, written=True)
    second = acquisition.scan({}, written=False)
    third = acquisition.scan({}, written=False)  # waits for the second: the next index
    acquisition.settle()
    assert [s.index for s in (first, second, third)] == [0, 1, 2]
    assert acquisition.store.indices() == [0, 1, 2]
    for s in (first, second, third):
        back = read_scan(s.path)
        assert np.array_equal(back.depth, s.depth) and np.array_equal(back.color, s.color)
    acquisition.settle()  # nothing pending: nothing happens


def test_a_failed_write_is_raised_by_the_settle_and_keeps_the_store(acquisition, monkeypatch):
    import errno

    from recon_cli.reconstruction import scan_store

    acquisition.scan({})

    def disk_full(path, image):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(scan_store, "_write_png", disk_full)
    acquisition.scan({}, written=False)
    with pytest.raises(FileError, match=r"cannot write scan .*scan_0001 \(No space left on device\)"):
        acquisition.settle()
    store = acquisition.store
    assert store.indices() == [0] and read_scan(store.folder(0)).index == 0
    assert not [p for p in store.root.iterdir() if p.name.startswith(".scan_")]  # no temporary folder left
