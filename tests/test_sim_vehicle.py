"""Simulated multicopter: dynamics limits with numbers, and its ArduCopter/PX4 MAVLink behaviour in lock-step."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

from conftest import free_udp_port
from layerpilot.geodesy import LocalFrame
from layerpilot.link.connection import open_connection
from layerpilot.link.frames import map_to_local_ned, yaw_enu_to_ned
from layerpilot.link.mission_transfer import GLOBAL, MissionItem
from layerpilot.sim.mavlink_vehicle import DEFAULT_INTERVALS, SITL_DATUM, EndpointConfig, MavlinkVehicle
from layerpilot.sim.vehicle import Multicopter, VehicleLimits

DT = 0.02


def fly(vehicle: Multicopter, seconds: float) -> np.ndarray:
    """Step ``seconds``; rows of (t, x, y, z, vx, vy, vz, ax, ay, az, yaw)."""
    rows = []
    for i in range(int(round(seconds / DT))):
        vehicle.step(DT)
        rows.append([(i + 1) * DT, *vehicle.position, *vehicle.velocity, *vehicle.acceleration, vehicle.yaw])
    return np.array(rows)


def airborne(z: float = 20.0) -> Multicopter:
    v = Multicopter(position=(0.0, 0.0, z), motors_on=True)
    v.hold()
    return v


def test_speed_and_acceleration_limits_on_a_100_m_leg():
    v = airborne()
    v.set_position_target(100.0, 0.0)
    rows = fly(v, 25.0)
    speed_h = np.hypot(rows[:, 4], rows[:, 5])
    accel = np.linalg.norm(rows[:, 7:10], axis=1)
    assert speed_h.max() == pytest.approx(10.0, abs=1e-9)      # cruises at the limit, never above
    assert accel.max() <= 4.0 + 1e-9
    assert np.all(np.abs(rows[:, 3] - 20.0) < 1e-9)            # constant altitude: z was not commanded
    assert rows[:, 1].max() < 100.05                           # no overshoot past the setpoint
    arrival = rows[np.argmax(np.abs(rows[:, 1] - 100.0) < 0.1), 0]
    # 2.5 s to reach 10 m/s, cruise, and a braking phase: 100 m / 10 m/s + 2.5 s is the bound below
    assert 12.5 <= arrival <= 16.0
    assert np.linalg.norm(v.velocity) < 0.01


def test_vertical_speed_limits_and_ground():
    v = airborne(5.0)
    v.set_position_target(z=35.0)
    up = fly(v, 15.0)
    assert up[:, 6].max() == pytest.approx(3.0, abs=1e-9)
    assert v.position[2] == pytest.approx(35.0, abs=0.05)
    v.set_position_target(z=-10.0)  # below ground: clamped to the ground
    down = fly(v, 30.0)
    assert down[:, 6].min() == pytest.approx(-2.0, abs=1e-9)
    assert v.position[2] == pytest.approx(0.0, abs=1e-3) and v.on_ground


def test_yaw_rate_limit_and_wrap():
    v = airborne()
    v.set_yaw_target(yaw=math.pi - 0.01)
    rows = fly(v, 6.0)
    rates = np.abs(np.diff(np.unwrap(rows[:, 10]))) / DT
    assert rates.max() <= math.radians(90.0) + 1e-9
    close = np.abs(rows[:, 10] - (math.pi - 0.01)) < 0.01
    assert close[-1]
    assert rows[np.argmax(close), 0] >= (math.pi - 0.02) / math.radians(90.0) - 1e-9
    v.set_yaw_target(yaw=-math.pi + 0.01)   # 0.02 rad away across the wrap, not a full turn
    fly(v, 0.1)
    assert abs(abs(v.yaw) - math.pi) < 0.011


def test_deterministic_and_motors_off_stays_on_ground():
    runs = []
    for _ in range(2):
        v = airborne()
        v.set_position_target(30.0, -12.0, 28.0, yaw=1.0)
        runs.append(fly(v, 10.0))
    assert np.array_equal(runs[0], runs[1])
    parked = Multicopter(limits=VehicleLimits(max_speed_h=5.0))
    parked.set_position_target(10.0, 10.0, 10.0)
    fly(parked, 2.0)
    assert np.array_equal(parked.position, [0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="dt"):
        parked.step(0.0)
    with pytest.raises(ValueError, match="max_speed_h"):
        VehicleLimits(max_speed_h=-1.0)


# --- the MAVLink endpoint in lock-step with a pymavlink client ------------------------------

class Bench:
    """Endpoint stepped by the test, with a pymavlink client on its TCP port."""

    def __init__(self, config: EndpointConfig | None = None, position=(0.0, 0.0, 0.0), streams: bool = True) -> None:
        self.endpoint = MavlinkVehicle(Multicopter(position=position, ground_z=position[2]), "tcp:127.0.0.1:0",
                                       config)
        port = self.endpoint.addresses[0][1]
        self.client = open_connection(f"tcp:127.0.0.1:{port}", 255, 190)
        self.received: list = []
        if streams:
            self.ask_streams()

    def ask_streams(self) -> None:
        """What a GCS does first: ask for every stream at its usual rate (ArduCopter sends none unasked)."""
        for msg_id, interval in DEFAULT_INTERVALS.items():
            self.client.mav.command_long_send(1, 1, mav.MAV_CMD_SET_MESSAGE_INTERVAL, 0, msg_id, interval * 1e6,
                                              0, 0, 0, 0, 0)

    def run(self, seconds: float) -> list:
        got = []
        for _ in range(int(round(seconds / DT))):
            self.endpoint.step(DT)
            while (msg := self.client.recv_match(blocking=False)) is not None:
                got.append(msg)
        self.received += got
        return got

    def command(self, command: int, *params: float) -> int:
        p = list(params) + [0.0] * (7 - len(params))
        self.client.mav.command_long_send(1, 1, command, 0, *p)
        for _ in range(50):
            for msg in self.run(DT):
                if msg.get_type() == "COMMAND_ACK" and msg.command == command:
                    assert (msg.target_system, msg.target_component) == (255, 190)
                    return msg.result
        raise AssertionError(f"no COMMAND_ACK for {command}")

    def set_mode(self, custom: int, sub: int = 0) -> int:
        return self.command(mav.MAV_CMD_DO_SET_MODE, mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, custom, sub)

    def texts(self) -> list[str]:
        return [m.text for m in self.received if m.get_type() == "STATUSTEXT"]

    def last(self, kind: str):
        return [m for m in self.received if m.get_type() == kind][-1]

    def close(self) -> None:
        self.client.close()
        self.endpoint.stop()


@pytest.fixture
def bench():
    b = Bench(position=(0.0, 0.0, 4.0))
    yield b
    b.close()


def test_telemetry_and_readiness(bench):
    early = bench.run(0.9)   # before the GPS fix: heartbeat, no position
    kinds = {m.get_type() for m in early}
    assert {"HEARTBEAT", "SYS_STATUS", "GPS_RAW_INT", "ATTITUDE"} <= kinds
    assert "LOCAL_POSITION_NED" not in kinds and "GLOBAL_POSITION_INT" not in kinds
    assert not bench.last("SYS_STATUS").onboard_control_sensors_health & mav.MAV_SYS_STATUS_PREARM_CHECK
    assert bench.command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1) == mav.MAV_RESULT_FAILED
    assert "PreArm: Need Position Estimate" in bench.texts()
    got = bench.run(2.0)
    hb = bench.last("HEARTBEAT")
    assert (hb.type, hb.autopilot, hb.custom_mode) == (mav.MAV_TYPE_QUADROTOR, mav.MAV_AUTOPILOT_ARDUPILOTMEGA, 0)
    assert hb.get_srcSystem() == 1 and hb.get_srcComponent() == 1
    assert bench.last("SYS_STATUS").onboard_control_sensors_health & mav.MAV_SYS_STATUS_PREARM_CHECK
    assert bench.last("GPS_RAW_INT").fix_type == 3
    local = bench.last("LOCAL_POSITION_NED")
    assert (local.x, local.y, local.z) == (0.0, 0.0, 0.0)   # the EKF origin: on the ground at home, like ArduCopter
    home = bench.last("HOME_POSITION")
    assert home.altitude == int(round((SITL_DATUM.alt + 4.0) * 1000))
    assert (home.x, home.y, home.z) == (0.0, 0.0, 0.0)      # ArduPilot sends zeros there
    origin = bench.last("GPS_GLOBAL_ORIGIN")
    assert (origin.latitude, origin.longitude, origin.altitude) == (home.latitude, home.longitude, home.altitude)
    assert bench.last("EKF_STATUS_REPORT").flags == 831
    # default 10 Hz position, 1 Hz heartbeat (mission time)
    assert sum(m.get_type() == "LOCAL_POSITION_NED" for m in got) in (19, 20, 21)
    assert sum(m.get_type() == "HEARTBEAT" for m in got) == 2
    assert bench.command(mav.MAV_CMD_SET_MESSAGE_INTERVAL, mav.MAVLINK_MSG_ID_LOCAL_POSITION_NED, 20000) == \
        mav.MAV_RESULT_ACCEPTED
    assert bench.command(mav.MAV_CMD_SET_MESSAGE_INTERVAL, mav.MAVLINK_MSG_ID_ATTITUDE, -1) == mav.MAV_RESULT_ACCEPTED
    got = bench.run(1.0)
    assert sum(m.get_type() == "LOCAL_POSITION_NED" for m in got) in (49, 50, 51)
    assert sum(m.get_type() == "ATTITUDE" for m in got) == 0
    assert bench.command(42424) == mav.MAV_RESULT_UNSUPPORTED


def test_arducopter_streams_only_what_was_asked_and_a_reboot_forgets_it():
    """Like ArduCopter (SRx_ rates 0): HEARTBEAT alone until a stream is asked for (plus home and the EKF
    origin once, when the fix sets them), REQUEST_DATA_STREAM groups at the asked rate, and after a
    reboot the same again. PX4 streams unasked."""
    unasked = ["HEARTBEAT", "HEARTBEAT", "HOME_POSITION", "GPS_GLOBAL_ORIGIN"]  # the fix comes at 1 s
    b = Bench(streams=False)
    try:
        assert sorted(m.get_type() for m in b.run(1.5)) == sorted(unasked)
        b.client.mav.request_data_stream_send(1, 1, mav.MAV_DATA_STREAM_POSITION, 5, 1)
        got = [m.get_type() for m in b.run(2.0)]
        assert set(got) == {"HEARTBEAT", "LOCAL_POSITION_NED", "GLOBAL_POSITION_INT"}
        assert got.count("LOCAL_POSITION_NED") in (9, 10, 11)
        b.endpoint.reboot()
        assert sorted(m.get_type() for m in b.run(1.5)) == sorted(unasked)
    finally:
        b.close()
    px4 = Bench(EndpointConfig(flavour="px4"), streams=False)
    try:
        assert {"SYS_STATUS", "ATTITUDE", "GPS_RAW_INT", "LOCAL_POSITION_NED"} <= {m.get_type() for m in px4.run(1.5)}
    finally:
        px4.close()


def test_arducopter_refusals_and_auto_disarm(bench):
    bench.run(2.5)
    assert bench.command(mav.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 30) == mav.MAV_RESULT_FAILED  # disarmed
    assert bench.set_mode(9) == mav.MAV_RESULT_ACCEPTED                                          # LAND
    assert bench.command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1) == mav.MAV_RESULT_FAILED           # not armable
    assert "Arm: Mode not armable" in bench.texts()
    assert bench.set_mode(77) == mav.MAV_RESULT_FAILED                                           # no such mode
    bench.client.mav.set_mode_send(1, mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 4)                  # SET_MODE GUIDED
    acks = [m for m in bench.run(0.1) if m.get_type() == "COMMAND_ACK"]
    assert [(a.command, a.result) for a in acks] == [(mav.MAVLINK_MSG_ID_SET_MODE, mav.MAV_RESULT_ACCEPTED)]
    assert bench.endpoint.mode == "GUIDED"
    assert bench.command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1) == mav.MAV_RESULT_ACCEPTED
    bench.run(1.0)
    assert bench.last("HEARTBEAT").base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED
    bench.run(8.0)
    assert bench.endpoint.armed
    bench.run(1.2)                    # 10 s armed on the ground: ArduCopter disarms itself
    assert not bench.endpoint.armed
    bench.run(1.0)
    assert not bench.last("HEARTBEAT").base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED


def test_guided_flight_with_type_masks_land_and_rtl(bench):
    bench.run(2.5)
    assert bench.set_mode(4) == mav.MAV_RESULT_ACCEPTED
    assert bench.command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1) == mav.MAV_RESULT_ACCEPTED
    assert bench.command(mav.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 30) == mav.MAV_RESULT_ACCEPTED
    assert bench.command(mav.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 30) == mav.MAV_RESULT_FAILED  # already flying
    bench.run(14.0)
    assert bench.endpoint.pose().position[2] == pytest.approx(34.0, abs=0.05)   # 30 m above home at z=4
    assert bench.command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 0) == mav.MAV_RESULT_FAILED           # in flight
    # position-only local NED target, yaw given: east 40, north 10, 25 m up
    n, e, d = map_to_local_ned(40.0, 10.0, 25.0, bench.endpoint.ekf_origin)   # local NED is EKF-origin relative
    assert (n, e, d) == (10.0, 40.0, -21.0)
    bench.client.mav.set_position_target_local_ned_send(0, 1, 1, mav.MAV_FRAME_LOCAL_NED, 0b100111111000,
                                                        n, e, d, 0, 0, 0, 0, 0, 0, yaw_enu_to_ned(math.pi / 2), 0)
    bench.run(15.0)
    pose = bench.endpoint.pose()
    assert np.allclose(pose.position, (40.0, 10.0, 25.0), atol=0.05)
    assert pose.yaw == pytest.approx(math.pi / 2, abs=1e-3)        # facing north
    att = bench.last("ATTITUDE")
    assert att.yaw == pytest.approx(0.0, abs=1e-3)                 # north is NED yaw 0
    glob = bench.last("GLOBAL_POSITION_INT")
    assert glob.relative_alt == pytest.approx(21000, abs=60) and glob.hdg in (0, 35999, 36000 - 1)
    # the velocity part of a position-only mask is ignored; a velocity-only mask flies the velocity for 3 s
    bench.client.mav.set_position_target_local_ned_send(0, 1, 1, mav.MAV_FRAME_LOCAL_NED, 0b110111000111,
                                                        0, 0, 0, 0.0, 2.0, 0.0, 0, 0, 0, 0, 0)
    bench.run(2.0)
    assert bench.endpoint.pose().velocity[0] == pytest.approx(2.0, abs=1e-6)
    bench.run(5.0)
    assert np.linalg.norm(bench.endpoint.pose().velocity) < 0.05   # ArduCopter's 3 s velocity timeout
    x_stop = bench.endpoint.pose().position[0]
    assert 45.0 < x_stop < 48.0
    # GLOBAL_INT target, altitude relative to home
    lat, lon, _ = SITL_DATUM.to_geodetic(-20.0, 30.0, 0.0)
    bench.client.mav.set_position_target_global_int_send(0, 1, 1, mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                                                          0b110111111000, int(round(lat * 1e7)),
                                                          int(round(lon * 1e7)), 18.0, 0, 0, 0, 0, 0, 0, 0, 0)
    bench.run(20.0)
    assert np.allclose(bench.endpoint.pose().position, (-20.0, 30.0, 22.0), atol=0.05)
    # no yaw given: like ArduCopter (WP_YAW_BEHAVIOR 2) it turned to face the destination on the way
    assert bench.endpoint.pose().yaw == pytest.approx(math.atan2(30.0 - 10.0, -20.0 - x_stop), abs=0.02)
    assert bench.command(mav.MAV_CMD_NAV_RETURN_TO_LAUNCH) == mav.MAV_RESULT_ACCEPTED
    bench.run(3.0)   # above RTL_ALT already: returns at its altitude, then lands at home
    pose = bench.endpoint.pose()
    assert bench.endpoint.mode == "RTL" and pose.position[2] == pytest.approx(22.0, abs=0.01)
    assert np.hypot(*pose.position[:2]) < 30.0
    bench.run(50.0)
    assert not bench.endpoint.armed and bench.endpoint.mode == "RTL"
    assert np.allclose(bench.endpoint.pose().position, (0.0, 0.0, 4.0), atol=0.3)
    assert bench.last("HEARTBEAT").custom_mode == 6


def test_auto_refuses_as_arducopter_then_takes_off_flies_and_lands_a_mission(bench):
    """AUTO from the ground: refused without a mission and, armed, without a takeoff first; a mission of
    takeoff, waypoint and land is flown item by item and ends disarmed on the ground at the landing point."""
    def item(x: float, y: float, alt: float, command: int = mav.MAV_CMD_NAV_WAYPOINT, frame: int = 3):
        lat, lon, _ = SITL_DATUM.to_geodetic(x, y, 0.0)
        return MissionItem(float(lat), float(lon), alt, command, frame, (0.0, 0.0, 0.0, math.nan))

    home = item(0.0, 0.0, SITL_DATUM.alt + 4.0, frame=GLOBAL)
    bench.run(2.1)
    assert bench.set_mode(3) == mav.MAV_RESULT_FAILED and "Mode change to AUTO failed: init failed" in bench.texts()
    bench.endpoint.mission.items = [home, item(10.0, 5.0, 6.0)]
    assert bench.set_mode(4) == mav.MAV_RESULT_ACCEPTED
    assert bench.command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1) == mav.MAV_RESULT_ACCEPTED
    assert bench.set_mode(3) == mav.MAV_RESULT_FAILED and "Auto: Missing Takeoff Cmd" in bench.texts()
    bench.endpoint.mission.items = [home, item(0.0, 0.0, 6.0, mav.MAV_CMD_NAV_TAKEOFF), item(10.0, 5.0, 6.0),
                                    item(10.0, 5.0, 0.0, mav.MAV_CMD_NAV_LAND)]
    assert bench.set_mode(3) == mav.MAV_RESULT_ACCEPTED
    bench.run(4.0)
    assert bench.endpoint.pose().position[2] == pytest.approx(10.0, abs=0.3)  # 6 m above home at z 4
    bench.run(30.0)
    assert not bench.endpoint.armed and bench.endpoint.mode == "AUTO"
    assert np.allclose(bench.endpoint.pose().position, (10.0, 5.0, 4.0), atol=0.3)
    assert [m.seq for m in bench.received if m.get_type() == "MISSION_ITEM_REACHED"] == [1, 2]
    assert [t for t in bench.texts() if t.startswith(("Mission:", "Reached", "Land"))] == [
        "Mission: 1 Takeoff", "Reached command #1", "Mission: 2 WP", "Reached command #2", "Mission: 3 Land",
        "Land complete, disarming"]


def test_px4_offboard_needs_a_setpoint_stream_and_falls_back():
    b = Bench(EndpointConfig(flavour="px4"))
    try:
        b.run(2.5)
        assert b.last("HEARTBEAT").autopilot == mav.MAV_AUTOPILOT_PX4
        assert b.set_mode(6) == mav.MAV_RESULT_TEMPORARILY_REJECTED        # no setpoint stream yet

        def stream(seconds: float, z_up: float, period: float = 0.2) -> None:
            for _ in range(int(round(seconds / period))):
                b.client.mav.set_position_target_local_ned_send(0, 1, 1, mav.MAV_FRAME_LOCAL_NED, 0b110111111000,
                                                                0.0, 5.0, -z_up, 0, 0, 0, 0, 0, 0, 0, 0)
                b.run(period)

        stream(0.2, 10.0)                                                  # one setpoint is not a stream
        assert b.set_mode(6) == mav.MAV_RESULT_TEMPORARILY_REJECTED
        stream(1.2, 10.0)                                                  # 5 Hz for 1.2 s
        assert b.set_mode(6) == mav.MAV_RESULT_ACCEPTED
        assert b.command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1) == mav.MAV_RESULT_ACCEPTED
        stream(8.0, 10.0)
        assert np.allclose(b.endpoint.pose().position, (5.0, 0.0, 10.0), atol=0.05)
        assert b.last("HEARTBEAT").custom_mode == 6 << 16
        b.run(1.5)                                                         # stream stops
        assert b.endpoint.mode == "LOITER" and b.last("HEARTBEAT").custom_mode == (4 << 16) | (3 << 24)
        assert any("offboard" in t for t in b.texts())
        assert np.allclose(b.endpoint.pose().position, (5.0, 0.0, 10.0), atol=0.05)
    finally:
        b.close()


def test_the_geodetic_messages_are_the_map_frame_on_the_earth():
    """HOME_POSITION, GPS_GLOBAL_ORIGIN and GLOBAL_POSITION_INT place map-frame points with geodesy.LocalFrame:
    read back through it, a home 500 m east and 500 m north of the datum comes back within MAVLink's 1e-7
    degrees (1.1 cm). (The simulator's former equirectangular formula on the equatorial radius put it 1.06 m off.)"""
    bench = Bench(position=(500.0, 500.0, 3.0))
    try:
        bench.run(1.2)  # the GPS fix comes after half of prearm_delay_s
        for kind, lat, lon, alt in (("HOME_POSITION", "latitude", "longitude", "altitude"),
                                    ("GPS_GLOBAL_ORIGIN", "latitude", "longitude", "altitude"),
                                    ("GLOBAL_POSITION_INT", "lat", "lon", "alt")):
            msg = bench.last(kind)
            x, y, z = SITL_DATUM.from_geodetic(getattr(msg, lat) * 1e-7, getattr(msg, lon) * 1e-7,
                                               getattr(msg, alt) * 1e-3)
            assert np.allclose((x, y, z), (500.0, 500.0, 3.0), atol=0.011), (kind, x, y, z)
    finally:
        bench.close()


def test_bad_arguments():
    with pytest.raises(ValueError, match="url"):
        MavlinkVehicle(Multicopter(), "serial:/dev/null")
    with pytest.raises(ValueError, match="flavour"):
        EndpointConfig(flavour="inav")
    with pytest.raises(ValueError, match="lat"):
        EndpointConfig(origin=LocalFrame(95.0, 8.5))


def test_hold_brakes_to_the_stopping_point_without_coming_back():
    v = airborne()
    v.set_velocity_target(10.0, 0.0, 0.0)
    fly(v, 4.0)
    x0 = v.position[0]
    v.hold()
    rows = fly(v, 8.0)
    assert np.all(np.diff(rows[:, 1]) >= -1e-9)              # never reverses
    assert v.position[0] - x0 == pytest.approx(10.0 ** 2 / (2 * 4.0 * 0.8), abs=0.3)
    assert np.linalg.norm(v.velocity) < 0.01


def test_udp_endpoints_px4_sitl_style_and_udpin():
    port = free_udp_port()
    endpoint = MavlinkVehicle(Multicopter(), [f"udpout:127.0.0.1:{port}", "udpin:127.0.0.1:0"])
    listener = open_connection(f"udpin:127.0.0.1:{port}", 255, 190)        # like an offboard API on 14540
    sender = open_connection(f"udpout:127.0.0.1:{endpoint.addresses[1][1]}", 254, 190)
    try:
        sender.mav.heartbeat_send(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0)  # udpin learns its peer
        got = {"listener": [], "sender": []}
        for _ in range(60):
            endpoint.step(DT)
            for name, conn in (("listener", listener), ("sender", sender)):
                while (msg := conn.recv_match(blocking=False)) is not None:
                    got[name].append(msg)
        for name in got:
            assert sum(m.get_type() == "HEARTBEAT" for m in got[name]) == 2, name
        assert endpoint.clients == 2
        listener.mav.command_long_send(1, 1, mav.MAV_CMD_DO_SET_MODE, 0, 1, 4, 0, 0, 0, 0, 0)
        for _ in range(10):
            endpoint.step(DT)
        assert endpoint.mode == "GUIDED"
    finally:
        listener.close()
        sender.close()
        endpoint.stop()


def test_realtime_loop_never_runs_ahead_of_the_paced_clock():
    endpoint = MavlinkVehicle(Multicopter(), "tcp:127.0.0.1:0")
    t0 = time.monotonic()
    endpoint.start(speed=4.0)
    time.sleep(0.5)
    endpoint.stop()
    elapsed = time.monotonic() - t0
    assert 0.0 < endpoint.time <= 4.0 * elapsed + 0.02
