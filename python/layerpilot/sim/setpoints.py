"""Guided setpoints: SET_POSITION_TARGET_LOCAL_NED and _GLOBAL_INT, followed as ArduCopter (GUIDED) or PX4
(OFFBOARD) follows them, with the type_mask honoured and the target taken in the vehicle's estimated frame."""

from __future__ import annotations

import math

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mav

from layerpilot.link import modes
from layerpilot.link.frames import local_ned_to_map, ned_to_enu, yaw_enu_to_ned, yaw_ned_to_enu
from layerpilot.sim.auto_mission import LOOK_AT_MIN_DISTANCE_M
from layerpilot.sim.autopilot_state import AutopilotState

POS_IGNORE = 0b111
VEL_IGNORE = 0b111000
YAW_IGNORE = 1024
YAW_RATE_IGNORE = 2048
GUIDED_VELOCITY_TIMEOUT_S = 3.0  # ArduCopter stops a velocity-only guided command after 3 s


class Setpoints:
    """Takes every setpoint message; follows it when the mode does (GUIDED airborne, or OFFBOARD)."""

    def __init__(self, state: AutopilotState) -> None:
        self._s = state

    def handle(self, msg: mav.MAVLink_message) -> None:
        s = self._s
        s.setpoint_times = [t for t in s.setpoint_times if t > s.time - 1.0] + [s.time]
        follows = s.mode == "OFFBOARD" if s.flavour == modes.PX4 else (s.mode == "GUIDED" and s.airborne)
        if not follows or not s.armed:
            return
        mask = msg.type_mask
        if msg.get_type() == "SET_POSITION_TARGET_LOCAL_NED":
            position, velocity = self._local_target(msg)
        else:
            position, velocity = self._global_target(msg)
        if position is None and velocity is None:
            return
        v = s.vehicle
        yaw = None if mask & YAW_IGNORE else yaw_ned_to_enu(msg.yaw)
        if mask & POS_IGNORE != POS_IGNORE:
            if yaw is None and mask & YAW_RATE_IGNORE and s.flavour == modes.ARDUPILOT:
                yaw = self._look_at(position)
            v.set_position_target(*position, yaw=yaw)
            s.velocity_deadline = None
            s.airborne = s.airborne or position[2] > v.ground_z + 0.2
        elif mask & VEL_IGNORE != VEL_IGNORE:
            v.set_velocity_target(*velocity, yaw=yaw)
            s.velocity_deadline = s.time + GUIDED_VELOCITY_TIMEOUT_S
            s.airborne = s.airborne or velocity[2] > 0.0
        else:
            v.set_yaw_target(yaw=yaw)
        if yaw is None and not mask & YAW_RATE_IGNORE:
            v.set_yaw_target(yaw_rate=-msg.yaw_rate)

    def stream_ok(self) -> bool:
        """PX4's offboard condition: setpoints arriving faster than ``offboard_min_rate_hz`` right now."""
        s = self._s
        recent = [t for t in s.setpoint_times if t > s.time - 1.0]
        return bool(recent) and s.time - recent[-1] <= 1.0 / s.config.offboard_min_rate_hz \
            and len(recent) >= s.config.offboard_min_rate_hz

    def _look_at(self, position) -> float | None:
        """ArduCopter's default WP_YAW_BEHAVIOR (2): face the destination while it is more than 2 m away."""
        here = self._s.vehicle.position
        dx, dy = position[0] - here[0], position[1] - here[1]
        return math.atan2(dy, dx) if math.hypot(dx, dy) > LOOK_AT_MIN_DISTANCE_M else None

    def _local_target(self, msg: mav.MAVLink_message) -> tuple[tuple | None, tuple | None]:
        s = self._s
        frame = msg.coordinate_frame
        n, e, d = msg.x, msg.y, msg.z
        vn, ve, vd = msg.vx, msg.vy, msg.vz
        if frame in (mav.MAV_FRAME_BODY_NED, mav.MAV_FRAME_BODY_OFFSET_NED):
            heading = yaw_enu_to_ned(s.vehicle.yaw)
            c, si = math.cos(heading), math.sin(heading)
            n, e = c * n - si * e, si * n + c * e
            vn, ve = c * vn - si * ve, si * vn + c * ve
        elif frame not in (mav.MAV_FRAME_LOCAL_NED, mav.MAV_FRAME_LOCAL_OFFSET_NED):
            s.text(mav.MAV_SEVERITY_WARNING, f"Unsupported setpoint frame {frame}")
            return None, None
        if frame == mav.MAV_FRAME_LOCAL_NED:
            position = s.true_target(local_ned_to_map(n, e, d, s.ekf_origin))   # relative to the EKF origin
        else:
            position = tuple(np.add(ned_to_enu(n, e, d), s.vehicle.position))
        return position, ned_to_enu(vn, ve, vd)

    def _global_target(self, msg: mav.MAVLink_message) -> tuple[tuple | None, tuple | None]:
        s = self._s
        frame = msg.coordinate_frame
        home_amsl = s.config.origin.alt + s.home[2]
        if frame in (mav.MAV_FRAME_GLOBAL, mav.MAV_FRAME_GLOBAL_INT):
            alt = msg.alt
        elif frame in (mav.MAV_FRAME_GLOBAL_RELATIVE_ALT, mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                       mav.MAV_FRAME_GLOBAL_TERRAIN_ALT, mav.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT):
            alt = home_amsl + msg.alt
        else:
            s.text(mav.MAV_SEVERITY_WARNING, f"Unsupported setpoint frame {frame}")
            return None, None
        x, y, z = s.config.origin.from_geodetic(msg.lat_int * 1e-7, msg.lon_int * 1e-7, alt)
        return s.true_target((float(x), float(y), float(z))), ned_to_enu(msg.vx, msg.vy, msg.vz)
