"""Map frame (ENU, z up, yaw counter-clockwise from east) <-> MAVLink NED.

The map frame is ENU everywhere in layerpilot; MAVLink speaks NED (x north,
y east, z down, yaw clockwise from north). This module is the one place the
two meet (the simulator's MAVLink endpoint imports it too).

Positions have one more step: an autopilot's local NED frame has its origin at the
EKF origin, which ArduCopter and PX4 set at the first good position on the ground
at home (z = 0 on the ground there). Where that origin lies in the map frame is the
``ekf_origin`` offset (ENU metres); :func:`map_to_local_ned` and
:func:`local_ned_to_map` convert positions between the two, and
:func:`map_to_autopilot_enu` / :func:`autopilot_enu_to_map` do the same without the
axis swap (for a link that speaks the autopilot's local frame in ENU). Velocities
and attitudes have no offset.
"""

from __future__ import annotations

import math


def enu_to_ned(x: float, y: float, z: float) -> tuple[float, float, float]:
    """ENU (east, north, up) -> NED (north, east, down)."""
    return (float(y), float(x), -float(z))


def ned_to_enu(n: float, e: float, d: float) -> tuple[float, float, float]:
    """NED (north, east, down) -> ENU (east, north, up)."""
    return (float(e), float(n), -float(d))


def _origin(ekf_origin) -> tuple[float, float, float]:
    if ekf_origin is None:
        return (0.0, 0.0, 0.0)
    x, y, z = (float(c) for c in ekf_origin)
    return x, y, z


def map_to_autopilot_enu(x: float, y: float, z: float, ekf_origin=None) -> tuple[float, float, float]:
    """Map-frame position -> the autopilot's local frame in ENU (metres from its EKF origin)."""
    ox, oy, oz = _origin(ekf_origin)
    return (float(x) - ox, float(y) - oy, float(z) - oz)


def autopilot_enu_to_map(x: float, y: float, z: float, ekf_origin=None) -> tuple[float, float, float]:
    """Inverse of :func:`map_to_autopilot_enu`."""
    ox, oy, oz = _origin(ekf_origin)
    return (float(x) + ox, float(y) + oy, float(z) + oz)


def map_to_local_ned(x: float, y: float, z: float, ekf_origin=None) -> tuple[float, float, float]:
    """Map-frame position (ENU) -> LOCAL_POSITION_NED coordinates relative to the EKF origin.

    ``ekf_origin``: where the autopilot's EKF origin (home, on the ground) lies in the map
    frame; None is the map origin itself.
    """
    return enu_to_ned(*map_to_autopilot_enu(x, y, z, ekf_origin))


def local_ned_to_map(n: float, e: float, d: float, ekf_origin=None) -> tuple[float, float, float]:
    """LOCAL_POSITION_NED coordinates (relative to the EKF origin) -> map-frame position (ENU)."""
    return autopilot_enu_to_map(*ned_to_enu(n, e, d), ekf_origin)


def wrap_pi(angle: float) -> float:
    """Angle wrapped into [-pi, pi)."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


def yaw_enu_to_ned(yaw_enu: float) -> float:
    """ENU yaw (CCW from east) -> NED yaw (CW from north), wrapped to [-pi, pi)."""
    return wrap_pi(math.pi / 2.0 - yaw_enu)


def yaw_ned_to_enu(yaw_ned: float) -> float:
    """NED yaw (CW from north) -> ENU yaw (CCW from east), wrapped to [-pi, pi)."""
    return wrap_pi(math.pi / 2.0 - yaw_ned)


def attitude_ned_to_enu(roll: float, pitch: float, yaw: float) -> tuple[float, float, float]:
    """Euler angles of body FRD in NED -> body FLU in ENU (the ROS/REP-103 convention).

    Roll keeps its sign, pitch flips (nose-up is positive in FRD/NED and negative about
    FLU's left-pointing y axis), yaw becomes counter-clockwise from east.
    """
    return float(roll), -float(pitch), yaw_ned_to_enu(yaw)


def attitude_enu_to_ned(roll: float, pitch: float, yaw: float) -> tuple[float, float, float]:
    """Inverse of :func:`attitude_ned_to_enu`."""
    return float(roll), -float(pitch), yaw_enu_to_ned(yaw)
