"""A plain pymavlink script written for ArduCopter SITL flies the simulated vehicle unchanged (issue 14).

The script knows nothing of layerpilot: it runs in its own process, waits for the EKF,
switches to GUIDED, arms, takes off to 30 m, waits until ``-LOCAL_POSITION_NED.z >= 28.5``
(the local NED origin is the EKF origin, on the ground at home) and flies to (20, 10, -30).
The vehicle stands on terrain 5.7 m below the world's datum, as at home in the default world
(where the old convention said LOCAL_POSITION_NED z = +5.7 on the ground and -24.3 at 30 m).
"""

from __future__ import annotations

import json
import subprocess
import sys
import time

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

from layerpilot.link.connection import open_connection
from layerpilot.geodesy import LocalFrame
from layerpilot.sim.mavlink_vehicle import EndpointConfig, MavlinkVehicle
from layerpilot.sim.vehicle import Multicopter

GROUND = -5.7
DATUM = LocalFrame(47.397742, 8.545594, 488.0)

SCRIPT = r'''
import json, sys, time
from pymavlink import mavutil

master = mavutil.mavlink_connection(f"tcp:127.0.0.1:{sys.argv[1]}")
master.wait_heartbeat(timeout=30)
deadline = time.time() + 60


def wait(kind, condition=lambda m: True):
    while time.time() < deadline:
        m = master.recv_match(type=kind, blocking=True, timeout=1)
        if m is not None and condition(m):
            return m
    raise SystemExit(f"timed out waiting for {kind}")


def snapshot():
    # HOME_POSITION and GPS_GLOBAL_ORIGIN are in no stream: ArduCopter sends them when set and on request
    for msg_id in (242, 49):
        master.mav.command_long_send(master.target_system, master.target_component,
                                     mavutil.mavlink.MAV_CMD_REQUEST_MESSAGE, 0, msg_id, 0, 0, 0, 0, 0, 0)
    kinds = ["LOCAL_POSITION_NED", "GLOBAL_POSITION_INT", "HOME_POSITION", "GPS_GLOBAL_ORIGIN", "EKF_STATUS_REPORT"]
    got = {}
    while len(got) < len(kinds):
        m = wait(kinds)
        got[m.get_type()] = m.to_dict()
    return got


# ArduCopter streams nothing but HEARTBEAT until asked (its SRn_ rates default to 0 without MAVProxy)
master.mav.request_data_stream_send(master.target_system, master.target_component,
                                    mavutil.mavlink.MAV_DATA_STREAM_ALL, 10, 1)
# wait for the EKF to use GPS (horizontal absolute position), as SITL scripts do
wait("EKF_STATUS_REPORT", lambda m: m.flags & mavutil.mavlink.EKF_POS_HORIZ_ABS)
ground = snapshot()
master.set_mode("GUIDED")
wait("HEARTBEAT", lambda m: m.custom_mode == 4)
while True:
    master.mav.command_long_send(master.target_system, master.target_component,
                                 mavutil.mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
    ack = wait("COMMAND_ACK", lambda m: m.command == mavutil.mavlink.MAV_CMD_COMPONENT_ARM_DISARM)
    if ack.result == mavutil.mavlink.MAV_RESULT_ACCEPTED:
        break
    time.sleep(0.5)
master.mav.command_long_send(master.target_system, master.target_component,
                             mavutil.mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 0, 30)
ack = wait("COMMAND_ACK", lambda m: m.command == mavutil.mavlink.MAV_CMD_NAV_TAKEOFF)
assert ack.result == mavutil.mavlink.MAV_RESULT_ACCEPTED, ack
wait("LOCAL_POSITION_NED", lambda m: -m.z >= 28.5)
master.mav.set_position_target_local_ned_send(0, master.target_system, master.target_component,
                                              mavutil.mavlink.MAV_FRAME_LOCAL_NED, 0b110111111000,
                                              20, 10, -30, 0, 0, 0, 0, 0, 0, 0, 0)
wait("LOCAL_POSITION_NED", lambda m: abs(m.x - 20) < 0.05 and abs(m.y - 10) < 0.05 and abs(m.z + 30) < 0.05)
print(json.dumps({"ground": ground, "there": snapshot()}))
'''


