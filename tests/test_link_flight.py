"""The flight link against the simulated vehicle over real MAVLink on loopback.

The simulated vehicle runs faster than real time; the link's timeouts are wall
clock by nature, so the tests shorten them through LinkConfig.
"""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

from conftest import free_tcp_port, free_udp_port
from layerpilot.cli import main as cli_main
from layerpilot.link.config import LinkConfig
from layerpilot.link.connection import open_connection
from layerpilot.link.geofence import Geofence
from layerpilot.link.link import (CommandRejected, ControlLost, FlightLink, LinkError, LinkLost, NotReady,
                                  WaypointRefused)
from layerpilot.sim.mavlink_vehicle import EndpointConfig, MavlinkVehicle
from layerpilot.sim.vehicle import Multicopter
from mavlink_relay import MavProxyRelay

SPEED = 10.0
FAST = dict(arrival_hold_s=0.3, arrival_tolerance_m=0.5, command_timeout_s=1.0, ready_timeout_s=10.0)


def start_vehicle(flavour: str = "ardupilot", speed: float = SPEED, **config) -> MavlinkVehicle:
    vehicle = Multicopter(position=(0.0, 0.0, 2.0), ground_z=2.0)
    return MavlinkVehicle(vehicle, "tcp:127.0.0.1:0", EndpointConfig(flavour=flavour, **config)).start(speed=speed)


def local(endpoint: MavlinkVehicle) -> np.ndarray:
    """The vehicle's position in the autopilot's local frame (ENU), the frame the link flies: like ArduCopter's,
    its origin is the EKF origin on the ground at home (here 2 m above the simulated world's datum)."""
    return endpoint.pose().position - endpoint.ekf_origin


def url_of(endpoint: MavlinkVehicle) -> str:
    return f"tcp:127.0.0.1:{endpoint.addresses[0][1]}"


@pytest.fixture
def vehicle():
    endpoint = start_vehicle()
    yield endpoint
    endpoint.stop()


@pytest.fixture
def link(vehicle):
    with FlightLink(LinkConfig(url=url_of(vehicle), **FAST), clock=lambda: vehicle.time) as lk:
        lk.connect(5.0)
        lk.wait_ready()
        yield lk


def wait_until(predicate, timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.02)


def test_full_flight(vehicle, link):
    assert link.flavour == "ardupilot" and (link.target_system, link.target_component) == (1, 1)
    tel = link.telemetry()
    # home on the ground is the EKF origin: (0, 0, 0) in the autopilot's frame, 2 m above the world's datum
    assert np.allclose(tel.home, (0.0, 0.0, 0.0)) and np.allclose(tel.position, (0.0, 0.0, 0.0), atol=0.01)
    assert np.allclose(vehicle.ekf_origin, (0.0, 0.0, 2.0))
    assert tel.battery_voltage == pytest.approx(16.8, abs=0.01) and tel.battery_remaining == 100
    link.start_guided()
    assert vehicle.mode == "GUIDED"
    link.arm()
    link.takeoff(25.0)
    assert vehicle.pose().position[2] == pytest.approx(27.0, abs=0.6)
    route = [(40.0, 0.0, 25.0), (40.0, 30.0, 30.0), (-10.0, 30.0, 25.0)]
    for i, wp in enumerate(route):
        link.goto(*wp, look_at=(40.0, 100.0) if i == 1 else None, face_waypoint=i == 2)
        assert np.linalg.norm(local(vehicle) - wp) < 0.6
        tel = link.telemetry()
        assert np.linalg.norm(tel.position - wp) <= 0.5          # telemetry in the autopilot's frame, ENU
        assert abs(tel.time - vehicle.time) < 1.0                 # stamped with the mission clock
        if i == 1:
            assert tel.yaw == pytest.approx(np.pi / 2, abs=0.05)  # looking at the point of interest, north
    assert np.cos(tel.yaw - np.pi) > 0.999                        # faced west toward the last waypoint
    assert np.cos(vehicle.pose().yaw - tel.yaw) > 0.999
    assert tel.armed and tel.mode == "GUIDED" and tel.link_ok and tel.heartbeat_age < 1.0
    link.land()
    assert not vehicle.armed and vehicle.pose().position[2] == pytest.approx(2.0, abs=0.01)
    assert np.allclose(vehicle.pose().position[:2], (-10.0, 30.0), atol=0.6)
    assert link.telemetry().mode == "LAND" and not link.telemetry().armed
    assert not [e for e in link.events if "rejected" in e or "lost" in e]


