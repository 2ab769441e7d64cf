"""Issue 14, item 3, against the simulated vehicle over real MAVLink on loopback: a reboot of the
autopilot (its uptime going back, disarmed on the ground) is reported as a reboot, a mode change
as a pilot takeover; every wait of the link (arrival, takeoff, readiness, the end action's
acknowledgement) ends at once with the reason; the link node ends or pauses the flying after a
reboot as ``link.on_reboot`` says."""

from __future__ import annotations

import threading
from contextlib import contextmanager

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

from conftest import wait_for
from test_link_flight import FAST, link, url_of, vehicle  # noqa: F401 (fixtures)
from layerpilot.cli import main as cli_main
from layerpilot.bus.keys import Keys
from layerpilot.bus.messages import Waypoint, decode_state, encode_waypoint
from layerpilot.bus.session import BusConfig, free_endpoint, open_session, publish
from layerpilot.config import ConfigError
from layerpilot.link.config import LinkConfig
from layerpilot.link.connection import open_connection
from layerpilot.link.geofence import Geofence
from layerpilot.link.link import ControlLost, FlightLink, LinkError
from layerpilot.mission.clock import MissionClock
from layerpilot.missionfile import LinkSettings, load_mission
from layerpilot.nodes.link import LinkNode
from layerpilot.sim.mavlink_vehicle import FORCE_DISARM_MAGIC, MavlinkVehicle

GUIDED, LOITER = 4, 5  # ArduCopter custom modes


@contextmanager
def flying_link_node(vehicle: MavlinkVehicle, clock: MissionClock = MissionClock(), **settings):
    """A link node on a real Zenoh session, flying ``vehicle`` (taken off to 15 m); yields (node, session)."""
    cfg = LinkSettings(link=LinkConfig(url=url_of(vehicle), **FAST), takeoff_altitude=15.0, **settings)
    stop = threading.Event()
    with open_session(BusConfig(endpoint=free_endpoint())) as session:
        node = LinkNode(session, "uav1", cfg, Geofence.circle((0.0, 0.0), 200.0), clock)
        runner = threading.Thread(target=node.run, args=(stop,))
        runner.start()
        try:
            wait_for(lambda: node.phase == "flying", "the take-off", timeout=30)
            yield node, session
        finally:
            stop.set()
            runner.join(timeout=10)
            node.stop()


def ground_station(vehicle: MavlinkVehicle):
    return open_connection(url_of(vehicle), 255, 190)


def command(gcs, cmd: int, *params: float) -> None:
    p = list(params) + [0.0] * (7 - len(params))
    gcs.mav.command_long_send(1, 1, cmd, 0, *p)


def fly_and_upset(vehicle: MavlinkVehicle, link: FlightLink, upset) -> tuple[ControlLost, float]:
    """Take off, fly a long goto and upset it once 20 m out; returns the error and the mission seconds
    the goto kept waiting after the upset."""
    link.start_guided()
    link.arm()
    link.takeoff(15.0)
    at: list[float] = []

    def watch() -> None:
        wait_for(lambda: vehicle.pose().position[0] > 20.0, "the flight to start")
        at.append(vehicle.time)
        upset()

    watcher = threading.Thread(target=watch)
    watcher.start()
    with pytest.raises(ControlLost) as info:
        link.goto(200.0, 0.0, 17.0, timeout=60.0)  # 20 min of mission time at 10x: a hang is obvious
    watcher.join()
    return info.value, vehicle.time - at[0]


def test_a_reboot_in_flight_is_a_reboot_and_ends_goto_at_once(vehicle, link):
    error, waited = fly_and_upset(vehicle, link, vehicle.reboot)
    assert error.kind == "reboot" and str(error).startswith("goto: autopilot rebooted: its uptime went back from ")
    assert waited < 600.0, waited  # ended by the reboot, within goto's own timeout (60 s wall = 600 mission s)
    assert link.reboots == 1 and not any("took over" in e or "disarmed while" in e for e in link.events)
    # (a mode change stays a pilot takeover: test_link_flight.test_pilot_mode_change_pauses_until_handed_back)
    assert any(e.startswith("autopilot rebooted") and e.endswith("disarmed in STABILIZE; the link let go of the "
                                                                  "vehicle") for e in link.events)
    assert not link.armed and not link.paused and vehicle.boots == 2 and vehicle.pose().position[2] == 2.0
    link.wait_ready()  # a new boot: pre-arm, fix, home and position again; the streams were asked for again
    assert link.position_valid and np.allclose(link.telemetry().home, (0.0, 0.0, 0.0))
    with pytest.raises(LinkError, match="not in control"):  # the link let go: nothing flies until asked again
        link.set_waypoint(10.0, 0.0, 15.0)


