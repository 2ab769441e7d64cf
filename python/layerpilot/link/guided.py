"""Guided flight: map-frame waypoints through the geofence to a setpoint stream (ArduPilot GUIDED,
PX4 OFFBOARD), take-off, and the waits for arrival.

Every waypoint passes the geofence (:class:`~layerpilot.link.geofence.Geofence`: the mission's
area of interest plus a margin, and its altitude limits) before anything is sent, whoever asked;
a refused one raises :class:`~layerpilot.link.errors.WaypointRefused` and is counted in
``refused``. The worker re-sends the current setpoint every ``setpoint_period_s`` and checks it
against the fence again right before it goes out. Without a fence (library and bench use only;
every mission path gives one) the altitude limits of the config still apply.
"""

from __future__ import annotations

import math
import time
from collections import Counter

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mav

from layerpilot.link import modes
from layerpilot.link.commands import Commands
from layerpilot.link.config import LinkConfig
from layerpilot.link.connection import MavlinkPort
from layerpilot.link.control import Control
from layerpilot.link.errors import LinkError, LinkLost, WaypointRefused
from layerpilot.link.frames import enu_to_ned, yaw_enu_to_ned
from layerpilot.link.geofence import Geofence, OutsideGeofence, check_altitude, check_finite
from layerpilot.link.separation import Separation
from layerpilot.link.sync import LinkSync
from layerpilot.link.vehicle_state import VehicleState

POSITION_ONLY = 0b110111111000      # x, y, z used; velocity, acceleration, yaw, yaw rate ignored
POSITION_AND_YAW = 0b100111111000   # as above plus yaw