def test_cruise_speed_is_set_and_reset(vehicle, link):
    link.start_guided()
    link.arm()
    link.takeoff(10.0)

    def fly(x: float) -> float:
        """Top horizontal speed on the way to (x, 0, 12), sampled while the link flies there."""
        speeds: list[float] = []
        arrived = threading.Event()

        def sample() -> None:
            while not arrived.is_set():
                speeds.append(float(np.hypot(*vehicle.pose().velocity[:2])))
                time.sleep(0.01)

        sampler = threading.Thread(target=sample)
        sampler.start()
        try:
            link.goto(x, 0.0, 12.0)
        finally:
            arrived.set()
            sampler.join()
        return max(speeds)

    link.set_speed(4.0)
    assert vehicle.vehicle.cruise_speed == 4.0
    assert 3.8 < fly(120.0) <= 4.0 + 1e-6
    link.set_speed(None)
    assert vehicle.vehicle.cruise_speed is None
    assert fly(0.0) > 9.0  # back to the airframe's 10 m/s
    link.set_speed(50.0)
    assert vehicle.vehicle.cruise_speed == 10.0  # capped at the airframe's limit
    with pytest.raises(ValueError, match="speed: must be a positive"):
        link.set_speed(float("nan"))
    with pytest.raises(CommandRejected, match="MAV_CMD_DO_CHANGE_SPEED rejected: MAV_RESULT_DENIED"):
        link.command(mav.MAV_CMD_DO_CHANGE_SPEED, 1.0, -5.0, -1.0)


def test_refusals_are_reported_with_the_mav_result_name(vehicle, link):
    with pytest.raises(CommandRejected, match="MAV_CMD_NAV_TAKEOFF rejected: MAV_RESULT_FAILED"):
        link.command(mav.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 20)     # disarmed
    link.set_mode("LAND")
    with pytest.raises(CommandRejected, match="MAV_RESULT_FAILED.*Arm: Mode not armable") as info:
        link.arm(timeout=0.5)
    assert info.value.result_name == "MAV_RESULT_FAILED"
    assert "MAV_CMD_COMPONENT_ARM_DISARM rejected: MAV_RESULT_FAILED" in link.events
    # an ACK nobody waits for (a stream request the vehicle cannot serve) is reported too
    link.commands.send(mav.MAV_CMD_SET_MESSAGE_INTERVAL, mav.MAVLINK_MSG_ID_WIND, 1e5)
    wait_until(lambda: "MAV_CMD_SET_MESSAGE_INTERVAL rejected: MAV_RESULT_FAILED" in link.events, 5.0,
               "the unsolicited rejection report")
    # waypoints outside the area / altitude limits are refused before anything is sent
    link.set_mode("GUIDED")
    link.arm()
    link.takeoff(10.0)
    target = vehicle.vehicle.position_target
    with FlightLink(LinkConfig(url=url_of(vehicle), source_component=192, **FAST),
                    geofence=Geofence.circle((0.0, 0.0), 50.0)) as other:
        other.connect(5.0)
        other.wait_ready()
        other.start_guided()
        with pytest.raises(WaypointRefused, match="outside the geofence"):
            other.goto(80.0, 0.0, 12.0)
        with pytest.raises(WaypointRefused, match="altitude 150.0 m above home is outside"):
            other.goto(0.0, 0.0, 150.0)  # home is 0 in the autopilot frame
        with pytest.raises(WaypointRefused, match="finite"):
            other.goto(0.0, float("nan"), 12.0)
    with pytest.raises(WaypointRefused, match="altitude 150.0 m above home is outside the limits"):
        link.goto(0.0, 0.0, 150.0)  # without a fence (bench use) the config's altitude limits still hold
    time.sleep(0.3)
    assert np.array_equal(vehicle.vehicle.position_target, target)


def test_arm_retries_until_prearm_passes_and_readiness_names_what_is_missing():
    endpoint = start_vehicle(prearm_delay_s=20.0)   # 4 s of wall time at 5x, the GPS fix at half: a slow connect
    # on a busy machine must not let the fix arrive before the first readiness check
    try:
        with FlightLink(LinkConfig(url=url_of(endpoint), **FAST)) as lk:
            lk.connect(5.0)
            with pytest.raises(NotReady, match=r"missing: pre-arm checks \(SYS_STATUS\)") as info:
                lk.wait_ready(timeout=0.3)
            assert "position estimate (LOCAL_POSITION_NED)" in info.value.missing
            lk.set_mode("GUIDED")
            lk.control.in_control = True
            lk.arm(timeout=12.0)                    # refused (PreArm) until the checks pass, then armed
            assert lk.armed
            assert "MAV_CMD_COMPONENT_ARM_DISARM rejected: MAV_RESULT_FAILED" in lk.events
    finally:
        endpoint.stop()