def test_link_goto_on_a_vehicle_that_reboots_exits_at_once_naming_the_reboot(vehicle, capsys):
    url = url_of(vehicle)
    assert cli_main(["link", "--mavlink", url, "takeoff", "12"]) == 0
    at: list[float] = []

    def reboot_on_the_way() -> None:
        wait_for(lambda: vehicle.pose().position[0] > 20.0, "the flight to start")
        at.append(vehicle.time)
        vehicle.reboot()

    rebooter = threading.Thread(target=reboot_on_the_way)
    rebooter.start()
    assert cli_main(["link", "--mavlink", url, "--timeout", "60", "goto", "110", "0", "15"]) == 1
    rebooter.join()
    assert vehicle.time - at[0] < 600.0  # ended by the reboot (the error below), within --timeout (600 mission s)
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("layerpilot link goto: error: goto: autopilot rebooted: its uptime "
                                               "went back from "), err


def test_a_disarm_in_flight_ends_goto_with_disarmed(vehicle, link):
    gcs = ground_station(vehicle)
    try:
        error, waited = fly_and_upset(vehicle, link, lambda: command(gcs, mav.MAV_CMD_COMPONENT_ARM_DISARM, 0,
                                                                     FORCE_DISARM_MAGIC))
        assert error.kind == "disarmed" and "the vehicle disarmed while the link was flying it" in str(error)
        assert waited < 600.0, waited  # ended by the disarm (its kind above), within goto's own timeout
        assert link.reboots == 0 and not any("took over" in e for e in link.events)
    finally:
        gcs.close()


def test_takeoff_ends_on_a_reboot_and_on_a_mode_change(vehicle, link):
    link.start_guided()
    link.arm()
    threading.Timer(0.3, vehicle.reboot).start()
    with pytest.raises(ControlLost, match="^takeoff: autopilot rebooted") as info:
        link.takeoff(100.0, timeout=60.0)
    assert info.value.kind == "reboot"
    link.wait_ready()
    gcs = ground_station(vehicle)
    try:
        link.start_guided()
        link.arm()
        threading.Timer(0.3, lambda: command(gcs, mav.MAV_CMD_DO_SET_MODE, mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                                             LOITER)).start()
        with pytest.raises(ControlLost, match="^takeoff: pilot took over: mode LOITER") as info:
            link.takeoff(100.0, timeout=60.0)
        assert info.value.kind == "takeover" and link.reboots == 1
    finally:
        gcs.close()


def test_readiness_and_the_end_action_wait_end_on_a_reboot(vehicle, link):
    real = vehicle.streams.send  # a vehicle that never becomes ready again: no position after its reboot

    def no_position(msg_id: int) -> bool:
        return False if msg_id == mav.MAVLINK_MSG_ID_LOCAL_POSITION_NED and vehicle.boots > 1 else real(msg_id)

    link.start_guided()
    link.arm()
    link.takeoff(15.0)
    vehicle.streams.send = no_position
    ack = vehicle._command
    # the RTL command reboots it: the answer comes from the new boot, which is disarmed and never flies the
    # RTL (run it, and the rebooted vehicle would be in RTL: its HEARTBEAT could beat the uptime's step back)
    vehicle._command = lambda msg: (vehicle.reboot(), mav.MAV_RESULT_ACCEPTED)[1] if msg.command == \
        mav.MAV_CMD_NAV_RETURN_TO_LAUNCH else ack(msg)
    ok, text = link.end_mission("rtl", 10.0)
    assert not ok and text.startswith("RTL ") and "autopilot rebooted" in text, text
    # and again while the link waits for readiness: a rebooted ArduCopter streams nothing, so the link sees
    # the uptime go back only at its next ask (every READY_STREAMS_S, 2 s = 20 mission s at 10x): the old
    # boot must be older than that
    wait_for(lambda: vehicle.uptime > 30.0, "the new boot to be under way", timeout=30)
    threading.Timer(0.3, vehicle.reboot).start()
    with pytest.raises(ControlLost, match="^waiting for the autopilot to be ready: autopilot rebooted"):
        link.wait_ready(timeout=30.0)


