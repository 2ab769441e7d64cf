"""The simulated vehicle from outside: MAVProxy relays it, a plain pymavlink script flies it through the relay."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

from conftest import free_udp_port
from layerpilot.link.connection import open_connection
from layerpilot.link.frames import enu_to_ned
from layerpilot.sim.mavlink_vehicle import MavlinkVehicle
from layerpilot.sim.vehicle import Multicopter
from mavlink_relay import MavProxyRelay

SPEED = 4.0  # mission clock runs 4x faster than the wall clock


@pytest.fixture
def vehicle():
    endpoint = MavlinkVehicle(Multicopter(), "tcp:127.0.0.1:0").start(speed=SPEED)
    yield endpoint
    endpoint.stop()


def wait_for(conn, predicate, timeout: float, what: str):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        msg = conn.recv_match(blocking=True, timeout=0.2)
        if msg is not None and predicate(msg):
            return msg
    raise AssertionError(f"timed out waiting for {what}")


def command(conn, cmd: int, *params: float) -> int:
    p = list(params) + [0.0] * (7 - len(params))
    conn.mav.command_long_send(1, 1, cmd, 0, *p)
    ack = wait_for(conn, lambda m: m.get_type() == "COMMAND_ACK" and m.command == cmd, 10.0, f"ACK of {cmd}")
    return ack.result


def test_script_flies_through_mavproxy(vehicle):
    port = free_udp_port()
    master = f"tcp:127.0.0.1:{vehicle.addresses[0][1]}"
    with MavProxyRelay(master, [f"udp:127.0.0.1:{port}"]) as relay:
        script = open_connection(f"udpin:127.0.0.1:{port}", 255, 191)
        direct = open_connection(master, 254, 190)   # a second TCP client on the same port, beside MAVProxy
        try:
            hb = wait_for(script, lambda m: m.get_type() == "HEARTBEAT" and m.get_srcSystem() == 1, 60.0,
                          "the vehicle's HEARTBEAT through MAVProxy")
            assert hb.autopilot == mav.MAV_AUTOPILOT_ARDUPILOTMEGA and hb.type == mav.MAV_TYPE_QUADROTOR
            wait_for(direct, lambda m: m.get_type() == "HEARTBEAT", 10.0, "a HEARTBEAT on the direct client")
            assert vehicle.clients == 2
            wait_for(script, lambda m: m.get_type() == "SYS_STATUS"
                     and m.onboard_control_sensors_health & mav.MAV_SYS_STATUS_PREARM_CHECK, 20.0, "pre-arm healthy")
            assert command(script, mav.MAV_CMD_DO_SET_MODE, mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 4) == \
                mav.MAV_RESULT_ACCEPTED
            assert command(script, mav.MAV_CMD_COMPONENT_ARM_DISARM, 1) == mav.MAV_RESULT_ACCEPTED
            assert command(script, mav.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 30) == mav.MAV_RESULT_ACCEPTED
            wait_for(script, lambda m: m.get_type() == "GLOBAL_POSITION_INT" and m.relative_alt > 29500, 20.0,
                     "30 m altitude")
            n, e, d = enu_to_ned(60.0, -40.0, 30.0)
            script.mav.set_position_target_local_ned_send(0, 1, 1, mav.MAV_FRAME_LOCAL_NED, 0b110111111000,
                                                          n, e, d, 0, 0, 0, 0, 0, 0, 0, 0)
            at = wait_for(script, lambda m: m.get_type() == "LOCAL_POSITION_NED"
                          and math.dist((m.x, m.y, m.z), (n, e, d)) < 0.5, 30.0, "arrival at the point")
            assert at.z == pytest.approx(-30.0, abs=0.5)
            assert np.allclose(vehicle.pose().position, (60.0, -40.0, 30.0), atol=0.5)
            assert vehicle.armed and vehicle.mode == "GUIDED"
            assert relay.process.poll() is None
        finally:
            script.close()
            direct.close()
    assert relay.process.poll() is not None
