"""ArduCopter's AUTO mode for the simulated vehicle: fly the stored mission item by item.

As ArduCopter does it: item 0 is home and is not flown; the mission starts at item 1.
NAV_WAYPOINT flies to its place (lat and lon both 0: where the vehicle is; altitude
relative to home in the GLOBAL_RELATIVE_ALT frames, above mean sea level in GLOBAL) and
is reached within its acceptance radius (param2; 0 means WPNAV_RADIUS, 2 m) - flying
through when a waypoint follows without a hold, else once stopped there - then holds param1
seconds; it faces the waypoint on the way (WP_YAW_BEHAVIOR 2) unless param4 gives a
heading. NAV_TAKEOFF climbs to its altitude where the vehicle is. NAV_LAND (flown to its
place first when it has one, at the height it is at, until stopped there within WPNAV_RADIUS)
and NAV_RETURN_TO_LAUNCH hand the vehicle to the endpoint's landing and RTL, which end in a
disarm. A DO_* item (the simulator knows DO_CHANGE_SPEED) is done at once, as ArduCopter starts
it on the way. Starting an item sends MISSION_CURRENT and the
STATUSTEXT ``Mission: N WP``; completing one ``Reached command #N`` and MISSION_ITEM_REACHED.
After the last item the mission is complete and the vehicle loiters where it is, still in
AUTO (ArduCopter's exit_mission). Leaving AUTO and coming back resumes at the current item
(MIS_RESTART 0); after completion it starts again from item 1.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mav

from layerpilot.geodesy import LocalFrame
from layerpilot.link.frames import yaw_ned_to_enu
from layerpilot.link.mission_transfer import MissionItem
from layerpilot.sim.vehicle import Multicopter

WPNAV_RADIUS_M = 2.0         # ArduCopter's default waypoint radius
TAKEOFF_REACHED_M = 0.3      # a takeoff is complete this close to its altitude
STOPPED_M_S = 0.3            # a waypoint the vehicle stops at is reached once it is this slow
LOOK_AT_MIN_DISTANCE_M = 2.0  # WP_YAW_BEHAVIOR 2: face the waypoint while farther than this
_NAMES = {mav.MAV_CMD_NAV_WAYPOINT: "WP", mav.MAV_CMD_NAV_TAKEOFF: "Takeoff", mav.MAV_CMD_NAV_LAND: "Land",
          mav.MAV_CMD_NAV_RETURN_TO_LAUNCH: "RTL"}


class AutoMission:
    """One run of a stored mission; the endpoint calls :meth:`step` every step while in AUTO and airborne."""

    def __init__(self, mavlink: mav.MAVLink, items: list[MissionItem], frame: LocalFrame, home: np.ndarray,
                 run: Callable[[MissionItem], None], first: int = 1) -> None:
        """``run``: the endpoint's way of doing a DO_* item (as its COMMAND_LONG would)."""
        if len(items) <= first:
            raise ValueError(f"mission: no items to fly after item {first - 1}")
        self._mav = mavlink
        self._run = run
        self.items = items
        self._frame = frame
        self._home = home
        self._first = first  # ArduPilot's item 0 is home: 1; PX4's missions start at 0
        self.current = first
        self.complete = False
        self._target: np.ndarray | None = None  # where the current item flies; None until it starts
        self._reached_at: float | None = None

    @property
    def state(self) -> int:
        return mav.MISSION_STATE_COMPLETE if self.complete else mav.MISSION_STATE_ACTIVE

    def resume(self, vehicle: Multicopter) -> None:
        """(Re)start the current item: AUTO entered, or the next item."""
        item = self.items[self.current]
        self._reached_at = None
        self._target = item.place(self._frame, float(self._home[2]), vehicle.position)
        if item.command == mav.MAV_CMD_NAV_TAKEOFF:
            self._target[:2] = vehicle.position[:2]
        elif item.command == mav.MAV_CMD_NAV_LAND:
            self._target[2] = vehicle.position[2]  # there at this height, then down
        if item.command in (mav.MAV_CMD_NAV_WAYPOINT, mav.MAV_CMD_NAV_TAKEOFF, mav.MAV_CMD_NAV_LAND):
            vehicle.set_position_target(*self._target, yaw=self._yaw(item, vehicle))
        self._mav.statustext_send(mav.MAV_SEVERITY_INFO,
                                  f"Mission: {self.current} {_NAMES.get(item.command, item.command)}".encode())
        self.send_current()

    def step(self, vehicle: Multicopter, now: float) -> str:
        """Advance the mission; returns ``"land"`` or ``"rtl"`` when the endpoint must take over, else ``""``."""
        if self.complete:
            return ""
        if self._target is None:
            self.resume(vehicle)
        item = self.items[self.current]
        if item.command == mav.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            return "rtl"
        if not item.flies:  # a DO_* item: done at once, on the way
            self._run(item)
            self._advance(vehicle)
            return ""
        error = vehicle.position - self._target
        if item.command == mav.MAV_CMD_NAV_LAND:  # ArduCopter flies to the point, then lands where it stopped
            there = float(np.hypot(error[0], error[1])) <= WPNAV_RADIUS_M
            return "land" if there and float(np.linalg.norm(vehicle.velocity)) <= STOPPED_M_S else ""
        hold = item.params[0] if item.command == mav.MAV_CMD_NAV_WAYPOINT and item.params[0] > 0.0 else 0.0
        if item.command == mav.MAV_CMD_NAV_TAKEOFF:
            arrived = abs(error[2]) <= TAKEOFF_REACHED_M
        else:
            radius = item.params[1] if item.params[1] > 0.0 else WPNAV_RADIUS_M
            arrived = float(np.linalg.norm(error)) <= radius
            if hold > 0.0 or not self._passes_through():  # a stop there: reached once stopped
                arrived = arrived and float(np.linalg.norm(vehicle.velocity)) <= STOPPED_M_S
        if self._reached_at is None:
            if not arrived:
                return ""
            self._reached_at = now
        if now - self._reached_at >= hold:
            self._advance(vehicle)
        return ""

    def _passes_through(self) -> bool:
        """ArduCopter flies through a waypoint (reached at its radius) when a waypoint follows; it stops
        at the last one and before a takeoff, landing or return."""
        nxt = self.current + 1
        return nxt < len(self.items) and self.items[nxt].command == mav.MAV_CMD_NAV_WAYPOINT

    def send_current(self, in_auto: bool = True) -> None:
        """MISSION_CURRENT: the item flown, the number of items (without ArduPilot's home), the mission's state, and
        whether the vehicle is in its mission mode (1) or not (0)."""
        self._mav.mission_current_send(self.current, len(self.items) - self._first, self.state, int(in_auto))

    def _advance(self, vehicle: Multicopter) -> None:
        self._mav.statustext_send(mav.MAV_SEVERITY_INFO, f"Reached command #{self.current}".encode())
        self._mav.mission_item_reached_send(self.current)
        if self.current + 1 < len(self.items):
            self.current += 1
            self.resume(vehicle)
        else:
            self.complete = True
            vehicle.hold()  # ArduCopter's exit_mission: loiter here, in AUTO
            self.send_current()

    def _yaw(self, item: MissionItem, vehicle: Multicopter) -> float | None:
        if item.command == mav.MAV_CMD_NAV_WAYPOINT and math.isfinite(item.params[3]):
            return yaw_ned_to_enu(math.radians(item.params[3]))
        dx, dy = self._target[0] - vehicle.position[0], self._target[1] - vehicle.position[1]
        return math.atan2(dy, dx) if math.hypot(dx, dy) > LOOK_AT_MIN_DISTANCE_M else None
