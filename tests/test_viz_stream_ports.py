"""`view --web` with a port another process holds: one line naming the port and its flag, exit 1, no ready line."""

from __future__ import annotations

import socket

import pytest

from layerpilot.bus.session import free_endpoint
from layerpilot.cli import main
from conftest import free_tcp_port


@pytest.mark.parametrize("flag", ["--web-port", "--grpc-port"])
def test_view_web_refuses_a_port_in_use(flag, tmp_path, capsys):
    mission = tmp_path / "mission.toml"
    mission.write_text('vehicles = ["uav1"]\n[bus]\nsecurity = false\n')
    with socket.socket() as other:  # another server on the port
        other.bind(("127.0.0.1", 0))
        other.listen()
        busy = other.getsockname()[1]
        ports = {"--web-port": free_tcp_port(), "--grpc-port": free_tcp_port(), flag: busy}
        code = main(["view", "--config", str(mission), "--endpoint", free_endpoint(), "--web",
                     *(str(x) for kv in ports.items() for x in kv)])
    out, err = capsys.readouterr()
    assert code == 1 and "ready" not in out
    lines = [ln for ln in err.splitlines() if ln.startswith("layerpilot: error:")]
    assert len(lines) == 1 and f"({flag}): port {busy}" in lines[0] and "already in use" in lines[0], err
    assert "Traceback" not in err
