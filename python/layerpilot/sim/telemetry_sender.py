"""The simulated autopilot's telemetry messages, each as ArduCopter (or PX4) fills it in.

Positions and attitude are the EKF's (the truth plus the sensors' errors), GPS_RAW_INT the
receiver's own fix; home and the EKF origin are exact. Map frame (ENU) to MAVLink's NED and
lat/lon/alt through the datum (``EndpointConfig.origin``).
"""

from __future__ import annotations

import math

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mav

from layerpilot.link import modes
from layerpilot.link.frames import enu_to_ned, map_to_local_ned, yaw_enu_to_ned
from layerpilot.sim.auto_mode import AutoMode
from layerpilot.sim.autopilot_state import AutopilotState

# EKF_STATUS_REPORT flags, after ArduCopter's estimator: without GPS attitude, vertical velocity
# and height in constant-position mode (0xA5 = 165); with a 3D fix and the origin set, attitude,
# velocities, relative and absolute horizontal position, absolute height and the predicted
# positions (0x33F = 831).
EKF_FLAGS_NO_GPS = (mav.EKF_ATTITUDE | mav.EKF_VELOCITY_VERT | mav.EKF_POS_VERT_ABS | mav.EKF_CONST_POS_MODE)
EKF_FLAGS_GOOD = (mav.EKF_ATTITUDE | mav.EKF_VELOCITY_HORIZ | mav.EKF_VELOCITY_VERT | mav.EKF_POS_HORIZ_REL
                  | mav.EKF_POS_HORIZ_ABS | mav.EKF_POS_VERT_ABS | mav.EKF_PRED_POS_HORIZ_REL
                  | mav.EKF_PRED_POS_HORIZ_ABS)

SENSORS = (mav.MAV_SYS_STATUS_SENSOR_3D_GYRO | mav.MAV_SYS_STATUS_SENSOR_3D_ACCEL | mav.MAV_SYS_STATUS_SENSOR_3D_MAG
           | mav.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE | mav.MAV_SYS_STATUS_SENSOR_GPS
           | mav.MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL | mav.MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION
           | mav.MAV_SYS_STATUS_SENSOR_Z_ALTITUDE_CONTROL | mav.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL
           | mav.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS | mav.MAV_SYS_STATUS_AHRS | mav.MAV_SYS_STATUS_SENSOR_BATTERY)
GUIDED_FLAG_MODES = ("GUIDED", "OFFBOARD", "RTL", "LAND", "LOITER", "TAKEOFF", "AUTO", "MISSION")