class Guided:
    """Waypoints, the setpoint stream and the waits for arrival of one link."""

    def __init__(self, config: LinkConfig, geofence: Geofence | None, state: VehicleState, commands: Commands,
                 control: Control, port: MavlinkPort, sync: LinkSync, separation: Separation | None = None) -> None:
        self.config, self.geofence, self.separation = config, geofence, separation
        self.state, self.commands, self.control, self.port, self.sync = state, commands, control, port, sync
        self.refused: Counter[str] = Counter()  # refused waypoints by kind (see WaypointRefused)

    # --- taking control and flying ----------------------------------------------------
    def start(self) -> None:
        """Take control: GUIDED on ArduPilot; on PX4 stream setpoints for ``offboard_prestream_s`` then OFFBOARD."""
        self.state.require_link()
        guided = modes.GUIDED_MODE[self.state.flavour]
        control = self.control
        control.auto = False
        if self.state.flavour == modes.PX4:
            with self.sync.cond:
                control.stream_hold = True
            self.sync.sleep(self.config.offboard_prestream_s)
        control.in_control, control.paused = True, False
        if self.state.mode != guided:
            try:
                self.commands.set_mode(guided)
            except LinkError:
                control.in_control = False
                raise

    def takeoff(self, altitude: float, timeout: float | None = None) -> None:
        """Climb to ``altitude`` metres above home and hold there (NAV_TAKEOFF; PX4: an OFFBOARD setpoint)."""
        self.state.require_link()
        if not self.state.armed:
            raise LinkError("takeoff: the vehicle is not armed")
        home = self.state.home_or_error()
        target = self.check(self.state.position[0], self.state.position[1], home[2] + altitude)
        if self.state.flavour == modes.ARDUPILOT:
            upsets = len(self.control.upsets)
            self.commands.command(mav.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, 0, 0, altitude)
            timeout = timeout if timeout is not None else 30.0 + 2.0 * altitude
            if not self._wait_arrival(target, timeout, use_setpoint=False, upsets=upsets, doing="takeoff"):
                raise LinkError(f"takeoff: did not reach {altitude:.1f} m within {timeout:.1f} s")
            self._set(target, None, None, False)
        else:
            self.goto(*target, timeout=timeout)

    def set_waypoint(self, x: float, y: float, z: float, yaw: float | None = None,
                     look_at: tuple[float, float] | None = None, face_waypoint: bool = False,
                     separate: bool = True) -> np.ndarray:
        """Start flying to map-frame (x, y, z) without waiting; the worker re-sends it. Returns the waypoint.

        ``yaw`` (ENU radians), ``look_at`` (a map point to face, e.g. an orbit centre) or
        ``face_waypoint`` choose the heading; by default the autopilot keeps its own. ``separate`` False:
        a return home, which is never refused for another drone's nearness (live it is the autopilot's RTL).
        """
        target = self.check(x, y, z, separate)
        self.state.require_link()
        if self.control.paused:
            raise LinkError(f"paused: the pilot has the vehicle in {self.state.mode}; hand back "
                            f"{modes.GUIDED_MODE[self.state.flavour]} to continue")
        if not self.control.in_control:
            raise LinkError("not in control: call start_guided() first")
        self._set(target, yaw, look_at, face_waypoint)
        return target

    def goto(self, x: float, y: float, z: float, yaw: float | None = None,
             look_at: tuple[float, float] | None = None, face_waypoint: bool = False,
             timeout: float | None = None) -> None:
        """Fly to map-frame (x, y, z) and return once within the tolerance for ``arrival_hold_s``.

        Waits out link losses (they do not count as arrival); raises LinkLost when the link came
        back after a long loss and the configured action was taken, and :class:`ControlLost` at
        once when the pilot takes over, the vehicle disarms or the autopilot reboots.
        """
        upsets = len(self.control.upsets)
        target = self.set_waypoint(x, y, z, yaw, look_at, face_waypoint)
        if timeout is None:
            timeout = 60.0 + 3.0 * float(np.linalg.norm(target - self.state.position))
        if not self._wait_arrival(target, timeout, use_setpoint=True, upsets=upsets, doing="goto"):
            raise LinkError(f"goto: did not arrive at ({x:.1f}, {y:.1f}, {z:.1f}) within {timeout:.1f} s "
                            f"(now at {np.round(self.state.position, 1).tolist()})")

    def _wait_arrival(self, target: np.ndarray, timeout: float, use_setpoint: bool, upsets: int, doing: str) -> bool:
        """True once within tolerance for arrival_hold_s with the link up and not paused; ControlLost
        as soon as an upset after number ``upsets`` (takeover, disarm, reboot) is known."""
        deadline = time.monotonic() + timeout
        since: float | None = None
        while time.monotonic() < deadline:
            if self.sync.stop.is_set():
                raise LinkError("link closed")
            self.sync.check_interrupted("flying to a waypoint")
            self.control.check_upsets(upsets, doing)
            abandoned = self.control.abandoned
            if use_setpoint and abandoned:
                raise LinkLost(f"waypoint abandoned: {abandoned}") if "link loss" in abandoned \
                    else LinkError(f"waypoint abandoned: {abandoned}")
            close = np.linalg.norm(self.state.position - target) <= self.config.arrival_tolerance_m
            if self.state.link_ok and self.state.position_fresh() and close and not self.control.paused:
                since = time.monotonic() if since is None else since
                if time.monotonic() - since >= self.config.arrival_hold_s:
                    return True
            else:
                since = None
            self.sync.sleep(0.05)
        return False

    # --- the geofence -----------------------------------------------------------------
    def check(self, x: float, y: float, z: float, separate: bool = True) -> np.ndarray:
        """The map-frame waypoint as an array if the geofence (and with ``separate`` the fleet's
        separation) allows it, else :class:`WaypointRefused` (counted in ``refused``). Sends nothing."""
        x, y, z = float(x), float(y), float(z)
        try:
            self._fence_check(x, y, z)
            if separate and self.separation is not None:
                self.separation.check(x, y)
        except OutsideGeofence as exc:
            with self.sync.cond:
                self.refused[exc.kind] += 1
            raise WaypointRefused(str(exc), exc.kind) from None  # the caller reports it
        return np.array([x, y, z], dtype=np.float64)

    def _fence_check(self, x: float, y: float, z: float) -> None:
        fence = self.geofence
        if fence is not None:
            fence.check_area(x, y, z)  # needs no home: refused even before HOME_POSITION
        else:
            check_finite(x, y, z)
        home_z = float(self.state.home_or_error()[2])
        if fence is not None:
            fence.check(x, y, z, home_z)
        else:
            check_altitude(x, y, z, home_z, self.config.alt_min_m, self.config.alt_max_m)

    # --- the setpoint stream ----------------------------------------------------------
    def _set(self, target: np.ndarray, yaw: float | None, look_at: tuple[float, float] | None, face: bool) -> None:
        with self.sync.cond:
            self.control.setpoint = (target, yaw, look_at, face)
            self.control.stream_hold, self.control.abandoned = False, ""
        self.send()

    def send(self) -> None:
        """Send the current setpoint now if the failsafes allow it (worker and mission thread)."""
        state, control = self.state, self.control
        with self.sync.cond:
            if not state.link_ok or state.flavour is None:
                return
            hold = control.stream_hold or (control.paused and state.flavour == modes.PX4)
            if hold:
                target, yaw = state.position.copy(), None
            elif control.setpoint is not None and control.in_control and not control.paused:
                target, yaw, look_at, face = control.setpoint
                yaw = self._heading(target, yaw, look_at, face)
            else:
                return
            if state.flavour == modes.ARDUPILOT and state.mode != "GUIDED":
                return
            dropped = None
            if not hold:  # the last gate: a setpoint no longer inside (home moved since) is dropped
                try:
                    self._fence_check(*target)
                except (OutsideGeofence, LinkError) as exc:  # LinkError: home unknown (cannot happen once set)
                    control.setpoint, control.abandoned = None, f"no longer inside the geofence: {exc}"
                    dropped = exc
                    self.refused[getattr(exc, "kind", "altitude")] += 1
        if dropped is not None:
            self.sync.report(f"setpoint dropped: {dropped}")
            return
        n, e, d = enu_to_ned(*target)
        mask = POSITION_ONLY if yaw is None else POSITION_AND_YAW
        self.port.transmit(lambda m: m.set_position_target_local_ned_send(
            int(time.monotonic() * 1000) & 0xFFFFFFFF, state.target_system, state.target_component,
            mav.MAV_FRAME_LOCAL_NED, mask, n, e, d, 0, 0, 0, 0, 0, 0,
            0.0 if yaw is None else yaw_enu_to_ned(yaw), 0))

    def _heading(self, target: np.ndarray, yaw: float | None, look_at: tuple[float, float] | None,
                 face: bool) -> float | None:
        position = self.state.position
        if look_at is not None:
            dx, dy = look_at[0] - position[0], look_at[1] - position[1]
            return math.atan2(dy, dx) if math.hypot(dx, dy) > 1.0 else None
        if face:
            dx, dy = target[0] - position[0], target[1] - position[1]
            return math.atan2(dy, dx) if math.hypot(dx, dy) > 2.0 else None
        return yaw
