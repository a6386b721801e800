"""The scan store: round trip, and never a half-written scan (even when killed)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

from recon_cli.errors import FileError
from recon_cli.perception.camera_model import Intrinsics
from recon_cli.reconstruction.scan_store import Scan, ScanStore, read_scan

K = Intrinsics(64, 48, 50.0, 50.0, 31.5, 23.5)


def _scan(index: int, rng) -> Scan:
    depth = rng.uniform(0.5, 0.9, size=(48, 64))
    depth[:5] = 0.0
    color = rng.integers(0, 255, size=(48, 64, 3), dtype=np.uint8)
    return Scan(index, color, depth, K, {"a": 0.1, "b": -0.2}, np.eye(4),
                meta={"planned_view": {"radius": 0.6}}, ground_truth={"world_T_camera": np.eye(4)})


def test_round_trip(tmp_path):
    rng = np.random.default_rng(0)
    store = ScanStore.create(tmp_path / "s", {"backend": "hardware"})
    original = _scan(store.next_index(), rng)
    store.write(original, depth_scale=20000.0)
    back = store.read(0)
    assert back.intrinsics == K
    assert np.array_equal(back.color, original.color)
    assert np.max(np.abs(back.depth - original.depth)) <= 0.5 / 20000.0  # 0.05 mm units
    assert back.joints == original.joints
    assert back.meta["planned_view"] == {"radius": 0.6}
    assert back.ground_truth["world_T_camera"] == np.eye(4).tolist()
    assert store.session().backend == "hardware"
    assert len(back.points_camera()) == np.count_nonzero(original.depth)
    cloud = back.to_open3d_cloud(np.eye(4))
    assert len(cloud.points) == np.count_nonzero(original.depth)
    assert back.to_open3d_rgbd().depth is not None


def test_existing_scan_is_not_overwritten(tmp_path):
    rng = np.random.default_rng(1)
    store = ScanStore.create(tmp_path, {})
    store.write(_scan(0, rng), 20000.0)
    with pytest.raises(FileError, match="already exists"):
        store.write(_scan(0, rng), 20000.0)


def test_not_a_scan(tmp_path):
    with pytest.raises(FileError, match="without scan.json"):
        read_scan(tmp_path)


WRITER = textwrap.dedent("""
    import sys, numpy as np
    from recon_cli.perception.camera_model import Intrinsics
    from recon_cli.reconstruction.scan_store import Scan, ScanStore
    store = ScanStore.create(sys.argv[1], {})
    rng = np.random.default_rng(0)
    K = Intrinsics(640, 480, 500.0, 500.0, 319.5, 239.5)
    i = 0
    while True:
        depth = rng.uniform(0.5, 0.9, size=(480, 640))
        color = rng.integers(0, 255, size=(480, 640, 3), dtype=np.uint8)
        store.write(Scan(i, color, depth, K, {"a": float(i)}, np.eye(4)), 20000.0)
        print(i, flush=True)
        i += 1
""")


def test_killed_writer_leaves_only_complete_scans(tmp_path):
    """SIGKILL a writer at random moments: every scan folder present reads back whole."""
    rng = np.random.default_rng(2)
    for attempt in range(4):
        folder = tmp_path / f"session{attempt}"
        proc = subprocess.Popen([sys.executable, "-c", WRITER, str(folder)], stdout=subprocess.PIPE)
        proc.stdout.readline()  # at least one scan is complete
        time.sleep(float(rng.uniform(0.0, 0.3)))
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
        store = ScanStore(folder)
        indices = store.indices()
        assert indices == list(range(len(indices))) and indices
        for scan in store:
            assert scan.depth.shape == (480, 640) and scan.color.shape == (480, 640, 3)
            assert scan.joints == {"a": float(scan.index)}
        leftovers = [p.name for p in folder.iterdir() if p.name.startswith(".scan_")]
        assert all(".tmp" in name for name in leftovers)  # ignored by readers


@pytest.mark.parametrize("what", ["folder", "file", "session"])
def test_every_reader_refuses_links_out_of_the_store(tmp_path, what):
    """Whoever reads a store (register, calibrate, replay, evaluate, reports) reads only what
    lies inside it: a scan folder, a file of a scan or session.json that links out is refused."""
    from recon_cli.errors import MetadataError

    rng = np.random.default_rng(0)
    outside = ScanStore.create(tmp_path / "outside", {"created": 0.0})
    outside.write(_scan(0, rng), depth_scale=1000.0)
    store = ScanStore.create(tmp_path / "store", {"created": 0.0})
    store.write(_scan(0, rng), depth_scale=1000.0)
    if what == "folder":
        os.symlink(tmp_path / "outside" / "scan_0000", tmp_path / "store" / "scan_0001")
        with pytest.raises(MetadataError, match="outside the scan store"):
            store.read(1)
    elif what == "file":
        (tmp_path / "store" / "scan_0000" / "depth.png").unlink()
        os.symlink(tmp_path / "outside" / "scan_0000" / "depth.png", tmp_path / "store" / "scan_0000" / "depth.png")
        with pytest.raises(MetadataError, match="depth.png is a link to .*outside the scan store"):
            read_scan(tmp_path / "store" / "scan_0000")
    else:
        (tmp_path / "outside" / "session.json").write_text('{"created": 0.0}')
        (tmp_path / "store" / "session.json").unlink(missing_ok=True)
        os.symlink(tmp_path / "outside" / "session.json", tmp_path / "store" / "session.json")
        with pytest.raises(MetadataError, match="session.json is a link to .*outside the scan store"):
            store.session()