def test_plain_arducopter_sitl_script_flies_the_simulated_vehicle():
    endpoint = MavlinkVehicle(Multicopter(position=(0.0, 0.0, GROUND), ground_z=GROUND), "tcp:127.0.0.1:0",
                              EndpointConfig(origin=DATUM))
    with endpoint.start(speed=5.0):
        port = endpoint.addresses[0][1]
        run = subprocess.run([sys.executable, "-c", SCRIPT, str(port)], capture_output=True, text=True, timeout=120)
        assert run.returncode == 0, run.stderr[-2000:]
        pose = endpoint.pose()
    seen = json.loads(run.stdout.strip().splitlines()[-1])
    ground, there = seen["ground"], seen["there"]
    home_mm = round((DATUM.alt + GROUND) * 1000)   # home's altitude AMSL: the datum plus the terrain under home
    # on the ground at home: the EKF origin, z = 0
    g = ground["LOCAL_POSITION_NED"]
    assert (g["x"], g["y"], g["z"]) == (0.0, 0.0, 0.0)
    assert ground["GLOBAL_POSITION_INT"]["relative_alt"] == 0
    assert ground["GLOBAL_POSITION_INT"]["alt"] == home_mm
    h = ground["HOME_POSITION"]
    assert (h["altitude"], h["x"], h["y"], h["z"]) == (home_mm, 0.0, 0.0, 0.0)
    o = ground["GPS_GLOBAL_ORIGIN"]
    assert (o["latitude"], o["longitude"], o["altitude"]) == (h["latitude"], h["longitude"], home_mm)
    assert ground["EKF_STATUS_REPORT"]["flags"] == 831
    # at 30 m over (20 m north, 10 m east)
    t = there["LOCAL_POSITION_NED"]
    assert (t["x"], t["y"], t["z"]) == pytest.approx((20.0, 10.0, -30.0), abs=0.1)
    assert there["GLOBAL_POSITION_INT"]["relative_alt"] == pytest.approx(30000, abs=100)
    assert there["GLOBAL_POSITION_INT"]["alt"] == pytest.approx(home_mm + 30000, abs=100)
    assert there["HOME_POSITION"] == ground["HOME_POSITION"] | {"time_usec": there["HOME_POSITION"]["time_usec"]}
    assert there["GPS_GLOBAL_ORIGIN"]["altitude"] == home_mm
    # in layerpilot's map frame the vehicle is 30 m above the terrain at home, 20 m north and 10 m east
    assert tuple(pose.position) == pytest.approx((10.0, 20.0, GROUND + 30.0), abs=0.1)
    assert mav.EKF_POS_HORIZ_ABS & there["EKF_STATUS_REPORT"]["flags"]


def test_px4_local_origin_is_home_on_the_ground_too():
    """PX4 SITL's local origin is also at home on the ground; PX4 sends no EKF_STATUS_REPORT."""
    endpoint = MavlinkVehicle(Multicopter(position=(3.0, -2.0, GROUND), ground_z=GROUND), "tcp:127.0.0.1:0",
                              EndpointConfig(flavour="px4", origin=DATUM))
    client = open_connection(f"tcp:127.0.0.1:{endpoint.addresses[0][1]}", 255, 190)
    got: list = []

    def run(seconds: float) -> None:
        for _ in range(int(round(seconds / 0.02))):
            endpoint.step(0.02)
            while (m := client.recv_match(blocking=False)) is not None:
                got.append(m)

    def last(kind: str):
        return [m for m in got if m.get_type() == kind][-1]

    try:
        for _ in range(50):   # the TCP client is accepted on the endpoint's first polls
            run(0.02)
            time.sleep(0.002)
        run(6.0)
        local, home, origin = last("LOCAL_POSITION_NED"), last("HOME_POSITION"), last("GPS_GLOBAL_ORIGIN")
        assert (local.x, local.y, local.z) == (0.0, 0.0, 0.0)
        assert (home.x, home.y, home.z) == (0.0, 0.0, 0.0)
        assert home.altitude == origin.altitude == round((DATUM.alt + GROUND) * 1000)
        assert not [m for m in got if m.get_type() == "EKF_STATUS_REPORT"]
        for _ in range(8):   # an OFFBOARD stream 10 m up, 5 m east of the local origin
            client.mav.set_position_target_local_ned_send(0, 1, 1, mav.MAV_FRAME_LOCAL_NED, 0b110111111000,
                                                          0.0, 5.0, -10.0, 0, 0, 0, 0, 0, 0, 0, 0)
            run(0.2)
        client.mav.command_long_send(1, 1, mav.MAV_CMD_DO_SET_MODE, 0, mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                                     6, 0, 0, 0, 0, 0)
        client.mav.command_long_send(1, 1, mav.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
        for _ in range(60):
            client.mav.set_position_target_local_ned_send(0, 1, 1, mav.MAV_FRAME_LOCAL_NED, 0b110111111000,
                                                          0.0, 5.0, -10.0, 0, 0, 0, 0, 0, 0, 0, 0)
            run(0.2)
        local = last("LOCAL_POSITION_NED")
        assert (local.x, local.y, local.z) == pytest.approx((0.0, 5.0, -10.0), abs=0.05)
        assert tuple(endpoint.pose().position) == pytest.approx((8.0, -2.0, GROUND + 10.0), abs=0.05)
        assert last("GLOBAL_POSITION_INT").relative_alt == pytest.approx(10000, abs=50)
    finally:
        client.close()
        endpoint.stop()
