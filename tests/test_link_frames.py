"""Map frame (ENU) <-> MAVLink NED, both ways, including yaw and attitude; link settings validation."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from layerpilot.config import ConfigError, from_dict
from layerpilot.link.config import LinkConfig
from layerpilot.link.connection import parse_url
from layerpilot.link.frames import (attitude_enu_to_ned, attitude_ned_to_enu, autopilot_enu_to_map, enu_to_ned,
                                    local_ned_to_map, map_to_autopilot_enu, map_to_local_ned, ned_to_enu,
                                    yaw_enu_to_ned, yaw_ned_to_enu)
from layerpilot.link.modes import ARDUPILOT, PX4, custom_mode_of, mode_name, result_name

T_ENU_NED = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])  # NED vector -> ENU vector
T_FRD_FLU = np.diag([1.0, -1.0, -1.0])                                        # FLU body vector -> FRD


def rot_zyx(roll: float, pitch: float, yaw: float) -> np.ndarray:
    cr, sr, cp, sp, cy, sy = (math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch),
                              math.cos(yaw), math.sin(yaw))
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    return rz @ ry @ rx


def test_points_and_headings_by_hand():
    assert enu_to_ned(10.0, 20.0, 30.0) == (20.0, 10.0, -30.0)       # 10 m east, 20 m north, 30 m up
    assert ned_to_enu(20.0, 10.0, -30.0) == (10.0, 20.0, 30.0)
    assert yaw_enu_to_ned(0.0) == pytest.approx(math.pi / 2)          # facing east
    assert yaw_enu_to_ned(math.pi / 2) == pytest.approx(0.0)          # facing north
    assert yaw_enu_to_ned(math.pi) == pytest.approx(-math.pi / 2)     # facing west
    assert yaw_ned_to_enu(math.pi) == pytest.approx(-math.pi / 2)     # facing south
    assert yaw_ned_to_enu(-math.pi / 2) == pytest.approx(-math.pi)    # facing west, wrapped to [-pi, pi)


@given(st.floats(-1e4, 1e4), st.floats(-1e4, 1e4), st.floats(-1e3, 1e3))
def test_position_round_trip(x, y, z):
    assert ned_to_enu(*enu_to_ned(x, y, z)) == (x, y, z)


def test_ekf_origin_offset_by_hand():
    # ArduCopter's EKF origin is home on the ground; here home lies at (0, 0) on terrain 5.7 m above the map origin
    origin = (0.0, 0.0, 5.7)
    assert map_to_local_ned(0.0, 0.0, 5.7, origin) == (0.0, 0.0, 0.0)            # on the ground at home: z = 0
    assert map_to_local_ned(10.0, 20.0, 35.7, origin) == pytest.approx((20.0, 10.0, -30.0))  # 30 m above home
    assert local_ned_to_map(20.0, 10.0, -30.0, origin) == pytest.approx((10.0, 20.0, 35.7))
    assert map_to_autopilot_enu(10.0, 20.0, 35.7, origin) == pytest.approx((10.0, 20.0, 30.0))
    assert autopilot_enu_to_map(10.0, 20.0, 30.0, origin) == pytest.approx((10.0, 20.0, 35.7))
    # without an offset the map origin is the EKF origin (a real autopilot's convention in layerpilot)
    assert map_to_local_ned(10.0, 20.0, 30.0) == enu_to_ned(10.0, 20.0, 30.0)
    assert local_ned_to_map(20.0, 10.0, -30.0, None) == ned_to_enu(20.0, 10.0, -30.0)


@given(st.floats(-1e4, 1e4), st.floats(-1e4, 1e4), st.floats(-1e3, 1e3),
       st.tuples(st.floats(-1e3, 1e3), st.floats(-1e3, 1e3), st.floats(-1e2, 1e2)))
def test_ekf_origin_round_trip_both_ways(x, y, z, origin):
    assert local_ned_to_map(*map_to_local_ned(x, y, z, origin), origin) == pytest.approx((x, y, z), abs=1e-9)
    assert map_to_local_ned(*local_ned_to_map(x, y, z, origin), origin) == pytest.approx((x, y, z), abs=1e-9)
    assert autopilot_enu_to_map(*map_to_autopilot_enu(x, y, z, origin), origin) == pytest.approx((x, y, z),
                                                                                                  abs=1e-9)
    # the NED form is the ENU form with the axes swapped
    assert map_to_local_ned(x, y, z, origin) == enu_to_ned(*map_to_autopilot_enu(x, y, z, origin))


@given(st.floats(-1.4, 1.4), st.floats(-1.4, 1.4), st.floats(-3.1, 3.1))
def test_attitude_conversion_is_the_frame_change_both_ways(roll, pitch, yaw):
    r_ned_frd = rot_zyx(roll, pitch, yaw)
    enu = attitude_ned_to_enu(roll, pitch, yaw)
    # the same physical orientation: R_enu_flu = T_enu_ned R_ned_frd T_frd_flu
    assert np.allclose(rot_zyx(*enu), T_ENU_NED @ r_ned_frd @ T_FRD_FLU, atol=1e-9)
    back = attitude_enu_to_ned(*enu)
    assert back[0] == pytest.approx(roll) and back[1] == pytest.approx(pitch)
    assert math.cos(back[2] - yaw) == pytest.approx(1.0)
    assert math.cos(yaw_ned_to_enu(yaw_enu_to_ned(yaw)) - yaw) == pytest.approx(1.0)


def test_mode_numbers():
    assert custom_mode_of(ARDUPILOT, "GUIDED") == 4 and mode_name(ARDUPILOT, 9) == "LAND"
    assert custom_mode_of(PX4, "OFFBOARD") == 6 << 16
    assert mode_name(PX4, (4 << 16) | (3 << 24)) == "LOITER" and mode_name(PX4, 3 << 16) == "POSCTL"
    assert result_name(4) == "MAV_RESULT_FAILED"
    with pytest.raises(ValueError, match="mode"):
        custom_mode_of(ARDUPILOT, "HOVER")


def test_urls_and_config_errors_name_the_key():
    assert parse_url("tcp:127.0.0.1:5760") == ("tcp:127.0.0.1:5760", 57600)
    assert parse_url("udpin:0.0.0.0:14540") == ("udpin:0.0.0.0:14540", 57600)
    assert parse_url("/dev/ttyACM0:921600") == ("/dev/ttyACM0", 921600)
    assert parse_url("serial:/dev/ttyUSB0") == ("/dev/ttyUSB0", 57600)
    with pytest.raises(ValueError, match="url"):
        parse_url("http://drone")
    with pytest.raises(ValueError, match=r"port 99999 is out of range \(0-65535\)"):
        parse_url("tcp:127.0.0.1:99999")
    cfg = from_dict(LinkConfig, {"url": "udpin:0.0.0.0:14540", "long_loss_action": "rtl"}, "link")
    assert cfg.long_loss_action == "rtl"
    with pytest.raises(ConfigError, match=r"^url: port 99999 is out of range"):
        from_dict(LinkConfig, {"url": "tcp:127.0.0.1:99999"}, "link")
    with pytest.raises(ConfigError, match="link.area"):  # where the vehicle may go is the mission's geofence
        from_dict(LinkConfig, {"area": [-200, -200, 200, 200]}, "link")
    with pytest.raises(ConfigError, match="link.heartbeat_timout_s"):
        from_dict(LinkConfig, {"heartbeat_timout_s": 3}, "link")
    with pytest.raises(ConfigError, match="setpoint_period_s"):
        LinkConfig(setpoint_period_s=0.6)
    with pytest.raises(ConfigError, match="url: expected tcp:HOST:PORT"):
        LinkConfig(url="localhost")
    with pytest.raises(ConfigError, match="long_loss_action"):
        LinkConfig(long_loss_action="explode")