class TelemetrySender:
    """One method per message, named after it (``heartbeat``, ``gps_raw_int``, ...): sends it now."""

    def __init__(self, state: AutopilotState, auto: AutoMode) -> None:
        self._s = state
        self._auto = auto

    def heartbeat(self) -> None:
        s = self._s
        base = mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | mav.MAV_MODE_FLAG_STABILIZE_ENABLED
        if s.mode in GUIDED_FLAG_MODES:
            base |= mav.MAV_MODE_FLAG_GUIDED_ENABLED
        if s.armed:
            base |= mav.MAV_MODE_FLAG_SAFETY_ARMED
        autopilot = mav.MAV_AUTOPILOT_ARDUPILOTMEGA if s.flavour == modes.ARDUPILOT else mav.MAV_AUTOPILOT_PX4
        s.mav.heartbeat_send(mav.MAV_TYPE_QUADROTOR, autopilot, base, modes.custom_mode_of(s.flavour, s.mode),
                             mav.MAV_STATE_ACTIVE if s.armed else mav.MAV_STATE_STANDBY)

    def sys_status(self) -> None:
        s = self._s
        present = SENSORS | mav.MAV_SYS_STATUS_PREARM_CHECK
        health = SENSORS if s.has_fix() else SENSORS & ~mav.MAV_SYS_STATUS_SENSOR_GPS
        if s.prearm_ok():
            health |= mav.MAV_SYS_STATUS_PREARM_CHECK
        b = s.battery
        s.mav.sys_status_send(present, present, health, 200, int(b.voltage * 1000), int(b.current_a * 100),
                              int(round(100 * b.remaining)), 0, 0, 0, 0, 0, 0)

    def battery_status(self) -> None:
        """As ArduCopter sends it without cell monitoring: the pack voltage in the first cell, the others unknown."""
        b = self._s.battery
        cells = [min(int(b.voltage * 1000), 65534)] + [65535] * 9
        self._s.mav.battery_status_send(0, mav.MAV_BATTERY_FUNCTION_UNKNOWN, mav.MAV_BATTERY_TYPE_LIPO, 32767,
                                        cells, int(b.current_a * 100), int(b.consumed_mah), -1,
                                        int(round(100 * b.remaining)))

    def mission_current(self) -> None:
        self._auto.send_current()

    def system_time(self) -> None:
        self._s.mav.system_time_send(0, self._s.boot_ms())

    def gps_raw_int(self) -> None:
        """The receiver's own fix: its error without the EKF's (no barometer, no white noise smoothing)."""
        s = self._s
        gnss = 0.0 if s.exact_pose else s.estimator.errors.current.gnss
        lat, lon, alt = self._geodetic(s.vehicle.position + gnss)
        v = s.vehicle.velocity
        fix = s.has_fix()
        cog = int(math.degrees(math.atan2(v[0], v[1])) % 360 * 100) if np.hypot(v[0], v[1]) > 0.2 else 0xFFFF
        s.mav.gps_raw_int_send(int(s.uptime * 1e6), mav.GPS_FIX_TYPE_3D_FIX if fix else mav.GPS_FIX_TYPE_NO_FIX,
                               lat, lon, alt, 80, 120, int(np.hypot(v[0], v[1]) * 100), cog, 14 if fix else 3)

    def global_position_int(self) -> None:
        s = self._s
        reported = s.reported_pose()
        lat, lon, alt = self._geodetic(reported.position)
        vn, ve, vd = enu_to_ned(*reported.velocity)
        relative = int(round((reported.position[2] - s.home[2]) * 1000))
        hdg = int(round(math.degrees(yaw_enu_to_ned(reported.yaw)) % 360 * 100)) % 36000
        s.mav.global_position_int_send(s.boot_ms(), lat, lon, alt, relative, int(vn * 100), int(ve * 100),
                                       int(vd * 100), hdg)

    def local_position_ned(self) -> None:
        s = self._s
        reported = s.reported_pose()
        n, e, d = map_to_local_ned(*reported.position, s.ekf_origin)
        vn, ve, vd = enu_to_ned(*reported.velocity)
        s.mav.local_position_ned_send(s.boot_ms(), n, e, d, vn, ve, vd)

    def attitude(self) -> None:
        s = self._s
        reported = s.reported_pose()
        s.mav.attitude_send(s.boot_ms(), reported.roll, reported.pitch, yaw_enu_to_ned(reported.yaw), 0.0, 0.0,
                            -s.vehicle.yaw_rate)

    def home_position(self) -> None:
        """Home's latitude, longitude and altitude AMSL (the world's datum plus the terrain height under home);
        its local position relative to the EKF origin, which is home on the ground: 0, 0, 0, what ArduPilot
        always sends there (should a test move ``home``, the endpoint sends the offset, which ArduPilot would not)."""
        s = self._s
        n, e, d = map_to_local_ned(*s.home, s.ekf_origin)
        s.mav.home_position_send(*self._geodetic(s.home), n, e, d, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0,
                                 int(s.uptime * 1e6))

    def gps_global_origin(self) -> None:
        """The EKF origin's latitude, longitude and altitude AMSL (the local NED frame's 0, 0, 0)."""
        s = self._s
        s.mav.gps_global_origin_send(*self._geodetic(s.ekf_origin), int(s.uptime * 1e6))

    def ekf_status_report(self) -> None:
        if self._s.has_fix():
            self._s.mav.ekf_status_report_send(EKF_FLAGS_GOOD, 0.02, 0.01, 0.01, 0.02, 0.0)
        else:
            self._s.mav.ekf_status_report_send(EKF_FLAGS_NO_GPS, 0.0, 0.0, 0.0, 0.02, 0.0)

    def _geodetic(self, point) -> tuple[int, int, int]:
        """A map-frame point as MAVLink's lat, lon (1e-7 degrees) and altitude AMSL (mm)."""
        lat, lon, alt = self._s.config.origin.to_geodetic(*point)
        return int(round(float(lat) * 1e7)), int(round(float(lon) * 1e7)), int(round(float(alt) * 1000))
