"""`layerpilot link` as a user runs it (a subprocess): errors a user can act on, in one line on stderr,
no traceback; --timeout bounds every wait; no telemetry line unless an autopilot was heard; the link
node says `ready` only once connected; `rtl` and `land` on a disarmed vehicle are errors."""

from __future__ import annotations

import json
import socket
import subprocess
import sys
import time

import pytest

from conftest import cli_process
from layerpilot.bus.session import free_endpoint
from layerpilot.sim.mavlink_vehicle import EndpointConfig, MavlinkVehicle
from layerpilot.sim.vehicle import Multicopter


def link(*args: str, timeout: float = 60) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "layerpilot.cli", "link", *args], capture_output=True, text=True,
                          timeout=timeout)


def one_line_error(done: subprocess.CompletedProcess) -> str:
    assert "Traceback" not in done.stderr, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1, done.stderr
    return lines[0]


@pytest.fixture(scope="module")
def nobody() -> str:
    """A loopback TCP URL nothing serves: connections are refused."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return f"tcp:127.0.0.1:{s.getsockname()[1]}"


@pytest.fixture
def vehicle():
    endpoint = MavlinkVehicle(Multicopter(position=(0.0, 0.0, 2.0), ground_z=2.0), "tcp:127.0.0.1:0",
                              EndpointConfig()).start(speed=10.0)
    yield f"tcp:127.0.0.1:{endpoint.addresses[0][1]}", endpoint
    endpoint.stop()


@pytest.mark.parametrize("url, message", [
    ("tcp:127.0.0.1:99999", "--mavlink 'tcp:127.0.0.1:99999': port 99999 is out of range (0-65535)"),
    ("http://drone", "--mavlink 'http://drone': expected tcp:HOST:PORT"),
    ("tcp::5760", "--mavlink 'tcp::5760': no host"),
])
def test_a_bad_url_is_a_one_line_error_naming_the_flag(url, message):
    done = link("--mavlink", url, "goto", "1", "1", "10")
    assert done.returncode == 2 and message in one_line_error(done)
    assert done.stdout == ""


def test_a_bad_timeout_names_the_flag():
    done = link("--mavlink", "tcp:127.0.0.1:5760", "--timeout", "0", "land")
    assert done.returncode == 2 and "--timeout must be >= 1e-06, got 0.0" in one_line_error(done)


def test_a_refused_connection_fails_within_the_timeout_without_telemetry(nobody):
    t0 = time.monotonic()
    done = link("--mavlink", nobody, "--timeout", "1", "land")
    assert time.monotonic() - t0 < 15.0  # 1 s of waiting plus the interpreter's start (the default is 30 s)
    error = one_line_error(done)
    assert done.returncode == 1
    assert error == (f"layerpilot link land: error: no ArduPilot/PX4 HEARTBEAT on {nobody} within 1.0 s "
                     "(Connection refused)")
    assert "pos=" not in done.stdout and "done" not in done.stdout  # no telemetry from a vehicle never heard


def test_rtl_and_land_on_a_disarmed_vehicle(vehicle):
    url, endpoint = vehicle
    done = link("--mavlink", url, "--timeout", "10", "rtl")
    assert done.returncode == 1
    assert "RTL: the vehicle is disarmed (on the ground" in one_line_error(done)
    assert "rtl: done" not in done.stdout and "disarmed" in done.stdout  # the real telemetry line
    assert endpoint.mode != "RTL"
    done = link("--mavlink", url, "--timeout", "10", "land")
    assert done.returncode == 1
    assert "layerpilot link land: error: LAND: the vehicle is disarmed (on the ground" in one_line_error(done)
    assert "land: done" not in done.stdout and "disarmed" in done.stdout
    assert endpoint.mode != "LAND"


def test_timeout_bounds_the_action(vehicle):
    url, endpoint = vehicle
    done = link("--mavlink", url, "takeoff", "10")
    assert done.returncode == 0, done.stderr
    assert "takeoff: done" in done.stdout
    done = link("--mavlink", url, "--timeout", "1", "goto", "100", "0", "12")  # 10 s of flight at 10 m/s
    assert done.returncode == 1
    assert "goto: did not arrive at (100.0, 0.0, 12.0) within 1.0 s" in one_line_error(done)
    done = link("--mavlink", url, "goto", "300", "0", "12")
    assert done.returncode == 1 and "outside the geofence" in one_line_error(done)  # the mission's fence
    done = link("--mavlink", url, "rtl")
    assert done.returncode == 0 and "rtl: done" in done.stdout, done.stderr
    assert not endpoint.armed


def test_the_link_node_never_says_ready_when_its_connection_is_refused(nobody, tmp_path):
    mission = tmp_path / "m.toml"
    mission.write_text("[link]\ntakeoff_altitude = 20.0\n")
    with cli_process("link", "--config", str(mission), "--endpoint", free_endpoint(), "--mavlink", nobody,
                     "--timeout", "1", "--status-every", "0.2") as proc:
        out, err = proc.communicate(timeout=60)
    lines = [json.loads(line) for line in out.strip().splitlines()]
    assert proc.returncode == 1 and "Traceback" not in err, err
    statuses = [ln["status"] for ln in lines if "status" in ln]
    assert statuses == ["connecting", "failed"]
    assert lines[-1]["error"] == (f"connecting: no ArduPilot/PX4 HEARTBEAT on {nobody} within 1.0 s "
                                  "(Connection refused)")
    assert all(ln.get("telemetry", "no autopilot heard yet") == "no autopilot heard yet" for ln in lines)