def test_pilot_mode_change_pauses_until_handed_back(vehicle, link):
    link.start_guided()
    link.arm()
    link.takeoff(15.0)
    pilot = open_connection(url_of(vehicle), 255, 190)       # a ground station on the same vehicle
    try:
        result: dict = {}

        def fly() -> None:
            try:
                link.goto(120.0, 0.0, 17.0)
            except ControlLost as exc:
                result["goto"] = exc

        flight = threading.Thread(target=fly)
        flight.start()
        wait_until(lambda: vehicle.pose().position[0] > 20.0, 20.0, "the flight to start")
        pilot.mav.command_long_send(1, 1, mav.MAV_CMD_DO_SET_MODE, 0, mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                                    5, 0, 0, 0, 0, 0)                         # pilot: LOITER
        wait_until(lambda: link.paused, 5.0, "the link to pause")
        assert any(e.startswith("pilot took over: mode LOITER") for e in link.events)
        flight.join(timeout=5.0)  # the goto's wait ends at once with the takeover (issue 14 item 3)
        assert not flight.is_alive() and result["goto"].kind == "takeover"
        with pytest.raises(LinkError, match="paused"):
            link.set_waypoint(0.0, 0.0, 17.0)
        time.sleep(1.0)
        x_paused = vehicle.pose().position[0]
        time.sleep(1.0)                                                    # 5 s of mission time
        assert abs(vehicle.pose().position[0] - x_paused) < 0.2 and vehicle.mode == "LOITER"
        pilot.mav.command_long_send(1, 1, mav.MAV_CMD_DO_SET_MODE, 0, mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                                    4, 0, 0, 0, 0, 0)                         # handed back: GUIDED
        wait_until(lambda: not link.paused, 5.0, "control handed back")
        assert "control handed back (GUIDED); resuming" in link.events
        link.goto(120.0, 0.0, 17.0)                                        # and the link flies on
        assert np.linalg.norm(local(vehicle) - (120.0, 0.0, 17.0)) < 0.6
    finally:
        pilot.close()


def test_link_loss_and_recovery(vehicle, link):
    link.start_guided()
    link.arm()
    link.takeoff(15.0)
    result: dict = {}
    flight = threading.Thread(target=lambda: result.setdefault("goto", link.goto(150.0, 0.0, 17.0)))
    flight.start()
    wait_until(lambda: vehicle.pose().position[0] > 10.0, 20.0, "the flight to start")
    vehicle.pause_output()
    t_pause = time.monotonic()
    wait_until(lambda: not link.link_ok, 5.0, "link loss to be detected")
    assert 2.9 < time.monotonic() - t_pause < 4.5                            # 3 s without HEARTBEAT
    assert any(e.startswith("link lost: no HEARTBEAT for 3.0 s") for e in link.events)
    with pytest.raises(LinkLost):
        link.set_waypoint(0.0, 0.0, 20.0)                                   # no new waypoints while lost
    assert not link.telemetry().link_ok
    time.sleep(max(0.0, 5.0 - (time.monotonic() - t_pause)))
    vehicle.resume_output()
    wait_until(lambda: link.link_ok, 5.0, "the link to come back")
    assert any(e.startswith("link restored after") and e.endswith("resuming") for e in link.events)
    flight.join(timeout=40.0)
    assert "goto" in result and np.linalg.norm(local(vehicle) - (150.0, 0.0, 17.0)) < 0.6
    assert vehicle.mode == "GUIDED" and vehicle.armed


def test_long_link_loss_commands_rtl_when_it_returns(vehicle):
    cfg = LinkConfig(url=url_of(vehicle), heartbeat_timeout_s=0.5, long_loss_s=1.0, long_loss_action="rtl", **FAST)
    with FlightLink(cfg) as lk:
        lk.connect(5.0)
        lk.wait_ready()
        lk.start_guided()
        lk.arm()
        lk.takeoff(10.0)
        result: dict = {}

        def fly() -> None:
            try:
                lk.goto(200.0, 0.0, 12.0)
            except LinkLost as exc:
                result["error"] = str(exc)

        flight = threading.Thread(target=fly)
        flight.start()
        wait_until(lambda: vehicle.pose().position[0] > 5.0, 20.0, "the flight to start")
        vehicle.pause_output()
        wait_until(lambda: not lk.link_ok, 3.0, "link loss")
        time.sleep(1.5)
        vehicle.resume_output()
        flight.join(timeout=10.0)
        assert "RTL after a long link loss" in result["error"]
        wait_until(lambda: vehicle.mode == "RTL", 5.0, "RTL")
        assert any("commanding RTL" in e for e in lk.events)


