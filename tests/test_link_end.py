"""Issue 14, items 2, 4 and 6, against the simulated vehicle over real MAVLink on loopback:
a mission's end commands its end action (RTL, LAND, LOITER) and waits for the autopilot to
acknowledge it; the link node publishes no pose before the autopilot has a position and says
it is waiting for one; `layerpilot link` prints each warning once and its readiness wait names
what is missing."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import threading

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

from conftest import cli_process, wait_for
from layerpilot.bus import messages as msg
from layerpilot.bus.keys import Keys
from layerpilot.bus.session import BusConfig, free_endpoint, open_session
from layerpilot.config import ConfigError
from layerpilot.link.config import LinkConfig
from layerpilot.link.link import FlightLink, LinkError, NotReady
from layerpilot.missionfile import load_mission
from layerpilot.sim.mavlink_vehicle import EndpointConfig, MavlinkVehicle
from layerpilot.sim.vehicle import Multicopter

FAST = dict(arrival_hold_s=0.3, arrival_tolerance_m=0.5, command_timeout_s=1.0, ready_timeout_s=10.0)


def start_vehicle(speed: float = 10.0, **config) -> MavlinkVehicle:
    return MavlinkVehicle(Multicopter(position=(0.0, 0.0, 2.0), ground_z=2.0), "tcp:127.0.0.1:0",
                          EndpointConfig(**config)).start(speed=speed)


def url_of(endpoint: MavlinkVehicle) -> str:
    return f"tcp:127.0.0.1:{endpoint.addresses[0][1]}"


def withhold_position(endpoint: MavlinkVehicle) -> threading.Event:
    """The vehicle sends no LOCAL_POSITION_NED until the returned event is set (a cold SITL's EKF)."""
    release, send = threading.Event(), endpoint.streams.send

    def gated(msg_id: int) -> bool:
        if msg_id == mav.MAVLINK_MSG_ID_LOCAL_POSITION_NED and not release.is_set():
            return False
        return send(msg_id)

    endpoint.streams.send = gated
    return release


@pytest.fixture
def vehicle():
    endpoint = start_vehicle()
    yield endpoint
    endpoint.stop()


def flying_link(vehicle: MavlinkVehicle) -> FlightLink:
    link = FlightLink(LinkConfig(url=url_of(vehicle), **FAST), clock=lambda: vehicle.time)
    link.connect(5.0)
    link.wait_ready()
    link.start_guided()
    link.arm()
    link.takeoff(15.0)
    return link


@pytest.mark.parametrize("action, mode", [("rtl", "RTL"), ("land", "LAND"), ("loiter", "LOITER")])
def test_end_mission_commands_the_action_and_waits_for_the_mode(vehicle, action, mode):
    link = flying_link(vehicle)
    try:
        link.goto(20.0, 0.0, 17.0)
        ok, text = link.end_mission(action, 5.0)
        assert ok and text == f"{mode} acknowledged (COMMAND_ACK accepted, mode {mode})"
        assert vehicle.mode == mode and link.mode == mode
        assert f"mission end: {text}" in link.events
        with pytest.raises(LinkError, match="not in control"):  # the link let go of the vehicle
            link.set_waypoint(0.0, 0.0, 17.0)
    finally:
        link.close()


def test_end_mission_sends_nothing_to_a_disarmed_vehicle_nor_over_a_silent_link(vehicle):
    with FlightLink(LinkConfig(url=url_of(vehicle), **FAST)) as link:
        link.connect(5.0)
        ok, text = link.end_mission("rtl", 2.0)
        assert ok and text.startswith("RTL not needed: the vehicle is disarmed")
        assert vehicle.mode == "STABILIZE"
    with FlightLink(LinkConfig(url="tcp:127.0.0.1:1", **FAST)) as nobody:
        ok, text = nobody.end_mission("land", 1.0)
        assert not ok and text == "LAND not sent: no autopilot heard on tcp:127.0.0.1:1"


def test_an_interrupted_takeoff_still_ends_with_rtl(vehicle):
    """A stop during the climb ends the link's waits (interrupt) but not its connection."""
    link = FlightLink(LinkConfig(url=url_of(vehicle), **FAST), clock=lambda: vehicle.time)
    try:
        link.connect(5.0)
        link.wait_ready()
        link.start_guided()
        link.arm()
        threading.Timer(0.5, link.interrupt).start()
        with pytest.raises(LinkError, match="interrupted"):
            link.takeoff(100.0)
        ok, text = link.end_mission("rtl", 5.0)
        assert ok and vehicle.mode == "RTL", text
    finally:
        link.close()


def test_position_valid_only_after_local_position_ned_and_readiness_names_it():
    endpoint = start_vehicle()
    release = withhold_position(endpoint)
    try:
        with FlightLink(LinkConfig(url=url_of(endpoint), **FAST)) as link:
            link.connect(5.0)
            wait_for(lambda: link.missing() == ["position estimate (LOCAL_POSITION_NED)"],
                     "everything but a position", timeout=10)
            assert not link.position_valid
            with pytest.raises(NotReady, match=r"not ready after 0\.5 s; missing: .*position estimate "
                                               r"\(LOCAL_POSITION_NED\)") as info:
                link.wait_ready(timeout=0.5)
            assert "position estimate (LOCAL_POSITION_NED)" in info.value.missing
            release.set()
            wait_for(lambda: link.position_valid, "a position", timeout=5)
            link.wait_ready()
    finally:
        endpoint.stop()


def test_an_ekf_without_a_horizontal_position_is_not_a_position(vehicle):
    with FlightLink(LinkConfig(url=url_of(vehicle), **FAST)) as link:
        link.connect(5.0)
        wait_for(lambda: link.position_valid, "a position", timeout=5)
        link.state.ekf_flags = mav.EKF_ATTITUDE | mav.EKF_POS_VERT_ABS | mav.EKF_CONST_POS_MODE  # ArduPilot without GPS
        assert not link.position_valid
        assert any(m.startswith("EKF position (EKF_STATUS_REPORT flags 0x") for m in link.missing())


def test_end_action_is_a_checked_mission_key(tmp_path):
    assert load_mission().link.end_action == "rtl"
    bad = tmp_path / "m.toml"
    bad.write_text('[link]\nend_action = "hover"\n')
    with pytest.raises(ConfigError, match="link.end_action: expected 'rtl', 'land' or 'loiter'"):
        load_mission(bad)
    bad.write_text("[link]\nend_timeout = 30.0\n")
    with pytest.raises(ConfigError, match="link.end_timeout"):
        load_mission(bad)
    assert LinkConfig().ready_timeout_s == 120.0  # a cold-started SITL took 41 s


def test_link_node_waits_for_a_position_then_flies_and_ends_with_rtl_on_sigterm(tmp_path):
    """Items 4 and 2 on the node: no pose while the autopilot has no position (the status says so),
    then take-off and poses; SIGTERM commands RTL, and the last status line says it was acknowledged."""
    endpoint = start_vehicle()
    release = withhold_position(endpoint)
    ep = free_endpoint()
    mission = tmp_path / "m.toml"
    mission.write_text("[link]\ntakeoff_altitude = 15.0\n[link.link]\nready_timeout_s = 60.0\n"
                       "arrival_tolerance_m = 0.5\narrival_hold_s = 0.3\n")
    poses: list[msg.State] = []
    try:
        with open_session(BusConfig(endpoint=ep)) as spy, \
                cli_process("link", "--config", str(mission), "--endpoint", ep, "--mavlink", url_of(endpoint),
                            "--status-every", "0.2") as proc:
            sub = spy.declare_subscriber(Keys("uav1").pose, lambda s: poses.append(msg.decode_state(
                s.payload.to_bytes())))
            lines: list[dict] = []

            def line_where(predicate) -> bool:
                """The next status line (not the `connecting`/`ready` announcements) satisfies ``predicate``."""
                while True:
                    lines.append(json.loads(proc.stdout.readline()))
                    if "status" not in lines[-1]:
                        return predicate(lines[-1])

            wait_for(lambda: line_where(lambda ln: ln.get("phase") == "waiting for the autopilot"
                                        and ln.get("pose", "").startswith("waiting for a position")),
                     "the node to wait for a position", timeout=30)
            assert any("position estimate (LOCAL_POSITION_NED)" in m for m in lines[-1]["missing"])
            for _ in range(10):  # 2 s of status lines: still waiting, not one pose on the bus
                assert line_where(lambda ln: ln["phase"] == "waiting for the autopilot")
            assert poses == [] and lines[-1]["poses"] == 0 and not endpoint.armed
            release.set()
            wait_for(lambda: line_where(lambda ln: ln.get("phase") == "flying"), "the take-off", timeout=60)
            assert lines[-1]["pose"] == "publishing"
            wait_for(lambda: poses, "poses on the bus", timeout=10)
            sub.undeclare()
            assert endpoint.armed and endpoint.mode == "GUIDED"
            proc.send_signal(signal.SIGTERM)
            out, err = proc.communicate(timeout=30)
        assert proc.returncode == 0, err
        last = json.loads(out.strip().splitlines()[-1])
        assert last["status"] == "stopped", last
        assert last["end"] == "RTL acknowledged (COMMAND_ACK accepted, mode RTL)", last
        # Flying home, supervised by the autopilot; at 10x a loaded machine may see it already landed.
        height = float(endpoint.vehicle.position[2] - endpoint.vehicle.ground_z)
        assert endpoint.mode == "RTL" and (endpoint.armed or height < 0.5), (endpoint.armed, height)
        assert err.count("mission end: RTL acknowledged") == 1
    finally:
        endpoint.stop()


def test_link_action_prints_each_warning_once_and_readiness_reports_what_is_missing():
    """A warning (here the autopilot refusing a stream request) is printed once, as `link: ...` on
    stdout; stderr stays empty on success."""
    endpoint = start_vehicle()
    interval = endpoint.streams.set_interval
    endpoint.streams.set_interval = lambda msg_id, us: (
        mav.MAV_RESULT_FAILED if msg_id == mav.MAVLINK_MSG_ID_ATTITUDE else interval(msg_id, us))
    try:
        done = subprocess.run([sys.executable, "-m", "layerpilot.cli", "link", "--mavlink", url_of(endpoint),
                               "--timeout", "20", "takeoff", "5"], capture_output=True, text=True, timeout=60)
        assert done.returncode == 0, done.stderr  # (land on the disarmed vehicle would be an error: issue 14)
        warning = "MAV_CMD_SET_MESSAGE_INTERVAL rejected: MAV_RESULT_FAILED"
        assert done.stdout.count(warning) == 1, done.stdout
        assert f"link: {warning}" in done.stdout
        assert done.stderr == "", done.stderr
    finally:
        endpoint.stop()
    # no autopilot position: the readiness error names what is missing, in one line
    endpoint = start_vehicle()
    withhold_position(endpoint)
    try:
        done = subprocess.run([sys.executable, "-m", "layerpilot.cli", "link", "--mavlink", url_of(endpoint),
                               "--timeout", "3", "land"], capture_output=True, text=True, timeout=60)
        assert done.returncode == 1
        lines = done.stderr.strip().splitlines()
        assert len(lines) == 1 and "Traceback" not in done.stderr, done.stderr
        assert lines[0].startswith("layerpilot link land: error: vehicle not ready after 3.0 s; missing: ")
        assert "position estimate (LOCAL_POSITION_NED)" in lines[0]
    finally:
        endpoint.stop()
