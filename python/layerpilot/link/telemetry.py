"""What the flight link knows about the vehicle, in the map frame (ENU) on the mission clock."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Telemetry:
    """A snapshot. Angles in radians: roll/pitch of body FLU, yaw counter-clockwise from east.

    ``time`` is the mission clock when the pose arrived; ``boot_time`` is the autopilot's
    own clock in that pose (time_boot_ms, s), the one clock every process of a mission
    shares; ``heartbeat_age`` is wall seconds since the autopilot's last HEARTBEAT;
    ``link_ok`` is False while lost.
    """

    time: float
    boot_time: float
    position: np.ndarray
    velocity: np.ndarray
    roll: float
    pitch: float
    yaw: float
    armed: bool
    mode: str
    autopilot: str
    battery_voltage: float
    battery_remaining: int
    link_ok: bool
    heartbeat_age: float
    home: np.ndarray | None
    paused: bool

    def line(self) -> str:
        """One readable line for logs and the command line."""
        x, y, z = self.position
        return (f"t={self.time:8.2f}  pos=({x:8.2f}, {y:8.2f}, {z:7.2f}) m  yaw={np.degrees(self.yaw):7.1f} deg  "
                f"{self.mode:<9} {'ARMED' if self.armed else 'disarmed':<8}  batt={self.battery_voltage:5.2f} V "
                f"{self.battery_remaining:3d}%  link={'ok' if self.link_ok else 'LOST'}"
                f"{'  PAUSED' if self.paused else ''}")