def test_on_reboot_is_a_checked_mission_key(tmp_path):
    assert load_mission().link.on_reboot == "end"
    bad = tmp_path / "m.toml"
    bad.write_text('[link]\non_reboot = "retry"\n')
    with pytest.raises(ConfigError, match="link.on_reboot: expected 'end' or 'pause', got 'retry'"):
        load_mission(bad)


@pytest.mark.parametrize("on_reboot", ["end", "pause"])
def test_link_node_ends_or_pauses_the_flying_after_a_reboot(vehicle, on_reboot):
    stamps: list[tuple[float, int]] = []  # (pose stamp, reboots the link had seen when it arrived)
    with flying_link_node(vehicle, MissionClock(100.0), on_reboot=on_reboot, pose_rate=20.0) as (node, session):
        session.declare_subscriber(Keys("uav1").pose, lambda s: stamps.append(
            (decode_state(s.payload.to_bytes()).stamp, node.link.reboots)))
        waypoint = Keys("uav1").waypoint
        publish(session, waypoint, encode_waypoint(Waypoint(0.0, "uav1", 1, np.array([40.0, 0.0, 17.0]))))
        wait_for(lambda: vehicle.pose().position[0] > 10.0 and len(stamps) > 3, "the first waypoint")
        vehicle.reboot()
        wait_for(lambda: node.phase != "flying", "the node to see the reboot", timeout=5)
        publish(session, waypoint, encode_waypoint(Waypoint(1.0, "uav1", 2, np.array([-30.0, 20.0, 17.0]))))
        if on_reboot == "end":
            assert node.phase == "ended: autopilot rebooted"
            assert node.link.reboots == 1 and not any("took over" in e for e in node.link.events)
            return
        assert node.phase == ("paused: autopilot rebooted; waiting for a pilot to arm, take off and hand "
                              "over GUIDED")
        gcs = ground_station(vehicle)  # the pilot flies it up again and hands over GUIDED
        try:
            wait_for(lambda: node.link.missing() == [], "the rebooted autopilot to be ready", timeout=10)
            command(gcs, mav.MAV_CMD_DO_SET_MODE, mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, GUIDED)
            wait_for(lambda: vehicle.mode == "GUIDED", "GUIDED", timeout=5)
            command(gcs, mav.MAV_CMD_COMPONENT_ARM_DISARM, 1)
            wait_for(lambda: vehicle.armed, "armed", timeout=5)
            command(gcs, mav.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 10.0)
            wait_for(lambda: node.phase == "flying", "the node to fly again", timeout=20)
        finally:
            gcs.close()
        # the waypoint heard while paused flies now
        wait_for(lambda: np.linalg.norm(vehicle.pose().position[:2] - (-30.0, 20.0)) < 1.0,
                 "the held waypoint", timeout=20)
        wait_for(lambda: sum(reboots for _, reboots in stamps) > 3, "poses after the reboot", timeout=10)
    # the rebooted autopilot counts from 0 again; the mission clock went on by the uptime it had, so the poses'
    # stamps never go back (the map keeps the newest stamp as a cell's last_seen)
    before = [stamp for stamp, reboots in stamps if reboots == 0]
    after = [stamp for stamp, reboots in stamps if reboots == 1]
    assert len(before) > 3 and len(after) > 3 and min(before) > 100.0
    assert all(b >= a for a, b in zip([s for s, _ in stamps], [s for s, _ in stamps][1:])), stamps
    assert min(after) > max(before)
