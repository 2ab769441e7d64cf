"""Map frame (ENU, z up, yaw counter-clockwise from east) <-> MAVLink NED.

The map frame is ENU everywhere in layerpilot; MAVLink speaks NED (x north,
y east, z down, yaw clockwise from north). This module is the one place the
two meet (the simulator's MAVLink endpoint imports it too).
"""

from __future__ import annotations

import math


def enu_to_ned(x: float, y: float, z: float) -> tuple[float, float, float]:
    """ENU (east, north, up) -> NED (north, east, down)."""
    return (float(y), float(x), -float(z))


def ned_to_enu(n: float, e: float, d: float) -> tuple[float, float, float]:
    """NED (north, east, down) -> ENU (east, north, up)."""
    return (float(e), float(n), -float(d))


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
