"""`recon station check` with an ADS robot that cannot be reached: one line, exit 1, none of
AdsLib's own log lines ("Socket(): connect failed", ...) on stderr, which AdsLib writes from
C++ straight to file descriptor 2 (hence ``capfd``)."""

from __future__ import annotations

import ctypes

import pytest

pytest.importorskip("pyads", reason="the ADS adapter needs pyads (pip install 'recon-scan[ads]')")

from recon_cli.cli import main  # noqa: E402

# nothing listens on 127.0.0.9 (the PLC stand-in of the other tests binds 127.0.0.1): the
# connection is refused at once
STATION = """\
format: 1
name: unreachable
cell: {kind: gantry, safety_distance: 0.03}
robot:
  adapter: ads
  ads: {ams_net_id: 127.0.0.9.1.1, ip: 127.0.0.9, port: 851, timeout: 0.5}
camera:
  adapter: sim
  sim: {resolution: 0.25}
"""


def test_station_check_that_cannot_connect_is_one_line_exit_1(tmp_path, capfd):
    path = tmp_path / "station.yaml"
    path.write_text(STATION)
    assert main(["station", "check", str(path)]) == 1
    out, err = capfd.readouterr()
    assert err.count("\n") == 1, err
    assert err.startswith("error: cannot reach the PLC 127.0.0.9.1.1:851 at 127.0.0.9"), err
    assert "Socket()" not in err and "Unable to create socket" not in err and "Traceback" not in err
    assert "robot stopped" not in err  # nothing moved: not a stopped robot (exit 4 is for faults of a run)


def test_adslib_is_quiet_only_while_connecting(capfd):
    import pyads
    from pyads import pyads_ex

    from recon_cli.backends.hardware.ads import adslib_quiet

    level = ctypes.c_size_t.in_dll(pyads_ex._adsDLL, "_ZN6Logger8logLevelE")
    before = level.value
    connection = pyads.Connection("127.0.0.9.1.1", 851, "127.0.0.9")
    with adslib_quiet():
        assert level.value > 3  # above AdsLib's error level
        try:
            connection.open()
            connection.read_by_name("MAIN.x", pyads.PLCTYPE_INT)
        except pyads.ADSError:
            pass
        finally:
            connection.close()
    assert level.value == before
    _, err = capfd.readouterr()
    assert "Socket()" not in err and "Unable to create socket" not in err, err