def test_px4_offboard_flight_and_fallback_recovery():
    # PX4's stream rules run on the vehicle's (mission) clock: at 3x, a 20 Hz wall-clock stream is 6.7 Hz
    endpoint = start_vehicle("px4", speed=3.0, land_speed_m_s=1.5)
    try:
        cfg = LinkConfig(url=url_of(endpoint), heartbeat_timeout_s=1.0, setpoint_period_s=0.05, **FAST)
        with FlightLink(cfg, clock=lambda: endpoint.time) as lk:
            assert lk.connect(5.0) == "px4"
            lk.wait_ready()
            with pytest.raises(CommandRejected, match="MAV_RESULT_TEMPORARILY_REJECTED"):
                lk.set_mode("OFFBOARD")                   # no setpoint stream yet: PX4 refuses
            lk.start_guided()                             # streams >2 Hz for 1 s, then OFFBOARD
            assert endpoint.mode == "OFFBOARD"
            lk.arm()
            lk.takeoff(12.0)
            assert endpoint.pose().position[2] == pytest.approx(14.0, abs=0.6)
            lk.goto(30.0, 10.0, 14.0)
            # link loss: our stream stops, PX4 falls back to hold; when the link returns we re-enter OFFBOARD
            endpoint.pause_output()
            wait_until(lambda: not lk.link_ok, 3.0, "link loss")
            wait_until(lambda: endpoint.mode == "LOITER", 5.0, "PX4's offboard-loss fallback")
            endpoint.resume_output()
            wait_until(lambda: endpoint.mode == "OFFBOARD", 8.0, "re-entry into OFFBOARD")
            assert not lk.paused
            lk.goto(0.0, 20.0, 14.0)
            lk.land()
            assert not endpoint.armed and endpoint.pose().position[2] == pytest.approx(2.0, abs=0.01)
    finally:
        endpoint.stop()


def test_link_flies_through_mavproxy(vehicle):
    port = free_udp_port()
    with MavProxyRelay(url_of(vehicle), [f"udp:127.0.0.1:{port}"]):
        with FlightLink(LinkConfig(url=f"udpin:127.0.0.1:{port}", **FAST)) as lk:
            lk.connect(60.0)
            lk.wait_ready()
            lk.start_guided()
            lk.arm()
            lk.takeoff(20.0)
            lk.goto(-30.0, 25.0, 22.0)
            assert np.linalg.norm(local(vehicle) - (-30.0, 25.0, 22.0)) < 0.6
            assert vehicle.clients == 1       # the link reaches the vehicle only through MAVProxy
            lk.rtl()
            assert not vehicle.armed and np.hypot(*vehicle.pose().position[:2]) < 0.6


def test_command_line(vehicle, capsys):
    url = url_of(vehicle)
    assert cli_main(["link", "--mavlink", url, "--timeout", "10", "goto", "5", "5", "20"]) == 1
    assert "not armed" in capsys.readouterr().err
    assert cli_main(["link", "--mavlink", url, "takeoff", "12"]) == 0
    assert vehicle.armed and vehicle.pose().position[2] == pytest.approx(14.0, abs=1.1)
    assert cli_main(["link", "--mavlink", url, "--tolerance", "0.5", "goto", "20", "-10", "15", "--yaw", "90"]) == 0
    out = capsys.readouterr().out
    assert "goto: done" in out and "GUIDED" in out
    assert np.linalg.norm(local(vehicle) - (20.0, -10.0, 15.0)) < 0.6
    assert vehicle.pose().yaw == pytest.approx(np.pi / 2, abs=0.05)
    assert cli_main(["link", "--mavlink", url, "land"]) == 0
    assert not vehicle.armed


def test_reconnects_when_the_vehicle_comes_back_on_the_same_port():
    port = free_tcp_port()
    url = f"tcp:127.0.0.1:{port}"
    with FlightLink(LinkConfig(url=url, heartbeat_timeout_s=1.0, **FAST)) as lk:
        with pytest.raises(LinkLost, match="Connection refused"):
            lk.connect(0.5)                          # nobody serves yet
        first = MavlinkVehicle(Multicopter(), url).start(speed=SPEED)
        lk.connect(5.0)
        first.stop()                                 # the autopilot goes away (reboot, cable)
        wait_until(lambda: not lk.link_ok, 5.0, "link loss")
        assert any(e.startswith("connection error") for e in lk.events)
        second = MavlinkVehicle(Multicopter(), url).start(speed=SPEED)
        try:
            wait_until(lambda: lk.link_ok, 5.0, "reconnection")
            lk.wait_ready()
            assert second.clients == 1
        finally:
            second.stop()
