"""`recon view --web --bind ADDRESS`: an address this machine does not have is named as such,
not as a port in use."""

from __future__ import annotations

import socket

import pytest

from recon_cli.recording.viewer import _bind_problem

# TEST-NET-1 (RFC 5737): documentation addresses, never an address of this machine
ELSEWHERE = "192.0.2.1"


def test_an_address_of_another_machine_is_named_as_such():
    problem = _bind_problem(ELSEWHERE, 9391)
    assert problem is not None
    assert problem.one_line().startswith(f"--bind {ELSEWHERE} is not an address of this machine")
    assert "in use" not in problem.one_line()


def test_a_port_in_use_is_still_named_as_such():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        problem = _bind_problem("127.0.0.1", port)
    assert problem is not None and problem.one_line() == f"port {port} is in use on 127.0.0.1; choose another --port"
    assert _bind_problem("127.0.0.1", port) is None  # free again


def test_the_command_says_it_in_one_line(tmp_path, capsys):
    pytest.importorskip("rerun", reason="recon view needs the viz extra (pip install 'recon-scan[viz]')")
    from recon_cli.cli import main
    from recon_cli.recording.recorder import Recorder

    path = tmp_path / "recording.rrd"
    Recorder(path, "tiny").close()
    assert main(["view", str(path), "--web", "--bind", ELSEWHERE, "--port", "9391"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"--bind {ELSEWHERE} is not an address of this machine" in err, err
    assert "in use" not in err
